"""Solving a path through manipulation modes (:mod:`regrasp_cli.manip.modes`).

A task hands over a list of :class:`Step`: a transition and the pieces of its waypoints,
in order, each either fixed by the task's key configurations (approach, lift and retreat
lines, finger closing and opening: the grasp, release and hand-over transitions are solved
by these straight lines) or the label of a :class:`Query`, a transit or transfer between
two configurations solved by the planner's path solver: the Super Graph query with lazy
revalidation and repair (Saut et al. 2010 §V-B, :func:`queries.roadmap_query`),
single-query RRT-Connect (:func:`queries.rrt_query`) or OMPL's (:func:`ompl_peer.ompl_query`).
Queries are independent once the key configurations are fixed: each has its own random
stream, so they give the same paths run in turn or in parallel.  The solved steps become
phases, timed without stopping where the corners can be cut (:mod:`regrasp_cli.motion.blend`):
at each interior corner of a phase a blend is tried and kept when its curve is free, checked
like the segments it replaces (in the query's certified world when both segments lie on a
query's path, else in the phase's world without clearance, as the approach and lift lines
were); a corner whose blend collides is a stop.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from regrasp_cli.manip.context import Scratch
from regrasp_cli.manip.modes import Transition
from regrasp_cli.manip.ompl_peer import ompl_query
from regrasp_cli.manip.queries import PhaseWorlds, QueryFailed, QueryStats, Roadmap, roadmap_query, rrt_query
from regrasp_cli.manip.status import PlanningFailed, Stage
from regrasp_cli.motion.blend import Timing, blended_path, choose_radii, time_optimal
from regrasp_cli.motion.timing import time_parameterise
from regrasp_cli.parallel import ordered_map


@dataclass(frozen=True)
class Query:
    """A transit or transfer from configuration a to b (nq,), in the phase's worlds."""

    label: str
    a: np.ndarray
    b: np.ndarray
    worlds: PhaseWorlds


@dataclass(frozen=True)
class QueryResult:
    label: str
    path: np.ndarray | None  # (k, nq), None when it failed
    stats: QueryStats
    error: str | None  # why it failed
    checks: int  # collision checks it made


@dataclass(frozen=True)
class Step:
    """A transition and its waypoint pieces: arrays (k, nq), or a query label.  A step
    of the fingers turning the object (the in-hand kinds) has one piece, and the object's
    poses (k, 4, 4) in W and the contacts at each of its waypoints."""

    transition: Transition
    pieces: tuple = ()
    object_poses: np.ndarray | None = None
    contacts: tuple | None = None


@dataclass(frozen=True)
class PhaseMotion:
    """A solved, timed transition: waypoints (k, nq), the time (k,) s from the plan start
    at which the motion passes each waypoint, blend radii (k,) (0: a stop) and the path
    speed ``timing`` (grid times from the plan start), both None when it stops at every
    waypoint (trapezoids)."""

    transition: Transition
    waypoints: np.ndarray
    times: np.ndarray
    radii: np.ndarray | None = None
    timing: Timing | None = None
    object_poses: np.ndarray | None = None  # (k, 4, 4), an in-hand step's
    contacts: tuple | None = None


@dataclass(frozen=True)
class TransitionStats:
    """Table I of Saut et al. 2010 per solved query: n nodes, T seconds."""

    nodes: int = 0
    searches: int = 0
    invalid_edges: int = 0
    rrt_calls: int = 0
    planning_s: float = 0.0
    validation_s: float = 0.0

    def plus(self, q: QueryStats) -> "TransitionStats":
        return TransitionStats(self.nodes + q.nodes, self.searches + q.searches,
                               self.invalid_edges + q.invalid_edges, self.rrt_calls + q.rrt_calls,
                               self.planning_s + q.planning, self.validation_s + q.validation)

    def counts(self) -> dict:
        return {"nodes": self.nodes, "searches": self.searches, "invalid_edges": self.invalid_edges,
                "rrt_calls": self.rrt_calls}


@dataclass(frozen=True)
class Outcome:
    """What a planning run produced; ``failure`` is set when it failed (phases then empty).

    ``grasps``: (id, hand, index in the hand's grasp list) of the grasps the phases hold
    with; ``placements``: id -> X_WO (4, 4); ``stages``: seconds per stage of the task, in
    order; ``transitions``: Table I per query label, in plan order; ``counts``:
    deterministic statistics (the same for the same seed)."""

    task: str
    phases: tuple[PhaseMotion, ...] = ()
    grasps: tuple[tuple[str, str, int], ...] = ()
    placements: dict = field(default_factory=dict)
    stages: dict = field(default_factory=dict)
    transitions: dict = field(default_factory=dict)
    counts: dict = field(default_factory=dict)
    failure: PlanningFailed | None = None

    @property
    def planning_s(self) -> float:
        return float(sum(self.stages.values()))


def check_ends(scratch: Scratch) -> None:
    """The robot's start and goal configurations (the object at its start and goal)
    free, and with the queries' clearance: nothing else matters if the robot starts in
    collision, whatever the task.  Raises PlanningFailed(Stage.ENDS)."""
    p, task = scratch.problem, scratch.problem.spec.task
    for q, X, what in ((p.q_start, task.X_WO_start, "start"), (p.q_goal, task.X_WO_goal, "goal")):
        plain = scratch.world(X)
        for world, fault in ((plain, "is in collision"),
                             (scratch.certified(plain), f"is closer than {1000 * scratch.local.margin:g} mm to an "
                                                        "obstacle or itself")):
            if not world.is_free(q):
                pairs = ", ".join("-".join(p) for p in world.colliding_pairs(q)[:3])
                need = "" if world is plain else "; the query checks need that clearance"
                raise PlanningFailed(Stage.ENDS, f"the robot's {what} configuration {fault} ({pairs}){need}")


def ends_failure(problem, options) -> PlanningFailed | None:
    """Why :func:`check_ends` fails for ``problem`` (a :class:`~regrasp_cli.scene.Problem`)
    with ``options`` (:class:`~manip.context.OnlineOptions`), or None: for callers to ask
    before they load or build any artefact."""
    try:
        check_ends(Scratch(problem, options))
    except PlanningFailed as exc:
        return exc
    return None


def _query_job(j: dict, i: int) -> QueryResult:
    """Query ``i`` of the batch ``j`` (in a forked worker, or in this process)."""
    scratch, roadmap, query = j["scratch"], j["roadmap"], j["queries"][i]
    rng = np.random.default_rng(j["streams"][i])
    qs, before = QueryStats(), scratch.checks
    try:
        if scratch.options.planner == "ompl-rrtconnect":
            path = ompl_query(scratch, rng, query.a, query.b, query.worlds, j["weights"], qs)
        elif roadmap is None:
            path = rrt_query(scratch, rng, query.a, query.b, query.worlds, j["weights"], qs)
        else:
            path = roadmap_query(scratch, rng, roadmap, query.a, query.b, query.worlds, qs)
        return QueryResult(query.label, path, qs, None, scratch.checks - before)
    except QueryFailed as exc:
        return QueryResult(query.label, None, qs, str(exc), scratch.checks - before)


def solve_queries(scratch: Scratch, roadmap: Roadmap | None, weights: np.ndarray, queries: list[Query],
                  streams: list, jobs: int) -> dict[str, QueryResult]:
    """Every query, by label; ``streams[i]`` seeds query i's generator.  With several
    jobs they run in the order given (longest first balances two workers)."""
    job = {"scratch": scratch, "roadmap": roadmap, "weights": weights, "queries": queries, "streams": streams}
    return {r.label: r for r in ordered_map(_query_job, list(range(len(queries))), jobs, job)}


def join(pieces: list[np.ndarray], labels: list[str | None] | None = None,
         tol: float = 1e-9) -> tuple[np.ndarray, list[str | None]]:
    """Waypoints (k, nq) of consecutive pieces, each repeated configuration once (closer
    than ``tol`` to the previous one, the last waypoint kept exact), and for each
    segment (k - 1) the label of the piece it lies on (None for a fixed piece)."""
    labels = labels or [None] * len(pieces)
    w, seg = [np.asarray(pieces[0])[0]], []
    for rows, label in zip(pieces, labels):
        for q in np.asarray(rows):
            if np.linalg.norm(q - w[-1]) > tol:
                w.append(q)
                seg.append(label)
    last = np.asarray(pieces[-1])[-1]
    if len(w) > 1:
        w[-1] = last
    return np.array(w), seg


def _corner_checks(seg: list[str | None], curve_free):
    """blend_free(i, A, C, B) of :func:`motion.blend.choose_radii` for a phase whose
    segments lie on the pieces ``seg``: ``curve_free(label, A, C, B)`` with the query's
    label when a segment at corner i lies on its path (the corner where an approach,
    lift or retreat line meets it too: its blend cuts towards the path, away from the
    contact, and is certified in the query's world like the path), else None (a corner
    between two lines, sampled as they were)."""
    def free(i, A, C, B):
        return curve_free(seg[i - 1] or seg[i], A, C, B)
    return free


def timed_phase(w: np.ndarray, seg: list[str | None], velocity: np.ndarray, acceleration: np.ndarray,
                curve_free) -> tuple[np.ndarray, np.ndarray | None, Timing | None]:
    """(waypoint times (k,) from 0, radii (k,), timing) of waypoints w (k, nq); radii and
    timing None when the motion stops at every waypoint (no corner, or no blend free):
    the trapezoids of :mod:`motion.timing` are then exactly time-optimal."""
    radii = choose_radii(w, _corner_checks(seg, curve_free)) if curve_free and len(w) > 2 else None
    if radii is None or not np.any(radii > 0):
        return time_parameterise(w, velocity, acceleration), None, None
    path = blended_path(w, radii)
    timing = time_optimal(path, velocity, acceleration)
    return np.interp(path.knots, timing.s, timing.t), radii, timing


def time_steps(steps: list[Step], paths: dict[str, np.ndarray], velocity: np.ndarray,
               acceleration: np.ndarray, curve_free=None, held_speed: float = 1.0) -> tuple[PhaseMotion, ...]:
    """The steps with their query labels replaced by the solved paths, timed in turn.

    ``curve_free(step, label, A, C, B)`` says whether the blend A, C, B (nq,) at a corner
    of ``step`` is collision-free (``label``: the query whose path holds both segments,
    else None); without it every waypoint is a stop.  A step whose transition holds the
    object rigidly (:attr:`Transition.holding`) is timed with ``velocity`` times
    ``held_speed`` (in (0, 1]) and ``acceleration`` times its square
    (:attr:`OnlineOptions.held_speed`)."""
    out, clock = [], 0.0
    for step in steps:
        slow = held_speed if step.transition.holding else 1.0
        velocity_, acceleration_ = velocity * slow, acceleration * slow * slow
        if step.object_poses is not None:  # the fingers turn the object: a stop at every waypoint
            w = np.asarray(step.pieces[0], float)
            times = time_parameterise(w, velocity_, acceleration_)
            out.append(PhaseMotion(step.transition, w, times + clock, object_poses=step.object_poses,
                                   contacts=step.contacts))
            clock = float(times[-1]) + clock
            continue
        pieces = [paths[p] if isinstance(p, str) else p for p in step.pieces]
        w, seg = join(pieces, [p if isinstance(p, str) else None for p in step.pieces])
        check = (lambda label, A, C, B, st=step: curve_free(st, label, A, C, B)) if curve_free else None
        times, radii, timing = timed_phase(w, seg, velocity_, acceleration_, check)
        out.append(PhaseMotion(step.transition, w, times + clock, radii,
                               None if timing is None else timing.shifted(clock)))
        clock = float(times[-1]) + clock
    return tuple(out)
