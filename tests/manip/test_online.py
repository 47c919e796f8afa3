"""The online stage (Saut et al. 2010, §IV-B, §V-B, §V-C) piece by piece, on the default
scene with small grasp lists built once per test run (shared with tests/test_cli_plan.py):

* hand shapes: hand-hand and hand-environment tests, against a brute-force coal check
  without the bounding-sphere filter;
* key configurations: a single grasp (pose, collisions, approach, lift) and the straight
  Cartesian lines they are made of;
* exchange: the orientation from the grasp directions, the exchange pose on the grid;
* the hand-over task's failures (:func:`handover.plan`), each at its own
  :class:`~regrasp_cli.manip.status.Stage` with its reason (its independence of the number
  of worker processes: tests/test_cli_plan.py, the same plan bytes with one job or two);
* a roadmap query on a hand-made three-node Super Graph whose short edge the object blocks.

Collision checks of results use worlds built here from the Problem and the plan checker's
dense sampling (:func:`regrasp_cli.validate.collision_issues`), not the planner's own.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import coal
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from regrasp_cli.grasp.build import BuildOptions, GraspList, load_or_build
from regrasp_cli.grasp.single import GraspOptions
from regrasp_cli.model.collision import CollisionWorld, ObjectPlacement, mesh_geometry, obstacle_geometry, \
    segment_samples
from regrasp_cli.manip.context import OnlineOptions, Scratch
from regrasp_cli.manip.doublegrasp import cheap_order, double_grasps, environment_free, single_configurations
from regrasp_cli.manip.exchange import exchange_orientation, wrist_path_cost
from regrasp_cli.model.handshape import HandShape, StaticGeometry, hand_hits_static, hand_shapes, hands_collide, \
    static_geometry
from regrasp_cli.manip.keyconf import PRESHAPE_LIFT, SingleConfig, _backed_off, approach_axis, cartesian_line, preshapes, \
    shoulder, single_configuration, with_fingers, wrist
from regrasp_cli.manip.modes import Kind
from regrasp_cli.manip.queries import QueryStats, Roadmap, _retreats, roadmap_query
from regrasp_cli.manip.solve import TransitionStats
from regrasp_cli.manip.status import Stage
from regrasp_cli.manip.tasks import handover
from regrasp_cli.manip.tasks.handover import TRANSITIONS, object_shape, exchange_pose, grasp_id, phase_worlds, plan
from regrasp_cli.model.robot import Kinematics
from regrasp_cli.motion.local import distance, joint_reach, joint_weights
from regrasp_cli.motion.rrt import RRTOptions
from regrasp_cli.spatial import inverse, pose_error, rotation_angle
from regrasp_cli.trajectory import Phase
from regrasp_cli.validate import collision_issues

ROOT = Path(__file__).resolve().parents[2]
SCENE_YAML = ROOT / "configs" / "scenes" / "desk_handover.yaml"
GRASP_TARGET = 40  # grasps per hand: small lists (~3 s per hand), as `plan --grasp-target 40`
POSE_TOL = (0.001, 0.01)  # m, rad
QUERIES = ("grasp", "carry", "place", "rest")  # the hand-over's transit and transfer queries, in plan order


# ------------------------------------------------------------------ fixtures and helpers


@pytest.fixture(scope="module")
def lists(problem, cache_dir) -> dict[str, GraspList]:
    """Both hands' grasp lists, in the run's cache (the CLI tests use the same ones)."""
    options = BuildOptions(grasp=replace(GraspOptions(), target=GRASP_TARGET), seed=problem.spec.planning.seed,
                           jobs=2)
    return {h: load_or_build(SCENE_YAML, cache_dir, h, options) for h in ("right", "left")}


@pytest.fixture(scope="module")
def shapes(problem, lists) -> dict[str, list[HandShape]]:
    return {h: hand_shapes(problem.robot, h, lists[h].finger_q) for h in lists}


@pytest.fixture(scope="module")
def env(problem) -> StaticGeometry:
    return static_geometry(problem.spec.obstacles)


def obstacle(problem, name: str):
    return next(o for o in problem.spec.obstacles if o.name == name)


def new_scratch(problem, **options) -> Scratch:
    return Scratch(problem, OnlineOptions(**options))


def test_the_task_spells_the_four_queries_in_plan_order():
    assert TRANSITIONS == QUERIES


def _tf(X: np.ndarray) -> coal.Transform3s:
    return coal.Transform3s(X[:3, :3].copy(), X[:3, 3].copy())


def _collide(g1, X1: np.ndarray, g2, X2: np.ndarray) -> bool:
    return coal.collide(g1, _tf(X1), g2, _tf(X2), coal.CollisionRequest(), coal.CollisionResult()) > 0


def brute_hits_static(shape: HandShape, X_WG: np.ndarray, env: StaticGeometry) -> bool:
    """Every hand geometry against every obstacle, without the bounding-sphere filter."""
    return any(_collide(g, X_WG @ X_GL, o, X_WO) for g, X_GL in zip(shape.geometries, shape.X_GL)
               for o, X_WO in zip(env.geometries, env.X_W))


def brute_hands_collide(a: HandShape, X_OGa: np.ndarray, b: HandShape, X_OGb: np.ndarray) -> bool:
    return any(_collide(ga, X_OGa @ Xa, gb, X_OGb @ Xb) for ga, Xa in zip(a.geometries, a.X_GL)
               for gb, Xb in zip(b.geometries, b.X_GL))


def translated(X: np.ndarray, d) -> np.ndarray:
    Y = X.copy()
    Y[:3, 3] += np.asarray(d, float)
    return Y


def path_collisions(world: CollisionWorld, path: np.ndarray, problem) -> list:
    """Issues of the plan checker's dense collision test along ``path`` (k, nq)."""
    phase = Phase("test", Kind.TRANSIT, {}, (), None, np.asarray(path), np.zeros(len(path)))
    issues, _ = collision_issues(phase, world, joint_reach(problem.robot), 0.01, 0.005)
    return issues


def static_world(problem, X_WO: np.ndarray, touching: tuple[str, ...] = ()) -> CollisionWorld:
    return problem.world(ObjectPlacement(problem.object.mesh, X_WO, None, touching))


def grasp_from_below(problem, hand: str) -> np.ndarray:
    """X_OG (4, 4) of a hand under the object: its grasp frame 2 cm below the object's base
    (inside the 4 cm desk top when the object stands on it), approaching straight up."""
    a_G = approach_axis(new_scratch(problem), hand)  # wrist -> grasp frame, in G
    R_OG, _ = Rotation.align_vectors(np.array([[0.0, 0.0, 1.0]]), a_G[None])
    X = np.eye(4)
    X[:3, :3] = R_OG.as_matrix()
    c = problem.object.mesh.centroid
    X[:3, 3] = [c[0], c[1], -0.02]
    return X


# ------------------------------------------------------------------ hand shapes


def test_hands_at_the_same_pose_collide_and_apart_do_not(problem, lists, shapes):
    right, left = lists["right"], lists["left"]
    X = right.X_OG[0]
    assert hands_collide(shapes["right"][0], X, shapes["right"][0], X)
    assert hands_collide(shapes["right"][0], X, shapes["left"][0], X)  # the left hand where the right one is
    assert hands_collide(shapes["left"][0], X, shapes["right"][0], X)
    far = translated(left.X_OG[0], [1.0, 0.0, 0.0])  # the left hand 1 m away along the object x
    assert not hands_collide(shapes["right"][0], X, shapes["left"][0], far)


def test_hands_collide_is_symmetric_and_matches_a_brute_force_check(lists, shapes):
    right, left = lists["right"], lists["left"]
    n = 8
    seen = set()
    for i in range(n):
        for j in range(n):
            ab = hands_collide(shapes["right"][i], right.X_OG[i], shapes["left"][j], left.X_OG[j])
            ba = hands_collide(shapes["left"][j], left.X_OG[j], shapes["right"][i], right.X_OG[i])
            assert ab == ba, (i, j)
            assert ab == brute_hands_collide(shapes["right"][i], right.X_OG[i], shapes["left"][j], left.X_OG[j]), (i, j)
            seen.add(ab)
    assert seen == {True, False}  # both outcomes occur among these pairs: the check is not vacuous


def test_a_hand_from_below_hits_the_desk_top(problem, lists, shapes):
    X_WO = problem.spec.task.X_WO_start
    X_OG = grasp_from_below(problem, "right")
    X_WG = X_WO @ X_OG
    assert X_WG[2, 3] < 0.74  # the grasp frame is under the desk's top face
    desk = static_geometry((obstacle(problem, "desk_top"),))
    others = static_geometry(tuple(o for o in problem.spec.obstacles if o.name.startswith(("lamp", "vase"))))
    hand = shapes["right"][0]  # fingers closed as for grasp 0: the palm matters here
    assert hand_hits_static(hand, X_WG, desk)
    assert not hand_hits_static(hand, X_WG, others)
    # the same grasp of the object lifted 30 cm off the desk touches nothing
    assert not hand_hits_static(hand, translated(X_WO, [0, 0, 0.3]) @ X_OG, static_geometry(problem.spec.obstacles))


def test_a_touching_hand_may_rest_its_fingertips_on_the_desk(problem):
    """The shapes' fingertips are eroded by the contact tolerance for a hand that touches
    (and only they); a tip 1 mm into the desk then clears it, 3 mm does not."""
    import coal

    robot, tol = problem.robot, 0.002
    h = robot.hands["right"]
    shape = hand_shapes(robot, "right", h.open, tol)[0]
    names = [robot.model.frames[go.parentFrame].name for go in robot.collision_model.geometryObjects
             if go.parentJoint in {robot.model.getJointId(robot.joint_names[i]) for i in h.idx}
             | {robot.model.frames[h.grasp_frame].parentJoint}]
    tips = {robot.model.frames[t].name for t in h.tip_frames}
    assert len(names) == len(shape.geometries) and tips <= set(names)
    for name, g, t in zip(names, shape.geometries, shape.touch_geometries):
        if name in tips:
            assert isinstance(t, coal.Sphere) and t.radius == pytest.approx(g.radius - tol)
        else:
            assert t is g
    # the index tip alone, 1 mm or 3 mm into a desk under it
    i = names.index(robot.spec.hands["right"].fingers[1].tip_link)
    tip = HandShape((shape.geometries[i],), shape.X_GL[i:i + 1], shape.centres[i:i + 1], shape.radii[i:i + 1],
                    (shape.touch_geometries[i],))
    r = shape.geometries[i].radius
    for depth, hits in ((0.001, False), (0.003, True)):
        X_WG = np.eye(4)
        X_WG[:3, 3] = -shape.X_GL[i][:3, 3] + [0.72, 0.0, 0.74 + r - depth]  # the tip's centre above the desk top
        desk = static_geometry((obstacle(problem, "desk_top"),))
        assert hand_hits_static(tip, X_WG, desk)  # not touching: any contact collides
        assert hand_hits_static(tip, X_WG, desk, touching=True) == hits, depth


def test_environment_filter_drops_the_grasps_that_hit_the_desk(problem, lists, env):
    """A list with a grasp from below appended: at the start pose (on the desk) the filter
    keeps exactly the grasps whose hand touches no obstacle (brute force), the one from
    below dropped; with the object lifted into free space it keeps them all."""
    g = lists["right"]
    below = grasp_from_below(problem, "right")
    extended = replace(g, X_OG=np.concatenate([g.X_OG, below[None]]),
                       finger_q=np.concatenate([g.finger_q, g.finger_q[:1]]))
    shapes = hand_shapes(problem.robot, "right", extended.finger_q)
    X_WO = problem.spec.task.X_WO_start
    kept = environment_free(extended, shapes, X_WO, env)
    assert len(g) not in kept  # the grasp from below
    assert 0 < len(kept) < len(extended)
    expected = [k for k in range(len(extended)) if not brute_hits_static(shapes[k], X_WO @ extended.X_OG[k], env)]
    assert kept.tolist() == expected
    lifted = translated(X_WO, [0, 0, 0.3])
    assert environment_free(extended, shapes, lifted, env).tolist() == list(range(len(extended)))


# ------------------------------------------------------------------ key configurations


@pytest.fixture(scope="module")
def single(problem, lists, shapes, env) -> tuple[Scratch, SingleConfig]:
    """The first single-grasp configuration of the right hand at the object's start pose,
    in the planner's order."""
    scratch, rng = new_scratch(problem), np.random.default_rng(0)
    g, X_WO = lists["right"], problem.spec.task.X_WO_start
    for k in cheap_order(scratch, g, environment_free(g, shapes["right"], X_WO, env), X_WO)[:10]:
        c = single_configuration(scratch, rng, g, int(k), X_WO)
        if c is not None:
            return scratch, c
    pytest.fail("no single-grasp configuration among the 10 best right-hand grasps at the start pose")


def test_single_configuration_grasps_at_the_grasp_pose(problem, lists, single):
    _, c = single
    robot, h, g = problem.robot, problem.robot.hands["right"], lists["right"]
    assert (c.hand, c.X_WO.tolist()) == ("right", problem.spec.task.X_WO_start.tolist())
    dp, da = pose_error(Kinematics(robot).fk(c.q_closed, h.grasp_frame), c.X_WO @ g.X_OG[c.grasp])
    assert dp <= POSE_TOL[0] and da <= POSE_TOL[1], (dp, da)
    assert np.array_equal(c.q_closed[h.idx], g.finger_q[c.grasp])
    assert robot.within_limits(c.q_closed)


def test_single_configuration_is_collision_free(problem, lists, single):
    """Closed on the object (its fingertips may touch it), the approach with the object
    standing free of the hand, the lift with the object held."""
    _, c = single
    X_OG = lists["right"].X_OG[c.grasp]
    assert static_world(problem, c.X_WO, ("right",)).colliding_pairs(c.q_closed) == []
    assert path_collisions(static_world(problem, c.X_WO), c.approach, problem) == []
    held = problem.world(ObjectPlacement(problem.object.mesh, inverse(X_OG), "right", ("right",)))
    assert path_collisions(held, c.lift, problem) == []


@pytest.mark.parametrize("distance", [0.008, 0.015])
def test_backed_off_preshape_moves_each_tip_straight_out_of_its_contact(problem, lists, single, distance):
    """The pre-shape for low pinches: every fingertip in contact moves out of its
    contact along the normal, by at least half of ``distance`` (its sphere centre at
    (p_tip - p) . n >= r + d / 2 in the object frame); the fingers without contact stay
    as they were."""
    scratch, _ = single
    robot, h, g = problem.robot, problem.robot.hands["right"], lists["right"]
    kin = Kinematics(robot)
    backed = 0
    for k in range(12):
        f = _backed_off(scratch, g, k, distance)
        if f is None:
            continue
        backed += 1
        q = with_fingers(scratch, robot.q_rest, "right", f)
        X_OW = g.X_OG[k] @ inverse(kin.fk(q, h.grasp_frame))
        for i, finger in enumerate(h.spec.fingers):
            p_O = X_OW[:3, :3] @ kin.fk(q, h.tip_frames[i])[:3, 3] + X_OW[:3, 3]
            if g.in_contact[k, i]:
                assert (p_O - g.points[k, i]) @ g.normals[k, i] >= finger.tip_radius + distance / 2 - 1e-9
            else:
                at = [list(h.idx).index(j) for j in h.finger_idx[i]]
                np.testing.assert_array_equal(f[at], g.finger_q[k][at])
    assert backed >= 4, backed  # many grasps can back off


def test_paired_search_returns_configurations_that_pair(problem, lists, shapes, env):
    """The pairs-first search (few pairs among the first configurations): each giver
    configuration it returns has a grasp the taker's arm reaches at the goal that shares
    the object with it, each taker configuration shares it with one of the giver's new
    ones, and every configuration is collision-free, closed on the object at its end.
    With nothing found before, on the default scene, it finds pairs (the search alone)."""
    scratch = new_scratch(problem)
    task = problem.spec.task
    giver, taker = handover._paired_search(scratch, np.random.default_rng(3), lists, shapes, env, "right", ([], []),
                                           lean=False)
    assert giver and taker
    reach_t = handover.workable(scratch, lists["left"], shapes["left"], task.X_WO_goal, env)[1]
    for c in giver:
        assert any(not hands_collide(shapes["right"][c.grasp], lists["right"].X_OG[c.grasp], shapes["left"][b],
                                     lists["left"].X_OG[b]) for b in reach_t)
        assert static_world(problem, task.X_WO_start, ("right",)).colliding_pairs(c.q_closed) == []
    for c in taker:
        assert any(not hands_collide(shapes["right"][a.grasp], lists["right"].X_OG[a.grasp], shapes["left"][c.grasp],
                                     lists["left"].X_OG[c.grasp]) for a in giver)
        assert static_world(problem, task.X_WO_goal, ("left",)).colliding_pairs(c.q_closed) == []
    assert double_grasps(giver, lists["right"], shapes["right"], taker, lists["left"], shapes["left"])


def test_lifted_preshape_raises_each_tip_off_the_support(problem, lists, single):
    """With the support's upward direction, a backed-off tip also rises: its centre ends
    higher along it than the plain backed-off tip's, by most of PRESHAPE_LIFT (finger IK
    from the closed values, so not exactly), and still out of its contact."""
    scratch, _ = single
    robot, h, g = problem.robot, problem.robot.hands["right"], lists["right"]
    kin = Kinematics(robot)
    up_O = np.array([0.0, 0.0, 1.0])
    rises = []
    for k in range(len(g)):
        plain = _backed_off(scratch, g, k, 0.008)
        lifted = _backed_off(scratch, g, k, 0.008, PRESHAPE_LIFT * up_O)
        if plain is None or lifted is None:
            continue
        for f in (plain, lifted):
            q = with_fingers(scratch, robot.q_rest, "right", f)
            X_OW = g.X_OG[k] @ inverse(kin.fk(q, h.grasp_frame))
            tips = [X_OW[:3, :3] @ kin.fk(q, h.tip_frames[i])[:3, 3] + X_OW[:3, 3] for i in range(len(h.spec.fingers))]
            if f is plain:
                before = tips
                continue
            for i, finger in enumerate(h.spec.fingers):
                if g.in_contact[k, i]:
                    rises.append((tips[i] - before[i]) @ up_O)
                    assert (tips[i] - g.points[k, i]) @ g.normals[k, i] >= finger.tip_radius + 0.004 - 1e-9
    assert len(rises) >= 8
    assert np.median(rises) >= 0.8 * PRESHAPE_LIFT


def test_approach_starts_open_and_ends_preshaped_at_the_grasp_pose(problem, lists, single):
    scratch, c = single
    robot, h = problem.robot, problem.robot.hands["right"]
    assert np.array_equal(c.approach[0][h.idx], h.open)
    end = c.approach[-1]
    shapes = preshapes(scratch, lists["right"], c.grasp)
    assert any(np.allclose(end[h.idx], f, atol=1e-12) for f in shapes)
    others = np.setdiff1d(np.arange(robot.nq), h.idx)
    assert np.array_equal(end[others], c.q_closed[others])  # the hand is at the grasp pose
    # it starts approach_distance away, with the same orientation
    X_end, X_start = Kinematics(robot).fk(end, h.grasp_frame), Kinematics(robot).fk(c.approach[0], h.grasp_frame)
    assert np.linalg.norm(X_start[:3, 3] - X_end[:3, 3]) == pytest.approx(scratch.options.approach_distance, abs=1e-3)
    assert rotation_angle(X_start[:3, :3].T @ X_end[:3, :3]) <= POSE_TOL[1]
    # only the grasping arm and hand move
    moving = np.flatnonzero(np.any(c.approach != c.approach[-1], axis=0))
    assert set(moving) <= set(h.arm_idx) | set(h.idx)


def test_lift_raises_the_object_by_lift_height(problem, lists, single):
    scratch, c = single
    robot, h = problem.robot, problem.robot.hands["right"]
    X_GO = inverse(lists["right"].X_OG[c.grasp])
    assert np.array_equal(c.lift[0], c.q_closed)
    assert np.all(c.lift[:, h.idx] == c.q_closed[h.idx])  # the fingers stay closed
    z = [(Kinematics(robot).fk(q, h.grasp_frame) @ X_GO)[2, 3] for q in c.lift]
    assert np.all(np.diff(z) > 0)
    X_lifted = Kinematics(robot).fk(c.lift[-1], h.grasp_frame) @ X_GO
    dp, da = pose_error(X_lifted, translated(c.X_WO, [0, 0, scratch.options.lift_height]))
    assert dp <= POSE_TOL[0] and da <= POSE_TOL[1], (dp, da)


def test_cartesian_line_moves_the_grasp_frame_on_a_straight_line(problem, single):
    scratch, c = single
    robot, h = problem.robot, problem.robot.hands["right"]
    X_end = Kinematics(robot).fk(c.q_closed, h.grasp_frame)
    X_far = translated(X_end, [0.05, -0.03, 0.08])
    steps = 4
    line = cartesian_line(scratch, np.random.default_rng(0), "right", c.q_closed, X_far, steps)
    assert line is not None and line.shape == (steps + 1, robot.nq)
    assert np.array_equal(line[-1], c.q_closed)
    for i, q in enumerate(line):  # from X_far (i = 0) to X_end, evenly
        X = Kinematics(robot).fk(q, h.grasp_frame)
        p_expected = X_far[:3, 3] + (i / steps) * (X_end[:3, 3] - X_far[:3, 3])
        assert np.linalg.norm(X[:3, 3] - p_expected) <= 1e-3, i
        assert rotation_angle(X[:3, :3].T @ X_end[:3, :3]) <= POSE_TOL[1], i  # orientation kept
    moving = np.flatnonzero(np.any(line != line[-1], axis=0))
    assert set(moving) <= set(h.arm_idx)


# ------------------------------------------------------------------ exchange


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_exchange_orientation_maps_consistent_directions_exactly(seed):
    rng = np.random.default_rng(seed)
    R_true = Rotation.random(random_state=rng).as_matrix()
    a_r, a_l = rng.normal(size=3), rng.normal(size=3)
    d_r, d_l = 0.4 * R_true @ a_r, 2.5 * R_true @ a_l  # lengths do not matter, directions do
    R = exchange_orientation(a_r, a_l, d_r, d_l)
    assert np.allclose(R.T @ R, np.eye(3), atol=1e-9) and np.linalg.det(R) == pytest.approx(1.0)
    unit = lambda v: v / np.linalg.norm(v)  # noqa: E731
    assert np.allclose(R @ unit(a_r), unit(d_r), atol=1e-9)
    assert np.allclose(R @ unit(a_l), unit(d_l), atol=1e-9)
    assert np.allclose(R, R_true, atol=1e-9)  # two independent directions fix the rotation


@pytest.fixture(scope="module")
def best_double(problem, lists, shapes, env):
    """The best double grasp of the default problem (right hand picks, left hand places)."""
    scratch, rng = new_scratch(problem), np.random.default_rng(0)
    task = problem.spec.task
    giver, _ = single_configurations(scratch, rng, lists["right"], shapes["right"], task.X_WO_start, env)
    taker, _ = single_configurations(scratch, rng, lists["left"], shapes["left"], task.X_WO_goal, env)
    doubles = double_grasps(giver, lists["right"], shapes["right"], taker, lists["left"], shapes["left"])
    assert doubles, "no double grasp on the default scene"
    return doubles[0]


@pytest.mark.parametrize("yaw", [0.0, np.pi / 4, -np.pi / 2, np.pi])
def test_exchange_samples_turn_about_the_vertical_through_the_object_centre(problem, yaw):
    """Without the Gaussian spread, a sample is the pose turned by ``yaw`` about the
    vertical through the object's centre: the centre stays, the orientation is Rz(yaw) R."""
    scratch = new_scratch(problem, exchange_sigma=0.0, exchange_angle_sigma=0.0)
    obj = object_shape(problem)
    X = np.eye(4)
    X[:3, :3] = Rotation.from_rotvec([0.3, -0.2, 1.0]).as_matrix()
    X[:3, 3] = [0.5, 0.1, 1.0]
    Y = handover._perturbed(scratch, np.random.default_rng(0), X, obj, yaw)
    centre = lambda T: T[:3, :3] @ obj.centres[0] + T[:3, 3]  # noqa: E731
    np.testing.assert_allclose(centre(Y), centre(X), atol=1e-12)
    np.testing.assert_allclose(Y[:3, :3], Rotation.from_rotvec([0, 0, yaw]).as_matrix() @ X[:3, :3], atol=1e-12)


def test_exchange_pose_puts_the_object_centre_on_a_free_grid_node(problem, lists, env, best_double):
    scratch = new_scratch(problem)
    robot, task = problem.robot, problem.spec.task
    obj = object_shape(problem)
    X, tested = exchange_pose(scratch, best_double, lists, env, obj)
    assert X is not None and tested >= 1
    assert np.allclose(X[:3, :3].T @ X[:3, :3], np.eye(3), atol=1e-9) and np.linalg.det(X[:3, :3]) > 0
    centre = X[:3, :3] @ obj.centres[0] + X[:3, 3]
    # Fig. 6's grid: the cubes of the arms' reach maps that both hands get to, from 8 cm
    # above the start and the goal up
    start, goal = task.X_WO_start[:3, 3], task.X_WO_goal[:3, 3]
    anchors = np.array([start, goal, wrist(scratch, "right", robot.q_rest), wrist(scratch, "left", robot.q_rest)])
    maps = {h: scratch.reach(h) for h in ("right", "left")}
    nodes = maps["right"].centres()
    nodes = nodes[(nodes[:, 2] >= max(start[2], goal[2]) + 0.08) & maps["left"].reaches(nodes)]
    assert np.min(np.linalg.norm(nodes - centre, axis=1)) < 1e-9
    # ... where each hand was seen pointing within 50 degrees of its grasp's approach
    for c in (best_double.giver, best_double.taker):
        a_W = X[:3, :3] @ lists[c.hand].X_OG[c.grasp, :3, :3] @ approach_axis(scratch, c.hand)
        assert maps[c.hand].reaches(centre[None], a_W[None])[0]
    # ... the ``tested``-th cheapest node of the wrist-path cost
    # the object there keeps 2 cm from every obstacle (coal distance, object mesh itself)
    mesh = mesh_geometry(problem.object.mesh)
    for ob in problem.spec.obstacles:
        d = coal.distance(mesh, _tf(X), obstacle_geometry(ob), _tf(ob.X_WO), coal.DistanceRequest(),
                          coal.DistanceResult())
        assert d >= 0.02 - 1e-6, ob.name
    # and both shoulders reach it
    reach = joint_reach(robot)
    for h in ("right", "left"):
        assert np.linalg.norm(centre - shoulder(scratch, h, robot.q_rest)) <= reach[robot.hands[h].arm_idx[0]]


# ------------------------------------------------------------------ planner failures


def problem_with(problem, **task):
    return replace(problem, spec=replace(problem.spec, task=replace(problem.spec.task, **task)))


def recording_exchanges(monkeypatch) -> list:
    """Wraps :func:`handover._exchanges`: the list filled with what it yields, in turn
    (double grasp, exchange configuration, double grasps tried)."""
    real, seen = handover._exchanges, []

    def wrapped(*args, **kwargs):
        for found in real(*args, **kwargs):
            seen.append(found)
            yield found

    monkeypatch.setattr(handover, "_exchanges", wrapped)
    return seen


def test_object_out_of_reach_fails_at_double_grasps(problem, lists, monkeypatch):
    exchanges = recording_exchanges(monkeypatch)
    X_far = translated(problem.spec.task.X_WO_start, [0.0, -1.6, 0.0])  # 2.45 m to the robot's right
    out = plan(problem_with(problem, X_WO_start=X_far), lists, None,
               OnlineOptions(planner="rrt-connect", grasp_attempts=5), seed=0)
    assert out.failure is not None and out.failure.stage == Stage.GRASPS and out.failure.transition is None
    assert "right-hand" in out.failure.reason and "start pose" in out.failure.reason
    # 2.45 m away: the batched reachability test rules every grasp out, no IK is tried
    assert "0 of them in the arm's reach, 0 tried with IK" in out.failure.reason
    # no double grasp, hence no exchange searched and no query
    assert out.phases == () and out.grasps == () and exchanges == []
    assert out.counts.get("key_attempts", 0) == 0
    assert out.counts["single_grasps"]["right"]["kept"] == 0


@pytest.mark.parametrize("joint, value, pair", [("r_arm_j4", 0.7, "obstacle:desk_top"),  # the hand in the desk
                                                ("r_arm_j6", 2.09, "r_arm_link7")])  # wrist folded on the forearm
def test_start_configuration_in_collision_fails_at_ends(problem, lists, joint, value, pair):
    q = problem.robot.q_rest.copy()
    q[problem.robot.joint_names.index(joint)] = value
    pairs = static_world(problem, problem.spec.task.X_WO_start).colliding_pairs(q)
    assert any(pair in p for p in pairs), pairs
    out = plan(replace(problem, q_start=q), lists, None, OnlineOptions(planner="rrt-connect"), seed=0)
    assert out.failure is not None and out.failure.stage == Stage.ENDS and out.failure.transition is None
    assert "start configuration" in out.failure.reason  # the start's, not the goal's
    assert "collision" in out.failure.reason and pair in out.failure.reason
    assert out.phases == () and out.grasps == ()


def test_a_one_iteration_rrt_budget_fails_in_a_query(problem, lists, monkeypatch):
    exchanges = recording_exchanges(monkeypatch)
    out = plan(problem, lists, None, OnlineOptions(planner="rrt-connect", rrt=RRTOptions(step=0.4, max_iterations=1)),
               seed=0)
    assert out.failure is not None and out.failure.stage == Stage.TRANSITION
    assert out.failure.transition in QUERIES
    assert "RRT-Connect" in out.failure.reason and "1 iteration" in out.failure.reason
    assert out.phases == () and out.grasps == ()
    # the stages before the queries succeeded; the transition named is the first query (in
    # plan order) that failed, each query up to it made one RRT-Connect call per attempt,
    # and every attempt failed (one per double grasp with an exchange, with the arms alone,
    # then one per double grasp leaning, up to key_attempts: the small lists give 2 or more)
    attempts = out.counts["key_attempts"]
    assert 2 <= attempts <= OnlineOptions().key_attempts
    assert 2 * out.counts["double_grasps"] >= attempts  # each with the arms alone, then leaning
    assert len(exchanges) >= attempts
    assert all(dg is not None and ex is not None for dg, ex, _ in exchanges[:attempts])
    assert f"the last of {attempts} double grasps" in out.failure.reason
    tried = QUERIES[:QUERIES.index(out.failure.transition) + 1]
    assert list(out.transitions) == list(QUERIES)
    assert all(out.transitions[q].rrt_calls == attempts for q in tried)


@pytest.fixture(scope="module")
def roadmap(problem, cache_dir) -> Roadmap:
    """The roadmap of `plan --roadmap-nodes 12`, in the run's cache (shared with the CLI tests)."""
    from regrasp_cli.roadmap.build import RoadmapOptions
    from regrasp_cli.roadmap.build import load_or_build as load_or_build_roadmap

    options = RoadmapOptions(nodes=12, seed=problem.spec.planning.seed)
    return Roadmap.of(load_or_build_roadmap(SCENE_YAML, cache_dir, options, jobs=2))


# ------------------------------------------------------------------ roadmap query


def _q(problem, **offsets) -> np.ndarray:
    q = problem.robot.q_rest.copy()
    for name, v in offsets.items():
        q[problem.robot.joint_names.index(name)] += v
    return q


@pytest.fixture(scope="module")
def blocked(problem):
    """The statuette stands where the right hand is at rest.  a and b swing the right
    shoulder (r_arm_j1) 0.5 rad either side of rest, so the straight segment a-b, and the
    short Super Graph edge n0-n1 next to it, go through the object; the detour n0-n2-n1
    raises the arm (r_arm_j2).  Returns (X_WO, a, b, roadmap)."""
    robot = problem.robot
    X_WO = translated(np.eye(4), Kinematics(robot).fk(robot.q_rest, robot.hands["right"].grasp_frame)[:3, 3] - [0, 0, 0.11])
    a, b = _q(problem, r_arm_j1=-0.5), _q(problem, r_arm_j1=0.5)
    nodes = np.array([_q(problem, r_arm_j1=-0.45), _q(problem, r_arm_j1=0.45), _q(problem, r_arm_j2=0.7)])
    full = static_world(problem, X_WO)
    assert path_collisions(full, [a, b], problem) and path_collisions(full, nodes[[0, 1]], problem)
    assert not path_collisions(full, nodes[[0, 2, 1]], problem)
    weights = joint_weights(robot)
    edges = np.array([[0, 1], [0, 2], [2, 1]])
    lengths = np.array([float(distance(nodes[u], nodes[v], weights)) for u, v in edges])
    assert lengths[0] < lengths[1] + lengths[2]  # the blocked edge is the short way
    return X_WO, a, b, Roadmap.from_arrays(nodes, edges, lengths, weights)


def _query(problem, blocked, seed: int = 0, **options) -> tuple[np.ndarray, QueryStats]:
    X_WO, a, b, rm = blocked
    scratch = new_scratch(problem, **options)
    open_ = {h: problem.robot.hands[h].open for h in problem.robot.hands}
    stats = QueryStats()
    rng = np.random.default_rng(seed)
    return roadmap_query(scratch, rng, rm, a, b, phase_worlds(scratch, X_WO, None, open_), stats), stats


def test_roadmap_query_hides_the_blocked_edge_and_takes_the_detour(problem, blocked):
    """With one connection per end and no smoothing the answer is exact: [a, n0, n2, n1, b],
    after one invalid edge and two searches; the roadmap itself is left as it was."""
    X_WO, a, b, rm = blocked
    before = {k: getattr(rm, k).copy() for k in ("nodes", "edges", "lengths", "weights")}
    path, stats = _query(problem, blocked, connections=1, shortcut_iterations=0, partial_shortcuts=0,
                         final_shortcuts=0, prune=False)
    n0, n1, n2 = rm.nodes
    assert np.array_equal(path, np.array([a, n0, n2, n1, b]))
    assert (stats.searches, stats.invalid_edges, stats.rrt_calls) == (2, 1, 0)
    assert not path_collisions(static_world(problem, X_WO), path, problem)
    for k, v in before.items():  # the memo is beside the roadmap, not in it
        assert np.array_equal(getattr(rm, k), v), k


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_roadmap_query_with_default_options_stays_collision_free(problem, blocked, seed):
    """The same query with the default options (more connections, shortcuts): whatever
    path comes back joins a to b without touching the object."""
    X_WO, a, b, _ = blocked
    path, stats = _query(problem, blocked, seed)
    assert np.array_equal(path[0], a) and np.array_equal(path[-1], b)
    assert stats.invalid_edges >= 1 and stats.searches >= 2
    assert not path_collisions(static_world(problem, X_WO), path, problem)


def test_no_reachable_exchange_pose_fails_at_key_configurations(problem, lists, monkeypatch):
    # as if neither arm pair reached any sample around the exchange position
    calls = []
    monkeypatch.setattr(handover, "exchange_configuration", lambda *a, **k: calls.append(a[-1]) or None)  # lean
    options = OnlineOptions(planner="rrt-connect", double_grasps_tried=2, exchange_samples=3)
    out = plan(problem, lists, None, options, seed=0)
    assert out.failure is not None and out.failure.stage == Stage.KEYS and out.failure.transition is None
    assert "exchange pose" in out.failure.reason and "2 double grasps" in out.failure.reason
    assert out.phases == () and out.grasps == ()
    assert out.counts.get("key_attempts", 0) == 0  # no key configurations, so no query
    # samples clear of the obstacles only, for at most 2 double grasps, the arms alone
    # first, then leaning (the torso solved with both arms)
    assert 1 <= len(calls) <= 2 * 2 * 3
    assert calls[0] is False and True in calls


def test_the_other_hand_picks_when_the_nearer_one_cannot(problem, lists, monkeypatch):
    real, chosen = handover.choose_hands, []

    def recording(*args, **kwargs):
        found = real(*args, **kwargs)
        chosen.append(found[0])
        return found

    monkeypatch.setattr(handover, "choose_hands", recording)
    monkeypatch.setattr(handover, "picking_hand", lambda *a: "left")  # a wrong guess: the start is on the right
    monkeypatch.setattr(handover, "exchange_configuration", lambda *a, **k: None)  # stop after the double grasps
    out = plan(problem, lists, None, OnlineOptions(planner="rrt-connect", double_grasps_tried=1, exchange_samples=1),
               seed=0)
    assert chosen == ["right"] and out.failure.stage == Stage.KEYS
    assert out.counts["single_grasps"]["right"]["kept"] > 0 and out.counts["double_grasps"] > 0


# ------------------------------------------------------------------ certified query worlds


def just_below_the_hand(problem, X_WO: np.ndarray, gap: float = 0.002) -> np.ndarray:
    """X_WO (where the object meets the right hand at rest) lowered 30 cm, then raised to
    the first 0.5 mm step where the object touches the robot at rest (found by bisection:
    free 30 cm below, touching at X_WO), then lowered by ``gap``: within ``gap`` of the
    robot, not touching it."""
    q = problem.robot.q_rest
    X_low = translated(X_WO, [0, 0, -0.3])

    def free(i: int) -> bool:  # the object raised i half-millimetres
        return static_world(problem, translated(X_low, [0, 0, 0.0005 * i])).is_free(q)

    lo, hi = 0, 600  # free at lo, touching at hi
    assert free(lo) and not free(hi)
    while hi - lo > 1:
        mid = (lo + hi) // 2
        lo, hi = (mid, hi) if free(mid) else (lo, mid)
    return translated(X_low, [0, 0, 0.0005 * hi - gap])


def test_query_worlds_keep_the_clearance_the_sampled_worlds_do_not(problem, blocked):
    """The object is lowered onto the right hand at rest until it touches, then raised
    2 mm: rest is free, but not with the queries' 5 mm clearance; with ``certify`` off
    the query world is the plain one."""
    X_WO, *_ = blocked
    q = problem.robot.q_rest
    scratch = new_scratch(problem)
    plain = scratch.world(X_WO)
    X_near = just_below_the_hand(problem, X_WO)
    assert plain.world.object is not None and static_world(problem, X_near).is_free(q)
    near = scratch.world(X_near)
    assert near.is_free(q) and not scratch.certified(near).is_free(q)
    assert scratch.certified(scratch.world(translated(X_near, [0, 0, -0.01]))).is_free(q)  # 12 mm: clear
    off = new_scratch(problem, certify=False)
    assert off.certified(off.world(X_near)).is_free(q)


@pytest.mark.parametrize("seed", [0, 1])
def test_segments_the_certified_check_accepts_are_free_at_a_finer_resolution(problem, blocked, seed):
    """Random segments of the right arm around the object: every one the query worlds'
    check accepts is free when checked at 0.002 rad / 1 mm; some are refused that the
    plain check at the same samples lets through or that do collide."""
    X_WO, *_ = blocked
    robot = problem.robot
    scratch = new_scratch(problem)
    world = scratch.certified(scratch.world(X_WO))
    fine = static_world(problem, X_WO)
    arm = robot.hands["right"].arm_idx
    rng = np.random.default_rng(seed)
    accepted = refused = 0
    for _ in range(40):
        a, b = robot.q_rest.copy(), robot.q_rest.copy()
        a[arm] += rng.normal(0.0, 0.4, len(arm))
        b[arm] += rng.normal(0.0, 0.4, len(arm))
        a, b = np.clip(a, robot.lower, robot.upper), np.clip(b, robot.lower, robot.upper)
        if not (fine.is_free(a) and fine.is_free(b)):
            continue
        if scratch.segment_free(world, a, b):
            accepted += 1
            phase = Phase("test", Kind.TRANSIT, {}, (), None, np.array([a, b]), np.zeros(2))
            issues, _ = collision_issues(phase, fine, joint_reach(robot), 0.002, 0.001)
            assert not issues, issues
        else:
            refused += 1
    assert accepted >= 5 and refused >= 1, (accepted, refused)


def test_start_configuration_closer_than_the_clearance_fails_at_ends(problem, lists, blocked):
    """The object 2 mm below the right hand at rest: free, yet too close to certify the
    query that leaves it."""
    X_WO, *_ = blocked
    X_near = just_below_the_hand(problem, X_WO)
    out = plan(problem_with(problem, X_WO_start=X_near), lists, None, OnlineOptions(planner="rrt-connect"), seed=0)
    assert out.failure is not None and out.failure.stage == Stage.ENDS, out.failure
    assert out.failure.transition is None and "start configuration" in out.failure.reason
    assert "closer than 5 mm" in out.failure.reason and "object" in out.failure.reason
    assert out.phases == () and out.grasps == ()


# ------------------------------------------------------------------ retries


def test_a_failed_query_is_retried_with_the_next_double_grasp(problem, lists, roadmap, monkeypatch):
    """The first set of key configurations is made to fail at `place`: the planner takes
    the next double grasps with their own exchange until one solves; with one attempt
    allowed it fails at `place`.  The work of every attempt is counted."""
    real_steps, real_solve = handover.steps_of, handover.solve_queries
    seen, streams, stats = [], [], []  # per attempt: double grasp, query streams, query stats

    def recording_steps(scratch, dg, ex, lists):
        seen.append(dg)
        return real_steps(scratch, dg, ex, lists)

    def first_fails(scratch, roadmap, weights, queries, streams_, jobs):
        results = real_solve(scratch, roadmap, weights, queries, streams_, jobs)
        streams.append({q.label: list(s) for q, s in zip(queries, streams_)})
        stats.append({q: r.stats for q, r in results.items()})
        if len(stats) == 1:
            assert all(r.error is None for r in results.values())  # the queries themselves succeeded
            results["place"] = replace(results["place"], path=None, error="made to fail")
        return results

    monkeypatch.setattr(handover, "steps_of", recording_steps)
    monkeypatch.setattr(handover, "solve_queries", first_fails)
    out = plan(problem, lists, roadmap, OnlineOptions(jobs=1), seed=0)
    assert out.failure is None, out.failure
    n = len(seen)  # the next double grasp's own queries may fail too: attempts until one solves
    assert n == len(streams) >= 2 and len({id(dg) for dg in seen}) == n
    # each attempt with its own random streams
    assert streams[0] == {q: [0, i] for i, q in enumerate(QUERIES)}
    for a in range(1, n):
        assert streams[a] == {q: [0, i, a] for i, q in enumerate(QUERIES)}
    # the plan holds the last attempt's double grasp, not the first's
    g, t = seen[-1].giver.hand, seen[-1].taker.hand
    expected = ((grasp_id(lists, g, seen[-1].giver.grasp), g, seen[-1].giver.grasp),
                (grasp_id(lists, t, seen[-1].taker.grasp), t, seen[-1].taker.grasp))
    assert out.grasps == expected
    assert (seen[0].giver.grasp, seen[0].taker.grasp) != (seen[-1].giver.grasp, seen[-1].taker.grasp)
    assert {m.transition.label: dict(m.transition.holding) for m in out.phases}["carry"] == {g: expected[0][0]}
    assert out.counts["key_attempts"] == n and out.counts["double_grasps_tried"] >= n
    for q in QUERIES:  # every attempt's work added to the first's
        total = TransitionStats()
        for st in stats:
            total = total.plus(st[q])
        assert out.transitions[q] == total, q
        assert out.transitions[q].planning_s > stats[0][q].planning
        assert all(v >= getattr(stats[0][q], k) for k, v in out.transitions[q].counts().items())
    first = stats[0]
    for recorded in (seen, streams, stats):
        recorded.clear()
    once = plan(problem, lists, roadmap, OnlineOptions(jobs=1, key_attempts=1), seed=0)
    assert once.failure is not None and once.failure.stage == Stage.TRANSITION
    assert once.failure.transition == "place" and once.failure.reason == "made to fail"
    assert len(seen) == 1 and once.phases == () and once.grasps == ()
    assert once.counts["key_attempts"] == 1
    assert {q: s.counts() for q, s in once.transitions.items()} == \
        {q: TransitionStats().plus(first[q]).counts() for q in QUERIES}  # the same first attempt's counts


# ------------------------------------------------------------------ retreats (an end no node sees)


def _retreat_lines(problem, q: np.ndarray, X_WO: np.ndarray) -> dict[str, np.ndarray]:
    """The retreat lines from q, by the hand whose arm moves (queries._retreats)."""
    scratch = new_scratch(problem)
    open_ = {h: problem.robot.hands[h].open for h in problem.robot.hands}
    lines = _retreats(scratch, np.random.default_rng(0), q, phase_worlds(scratch, X_WO, None, open_).full)
    out = {}
    for line in lines:
        moving = set(np.flatnonzero(np.any(line != q, axis=0)))
        hand = next(h for h in problem.robot.hands if moving <= set(problem.robot.hands[h].arm_idx))
        out[hand] = np.vstack([q[None], line])
    return out


def test_a_hand_retreats_on_a_straight_free_line_and_another_where_the_first_is_blocked(problem, single):
    """The right hand reaching down to the desk (a single-grasp configuration, the
    statuette away) backs straight out by ``retreat_distance`` on a free line; with the
    statuette put where that line ends, the right hand backs out another way, free of it.
    At rest no arm can follow a line that backs its hand towards the chest: no line."""
    robot, kin = problem.robot, Kinematics(problem.robot)
    q, h = single[1].q_closed, robot.hands["right"]
    far = translated(np.eye(4), [3.0, 3.0, 0.0])
    assert _retreat_lines(problem, robot.q_rest, far) == {}
    distance_ = OnlineOptions().retreat_distance
    X0 = kin.fk(q, h.grasp_frame)[:3, 3]

    def check(X_WO):
        lines = _retreat_lines(problem, q, X_WO)
        for hand, line in lines.items():
            assert not path_collisions(static_world(problem, X_WO), line, problem), hand
            p = np.array([kin.fk(x, robot.hands[hand].grasp_frame)[:3, 3] for x in line])
            step = p[-1] - p[0]
            assert np.linalg.norm(step) == pytest.approx(distance_, abs=2e-3)
            assert np.linalg.norm(np.cross(p - p[0], step / np.linalg.norm(step)), axis=1).max() < 2e-3  # straight
        return {hand: kin.fk(line[-1], robot.hands[hand].grasp_frame)[:3, 3] - X0 for hand, line in lines.items()}

    away = check(far)
    assert "right" in away
    d = away["right"] / distance_
    blocked = check(translated(np.eye(4), X0 + 0.2 * d - [0, 0, 0.1]))  # the statuette where that line ends
    assert "right" in blocked and blocked["right"] @ d < 0.9 * distance_


class _Pocket:
    """A world (the interface :func:`queries._retreats` uses) that is free where the right
    hand's grasp frame is, measured from p0: a block round it below 1.5 cm up (no
    sideways move beyond 5 mm there) and a roof 3 cm up (within 5 cm sideways): no
    straight line leaves it, a rise and then a level line do."""

    world, certified = SimpleNamespace(object=None), False

    def __init__(self, kin: Kinematics, frame: int, p0: np.ndarray):
        self.kin, self.frame, self.p0 = kin, frame, p0

    def is_free(self, q: np.ndarray, scale: float = 1.0) -> bool:
        d = self.kin.fk(q, self.frame)[:3, 3] - self.p0
        up, side = d[2], np.linalg.norm(d[:2])
        return not (up < 0.015 and side > 0.005) and not (up > 0.03 and side < 0.05)

    def segment_free(self, q0, q1, resolution, min_steps=1, limit=None) -> bool:
        return all(self.is_free(q0 + t * (q1 - q0)) for t in segment_samples(q0, q1, resolution, min_steps)[:limit])


def test_a_hand_no_straight_line_frees_rises_first_then_backs_out(problem, single):
    """From a pocket (:class:`_Pocket`) the right hand rises ``retreat_lift`` straight up,
    then backs out level by ``retreat_distance``, every waypoint and segment free; without
    the rise (``retreat_lift`` 0) no line of the right hand gets out."""
    robot, kin = problem.robot, Kinematics(problem.robot)
    q, h = single[1].q_closed, robot.hands["right"]
    p0 = kin.fk(q, h.grasp_frame)[:3, 3]
    pocket = _Pocket(kin, h.grasp_frame, p0)
    assert pocket.is_free(q)

    def right_line(**options):
        scratch = new_scratch(problem, **options)
        for line in _retreats(scratch, np.random.default_rng(0), q, pocket):
            if np.any(line[:, robot.hands["right"].arm_idx] != q[robot.hands["right"].arm_idx]):
                return scratch, np.vstack([q[None], line])
        return scratch, None

    assert right_line(retreat_lift=0.0)[1] is None
    scratch, line = right_line()
    assert line is not None
    o = scratch.options
    assert all(scratch.segment_free(pocket, a, b) for a, b in zip(line[:-1], line[1:]))
    p = np.array([kin.fk(x, h.grasp_frame)[:3, 3] for x in line]) - p0
    top = int(np.argmax(np.linalg.norm(p[:, :2], axis=1) > 1e-3))  # the first waypoint that moved sideways
    assert np.linalg.norm(p[:top, :2], axis=1).max() < 1e-3  # straight up first ...
    assert p[top - 1, 2] == pytest.approx(o.retreat_lift, abs=1e-3)
    out = p[-1] - p[top - 1]
    assert np.linalg.norm(out) == pytest.approx(o.retreat_distance, abs=2e-3)  # ... then straight out
    assert abs(out[2]) < 2e-3 and np.linalg.norm(out[:2]) > 0.1  # level, sideways
