"""The online stage of Saut et al. 2010 (§IV-B, §V-B, §V-C), from cached artefacts to a
timed motion.

Stages, each timed and each with its own failure reason:

1. ``double grasps``: single-grasp configurations of the picking hand at the start pose
   and of the placing hand at the goal pose, then scored pairs (:mod:`plan.doublegrasp`);
2. ``exchange``: for the best double grasps in turn, the exchange position on a grid
   (Fig. 6), its orientation from the grasp directions, then Gaussian samples around it
   until both arms reach it collision-free (:func:`keyconf.exchange_configuration`);
3. ``grasp``, ``carry``, ``place``, ``rest``: the four queries (:mod:`plan.queries`),
   each a roadmap query (or, with ``planner="rrt-connect"``, the single-query baseline;
   with ``"ompl-rrtconnect"``, OMPL's RRT-Connect as its peer, :mod:`plan.ompl_peer`)
   framed by the approach, lift and retreat lines of the key configurations; finger
   closing and opening are phases of their own;
4. timing: stop-at-every-waypoint trapezoids within the URDF velocity limits.

The picking hand is the one whose shoulder is nearer the object's start position.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from regrasp_cli.errors import RegraspError
from regrasp_cli.parallel import ordered_map, shared
from regrasp_cli.grasp.build import GraspList
from regrasp_cli.plan.context import OnlineOptions, Scratch
from regrasp_cli.plan.doublegrasp import DoubleGrasp, double_grasps, single_configurations
from regrasp_cli.plan.exchange import exchange_orientation, exchange_position, grid_nodes
from regrasp_cli.plan.handshape import HandShape, StaticGeometry, hand_hits_static, hand_shapes, \
    palm_and_finger_links, static_geometry
from regrasp_cli.plan.keyconf import OTHER, ExchangeConfig, approach_axis, exchange_configuration, shoulder, wrist
from regrasp_cli.plan.ompl_peer import ompl_query, ompl_version
from regrasp_cli.plan.queries import PhaseWorlds, QueryFailed, QueryStats, Roadmap, roadmap_query, rrt_query
from regrasp_cli.plan.timing import time_parameterise
from regrasp_cli.roadmap.local import joint_reach, joint_weights
from regrasp_cli.scene import Problem
from regrasp_cli.spatial import inverse

EXCHANGE_CLEARANCE = 0.02  # m: the object at the exchange pose keeps this from obstacles


class PlanningFailed(RegraspError):
    """No plan: ``stage`` is where it failed, ``reason`` why (exit code 1)."""

    exit_code = 1

    def __init__(self, stage: str, reason: str):
        self.stage, self.reason = stage, reason
        super().__init__(f"planning failed at stage '{stage}': {reason}")


@dataclass(frozen=True)
class PhaseMotion:
    name: str
    holding: tuple[str, ...]
    touching: tuple[str, ...]
    waypoints: np.ndarray  # (k, nq)
    times: np.ndarray  # (k,) s from the plan start


@dataclass
class Outcome:
    """What a run produced; ``failure`` is set when it failed (phases then empty)."""

    giver: str | None = None
    double: DoubleGrasp | None = None
    exchange: ExchangeConfig | None = None
    phases: list[PhaseMotion] = field(default_factory=list)
    stats: dict = field(default_factory=dict)  # deterministic counts
    timing: dict = field(default_factory=dict)  # seconds per stage and per query
    failure: PlanningFailed | None = None


def _clock(outcome: Outcome, name: str, t0: float) -> float:
    t = time.perf_counter()
    outcome.timing[name] = outcome.timing.get(name, 0.0) + t - t0
    return t


def picking_hand(problem: Problem, scratch: Scratch) -> str:
    p = problem.spec.task.X_WO_start[:3, 3]
    d = {h: float(np.linalg.norm(shoulder(scratch, h, problem.robot.q_rest) - p)) for h in ("right", "left")}
    return min(d, key=d.get)


def _object_shape(problem: Problem) -> HandShape:
    from regrasp_cli.model.collision import mesh_geometry

    g = mesh_geometry(problem.object.mesh)
    g.computeLocalAABB()
    return HandShape((g,), np.eye(4)[None], np.array([g.aabb_local.center()]), np.array([float(g.aabb_radius)]))


def exchange_pose(scratch: Scratch, dg: DoubleGrasp, lists: dict[str, GraspList], env: StaticGeometry,
                  obj: HandShape) -> tuple[np.ndarray | None, int]:
    """Centre X_WO (4, 4) of the exchange samples: the grid node of least wrist-path cost
    (Fig. 6) where both arms reach and the object, turned as the grasp directions ask,
    keeps clear of the obstacles; and the number of grid nodes tested."""
    p, robot = scratch.problem, scratch.problem.robot
    g, t = dg.giver.hand, dg.taker.hand
    start, goal = p.spec.task.X_WO_start[:3, 3], p.spec.task.X_WO_goal[:3, 3]
    anchors = np.array([start, goal, wrist(scratch, g, robot.q_rest), wrist(scratch, t, robot.q_rest)])
    lower, upper = anchors.min(axis=0) - 0.1, anchors.max(axis=0) + 0.1
    lower[2] = max(start[2], goal[2]) + 0.08
    upper[2] = max(upper[2], lower[2])
    nodes = grid_nodes(lower, upper, scratch.options.exchange_step)
    reach = joint_reach(robot)
    sh = {h: shoulder(scratch, h, robot.q_rest) for h in (g, t)}
    arm_reach = {h: 0.85 * reach[robot.hands[h].arm_idx[0]] for h in (g, t)}
    a_O = {dg.giver.hand: lists[g].X_OG[dg.giver.grasp, :3, :3] @ approach_axis(scratch, g),
           dg.taker.hand: lists[t].X_OG[dg.taker.grasp, :3, :3] @ approach_axis(scratch, t)}
    poses = {}

    def pose(x: np.ndarray) -> np.ndarray:
        X = np.eye(4)
        X[:3, :3] = exchange_orientation(a_O[g], a_O[t], x - sh[g], x - sh[t])
        X[:3, 3] = x - X[:3, :3] @ obj.centres[0]  # the object's centre at the grid node
        return X

    def is_free(x: np.ndarray) -> bool:
        if any(np.linalg.norm(x - sh[h]) > arm_reach[h] for h in (g, t)):
            return False
        X = pose(x)
        poses[x.tobytes()] = X
        return not hand_hits_static(obj, X, env, EXCHANGE_CLEARANCE)

    x, tested = exchange_position(nodes, anchors, is_free)
    return (None if x is None else poses[x.tobytes()]), tested


def _perturbed(scratch: Scratch, X: np.ndarray, obj: HandShape) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    o = scratch.options
    c = X[:3, :3] @ obj.centres[0] + X[:3, 3]
    R = Rotation.from_rotvec(scratch.rng.normal(0.0, o.exchange_angle_sigma, 3)).as_matrix() @ X[:3, :3]
    Y = np.eye(4)
    Y[:3, :3] = R
    Y[:3, 3] = c + scratch.rng.normal(0.0, o.exchange_sigma, 3) - R @ obj.centres[0]
    return Y


def _lazy_filter(object_pairs: bool, hands: set[str]):
    """Pairs the roadmap did not certify: with the object, or with a link in ``hands``."""
    return lambda a, b: (object_pairs and "object" in (a, b)) or a in hands or b in hands


def phase_worlds(scratch: Scratch, X_PO: np.ndarray, attached: str | None, fingers: dict) -> PhaseWorlds:
    robot = scratch.problem.robot
    changed = set()
    for hand, values in fingers.items():
        if not np.array_equal(values, robot.hands[hand].open):
            changed |= palm_and_finger_links(robot, hand)
    touching = (attached,) if attached else ()
    full = scratch.world(X_PO, attached, touching, certified=True)
    lazy = scratch.world(X_PO, attached, touching, pair_filter=_lazy_filter(True, changed),
                         key="lazy:" + ",".join(sorted(changed)), certified=True)
    return PhaseWorlds(full, lazy, fingers)


QUERY_NAMES = ("grasp", "carry", "place", "rest")
def _single_job(hand: str):
    """Single-grasp configurations of one hand (in a forked worker, or in this process)."""
    j = shared()
    scratch = j["scratch"]
    scratch.rng = np.random.default_rng([j["seed"], 10 + ("right", "left").index(hand)])
    before = scratch.checks
    found, stats = single_configurations(scratch, *j["singles"][hand])
    return found, stats, scratch.checks - before


def _query_job(name: str):
    """One query of the current run (in a forked worker, or in this process)."""
    j = shared()
    scratch, roadmap = j["scratch"], j["roadmap"]
    a, b, worlds = j["queries"][name]
    k = QUERY_NAMES.index(name)  # the first attempt's streams, then one per attempt
    scratch.rng = np.random.default_rng([j["seed"], k] if j["attempt"] == 0 else [j["seed"], k, j["attempt"]])
    qs, before = QueryStats(), scratch.checks
    try:
        if scratch.options.planner == "ompl-rrtconnect":
            path = ompl_query(scratch, a, b, worlds, j["weights"], qs)
        elif roadmap is None:
            path = rrt_query(scratch, a, b, worlds, j["weights"], qs)
        else:
            path = roadmap_query(scratch, roadmap, a, b, worlds, qs)
        return name, path, qs, None, scratch.checks - before
    except QueryFailed as exc:
        return name, None, qs, str(exc), scratch.checks - before


def _double_grasps(scratch: Scratch, lists: dict[str, GraspList], shapes: dict, env: StaticGeometry, g: str,
                   seed: int, options: OnlineOptions, out: Outcome, record: bool) -> list[DoubleGrasp] | str:
    """Double grasps with hand ``g`` picking, best first, or why there are none."""
    task, t = scratch.problem.spec.task, OTHER[g]
    # the two hands' searches are independent: in parallel, each with its own random stream
    job = {"scratch": scratch, "seed": seed, "singles": {g: (lists[g], shapes[g], task.X_WO_start, env),
                                                         t: (lists[t], shapes[t], task.X_WO_goal, env)}}
    (cfg_g, st_g, n_g), (cfg_t, st_t, n_t) = ordered_map(_single_job, [g, t], options.jobs, job)
    out.stats["single_checks"] = out.stats.get("single_checks", 0) + n_g + n_t
    scratch.rng = np.random.default_rng([seed, 20])  # the same stream after, whatever the jobs
    if record or (cfg_g and cfg_t):
        out.stats["single_grasps"] = {g: st_g.__dict__, t: st_t.__dict__}
    for hand, cfgs, st, where in ((g, cfg_g, st_g, "start"), (t, cfg_t, st_t, "goal")):
        if not cfgs:
            return (f"no collision-free {hand}-hand grasp configuration at the object's {where} pose "
                    f"({st.environment_free} of {st.listed} grasps clear the obstacles, {st.tried} tried with IK)")
    doubles = double_grasps(cfg_g, lists[g], shapes[g], cfg_t, lists[t], shapes[t])
    out.stats["double_grasps"] = len(doubles)
    return doubles or f"all {len(cfg_g)} x {len(cfg_t)} grasp pairs make the hands collide"


def _exchanges(scratch: Scratch, doubles: list[DoubleGrasp], lists: dict[str, GraspList], env: StaticGeometry,
               obj: HandShape, g: str, options: OnlineOptions, out: Outcome):
    """(double grasp, exchange configuration) pairs, best double grasp first: for each of
    the best ``double_grasps_tried``, the exchange pose of Fig. 6 and then Gaussian
    samples around it until both arms reach one (a generator: the next pair is searched
    only when a query of the previous one failed)."""
    t, o = OTHER[g], options
    out.stats["double_grasps_tried"] = 0
    for dg in doubles[:o.double_grasps_tried]:
        out.stats["double_grasps_tried"] += 1
        X_c, _ = exchange_pose(scratch, dg, lists, env, obj)
        if X_c is None:
            continue
        for s in range(o.exchange_samples):
            X = X_c if s == 0 else _perturbed(scratch, X_c, obj)
            if s and hand_hits_static(obj, X, env, EXCHANGE_CLEARANCE):
                continue
            ex = exchange_configuration(scratch, lists[g], dg.giver.grasp, lists[t], dg.taker.grasp, X)
            if ex is not None:
                yield dg, ex
                break


def _queries(scratch: Scratch, roadmap: Roadmap | None, weights: np.ndarray, seed: int, attempt: int, g: str,
             lists: dict[str, GraspList], out: Outcome) -> tuple[tuple[str, str] | None, dict]:
    """The four queries between the key configurations of ``out.double`` and
    ``out.exchange``; their counts and times are added to ``out``.  Returns the first
    failing query (in plan order) with its reason, or None, and the paths found."""
    problem, options = scratch.problem, scratch.options
    robot, task, t = problem.robot, problem.spec.task, OTHER[g]
    dg, ex = out.double, out.exchange
    sg, st = dg.giver, dg.taker
    open_ = {h: robot.hands[h].open for h in (g, t)}
    closed = {g: lists[g].finger_q[sg.grasp], t: lists[t].finger_q[st.grasp]}
    X_GO = {g: inverse(lists[g].X_OG[sg.grasp]), t: inverse(lists[t].X_OG[st.grasp])}
    queries = {
        "grasp": (problem.q_start, sg.approach[0], phase_worlds(scratch, task.X_WO_start, None, open_)),
        "carry": (sg.lift[-1], ex.approach[0], phase_worlds(scratch, X_GO[g], g, {g: closed[g], t: open_[t]})),
        "place": (ex.retreat[-1], st.lift[-1], phase_worlds(scratch, X_GO[t], t, {g: open_[g], t: closed[t]})),
        "rest": (st.approach[0], problem.q_goal, phase_worlds(scratch, task.X_WO_goal, None, open_)),
    }
    # the queries are independent once the key configurations are fixed: each has its own
    # random stream, so they give the same paths run in turn or in parallel
    job = {"scratch": scratch, "roadmap": roadmap, "weights": weights, "seed": seed, "attempt": attempt,
           "queries": queries}
    rng = scratch.rng  # an in-process query replaces it with its own stream
    try:
        results = {r[0]: r for r in ordered_map(_query_job, ["place", "rest", "grasp", "carry"],  # longest first
                                                 options.jobs, job)}
    finally:
        scratch.rng = rng
    paths = {}
    for name in QUERY_NAMES:
        _, path, qs, error, checks = results[name]
        st_q = out.stats.setdefault("queries", {}).setdefault(name, dict.fromkeys(
            ("nodes", "searches", "invalid_edges", "rrt_calls"), 0))
        for k in st_q:
            st_q[k] += getattr(qs, k)
        out.timing[f"{name} planning"] = out.timing.get(f"{name} planning", 0.0) + qs.planning
        out.timing[f"{name} validation"] = out.timing.get(f"{name} validation", 0.0) + qs.validation
        out.stats["query_checks"] = out.stats.get("query_checks", 0) + checks
        paths[name] = path
    failed = next((n for n in QUERY_NAMES if results[n][3] is not None), None)
    return (None if failed is None else (failed, results[failed][3])), paths


def run(problem: Problem, lists: dict[str, GraspList], roadmap: Roadmap | None, options: OnlineOptions,
        seed: int) -> Outcome:
    """Plan the pick, hand-over and place; never raises PlanningFailed (see ``failure``)."""
    out = Outcome()
    try:
        _run(problem, lists, roadmap, options, seed, out)
    except PlanningFailed as exc:
        out.failure = exc
        out.phases = []
    return out


def _run(problem: Problem, lists: dict[str, GraspList], roadmap: Roadmap | None, options: OnlineOptions,
         seed: int, out: Outcome) -> None:
    robot = problem.robot
    scratch = Scratch(problem, options, np.random.default_rng([seed, 20]))  # each parallel stage has its own
    task = problem.spec.task
    weights = roadmap.weights if roadmap is not None else joint_weights(robot)
    if options.planner == "ompl-rrtconnect":
        ompl_version()  # InputError now, not after the key configurations, when the extra is missing
    t0 = time.perf_counter()

    # the ends of the task first: nothing else matters if the robot starts in collision
    for q, X, stage, what in ((problem.q_start, task.X_WO_start, "grasp", "start"),
                              (problem.q_goal, task.X_WO_goal, "rest", "goal")):
        plain = scratch.world(X)
        for world, fault in ((plain, "is in collision"),
                             (scratch.certified(plain), f"is closer than {1000 * scratch.local.margin:g} mm to an "
                                                        "obstacle or itself")):
            if not world.is_free(q):
                pairs = ", ".join("-".join(p) for p in world.colliding_pairs(q)[:3])
                need = "" if world is plain else "; the query checks need that clearance"
                raise PlanningFailed(stage, f"the robot's {what} configuration {fault} ({pairs}){need}")

    # ---------------------------------------------------------------- double grasps
    env = static_geometry(problem.spec.obstacles)
    shapes = {h: hand_shapes(robot, h, lists[h].finger_q) for h in ("right", "left")}
    guess = picking_hand(problem, scratch)
    failures = []
    for g in (guess, OTHER[guess]):  # the nearer hand first; the other when it cannot
        found = _double_grasps(scratch, lists, shapes, env, g, seed, options, out, record=not failures)
        if isinstance(found, list):
            doubles, t = found, OTHER[g]
            break
        failures.append(found)
    else:
        _clock(out, "double grasps", t0)
        raise PlanningFailed("double grasps", f"{failures[0]}; with the {OTHER[guess]} hand picking instead: "
                                              f"{failures[1]}")
    out.giver = g
    t0 = _clock(out, "double grasps", t0)

    # ---------------------------------------------------------------- exchange and queries
    # key configurations (a double grasp with its exchange configuration), best double
    # grasp first; when a query fails, the next set is tried, key_attempts in all
    candidates = _exchanges(scratch, doubles, lists, env, _object_shape(problem), g, options, out)
    failure, paths = None, {}
    for attempt in range(options.key_attempts):
        found = next(candidates, None)
        t0 = _clock(out, "exchange", t0)
        if found is None:
            break
        out.double, out.exchange = found
        out.stats["key_attempts"] = attempt + 1
        failure, paths = _queries(scratch, roadmap, weights, seed, attempt, g, lists, out)
        t0 = _clock(out, "queries", t0)
        if failure is None:
            break
    if out.exchange is None:
        raise PlanningFailed("exchange", f"no reachable collision-free exchange pose for the best "
                             f"{out.stats['double_grasps_tried']} double grasps ({options.exchange_samples} "
                             f"samples each)")
    if failure is not None:
        stage, reason = failure
        n = out.stats["key_attempts"]
        raise PlanningFailed(stage, reason if n == 1 else f"{reason} (the last of {n} double grasps with their "
                                                         f"exchange tried)")
    dg, ex = out.double, out.exchange
    sg, st = dg.giver, dg.taker

    # ---------------------------------------------------------------- phases and timing
    def cat(*parts) -> np.ndarray:
        rows = [np.asarray(p) for p in parts]
        w = [rows[0][0]]
        for r in rows:
            for q in r:
                if not np.array_equal(q, w[-1]):
                    w.append(q)
        return np.array(w)

    motions = [
        ("grasp", (), (), cat(paths["grasp"], sg.approach)),
        (f"close_{g}", (), (g,), cat(sg.approach[-1:], sg.q_closed[None])),
        ("carry", (g,), (), cat(sg.lift, paths["carry"], ex.approach)),
        (f"close_{t}", (g,), (t,), cat(ex.approach[-1:], ex.q_both[None])),
        (f"open_{g}", (t,), (g,), cat(ex.q_both[None], ex.q_release[None])),
        ("place", (t,), (), cat(ex.retreat, paths["place"], st.lift[::-1])),
        (f"open_{t}", (), (t,), cat(st.q_closed[None], st.approach[-1:])),
        ("rest", (), (), cat(st.approach[::-1], paths["rest"])),
    ]
    v = robot.velocity
    a = np.full(robot.nq, options.acceleration)
    clock = 0.0
    for name, holding, touching, w in motions:
        times = time_parameterise(w, v, a) + clock
        clock = float(times[-1])
        out.phases.append(PhaseMotion(name, holding, touching, w, times))
    out.stats["waypoints"] = int(sum(len(m[3]) for m in motions))
    # every check, the workers' included (with one job they ran on this scratch)
    out.stats["checks"] = scratch.checks + (out.stats["single_checks"] + out.stats["query_checks"]
                                            if options.jobs > 1 else 0)
    _clock(out, "timing", t0)
