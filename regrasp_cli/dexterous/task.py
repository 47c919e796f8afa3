"""The in-hand task (seed 003): an ``regrasp.inhand/1`` scene loaded and planned.

The hand's wrist is fixed (the robot at its ``robot_config``, the hand open), the object
is held in its fingertips from the start pose, and the planner finds transfers and
finger regrasps that bring it to the goal pose (:mod:`.roadmap`, :mod:`.gait`).  The
scene gives poses in the hand's grasp frame G; the loaded problem
(:class:`~regrasp_cli.scene.Problem`, as a pick-and-place scene's) has its obstacles in W.
:func:`plan_inhand` returns the :class:`~regrasp_cli.manip.solve.Outcome` every task
returns: one step per transfer or finger regrasp, timed as any plan's
(:func:`~regrasp_cli.manip.solve.time_steps`: a stop at every waypoint, where a contact
changes or the object turns about another point).

Input that cannot work is refused before planning with an :class:`InputError` naming the
field: a hand with fewer than three fingertips, an object wider at its narrowest than the
fingertips can open, a start grasp that is not force closure, a goal pose at which no
grasp of the hand holds the object.  A planning failure names its stage: ``grasps`` (no
force-closure grasp found at the start pose) or ``roadmap`` (the start and goal trees did
not join within their budget).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, replace
from pathlib import Path
from time import perf_counter

import numpy as np
from scipy.spatial import ConvexHull

from regrasp_cli.artefacts import Builder, QuietBuilder, rebuild_notice
from regrasp_cli.config import InhandPlanning, ObstacleSpec, load_inhand_spec
from regrasp_cli.dexterous.gait import GaitOptions, Piece, Regrasp
from regrasp_cli.dexterous.gsn import GsConfig, GsOptions, GsScratch
from regrasp_cli.dexterous.multiquery import GsRoadmap, LearnOptions, LearnStats, from_arrays, learn, query, \
    to_arrays
from regrasp_cli.dexterous.hand import reach, tip_targets
from regrasp_cli.dexterous.motions import piece_motions
from regrasp_cli.dexterous.roadmap import GaitTreeOptions, grow, grow_connect, start_config, tree_budgets
from regrasp_cli.dexterous.smooth import smooth
from regrasp_cli.dexterous.surface import MeshSurface
from regrasp_cli.errors import InputError, StaleArtefactError
from regrasp_cli.grasp.single import HandModel
from regrasp_cli.grasp.surface import build_surface
from regrasp_cli.grasp.workspace import hand_workspace
from regrasp_cli.manip.context import OnlineOptions
from regrasp_cli.manip.solve import Outcome, time_steps
from regrasp_cli.manip.status import PlanningFailed, Stage
from regrasp_cli.manip.steps import turn
from regrasp_cli.model.collision import CollisionOptions, ObjectPlacement, collision_world
from regrasp_cli.model.handshape import palm_and_finger_links
from regrasp_cli.model.objects import mesh_sha256
from regrasp_cli.model.robot import Kinematics, Robot, load_robot
from regrasp_cli.model.selfcollision import disabled_pairs
from regrasp_cli.scene import Problem, scene_object
from regrasp_cli.store import Provenance, artefact_lock, read_artefact, robot_identity, sha256_params, write_artefact

CONTACT_TOLERANCE = InhandPlanning.contact_tolerance  # m: fingertip-object penetration allowed at a contact
PLANNER = "gsn-tree"  # the plan's ``planner``: seed 003's trees in GS_n
# options a query reads and the learning does not (the learning sets its own budget and aim
# for each join): changing them must not make a user learn the roadmap again
QUERY_ONLY = {"learn": ("query_expansions", "shortcuts"),
              "roadmap": ("nodes", "goal_bias", "start_samples", "first_tree", "goal_tree")}
GOAL_PROBES = 40  # RLG samples at the goal pose before it is called unreachable
ROADMAP_FORMAT, ROADMAP_VERSION = "regrasp.inhand-roadmap", 3  # 3: contacts per waypoint (fingertips roll)


def load_inhand_problem(path: str | Path, cache_dir: Path | None) -> Problem:
    """The in-hand scene at ``path`` as a :class:`~regrasp_cli.scene.Problem`: the robot
    at the scene's ``robot_config`` with the hand open (``q_start`` and ``q_goal``, the arm
    holds still), the obstacles posed in W."""
    spec = load_inhand_spec(path)
    robot = load_robot(spec.robot)
    if spec.hand not in robot.hands:
        raise InputError(spec.file, "hand", f"{spec.robot} has no {spec.hand} hand (hands: "
                                            f"{', '.join(robot.hands) or 'none'})")
    h = robot.hands[spec.hand]
    if len(h.finger_idx) < 3 or h.kind != "fingertips":
        raise InputError(spec.file, "hand", f"the {spec.hand} hand has {len(h.finger_idx)} fingers with "
                                            f"{h.kind} contacts; finger gaiting needs at least three fingertips")
    obj = scene_object(spec)
    if spec.robot_config == "rest":
        q = robot.q_rest.copy()
    else:
        try:
            q = robot.configuration(spec.robot_config, "robot_config")
        except InputError as exc:
            raise InputError(spec.file, exc.field, exc.message) from None
    q[h.idx] = h.open
    X_WG = Kinematics(robot).fk(q, h.grasp_frame)
    spec = replace(spec, obstacles=tuple(replace(o, X_WO=X_WG @ o.X_WO) for o in spec.obstacles))
    return Problem(spec, robot, obj, disabled_pairs(robot, cache_dir), q, q.copy(),
                   None if cache_dir is None else Path(cache_dir))


def scratch(problem: Problem, rng: np.random.Generator) -> GsScratch:
    """What the planner checks GS_n with (:func:`gs_scratch`) for the in-hand scene's problem."""
    return gs_scratch(problem.robot, problem.spec.hand, problem.object.mesh, problem.disabled.links(),
                      problem.q_start, problem.spec.obstacles, problem.spec.object.friction, problem.cache_dir, rng)


def gs_scratch(robot: Robot, hand: str, mesh, disabled_links, q_fixed: np.ndarray, obstacles: tuple[ObstacleSpec, ...],
               friction: float, cache_dir: Path | None, rng: np.random.Generator,
               tolerance: float = CONTACT_TOLERANCE) -> GsScratch:
    """What the planner checks GS_n with: the hand model with the object (the robot at
    ``q_fixed`` (nq,), the wrist held there), the fingers' workspaces, the surface sampled
    every half fingertip radius, the triangulated one; ``obstacles`` posed in W;
    ``tolerance`` (m) the fingertip-object penetration a contact may have (the one the
    plan records, which the validator checks with).  The world checks only the pairs of a
    finger or the object with an obstacle or a link of the robot outside the hand: nothing
    else moves while the wrist is held (:func:`still_collisions` is the rest, checked once),
    and the hand model checks the hand against itself and the object."""
    hm = HandModel(robot, hand, mesh, disabled_links, tolerance)
    hm.q = np.array(q_fixed, float)
    hm.X_WG = Kinematics(robot).fk(hm.q, robot.hands[hand].grasp_frame)
    ws = hand_workspace(robot, hand, cache_dir=cache_dir)
    tip = min(f.tip_radius for f in robot.hands[hand].spec.fingers)
    sampled = build_surface(mesh, 0.5 * tip, rng)
    rho = float(np.linalg.norm(mesh.vertices - sampled.mass_centre, axis=1).max())
    world = None
    if obstacles:  # checked as the validator does, with the object touched by this hand only
        moving, inside = finger_links(robot, hand) | {"object"}, palm_and_finger_links(robot, hand) | {"object"}
        world = collision_world(robot, obstacles, disabled_links, ObjectPlacement(mesh, hm.X_WG, None, (hand,)),
                                CollisionOptions(tolerance, tolerance),
                                pair_filter=lambda a, b: bool({a, b} & moving) and not {a, b} <= inside)
    return GsScratch(hm, ws, sampled, MeshSurface.of(mesh), rho, GsOptions(friction=friction), world=world)


def finger_links(robot: Robot, hand: str) -> set[str]:
    """The links that move with ``hand``'s fingers (not its palm)."""
    joints = set(robot.hand_joints(hand))
    return {robot.model.frames[go.parentFrame].name for go in robot.collision_model.geometryObjects
            if go.parentJoint in joints}


def still_collisions(robot: Robot, hand: str, disabled_links, q_fixed: np.ndarray,
                     obstacles: tuple[ObstacleSpec, ...]) -> list[tuple[str, str]]:
    """The pairs in collision at ``q_fixed`` (nq,) that no finger of ``hand`` is in: what
    the GS_n checks of :func:`gs_scratch` leave out, as nothing there moves."""
    moving = finger_links(robot, hand)
    world = collision_world(robot, obstacles, disabled_links, pair_filter=lambda a, b: not ({a, b} & moving))
    return world.colliding_pairs(q_fixed)


def turn_in_hand(s: GsScratch, start: GsConfig, goal: GsConfig, rng: np.random.Generator,
                 options: GaitTreeOptions = GaitTreeOptions(), gait: GaitOptions = GaitOptions(),
                 smoothing: bool = True) -> list[Piece] | None:
    """The transfers and finger regrasps that take the object held in ``start`` to exactly
    ``goal`` (its pose and contacts: another grasp of the hand), the wrist fixed (seed 003,
    the two-tree search of :func:`plan_inhand` ending at ``goal`` itself); None within the
    budget.  A regrasp move of the manipulation graph (:mod:`manip.graph`, ``inhand``)."""
    pieces, _, _ = grow_connect(s, start, goal, rng, options, gait, exact=True)
    if pieces is None or not smoothing:
        return pieces
    return smooth(s, pieces, rng, gait)


def _check_size(problem: Problem, s: GsScratch) -> None:
    """The object must fit between the fingertips: its narrowest extent (over the
    principal axes of its hull) no wider than the farthest two fingertips can be apart."""
    tips = [w.samples[ConvexHull(w.samples).vertices] for w in s.workspaces]  # the farthest are on the hulls
    span = max(float(np.linalg.norm(a[:, None] - b[None], axis=2).max())
               for i, a in enumerate(tips) for b in tips[i + 1:])
    narrowest = float(problem.object.mesh.convex_hull.bounding_box_oriented.extents.min())
    if narrowest > span:
        raise InputError(problem.spec.file, "object.mesh",
                         f"{problem.object.name} is {narrowest:.3f} m across at its narrowest, wider than the "
                         f"{problem.spec.hand} hand's fingertips can open ({span:.3f} m apart at most)")


def _check_still(problem: Problem) -> None:
    """The robot holding the wrist at ``robot_config`` must be free but for its fingers
    (the GS_n checks see only what moves)."""
    spec = problem.spec
    pairs = still_collisions(problem.robot, spec.hand, problem.disabled.links(), problem.q_start, spec.obstacles)
    if pairs:
        raise InputError(spec.file, "robot_config", f"the robot holding the wrist there is in collision, its fingers "
                                                    f"aside ({', '.join('-'.join(p) for p in pairs[:3])})")


def _check_reach(problem: Problem, s: GsScratch) -> None:
    """The object must be where the fingertips reach, at its start and at its goal: some
    fingertip workspace sample (G) within ``rho`` (the object's radius about its mass
    centre) and the fingertip's radius of that centre.
    The goal's position is the start's when the scene gives none, so the start is
    blamed for both then."""
    spec = problem.spec
    tips = np.concatenate([w.samples for w in s.workspaces])
    centre_O, reach = s.sampled.mass_centre, s.rho + float(np.max(s.hand.radii))
    for field, X_GO in (("object_start", spec.X_GO_start), ("object_goal", spec.X_GO_goal)):
        c = X_GO[:3, :3] @ centre_O + X_GO[:3, 3]
        gap = float(np.linalg.norm(tips - c, axis=1).min()) - reach
        if gap > 0:
            own = field == "object_start" or not np.allclose(X_GO[:3, 3], spec.X_GO_start[:3, 3])
            raise InputError(spec.file, field if own else "object_start",
                             f"the object's centre at [{', '.join(f'{v:.3g}' for v in c)}] m (grasp frame) is "
                             f"{gap:.3g} m beyond the reach of every fingertip of the {problem.spec.hand} hand")


def given_start(problem: Problem, s: GsScratch, rng: np.random.Generator) -> GsConfig:
    """The scene's start grasp: each finger's contact the surface point nearest the one
    given, the fingers by IK; InputError when it cannot be, or is not force closure."""
    spec, h = problem.spec, problem.robot.hands[problem.spec.hand]
    names = [f.name for f in h.spec.fingers]
    given = dict(spec.start_grasp)
    if set(given) != set(names):
        raise InputError(spec.file, "start_grasp", f"expected a contact for each finger of the {problem.spec.hand} hand "
                                                   f"({', '.join(names)}), found {', '.join(given) or 'none'}")
    tri, uv = s.surface.locate(np.array([given[n] for n in names], float))
    p, n = s.surface.points(tri, uv), s.surface.normals[tri]
    X_WO = s.X_WG @ spec.X_GO_start
    q = reach(s.hand, s.hm.q, tip_targets(X_WO, p, n, s.hand.radii), rng, restarts=10, tol=s.options.tol, kin=s.kin)
    if q is None:
        raise InputError(spec.file, "start_grasp", "the fingertips cannot reach these contacts with the object at "
                                                   "object_start")
    if s.collides(spec.X_GO_start, q):
        raise InputError(spec.file, "start_grasp", "with the fingertips on these contacts the hand collides with "
                                                   "the object or itself")
    if s.closure(p, n) <= 0:  # exact, with the validator's margin: this is the user's grasp
        raise InputError(spec.file, "start_grasp", f"these contacts do not hold the object: not force closure "
                                                   f"with friction {spec.object.friction:g}")
    return GsConfig(spec.X_GO_start.copy(), p, n, q)


def plan_inhand(problem: Problem, seed: int, progress: Callable[[int, int], None] | None = None,
                builder: Builder | None = None) -> Outcome:
    """Plan the reorientation: the outcome's steps bring the object to the goal pose, or
    its failure names the stage.  ``progress(done, budget)`` is called after each
    single-query expansion; ``builder`` is told why a cached roadmap is learned again."""
    spec, o = problem.spec, problem.spec.planning
    rng = np.random.default_rng(seed)
    t0 = perf_counter()
    s = scratch(problem, rng)
    _check_size(problem, s)
    _check_reach(problem, s)
    _check_still(problem)
    options = GaitTreeOptions(step_rad=o.step_rad, nodes=o.nodes)
    stages, counts = {"setup": perf_counter() - t0}, {}
    t = perf_counter()
    given = given_start(problem, s, rng) if spec.start_grasp else None
    goal = goal_config(problem, s, rng, options)
    start = given or start_config(s, spec.X_GO_start, rng, options)
    stages["start grasp"] = perf_counter() - t
    if start is None:
        return _outcome(problem, s, [], stages, counts, PlanningFailed(
            Stage.GRASPS, f"no force-closure grasp of the object at its start pose in {options.start_samples} samples"))
    if o.mode == "multi-query":
        return _plan_multi_query(problem, s, start, goal, rng, options, stages, builder)
    t = perf_counter()
    pieces, iterations, kept = None, 0, 0
    tick = None if progress is None else _ticker(progress, options.nodes)
    for k, budget in enumerate(tree_budgets(options.nodes, options.first_tree)):
        if k:  # fresh trees from fresh start and goal grasps
            start = given or start_config(s, spec.X_GO_start, rng, options) or start
            goal = start_config(s, spec.X_GO_goal, rng, replace(options, start_samples=GOAL_PROBES)) or goal
        budgeted, gait = replace(options, nodes=budget), GaitOptions(gait_m=o.gait_m)
        if options.goal_tree:
            pieces, _, st = grow_connect(s, start, goal, rng, budgeted, gait, tick)
        else:
            pieces, _, st = grow(s, start, spec.X_GO_goal, rng, budgeted, gait, tick)
        iterations, kept = iterations + st.iterations, kept + st.kept
        if pieces is not None:
            break
    stages["roadmap"] = perf_counter() - t
    counts.update(nodes_kept=st.kept, iterations=iterations, trees=k + 1, start_liftable=st.start_liftable)
    if pieces is None:
        what = "the start and goal trees did not join" if options.goal_tree else "the tree did not reach the goal pose"
        return _outcome(problem, s, [], stages, counts, PlanningFailed(
            Stage.ROADMAP, f"{what} in GS_n in {iterations} expansions ({k + 1} "
                           f"{'pairs of trees' if options.goal_tree else 'trees'}, {kept} nodes)"))
    return _smoothed(problem, s, pieces, rng, stages, counts)


def _ticker(progress: Callable[[int, int], None], budget: int) -> Callable[[], None]:
    """A per-expansion callback that reports the expansions done so far, over all trees."""
    done = 0

    def tick() -> None:
        nonlocal done
        done += 1
        progress(done, budget)
    return tick


def _smoothed(problem: Problem, s: GsScratch, pieces: list[Piece], rng: np.random.Generator, stages: dict,
              counts: dict) -> Outcome:
    o = problem.spec.planning
    counts.update(finger_regrasps_unsmoothed=sum(isinstance(p, Regrasp) for p in pieces),
                  transfers_unsmoothed=sum(not isinstance(p, Regrasp) for p in pieces))
    if o.smooth:
        t = perf_counter()
        pieces = smooth(s, pieces, rng, GaitOptions(gait_m=o.gait_m))
        stages["smoothing"] = perf_counter() - t
    return _outcome(problem, s, pieces, stages, counts)


def _plan_multi_query(problem: Problem, s: GsScratch, start: GsConfig, goal: GsConfig, rng: np.random.Generator,
                      options: GaitTreeOptions, stages: dict, builder: Builder | None) -> Outcome:
    """§V's multi-query version: the learned roadmap (built first when missing), the start
    and goal grasps joined to it, the path over it."""
    t = perf_counter()
    rm, _, built = inhand_roadmap(problem, builder=builder)
    stages["roadmap learning" if built else "roadmap loading"] = perf_counter() - t
    t = perf_counter()
    gait = GaitOptions(gait_m=problem.spec.planning.gait_m)
    pieces, st, why = query(s, rm, start, goal, rng, LearnOptions(), options, gait)
    stages["roadmap"] = perf_counter() - t
    counts = dict(nodes_kept=st.kept, iterations=st.iterations, trees=2, start_liftable=st.start_liftable,
                  roadmap_nodes=len(rm.nodes))
    if pieces is None:
        return _outcome(problem, s, [], stages, counts,
                        PlanningFailed(Stage.ROADMAP, f"multi-query: {why} ({len(rm.nodes)} roadmap nodes)"))
    return _smoothed(problem, s, pieces, rng, stages, counts)


def _outcome(problem: Problem, s: GsScratch, pieces: list[Piece], stages: dict, counts: dict,
             failure: PlanningFailed | None = None) -> Outcome:
    """The outcome of the turn ``pieces``: one step per transfer and finger regrasp, timed
    stop to stop with the robot's velocity limits and the plans' acceleration; the
    ``start`` and ``goal`` placements are the object's poses in W (it never rests)."""
    robot, spec = problem.robot, problem.spec
    names = [f.name for f in robot.hands[spec.hand].spec.fingers]
    steps = turn(spec.hand, piece_motions(pieces, names, s.X_WG))
    phases = time_steps(steps, {}, robot.velocity, np.full(robot.nq, OnlineOptions.acceleration))
    gaits = sum(isinstance(p, Regrasp) for p in pieces)
    counts = {**counts, "nodes_generated": s.generated, "finger_regrasps": gaits, "transfers": len(pieces) - gaits,
              "collision_checks": s.checks, "gs_failures": dict(s.failures)}
    return Outcome("inhand", () if failure else phases,
                   placements={"start": s.X_WG @ spec.X_GO_start, "goal": s.X_WG @ spec.X_GO_goal},
                   stages=stages, counts=counts, failure=failure)


def roadmap_provenance(problem: Problem, o: LearnOptions, r: GaitTreeOptions, g: GaitOptions) -> Provenance:
    """What a learned roadmap depends on: the robot, the object's geometry, the hand's
    posture, the friction, where the object is held, the obstacles and the options the
    learning reads (not a query's own: ``QUERY_ONLY``)."""
    spec = problem.spec
    plain = lambda a: (np.round(a, 9) + 0.0).tolist()  # noqa: E731 - -0.0 and 0.0 are one key
    learning = {k: v for k, v in asdict(o).items() if k not in QUERY_ONLY["learn"]}
    roadmap = {k: v for k, v in asdict(r).items() if k not in QUERY_ONLY["roadmap"]}
    params = {"hand": problem.spec.hand, "q_fixed": plain(problem.q_start), "friction": spec.object.friction,
              "p_GO": plain(spec.X_GO_start[:3, 3]), "obstacles": [repr(x) for x in spec.obstacles],
              "learn": learning, "roadmap": roadmap, "gait": asdict(g)}
    return Provenance(ROADMAP_FORMAT, ROADMAP_VERSION, {"urdf": problem.robot.urdf_sha256,
                                                        "robot_yaml": problem.robot.spec_sha256,
                                                        "mesh": mesh_sha256(problem.object),
                                                        "params": sha256_params(params)})


def roadmap_path(cache_dir: Path, problem: Problem, prov: Provenance) -> Path:
    """One file per robot, hand and inputs (the object's mesh among them: two objects'
    roadmaps must not take turns overwriting one file)."""
    return (Path(cache_dir) / "inhand-roadmap" /
            f"{robot_identity(problem.robot)}-{problem.spec.hand}-{sha256_params(dict(prov.inputs))[:12]}.h5")


def inhand_roadmap(problem: Problem, o: LearnOptions = LearnOptions(), progress=None,
                   builder: Builder | None = None) -> tuple[GsRoadmap, LearnStats | None, bool]:
    """The learned roadmap for the problem's hand, object and placement: read from the
    cache when fresh, else learned (seeded by the options, not the query) and written;
    (roadmap, the learning's counts when it ran, whether it was built).  A stale or
    damaged file is learned again, never used, and ``builder`` told why, as for a scene's
    artefacts (:mod:`regrasp_cli.artefacts`).  A roadmap of a single node is an error: no
    grasp at a random orientation joined it."""
    spec = problem.spec
    r = replace(GaitTreeOptions(), step_rad=spec.planning.step_rad)
    g = GaitOptions(gait_m=spec.planning.gait_m)
    prov = roadmap_provenance(problem, o, r, g)
    cache_dir = problem.cache_dir
    path = None if cache_dir is None else roadmap_path(cache_dir, problem, prov)
    if path is not None:
        with artefact_lock(path):
            if path.is_file():
                try:  # read once: the freshness check is the read itself
                    return from_arrays(read_artefact(path, prov, "regrasp inhand roadmap").data), None, False
                except StaleArtefactError as exc:
                    (builder or QuietBuilder()).notice(rebuild_notice(path, exc))
            rm, st = _learn(problem, o, r, g, progress)
            write_artefact(path, prov, to_arrays(rm), attrs={"roots": st.roots, "joined": st.joined})
            return rm, st, True
    rm, st = _learn(problem, o, r, g, progress)
    return rm, st, True


def _learn(problem: Problem, o: LearnOptions, r: GaitTreeOptions, g: GaitOptions,
           progress) -> tuple[GsRoadmap, LearnStats]:
    rng = np.random.default_rng(o.seed)
    s = scratch(problem, rng)
    rm, st = learn(s, problem.spec.X_GO_start[:3, 3], rng, o, r, g, progress)
    if len(rm.nodes) < 2:
        raise PlanningFailed(Stage.ROADMAP, f"the roadmap learning joined none of {st.roots} grasps at random "
                                            f"orientations ({o.roots} tried) to its first node")
    return rm, st


def goal_config(problem: Problem, s: GsScratch, rng: np.random.Generator, o: GaitTreeOptions) -> GsConfig:
    """The goal tree's root: the best of ``GOAL_PROBES`` RLG samples at the goal pose
    (:func:`roadmap.start_config`); InputError when none holds the object there."""
    spec = problem.spec
    goal = start_config(s, spec.X_GO_goal, rng, replace(o, start_samples=GOAL_PROBES))
    if goal is None:
        raise InputError(spec.file, "object_goal", f"no grasp of the {problem.spec.hand} hand holds the object at this "
                                                   f"pose ({GOAL_PROBES} samples): the fingers cannot reach it there")
    return goal
