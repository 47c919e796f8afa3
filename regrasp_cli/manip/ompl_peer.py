"""A peer single-query planner: OMPL's RRT-Connect on the queries of §V-B (issue 6).

The paper compares its roadmap planner with an RRT-Connect baseline (§VI).  To tell how
much of that comparison comes from our own RRT-Connect (:mod:`regrasp_cli.motion.rrt`),
``ompl-rrtconnect`` hands the very same four queries to OMPL's ``geometric::RRTConnect``
(the optional ``ompl`` extra, imported lazily) and changes nothing else:

* the state space is the moving joints (torso, right arm, left arm) within their limits;
  every other joint keeps its value in ``a`` with the phase's finger values;
* the metric is ours: a coordinate of the state is a joint value times the square root of
  its weight, so OMPL's Euclidean distance *is* :func:`regrasp_cli.motion.local.distance`
  and its ``range`` is our RRT step (``options.rrt.step``) in the same units;
* states are checked with ``worlds.full.is_free`` and motions with OUR certified dense
  segment check (``scratch.segment_free``) through a ``MotionValidator`` subclass, so
  OMPL's discrete resolution-based validator is never used;
* the budget is the RRT baseline's iteration count (``options.rrt.max_iterations``; OMPL
  evaluates the termination condition once per iteration, we count those evaluations),
  with ``options.ompl_time`` seconds as a wall-clock guard;
* OMPL's generator is seeded from the scratch's generator before every query (its
  samples are its own), and the path is shortcut by our :func:`smooth`, not OMPL's
  simplifier.

Differences that remain are the planner's own: OMPL's RRT-Connect has no goal bias (ours
samples the other root 5 % of the time) and uses GNAT nearest-neighbour search.
"""

from __future__ import annotations

import time
from importlib import metadata

import numpy as np

from regrasp_cli.errors import InputError
from regrasp_cli.manip.context import Scratch
from regrasp_cli.manip.queries import PhaseWorlds, QueryFailed, QueryStats, set_fingers, smooth

MOVING_GROUPS = ("torso", "right_arm", "left_arm")
MISSING = "ompl-rrtconnect needs the optional extra: pip install 'regrasp[ompl]'"


def _ompl():
    """The ompl modules (base, geometric, util), or InputError naming the extra."""
    try:
        from ompl import base, geometric, util
    except ImportError as exc:
        raise InputError(None, "--planner", MISSING) from exc
    return base, geometric, util


def ompl_version() -> str:
    """The installed OMPL Python package's version, e.g. ``"2.0.1"``."""
    _ompl()
    return metadata.version("ompl")


def _space_information(ob, scratch: Scratch, worlds: PhaseWorlds, lower: np.ndarray, upper: np.ndarray, to_q):
    """OMPL's space (the scaled moving joints within ``lower``..``upper``) with our
    collision checks: the validity of a state, and of a motion by our certified dense
    segment check."""
    n = len(lower)
    space = ob.RealVectorStateSpace(n)
    bounds = ob.RealVectorBounds(n)
    for i, (lo, hi) in enumerate(zip(lower, upper)):
        bounds.setLow(i, float(lo))
        bounds.setHigh(i, float(hi))
    space.setBounds(bounds)
    si = ob.SpaceInformation(space)
    si.setStateValidityChecker(lambda s: worlds.full.is_free(to_q(s)))

    class SegmentValidator(ob.MotionValidator):
        def checkMotion(self, s0, s1) -> bool:  # noqa: N802 (OMPL's name)
            return scratch.segment_free(worlds.full, to_q(s0), to_q(s1))

    si.setMotionValidator(SegmentValidator(si))
    si.setup()
    return si


def _exact_ends(scratch: Scratch, worlds: PhaseWorlds, path: np.ndarray, a: np.ndarray, b: np.ndarray) -> None:
    """The path's ends set to a and b exactly (not through the scaling, ~1e-16 off; b
    with its own non-moving joints): a segment next to an end is checked again only if
    that moved it noticeably.  Raises QueryFailed when that segment collides."""
    for end, q, near in ((0, a, 1), (-1, b, -2)):
        moved = float(np.abs(path[end] - q).max()) > 1e-9
        path[end] = q
        if moved and len(path) > 1 and not scratch.segment_free(worlds.full, path[near], q):
            raise QueryFailed("OMPL RRT-Connect's path reaches its end through a collision (the non-moving "
                              "joints differ between the ends)")


def ompl_query(scratch: Scratch, rng: np.random.Generator, a: np.ndarray, b: np.ndarray, worlds: PhaseWorlds, weights: np.ndarray,
               stats: QueryStats) -> np.ndarray:
    """A collision-free path (k, nq) from a to b (both free in ``worlds.full``), found by
    OMPL's RRT-Connect and shortcut; the contract of :func:`queries.rrt_query`.

    Raises:
        QueryFailed: OMPL found no exact solution within the budget (its status named).
        InputError: the ``ompl`` package is not installed.
    """
    ob, og, ou = _ompl()
    t0 = time.perf_counter()
    robot, o = scratch.problem.robot, scratch.options
    moving = np.concatenate([robot.groups[g] for g in MOVING_GROUPS])
    n = len(moving)
    scale = np.sqrt(np.asarray(weights, float)[moving])  # state = sqrt(w) * q: Euclidean = weighted
    base = set_fingers(scratch, np.asarray(a, float), worlds.fingers)

    def to_q(state) -> np.ndarray:
        q = base.copy()
        q[moving] = np.fromiter((state[i] for i in range(n)), float, n) / scale
        return q

    si = _space_information(ob, scratch, worlds, robot.lower[moving] * scale, robot.upper[moving] * scale, to_q)

    level = ou.getLogLevel()
    ou.setLogLevel(ou.LOG_NONE)  # reseeding after the first query logs an error, yet takes effect
    ou.RNG.setSeed(int(rng.integers(1, 2**31 - 1)))  # 0 is refused
    ou.setLogLevel(ou.LOG_WARN)
    try:
        setup = og.SimpleSetup(si)
        start, goal = si.allocState(), si.allocState()
        for i, (x, y) in enumerate(zip(a[moving] * scale, b[moving] * scale)):
            start[i], goal[i] = float(x), float(y)
        setup.setStartAndGoalStates(start, goal)
        planner = og.RRTConnect(si)
        planner.setRange(float(o.rrt.step))
        setup.setPlanner(planner)
        evaluations = 0

        def stop() -> bool:
            nonlocal evaluations
            evaluations += 1
            return evaluations > o.rrt.max_iterations or time.perf_counter() - t0 > o.ompl_time

        status = setup.solve(ob.PlannerTerminationCondition(stop))
        data = ob.PlannerData(si)
        setup.getPlannerData(data)
        stats.nodes += int(data.numVertices())
        stats.rrt_calls += 1
        if not setup.haveExactSolutionPath():
            stats.planning += time.perf_counter() - t0
            budget = (f"{o.ompl_time:g} s" if evaluations <= o.rrt.max_iterations
                      else f"{o.rrt.max_iterations} iterations")
            raise QueryFailed(f"OMPL RRT-Connect found no path within its budget of {budget} ({status})")
        solution = setup.getSolutionPath()
        path = np.array([to_q(solution.getState(i)) for i in range(solution.getStateCount())])
    finally:
        ou.setLogLevel(level)
    try:
        _exact_ends(scratch, worlds, path, a, b)
    finally:
        stats.planning += time.perf_counter() - t0
    t0 = time.perf_counter()
    path = smooth(scratch, rng, path, worlds.full, weights)
    stats.planning += time.perf_counter() - t0
    return path
