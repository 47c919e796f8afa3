"""The hand-over of Saut et al. 2010 (seed 000) as one fixed path through manipulation
modes: the object resting at ``start``, held by the picking hand, by both hands at the
exchange pose, by the placing hand, resting at ``goal``.

Stages (§IV-B, §V-B, §V-C), each timed, each returning what it found and its counts:

1. ``double grasps``: single-grasp configurations of the picking hand at the start pose
   and of the placing hand at the goal pose, then scored pairs (:mod:`manip.doublegrasp`);
   the hand whose shoulder is nearer the object's start picks, the other when it cannot;
2. ``exchange``: for the best double grasps in turn, the exchange position on a grid
   (Fig. 6), its orientation from the grasp directions, then Gaussian samples around it
   until both arms reach it collision-free (:func:`keyconf.exchange_configuration`): the
   sampler of the CG_r∩CG_l mode;
3. ``queries``: the four transit/transfer queries of §V-B (:data:`TRANSITIONS`: grasp,
   carry, place, rest, the rows of Table I) solved by :func:`solve.solve_queries`, framed
   by the approach, lift and retreat lines of the key configurations; finger closing and
   opening are the grasp, hand-over and release transitions.  When a query fails the next
   double grasp is tried with its own exchange, ``key_attempts`` in all;
4. ``timing``: :func:`solve.time_steps` within the URDF velocity limits, with blends at
   the corners whose curve is collision-free (``blend``), else a stop at each waypoint.

"Right picks, left places" and the four query names are spelled here and nowhere else.
"""

from __future__ import annotations

import time

import numpy as np

from regrasp_cli.grasp.build import GraspList
from regrasp_cli.manip import steps as moves
from regrasp_cli.manip.context import OnlineOptions, Scratch
from regrasp_cli.manip.doublegrasp import DoubleGrasp, double_grasps, empty_list_reason, pairable, partners, \
    single_configurations, workable
from regrasp_cli.manip.exchange import exchange_orientation, exchange_position
from regrasp_cli.model.handshape import HandShape, StaticGeometry, hand_hits_static, hand_shapes, single_shape, \
    palm_and_finger_links, static_geometry
from regrasp_cli.manip.keyconf import OTHER, ExchangeConfig, approach_axis, exchange_configuration, shoulder, wrist
from regrasp_cli.manip.ompl_peer import ompl_version
from regrasp_cli.manip.queries import PhaseWorlds, Roadmap
from regrasp_cli.manip.solve import Outcome, Query, Step, TransitionStats, check_ends, solve_queries, time_steps
from regrasp_cli.manip.status import PlanningFailed, Stage
from regrasp_cli.model.ik import arm_reachable
from regrasp_cli.motion.local import joint_weights
from regrasp_cli.parallel import ordered_map
from regrasp_cli.scene import Problem
from regrasp_cli.spatial import inverse

TASK = "handover"
TRANSITIONS = ("grasp", "carry", "place", "rest")  # the four queries of §V-B, in plan order
RUN_ORDER = ("place", "rest", "grasp", "carry")  # longest first, so that two workers finish together
STAGES = ("double grasps", "exchange", "queries", "timing")
EXCHANGE_CLEARANCE = 0.02  # m: the object at the exchange pose keeps this from obstacles
EXCHANGE_RISE = 0.08  # m: the exchange position is this much above the object's start and goal, at least
EXCHANGE_YAWS = np.radians([0, 0, 45, -45, 0, 90, -90, 0, 135, -135, 0, 180])  # turns of the samples, in turn
EXCHANGE_DRAWS = 4  # exchange poses drawn per sample tried: those out of an arm's reach are dropped


def grasp_id(lists: dict[str, GraspList], hand: str, k: int) -> str:
    """The plan's id of grasp ``k`` of ``hand``'s list: the hand and its index in the
    cached list (``lists`` may hold a scene's subset of it, :mod:`grasp.usable`)."""
    return f"{hand}-{lists[hand].stored_index(k)}"


def picking_hand(problem: Problem, scratch: Scratch) -> str:
    p = problem.spec.task.X_WO_start[:3, 3]
    d = {h: float(np.linalg.norm(shoulder(scratch, h, problem.robot.q_rest) - p)) for h in ("right", "left")}
    return min(d, key=d.get)


def object_shape(problem: Problem) -> HandShape:
    from regrasp_cli.model.collision import mesh_geometry

    return single_shape(mesh_geometry(problem.object.mesh))


def exchange_pose(scratch: Scratch, dg: DoubleGrasp, lists: dict[str, GraspList], env: StaticGeometry,
                  obj: HandShape) -> tuple[np.ndarray | None, int]:
    """Centre X_WO (4, 4) of the exchange samples: the node of least wrist-path cost
    (Fig. 6) where both arms reach with the approach directions the pose asks and the
    object keeps clear of the obstacles; and the number of nodes tested.

    The nodes are the cubes of the arms' reach maps (:mod:`model.reachmap`) that both
    hands' grasp frames get to, at least ``EXCHANGE_RISE`` above the higher of the object's
    start and goal (in the air, above its supports); the object's centre goes to the
    node, turned so that the two grasps' approach directions point as nearly as possible
    from each shoulder to it (:func:`exchange.exchange_orientation`), and each hand must
    have been seen in that cube pointing within 50 degrees of its direction."""
    p, robot = scratch.problem, scratch.problem.robot
    g, t = dg.giver.hand, dg.taker.hand
    start, goal = p.spec.task.X_WO_start[:3, 3], p.spec.task.X_WO_goal[:3, 3]
    anchors = np.array([start, goal, wrist(scratch, g, robot.q_rest), wrist(scratch, t, robot.q_rest)])
    maps = {h: scratch.reach(h) for h in (g, t)}
    nodes = maps[g].centres()
    nodes = nodes[(nodes[:, 2] >= max(start[2], goal[2]) + EXCHANGE_RISE) & maps[t].reaches(nodes)]
    sh = {h: shoulder(scratch, h, robot.q_rest) for h in (g, t)}
    a_O = {dg.giver.hand: lists[g].X_OG[dg.giver.grasp, :3, :3] @ approach_axis(scratch, g),
           dg.taker.hand: lists[t].X_OG[dg.taker.grasp, :3, :3] @ approach_axis(scratch, t)}
    poses = {}

    def pose(x: np.ndarray) -> np.ndarray:
        X = np.eye(4)
        X[:3, :3] = exchange_orientation(a_O[g], a_O[t], x - sh[g], x - sh[t])
        X[:3, 3] = x - X[:3, :3] @ obj.centres[0]  # the object's centre at the node
        return X

    def is_free(x: np.ndarray) -> bool:
        X = pose(x)
        if not all(maps[h].reaches(x[None], (X[:3, :3] @ a_O[h])[None])[0] for h in (g, t)):
            return False
        poses[x.tobytes()] = X
        return not hand_hits_static(obj, X, env, EXCHANGE_CLEARANCE)

    x, tested = exchange_position(nodes, anchors, is_free)
    return (None if x is None else poses[x.tobytes()]), tested


def _perturbed(scratch: Scratch, rng: np.random.Generator, X: np.ndarray, obj: HandShape, yaw: float = 0.0) -> np.ndarray:
    """X_WO (4, 4) turned by ``yaw`` (rad) about the vertical through the object's centre,
    then perturbed (Gaussian, ``exchange_sigma`` and ``exchange_angle_sigma``)."""
    from scipy.spatial.transform import Rotation

    o = scratch.options
    c = X[:3, :3] @ obj.centres[0] + X[:3, 3]
    R = Rotation.from_rotvec(rng.normal(0.0, o.exchange_angle_sigma, 3)).as_matrix() @ \
        Rotation.from_rotvec([0.0, 0.0, yaw]).as_matrix() @ X[:3, :3]
    Y = np.eye(4)
    Y[:3, :3] = R
    Y[:3, 3] = c + rng.normal(0.0, o.exchange_sigma, 3) - R @ obj.centres[0]
    return Y


def _lazy_filter(object_pairs: bool, hands: set[str], obstacles: tuple[str, ...] = ()):
    """Pairs the roadmap did not certify: with the object, with a link in ``hands``, or
    with one of the ``obstacles`` it was not built with."""
    fresh = {f"obstacle:{name}" for name in obstacles}
    return lambda a, b: (object_pairs and "object" in (a, b)) or a in hands or b in hands or a in fresh or b in fresh


def phase_worlds(scratch: Scratch, X_PO: np.ndarray, attached: str | None, fingers: dict) -> PhaseWorlds:
    robot = scratch.problem.robot
    changed = set()
    for hand, values in fingers.items():
        if not np.array_equal(values, robot.hands[hand].open):
            changed |= palm_and_finger_links(robot, hand)
    touching = (attached,) if attached else ()
    full = scratch.world(X_PO, attached, touching, certified=True)
    lazy = scratch.world(X_PO, attached, touching, pair_filter=_lazy_filter(True, changed, scratch.unchecked),
                         key="lazy:" + ",".join(sorted(changed)), certified=True)
    return PhaseWorlds(full, lazy, fingers)


# ------------------------------------------------------------------ double grasps


def single_stream(seed: int, hand: str) -> list[int]:
    """The random stream of a hand's single-grasp configurations (at the start for the
    picking hand, at the goal for the placing one)."""
    return [seed, 10 + ("right", "left").index(hand)]


def _single_job(j: dict, hand: str):
    """Single-grasp configurations of one hand (in a forked worker, or in this process)."""
    scratch = j["scratch"]
    rng = np.random.default_rng(single_stream(j["seed"], hand))
    before = scratch.checks
    found, stats = single_configurations(scratch, rng, *j["singles"][hand])
    return found, stats, scratch.checks - before


def _double_grasps(scratch: Scratch, lists: dict[str, GraspList], shapes: dict, env: StaticGeometry, g: str,
                   seed: int, known: dict) -> tuple[list[DoubleGrasp] | str, dict]:
    """Double grasps with hand ``g`` picking, best first, or why there are none; and counts.
    ``known``: (hand, "start" or "goal") -> (configurations, stats) already found with
    this task's random stream of that hand (:func:`single_stream`)."""
    task, t = scratch.problem.spec.task, OTHER[g]
    # the two hands' searches are independent: in parallel, each with its own random stream
    job = {"scratch": scratch, "seed": seed, "singles": {g: (lists[g], shapes[g], task.X_WO_start, env),
                                                         t: (lists[t], shapes[t], task.X_WO_goal, env)}}
    ends = {g: "start", t: "goal"}
    todo = [h for h in (g, t) if (h, ends[h]) not in known]
    done = dict(zip(todo, ordered_map(_single_job, todo, scratch.options.jobs, job)))
    (cfg_g, st_g, n_g), (cfg_t, st_t, n_t) = (done[h] if h in done else (*known[(h, ends[h])], 0) for h in (g, t))
    counts = {"single_checks": n_g + n_t, "single_grasps": {g: st_g.__dict__, t: st_t.__dict__}}
    for hand, cfgs, st, where in ((g, cfg_g, st_g, "start"), (t, cfg_t, st_t, "goal")):
        if not cfgs:
            return (f"no collision-free {hand}-hand grasp configuration at the object's {where} pose "
                    f"({st.environment_free} of {st.listed} grasps clear the obstacles, {st.reachable} of them in the "
                    f"arm's reach, {st.tried} tried with IK)",
                    counts)
    doubles = double_grasps(cfg_g, lists[g], shapes[g], cfg_t, lists[t], shapes[t])
    n_pairs = (len(cfg_g), len(cfg_t))
    if len(doubles) < scratch.options.double_grasps_wanted:
        # few pairs (a small object: both hands' best take the same side): each hand is
        # searched again among the other's partners; the new pairs come after, the
        # giver's first configurations with the taker's new ones first.  The torso helps
        # only when the first round gave no pair at all: leaning costs an IK from several
        # postures per grasp (4.5 s of 5.9 s on the default scene, for pairs it had)
        rng = np.random.default_rng([seed, 20])
        lean = not doubles
        cfg_t2, _ = single_configurations(scratch, rng, lists[t], shapes[t], task.X_WO_goal, env,
                                          _new(partners(cfg_g, lists[g], shapes[g], lists[t], shapes[t]), cfg_t),
                                          lean=lean)
        cfg_g2, _ = single_configurations(scratch, rng, lists[g], shapes[g], task.X_WO_start, env,
                                          _new(partners(cfg_t, lists[t], shapes[t], lists[g], shapes[g]), cfg_g),
                                          lean=lean)
        doubles = _plus(doubles, double_grasps(cfg_g, lists[g], shapes[g], cfg_t2, lists[t], shapes[t]),
                        double_grasps(cfg_g + cfg_g2, lists[g], shapes[g], cfg_t + cfg_t2, lists[t], shapes[t]))
        if len(doubles) < scratch.options.double_grasps_wanted:
            cfg_g, cfg_t = cfg_g + cfg_g2, cfg_t + cfg_t2
            cfg_g3, cfg_t3 = _paired_search(scratch, rng, lists, shapes, env, g, (cfg_g, cfg_t), lean)
            doubles = _plus(doubles, double_grasps(cfg_g + cfg_g3, lists[g], shapes[g], cfg_t + cfg_t3, lists[t],
                                                   shapes[t]))
    counts["double_grasps"] = len(doubles)
    return doubles or f"all {n_pairs[0]} x {n_pairs[1]} grasp pairs make the hands collide", counts


def _paired_search(scratch: Scratch, rng: np.random.Generator, lists: dict[str, GraspList], shapes: dict,
                   env: StaticGeometry, g: str, found: tuple[list, list], lean: bool) -> tuple[list, list]:
    """Configurations of the pairs first, as §IV-B pairs the filtered lists, when the
    configurations ``found`` (giver's, taker's) pair too rarely (the YCB apple: the first
    6 + 6 and their partners gave 1 free pair, while of the 70 x 46 grasps the two arms
    reach at the start and at the goal, 69 pairs share it): the giver searched among its
    reached grasps with a partner among the taker's, then the taker among the partners of
    the giver's new configurations.  Returns the new configurations of each."""
    task, t = scratch.problem.spec.task, OTHER[g]
    reach_g = workable(scratch, lists[g], shapes[g], task.X_WO_start, env)[1]
    reach_t = workable(scratch, lists[t], shapes[t], task.X_WO_goal, env)[1]
    shared = pairable(lists[g], shapes[g], reach_g, lists[t], shapes[t], reach_t)
    cfg_g, _ = single_configurations(scratch, rng, lists[g], shapes[g], task.X_WO_start, env,
                                     _new(reach_g[shared.any(axis=1)], found[0]), lean=lean)
    rows = np.isin(reach_g, [c.grasp for c in cfg_g])
    if not rows.any():
        return [], []
    cfg_t, _ = single_configurations(scratch, rng, lists[t], shapes[t], task.X_WO_goal, env,
                                     _new(reach_t[shared[rows].any(axis=0)], found[1]), lean=lean)
    return cfg_g, cfg_t


def _plus(doubles: list[DoubleGrasp], *more: list[DoubleGrasp]) -> list[DoubleGrasp]:
    """``doubles`` then the pairs of ``more`` not among them, in order (those found first stay first)."""
    out = list(doubles)
    for m in more:
        known = {(d.giver.grasp, d.taker.grasp) for d in out}
        out += [d for d in m if (d.giver.grasp, d.taker.grasp) not in known]
    return out


def _new(ks: np.ndarray, found: list) -> np.ndarray:
    """The grasp indices ``ks`` without those of the configurations already ``found``."""
    return ks[~np.isin(ks, [c.grasp for c in found])]


def choose_hands(scratch: Scratch, lists: dict[str, GraspList], seed: int,
                 known: dict | None = None) -> tuple[str, list[DoubleGrasp], dict]:
    """The picking hand and its double grasps: the hand nearer the start first, the
    other when it cannot.  Raises _Failed (Stage.GRASPS) when neither can."""
    problem = scratch.problem
    for h in ("right", "left"):
        if len(lists[h]) == 0:  # say so, not "0 of 0 grasps clear the obstacles"
            raise _Failed(PlanningFailed(Stage.GRASPS, empty_list_reason(h)), {}, {})
    env = static_geometry(problem.spec.obstacles)
    shapes = {h: hand_shapes(problem.robot, h, lists[h].finger_q, problem.spec.planning.contact_tolerance)
              for h in ("right", "left")}
    guess = picking_hand(problem, scratch)
    failures, counts = [], {"single_checks": 0}
    for g in (guess, OTHER[guess]):
        found, c = _double_grasps(scratch, lists, shapes, env, g, seed, known or {})
        counts["single_checks"] += c.pop("single_checks")
        if not failures or isinstance(found, list):
            counts.update(c)  # the first hand's counts, or those of the hand that succeeded
        if isinstance(found, list):
            return g, found, counts
        failures.append(found)
    raise _Failed(PlanningFailed(Stage.GRASPS, f"{failures[0]}; with the {OTHER[guess]} hand picking instead: "
                                               f"{failures[1]}"), {}, counts)


# ------------------------------------------------------------------ exchange and queries


def _exchanges(scratch: Scratch, rng: np.random.Generator, doubles: list[DoubleGrasp],
               lists: dict[str, GraspList], g: str):
    """(double grasp, exchange configuration, double grasps tried) best double grasp
    first: for each of the best ``double_grasps_tried``, the exchange pose of Fig. 6 and
    then Gaussian samples around it until both arms reach one; then, for each again,
    samples turned about the vertical with the torso solved with both arms (a generator:
    the next is searched only when a query of the previous one failed)."""
    o = scratch.options
    env, obj = static_geometry(scratch.problem.spec.obstacles), object_shape(scratch.problem)
    centres = {}  # the pose of Fig. 6 of each double grasp, found once
    for lean in (False, True):  # every double grasp with the arms alone first, as the paper
        for tried, dg in enumerate(doubles[:o.double_grasps_tried], 1):
            if tried not in centres:
                centres[tried] = exchange_pose(scratch, dg, lists, env, obj)[0]
            if centres[tried] is None:
                continue
            ex = exchange_near(scratch, rng, dg, lists, centres[tried], obj, env, lean)
            if ex is not None:
                yield dg, ex, tried
    yield None, None, min(len(doubles), o.double_grasps_tried)


def exchange_near(scratch: Scratch, rng: np.random.Generator, dg: DoubleGrasp, lists: dict[str, GraspList],
                   X_c: np.ndarray, obj: HandShape, env: StaticGeometry, lean: bool) -> ExchangeConfig | None:
    """The exchange configuration of the first of ``exchange_samples`` object poses around
    X_c (4, 4) that both arms reach: X_c itself and Gaussian samples; with ``lean``,
    samples turned about the vertical (the orientation of Fig. 6 is a least-squares
    compromise, which two grasps from above may not reach) and the torso solved with
    both arms (:func:`keyconf.exchange_configuration`).  ``EXCHANGE_DRAWS`` times as many
    poses are drawn, and those out of either arm's reach (one batched IK for all,
    :func:`~regrasp_cli.model.ik.arm_reachable`) are dropped before any arm IK: on a small
    cup, 4 in 5 of the arm IKs of the samples drawn failed.  Without ``lean`` the poses each
    arm reaches alone, the torso at rest, go first (the arms' IK starts from a torso drawn
    near rest: on the default scene, seed 0, 105 such IKs failed instead of 163); not only
    them: that test, from a few seeds, misses most poses the arm IK reaches."""
    g, t = dg.giver.hand, dg.taker.hand
    n = scratch.options.exchange_samples
    poses = [X_c] + [_perturbed(scratch, rng, X_c, obj, EXCHANGE_YAWS[s % len(EXCHANGE_YAWS)] if lean else 0.0)
                     for s in range(1, n * EXCHANGE_DRAWS)]
    poses = np.array([X for s, X in enumerate(poses) if not s or not hand_hits_static(obj, X, env, EXCHANGE_CLEARANCE)])
    robot, reach_rng = scratch.problem.robot, np.random.default_rng([int(rng.integers(2**31)), 39])
    reached, alone = np.ones(len(poses), dtype=bool), np.ones(len(poses), dtype=bool)
    for hand, grasps, k in ((g, lists[g], dg.giver.grasp), (t, lists[t], dg.taker.grasp)):
        X_WG = poses @ grasps.X_OG[k]
        reached &= arm_reachable(robot, hand, X_WG, reach_rng)
        if not lean:  # each arm alone, the torso at rest: those the arms reach alone first
            alone &= arm_reachable(robot, hand, X_WG, reach_rng, torso=False)
    order = np.flatnonzero(reached)
    order = order[np.argsort(~alone[order], kind="stable")]
    for X in poses[order][:n]:
        ex = exchange_configuration(scratch, rng, lists[g], dg.giver.grasp, lists[t], dg.taker.grasp, X, lean)
        if ex is not None:
            return ex
    return None


def steps_of(scratch: Scratch, dg: DoubleGrasp, ex: ExchangeConfig,
             lists: dict[str, GraspList]) -> tuple[list[Step], list[Query]]:
    """The mode path (:mod:`manip.steps`' arrive, hand-over and leave) with its fixed
    pieces (key configurations and their lines) and the four queries between them."""
    problem = scratch.problem
    robot, task = problem.robot, problem.spec.task
    sg, st = dg.giver, dg.taker
    g, t = sg.hand, st.hand
    open_ = {h: robot.hands[h].open for h in (g, t)}
    closed = {g: lists[g].finger_q[sg.grasp], t: lists[t].finger_q[st.grasp]}
    X_GO = {g: inverse(lists[g].X_OG[sg.grasp]), t: inverse(lists[t].X_OG[st.grasp])}
    queries = {
        "grasp": (problem.q_start, sg.approach[0], phase_worlds(scratch, task.X_WO_start, None, open_)),
        "carry": (sg.lift[-1], ex.approach[0], phase_worlds(scratch, X_GO[g], g, {g: closed[g], t: open_[t]})),
        "place": (ex.retreat[-1], st.lift[-1], phase_worlds(scratch, X_GO[t], t, {g: open_[g], t: closed[t]})),
        "rest": (st.approach[0], problem.q_goal, phase_worlds(scratch, task.X_WO_goal, None, open_)),
    }
    gid_g, gid_t = grasp_id(lists, g, sg.grasp), grasp_id(lists, t, st.grasp)
    steps = (moves.arrive("grasp", sg, gid_g, "start") + moves.handover("carry", "place", sg, gid_g, ex, st, gid_t)
             + moves.leave("rest", st, gid_t, "goal"))  # the graph's path arrive, hand-over, leave
    return steps, [Query(name, *queries[name]) for name in RUN_ORDER]


def _keys_and_paths(scratch: Scratch, roadmap: Roadmap | None, weights: np.ndarray, seed: int,
                    lists: dict[str, GraspList], g: str, doubles: list[DoubleGrasp], clock: dict):
    """Key configurations and the four queries, attempt after attempt: the steps and
    solved paths of the first attempt whose queries all succeed, the Table I statistics
    summed over attempts, and counts.  Raises _Failed (Stage.KEYS or TRANSITION)."""
    o = scratch.options
    candidates = _exchanges(scratch, np.random.default_rng([seed, 20]), doubles, lists, g)
    table = {name: TransitionStats() for name in TRANSITIONS}
    counts = {"query_checks": 0}
    t0 = time.perf_counter()
    for attempt in range(o.key_attempts):
        dg, ex, tried = next(candidates)
        t0 = tick(clock, "exchange", t0)
        counts["double_grasps_tried"] = tried
        if dg is None:
            if attempt == 0:
                raise _Failed(PlanningFailed(Stage.KEYS, f"no reachable collision-free exchange pose for the best "
                                                         f"{tried} double grasps ({o.exchange_samples} samples "
                                                         "each with the arms alone, as many leaning)"), {}, counts)
            break
        counts["key_attempts"] = attempt + 1
        steps, queries = steps_of(scratch, dg, ex, lists)
        # the first attempt's streams, then one per attempt
        streams = [[seed, TRANSITIONS.index(q.label)] + ([attempt] if attempt else []) for q in queries]
        results = solve_queries(scratch, roadmap, weights, queries, streams, o.jobs)
        t0 = tick(clock, "queries", t0)
        for name in TRANSITIONS:
            table[name] = table[name].plus(results[name].stats)
            counts["query_checks"] += results[name].checks
        failed = next((n for n in TRANSITIONS if results[n].error is not None), None)
        if failed is None:
            return dg, ex, steps, queries, {n: results[n].path for n in TRANSITIONS}, table, counts
    n = counts["key_attempts"]
    reason = results[failed].error
    raise _Failed(PlanningFailed(Stage.TRANSITION, reason if n == 1 else f"{reason} (the last of {n} double "
                                 "grasps with their exchange tried)", failed), table, counts)


def blend_check(scratch: Scratch, queries: list[Query]):
    """curve_free(step, label, A, C, B) of :func:`solve.time_steps`: a corner on or at the
    end of a query's path in its certified world; a corner between two pieces of an
    approach, lift or retreat line in the step's world without clearance, as those lines
    were checked; a step without a query has no corner to cut."""
    worlds = {q.label: q.worlds.full for q in queries}

    def free(step: Step, label: str | None, A: np.ndarray, C: np.ndarray, B: np.ndarray) -> bool:
        if label is not None:
            return scratch.blend_free(worlds[label], A, C, B)
        own = next((p for p in step.pieces if isinstance(p, str)), None)
        if own is None:
            return False
        return scratch.blend_free(scratch.world(*worlds[own].spec, certified=False), A, C, B)
    return free


class _Failed(Exception):
    """A failure with the statistics gathered up to it."""

    def __init__(self, failure: PlanningFailed, table: dict, counts: dict):
        self.failure, self.table, self.counts = failure, table, counts


def tick(clock: dict, stage: str, t0: float) -> float:
    t = time.perf_counter()
    clock[stage] = clock.get(stage, 0.0) + t - t0
    return t


def _checks(scratch: Scratch, counts: dict) -> int:
    """Every collision check, the workers' included (with one job they ran on this scratch)."""
    workers = counts.get("single_checks", 0) + counts.get("query_checks", 0)
    return scratch.checks + (workers if scratch.options.jobs > 1 else 0)


def _placements(problem: Problem) -> dict[str, np.ndarray]:
    task = problem.spec.task
    return {"start": task.X_WO_start, "goal": task.X_WO_goal}


def failed(problem: Problem, failure: PlanningFailed) -> Outcome:
    """The outcome of a run that failed before planning (its ends, an empty grasp list or
    roadmap): no phases, the task's placements."""
    return Outcome(TASK, placements=_placements(problem), stages=dict.fromkeys(STAGES, 0.0), failure=failure)


def plan(problem: Problem, lists: dict[str, GraspList], roadmap: Roadmap | None, options: OnlineOptions,
         seed: int, known: dict | None = None, scratch: Scratch | None = None) -> Outcome:
    """Plan the pick, hand-over and place; a failure is the Outcome's ``failure``.
    ``known``: single-grasp configurations already found (see :func:`_double_grasps`);
    ``scratch``: the run's scratch when a caller made one (its worlds and memos reused)."""
    scratch = scratch or Scratch(problem, options, roadmap.unchecked if roadmap is not None else ())
    weights = roadmap.weights if roadmap is not None else joint_weights(problem.robot)
    if options.planner == "ompl-rrtconnect":
        ompl_version()  # InputError now, not after the key configurations, when the extra is missing
    placements = _placements(problem)
    clock, counts, table = dict.fromkeys(STAGES, 0.0), {}, {}
    t0 = time.perf_counter()
    try:
        check_ends(scratch)
        try:
            g, doubles, c = choose_hands(scratch, lists, seed, known)
            counts.update(c)
            t0 = tick(clock, "double grasps", t0)
            dg, ex, steps, queries, paths, table, c = _keys_and_paths(scratch, roadmap, weights, seed, lists, g, doubles, clock)
        except _Failed as exc:  # the failure with the counts of its stage
            if exc.failure.stage == Stage.GRASPS:
                tick(clock, "double grasps", t0)
            counts.update(exc.counts)
            table = exc.table
            raise exc.failure from None
        counts.update(c)
        t0 = time.perf_counter()
        phases = time_steps(steps, paths, problem.robot.velocity, np.full(problem.robot.nq, options.acceleration),
                            blend_check(scratch, queries) if options.blend else None, options.held_speed)
        tick(clock, "timing", t0)
    except PlanningFailed as exc:
        counts["checks"] = _checks(scratch, counts)
        return Outcome(TASK, placements=placements, stages=clock, transitions=table, counts=counts, failure=exc)
    counts["waypoints"] = int(sum(len(p.waypoints) for p in phases))
    counts["checks"] = _checks(scratch, counts)
    grasps = ((grasp_id(lists, g, dg.giver.grasp), g, dg.giver.grasp),
              (grasp_id(lists, OTHER[g], dg.taker.grasp), OTHER[g], dg.taker.grasp))
    return Outcome(TASK, phases, grasps, placements, clock, table, counts)
