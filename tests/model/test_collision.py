"""Tests of regrasp_cli.model.collision and selfcollision on the default problem: built
configurations that collide or not (desk, crossed hands, obstacles, the object, fingertip
contact tolerance), segment checks, and the disabled self-collision pairs and their cache.

Desk top: a 0.04 m thick box centred at z = 0.72, so its top surface is at z = 0.74.
"""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET

import coal
import numpy as np
import pinocchio as pin
import pytest
import trimesh

from regrasp_cli.config import ObstacleSpec
from regrasp_cli.model import selfcollision
from regrasp_cli.model.collision import (
    CollisionOptions,
    CollisionWorld,
    ObjectPlacement,
    collision_world,
    eroded_geometry,
    mesh_geometry,
    segment_samples,
)
from regrasp_cli.model.ik import arm_ik
from regrasp_cli.model.robot import Kinematics
from regrasp_cli.model.selfcollision import DisabledPairs, disabled_pairs

DESK_TOP_Z = 0.74


@pytest.fixture(scope="module")
def world(problem):
    return problem.world()


def _is_cross(a: str, b: str) -> bool:
    return {a[:2], b[:2]} == {"l_", "r_"}


def _pose(R: np.ndarray, p) -> np.ndarray:
    X = np.eye(4)
    X[:3, :3], X[:3, 3] = R, p
    return X


def _ball(name: str, radius: float, p) -> ObstacleSpec:
    return ObstacleSpec(name, "sphere", (radius,), _pose(np.eye(3), p))


def _tip_link(problem, hand: str = "right", finger: int = 1) -> str:
    return problem.robot.spec.hands[hand].fingers[finger].tip_link


def _geometry_centre(robot, link: str, q: np.ndarray) -> np.ndarray:
    """World position of the (first) collision geometry of ``link`` at q."""
    gm = robot.collision_model
    gd, data = gm.createData(), robot.model.createData()
    pin.updateGeometryPlacements(robot.model, data, gm, gd, robot.to_pin(q))
    g = next(g for g in range(gm.ngeoms) if robot.link_of_geometry(g) == link)
    return gd.oMg[g].translation.copy()


# --------------------------------------------------------------------------- static world


def test_rest_is_free(problem, world):
    assert world.is_free(problem.robot.q_rest)
    assert world.colliding_pairs(problem.robot.q_rest) == []
    assert world.is_free(problem.q_start) and world.is_free(problem.q_goal)


def test_right_hand_in_the_desk_collides(problem, world):
    robot = problem.robot
    h = robot.hands["right"]
    X = Kinematics(robot).fk(robot.q_rest, h.grasp_frame)
    X[:3, 3] = [0.6, -0.4, DESK_TOP_Z - 0.05]
    res = arm_ik(robot, "right", X, robot.q_rest, np.random.default_rng(0))
    assert res.success
    assert not world.is_free(res.q)
    pairs = world.colliding_pairs(res.q)
    desk = [a if b == "obstacle:desk_top" else b for a, b in pairs if "obstacle:desk_top" in (a, b)]
    assert desk, pairs
    assert all(link.startswith("r_") for link in desk)  # only the right arm/hand is moved


def _hands_together(robot):
    """(right only, both): IK of both grasp frames, palms down, to one point in front of the
    chest (between the rest positions of the hands, or up to 10 cm closer to the chest)."""
    mid = (Kinematics(robot).fk(robot.q_rest, robot.hands["right"].grasp_frame)[:3, 3]
           + Kinematics(robot).fk(robot.q_rest, robot.hands["left"].grasp_frame)[:3, 3]) / 2
    for dx in (0.0, -0.05, -0.1):
        rng = np.random.default_rng(0)
        X = _pose(np.diag([1.0, -1.0, -1.0]), mid + [dx, 0.0, 0.0])
        right = arm_ik(robot, "right", X, robot.q_rest, rng)
        both = arm_ik(robot, "left", X, right.q, rng)
        if right.success and both.success:
            return right.q, both.q
    pytest.fail("no point in front of the chest reachable by both hands, palms down")


def test_hands_overlapping_collide(problem, world):
    """Both grasp frames at one point in front of the chest, palms down: the hands overlap,
    and the collision is found by a left/right pair (never auto-disabled)."""
    right, both = _hands_together(problem.robot)
    assert not any(_is_cross(*p) for p in world.colliding_pairs(right))  # one hand there: no l/r contact
    assert not world.is_free(both)
    pairs = world.colliding_pairs(both)
    cross = [p for p in pairs if _is_cross(*p)]
    assert cross, pairs
    assert ("l_palm", "r_palm") in pairs  # the palms overlap


def test_results_do_not_depend_on_earlier_queries(problem):
    """Regression: with pinocchio's cached GJK guesses, a world that had checked another
    configuration missed the overlap of the two palms above."""
    robot = problem.robot
    _, q = _hands_together(robot)
    expected = problem.world().colliding_pairs(q)
    assert ("l_palm", "r_palm") in expected
    used = problem.world()
    used.colliding_pairs(robot.q_rest)
    assert used.colliding_pairs(q) == expected


def _truth_is_free(world: CollisionWorld, q: np.ndarray) -> bool:
    """Every checked pair with a fresh coal request (no state kept between queries)."""
    gm = world.geometry_model
    gd, data = gm.createData(), world.robot.model.createData()
    pin.updateGeometryPlacements(world.robot.model, data, gm, gd, world.robot.to_pin(q))
    for cp in gm.collisionPairs:
        T = [coal.Transform3s(gd.oMg[g].rotation, gd.oMg[g].translation) for g in (cp.first, cp.second)]
        if coal.collide(gm.geometryObjects[cp.first].geometry, T[0], gm.geometryObjects[cp.second].geometry, T[1],
                        coal.CollisionRequest(), coal.CollisionResult()):
            return False
    return True


def test_random_configurations_agree_with_fresh_queries(problem, world):
    robot = problem.robot
    rng = np.random.default_rng(0)
    wrong = []
    for i in range(100):
        q = robot.sample(rng)
        truth = _truth_is_free(world, q)
        if world.is_free(q) != truth or (not world.colliding_pairs(q)) != truth:
            wrong.append(i)
    assert wrong == []


def test_sphere_obstacle_at_a_fingertip_collides(problem):
    robot = problem.robot
    tip = robot.hands["right"].tip_frames[1]
    p = Kinematics(robot).fk(robot.q_rest, tip)[:3, 3]
    links = problem.disabled.links()
    w = collision_world(robot, [_ball("ball", 0.01, p)], links)
    assert not w.is_free(robot.q_rest)
    assert (_tip_link(problem), "obstacle:ball") in w.colliding_pairs(robot.q_rest)
    far = collision_world(robot, [_ball("ball", 0.01, p + [0.0, 0.0, 0.3])], links)
    assert far.is_free(robot.q_rest)


def test_obstacles_fixed_to_the_root_are_not_checked(problem):
    """An obstacle touching only the (immobile) base of the robot is the user's design."""
    robot = problem.robot
    w = collision_world(robot, [_ball("stool", 0.05, [0.0, 0.0, 0.3])], problem.disabled.links())
    assert w.is_free(robot.q_rest)


# --------------------------------------------------------------------------- the object


def test_statuette_at_start_rest_is_free(problem):
    w = problem.world(problem.object_at(problem.spec.task.X_WO_start))
    assert w.object_geom is not None
    assert w.is_free(problem.robot.q_rest)
    assert w.colliding_pairs(problem.robot.q_rest) == []


def test_hand_inside_the_statuette_collides(problem):
    robot = problem.robot
    X_WO = problem.spec.task.X_WO_start
    w = problem.world(problem.object_at(X_WO))
    centre = X_WO[:3, :3] @ problem.object.mesh.bounds.mean(axis=0) + X_WO[:3, 3]
    X = _pose(np.diag([1.0, -1.0, -1.0]), centre)  # palm down, grasp frame at the centre
    res = arm_ik(robot, "right", X, robot.q_rest, np.random.default_rng(0), with_torso=True)
    assert res.success
    pairs = w.colliding_pairs(res.q)
    assert any("object" in p for p in pairs), pairs


def _touching_world(problem, penetration: float, touching, tolerance: float = 0.002):
    """A 1 cm cube just beyond the right index fingertip sphere (radius 1 cm), along the
    finger, overlapping it by ``penetration`` (m)."""
    robot = problem.robot
    finger = robot.spec.hands["right"].fingers[1]
    X_tip = Kinematics(robot).fk(robot.q_rest, finger.tip_link)
    u = X_tip[:3, 3] - Kinematics(robot).fk(robot.q_rest, finger.joints[-1])[:3, 3]  # the finger's direction
    u /= np.linalg.norm(u)
    helper = np.cross(u, [0.0, 0.0, 1.0] if abs(u[2]) < 0.9 else [1.0, 0.0, 0.0])
    R = np.column_stack([u, helper / np.linalg.norm(helper), np.cross(u, helper / np.linalg.norm(helper))])
    X = _pose(R, X_tip[:3, 3] + u * (finger.tip_radius - penetration + 0.005))
    cube = trimesh.creation.box(extents=[0.01, 0.01, 0.01])
    obj = ObjectPlacement(cube, X, touching=touching)
    return collision_world(robot, problem.spec.obstacles, problem.disabled.links(), obj,
                           CollisionOptions(contact_tolerance=tolerance, support_tolerance=tolerance))


def test_fingertip_contact_within_tolerance(problem):
    q = problem.robot.q_rest
    assert _touching_world(problem, 0.001, ("right",)).is_free(q)
    assert _touching_world(problem, 0.001, ("right", "left")).is_free(q)
    assert _touching_world(problem, -0.001, ()).is_free(q)  # 1 mm apart: free for anyone


@pytest.mark.parametrize("penetration, touching", [
    (0.001, ()),  # the hand is not in contact: no tolerance
    (0.001, ("left",)),  # the other hand is
    (0.003, ("right",)),  # deeper than the tolerance
])
def test_fingertip_contact_not_allowed(problem, penetration, touching):
    w = _touching_world(problem, penetration, touching)
    q = problem.robot.q_rest
    assert not w.is_free(q)
    assert w.colliding_pairs(q) == [(_tip_link(problem), "object")]


def _tip_on_obstacle_world(problem, penetration: float, touching):
    """A 2 cm ball obstacle just beyond the right index fingertip sphere, along the finger,
    overlapping it by ``penetration`` (m); the object far away, touched by ``touching``."""
    robot = problem.robot
    finger = robot.spec.hands["right"].fingers[1]
    X_tip = Kinematics(robot).fk(robot.q_rest, finger.tip_link)
    u = X_tip[:3, 3] - Kinematics(robot).fk(robot.q_rest, finger.joints[-1])[:3, 3]
    u /= np.linalg.norm(u)
    ball = _ball("desk", 0.02, X_tip[:3, 3] + u * (finger.tip_radius + 0.02 - penetration))
    obj = ObjectPlacement(trimesh.creation.box(extents=[0.01, 0.01, 0.01]), _pose(np.eye(3), [3.0, 0.0, 0.0]),
                          touching=touching)
    return collision_world(robot, [ball], problem.disabled.links(), obj,
                           CollisionOptions(contact_tolerance=0.002, support_tolerance=0.002))


def test_fingertips_of_a_touching_hand_may_rest_on_an_obstacle(problem):
    """A hand in contact with the object may rest its fingertips on the support (a pinch on
    a desk), as on the object, up to the contact tolerance; no other hand or link may."""
    q = problem.robot.q_rest
    assert _tip_on_obstacle_world(problem, 0.001, ("right",)).is_free(q)
    for penetration, touching in ((0.001, ()), (0.001, ("left",)), (0.003, ("right",))):
        w = _tip_on_obstacle_world(problem, penetration, touching)
        assert w.colliding_pairs(q) == [(_tip_link(problem), "obstacle:desk")], (penetration, touching)


def _held_cube_world(problem, support_gap: float, obstacles=()):
    """A 2 cm cube held by the right hand (at its grasp frame, axes aligned with W), and a
    4 x 4 x 2 cm support whose top is ``support_gap`` below the cube's bottom face."""
    robot = problem.robot
    X_WG = Kinematics(robot).fk(robot.q_rest, robot.hands["right"].grasp_frame)
    X_GO = _pose(X_WG[:3, :3].T, [0.0, 0.0, 0.0])
    support = ObstacleSpec("support", "box", (0.04, 0.04, 0.02), _pose(np.eye(3), X_WG[:3, 3] - [0, 0, 0.02 + support_gap]))
    obj = ObjectPlacement(trimesh.creation.box(extents=[0.02, 0.02, 0.02]), X_GO, attached_to="right")
    return collision_world(robot, [support, *obstacles], problem.disabled.links(), obj,
                           CollisionOptions(contact_tolerance=0.002, support_tolerance=0.002)), X_GO


def test_held_object_may_rest_on_a_support(problem):
    q = problem.robot.q_rest
    assert _held_cube_world(problem, 0.001)[0].is_free(q)
    assert _held_cube_world(problem, -0.001)[0].is_free(q)  # 1 mm into the support: allowed
    w = _held_cube_world(problem, -0.003)[0]  # 3 mm: not
    assert not w.is_free(q)
    assert w.colliding_pairs(q) == [("object", "obstacle:support")]


def test_held_object_moves_with_the_hand(problem):
    robot = problem.robot
    q = robot.q_rest.copy()
    q[robot.joint_index("r_arm_j1")] += 0.3
    _, X_GO = _held_cube_world(problem, 0.01)
    X_WO = Kinematics(robot).fk(q, robot.hands["right"].grasp_frame) @ X_GO
    p = X_WO[:3, :3] @ [0.0, 0.0, 0.01] + X_WO[:3, 3]  # centre of the cube's top face at q
    w, _ = _held_cube_world(problem, 0.01, [_ball("pin", 0.004, p)])
    assert w.is_free(robot.q_rest)
    assert w.colliding_pairs(q) == [("object", "obstacle:pin")]


def test_eroded_geometry():
    assert eroded_geometry(coal.Sphere(0.01), 0.002).radius == pytest.approx(0.008)
    box = eroded_geometry(coal.Box(0.1, 0.2, 0.3), 0.01)
    np.testing.assert_allclose(box.halfSide, [0.04, 0.09, 0.14])
    cyl = eroded_geometry(coal.Cylinder(0.05, 0.4), 0.01)
    assert (cyl.radius, cyl.halfLength) == pytest.approx((0.04, 0.19))
    cap = eroded_geometry(coal.Capsule(0.05, 0.4), 0.01)
    assert (cap.radius, cap.halfLength) == pytest.approx((0.04, 0.2))
    assert eroded_geometry(coal.Sphere(0.001), 0.002).radius > 0
    assert eroded_geometry(mesh_geometry(trimesh.creation.box(extents=[0.1, 0.1, 0.1])), 0.01) is None


def test_a_convex_hull_erodes_by_its_faces():
    """A hull (robot links under ``convex_hulls``, G1's and Alex's fingertips) shrinks by
    the tolerance on every side: a box's hull to the smaller box, a sphere's to a radius
    tol less (within the facets' sag); one thinner than twice the tolerance to a point
    inside it."""
    def hull(mesh):
        return coal.Convex.convexHull(list(mesh.vertices), False, None)

    box = np.asarray(eroded_geometry(hull(trimesh.creation.box(extents=[0.02, 0.04, 0.06])), 0.002).points())
    assert np.allclose(box.min(axis=0), [-0.008, -0.018, -0.028]) and np.allclose(box.max(axis=0), [0.008, 0.018, 0.028])
    ball = trimesh.creation.icosphere(subdivisions=3, radius=0.01)
    r = np.linalg.norm(np.asarray(eroded_geometry(hull(ball), 0.002).points()), axis=1)
    assert np.all((r > 0.0079) & (r < 0.0080 + 1e-9))
    plate = np.asarray(eroded_geometry(hull(trimesh.creation.box(extents=[0.003, 0.04, 0.06])), 0.002).points())
    assert np.ptp(plate, axis=0).max() < 1e-5 and np.allclose(plate.mean(axis=0), 0.0, atol=1e-5)


# --------------------------------------------------------------------------- segments


def test_segment_through_a_collision(problem):
    """Swing the right arm (j1 by 0.6 rad) through a ball placed at the palm's position
    half-way: both ends are free, the segment is not."""
    robot = problem.robot
    j = robot.joint_index("r_arm_j1")
    q0 = robot.q_rest.copy()
    q1, qm = q0.copy(), q0.copy()
    q1[j] += 0.6
    qm[j] += 0.3
    palm_centre = _geometry_centre(robot, "r_palm", qm)
    w = collision_world(robot, [*problem.spec.obstacles, _ball("ball", 0.03, palm_centre)], problem.disabled.links())
    assert w.is_free(q0) and w.is_free(q1) and not w.is_free(qm)
    assert not w.segment_free(q0, q1, problem.spec.planning.segment_resolution)
    assert not w.segment_free(q1, q0, problem.spec.planning.segment_resolution)
    q2 = q0.copy()
    q2[j] -= 0.05  # away from the ball
    assert w.is_free(q2)
    before = w.n_checks
    assert w.segment_free(q0, q2, 0.02)
    assert w.n_checks - before == 4  # ends + 2 intermediate samples (0.05 / 0.02 -> 3 steps)
    assert w.segment_free(q0, q0, 0.02)


@pytest.mark.parametrize("resolution", [0.02, 0.05, 0.3, 1.0, 5.0])
@pytest.mark.parametrize("seed", [0, 1])
def test_segment_samples(resolution, seed):
    rng = np.random.default_rng(seed)
    q0, q1 = rng.uniform(-2, 2, 10), rng.uniform(-2, 2, 10)
    t = segment_samples(q0, q1, resolution)
    assert t[0] == 0.0 and t[1] == 1.0
    assert len(np.unique(t)) == len(t)
    ts = np.sort(t)
    assert ts[0] == 0.0 and ts[-1] == 1.0
    step = np.max(np.abs(q1 - q0)) * np.diff(ts)
    assert np.all(step <= resolution + 1e-12)
    n = len(t) - 1
    np.testing.assert_allclose(ts, np.arange(n + 1) / n)  # evenly spaced
    assert n == max(1, int(np.ceil(np.max(np.abs(q1 - q0)) / resolution)))  # no more than needed


def test_segment_samples_coarse_to_fine():
    t = segment_samples(np.zeros(2), np.array([0.8, 0.1]), 0.1)
    assert list(t[:5]) == [0.0, 1.0, 0.5, 0.25, 0.75]


def test_segment_samples_are_shared_and_cannot_be_changed():
    # the order depends on the number of steps only: segments of 8 steps share it
    a = segment_samples(np.zeros(2), np.array([0.8, 0.1]), 0.1)
    b = segment_samples(np.ones(2), np.array([1.0, 0.8]), 0.025)
    assert a is b and sorted(a) == list(np.arange(9) / 8)
    with pytest.raises(ValueError):
        a[0] = 0.5


def test_segment_samples_of_a_point():
    t = segment_samples(np.ones(3), np.ones(3), 0.02)
    assert list(t) == [0.0, 1.0]


# --------------------------------------------------------------------------- self-collision


def _urdf_links_with_collision(problem) -> tuple[set[str], list[tuple[str, str]]]:
    root = ET.parse(problem.robot.spec.urdf).getroot()
    with_geom = {link.get("name") for link in root.iter("link") if link.find("collision") is not None}
    edges = [(j.find("parent").get("link"), j.find("child").get("link")) for j in root.iter("joint")]
    return with_geom, edges


def test_adjacent_pairs_are_disabled(problem):
    with_geom, edges = _urdf_links_with_collision(problem)
    d = problem.disabled
    n = 0
    for parent, child in edges:
        if parent in with_geom and child in with_geom:
            assert d.pairs.get(tuple(sorted((parent, child)))) == "adjacent", (parent, child)
            n += 1
    assert n >= 20
    assert d.count("adjacent") >= n


def test_no_cross_arm_pair_is_disabled(problem):
    d = problem.disabled
    assert d.count("never") > 0  # the statistical pass did run
    cross = [p for p in d.pairs if _is_cross(*p)]
    assert cross == []
    assert all(a < b for a, b in d.pairs)


def test_every_cross_arm_geometry_pair_is_checked(problem, world):
    robot = problem.robot
    n = robot.collision_model.ngeoms
    links = [robot.link_of_geometry(g) for g in range(n)]
    left = sum(1 for s in links if s.startswith("l_"))
    right = sum(1 for s in links if s.startswith("r_"))
    checked = sum(1 for cp in world.geometry_model.collisionPairs
                  if cp.first < n and cp.second < n and _is_cross(links[cp.first], links[cp.second]))
    assert left > 10 and right > 10
    assert checked == left * right


def _cache_file(problem, cache_dir):
    """The cache file of the default robot (other robots may have theirs in cache_dir)."""
    robot = problem.robot
    files = [f for f in (cache_dir / "self_collision").glob("*.json")
             if (b := json.loads(f.read_text()))["urdf_sha256"] == robot.urdf_sha256
             and b["robot_yaml_sha256"] == robot.robot_yaml_sha256]
    assert len(files) == 1
    return files[0]


def test_disabled_pairs_cache_is_written_and_reused(problem, cache_dir, monkeypatch):
    files = [_cache_file(problem, cache_dir)]
    body = json.loads(files[0].read_text())
    assert body["samples"] == problem.robot.spec.self_collision.samples
    from_file = {(a, b): r for a, b, r in body["pairs"]}
    assert from_file == problem.disabled.pairs  # robot.yaml lists no extra pairs

    def boom(*args, **kwargs):
        raise AssertionError("recomputed although cached")

    monkeypatch.setattr(selfcollision, "compute_disabled_pairs", boom)
    again = disabled_pairs(problem.robot, cache_dir)
    assert again == problem.disabled
    assert again.pairs == problem.disabled.pairs
    assert files[0].read_text() == json.dumps(body, indent=1) + "\n"  # untouched


def test_unreadable_cache_is_recomputed(problem, cache_dir, tmp_path, monkeypatch):
    name = _cache_file(problem, cache_dir).name
    bad = tmp_path / "self_collision" / name
    bad.parent.mkdir()
    bad.write_text('{"pairs": [["a"]')  # truncated
    fake = DisabledPairs({("chest", "r_arm_link1"): "adjacent"}, samples=1, never_margin=0.02)
    calls = []

    def compute(robot, samples, rng, never_margin=0.02):
        calls.append(samples)
        return fake

    monkeypatch.setattr(selfcollision, "compute_disabled_pairs", compute)
    assert disabled_pairs(problem.robot, tmp_path) == fake
    assert calls == [problem.robot.spec.self_collision.samples]
    assert json.loads(bad.read_text())["pairs"] == [["chest", "r_arm_link1", "adjacent"]]
    assert disabled_pairs(problem.robot, tmp_path) == fake and len(calls) == 1


def test_worlds_on_one_model_move_their_object_apart(problem):
    """Model/Data split: a model shared by two worlds is never changed by them; each world
    moves the object in its own data, so one world's placement does not leak into the
    other's answers."""
    robot = problem.robot
    world, X_GO = _held_cube_world(problem, 0.01)
    model = world.model
    before = model.geometry_model.geometryObjects[model.object_geom].placement.homogeneous.copy()
    other = CollisionWorld(model)
    q = robot.q_rest
    assert world.is_free(q) and other.is_free(q)
    X_down = X_GO.copy()
    X_down[:3, 3] += X_GO[:3, :3] @ [0.0, 0.0, -0.015]  # 1.5 cm lower in W: 5 mm into the support
    other.set_object_pose(X_down)
    assert not other.is_free(q)
    assert other.colliding_pairs(q) == [("object", "obstacle:support")]
    assert world.is_free(q)  # still at X_GO
    assert other.X_PO is X_down and world.X_PO is X_GO
    after = model.geometry_model.geometryObjects[model.object_geom].placement.homogeneous
    np.testing.assert_array_equal(before, after)


def test_a_scaled_check_keeps_that_many_margins(problem):
    """A ball moved away from a fingertip in 1 mm steps: it stops colliding 3 margins
    later when the check keeps 4 margins of clearance than when it keeps 1."""
    from regrasp_cli.roadmap.compose import margin_rule

    robot = problem.robot
    p = Kinematics(robot).fk(robot.q_rest, robot.hands["right"].tip_frames[1])[:3, 3]
    links, margin = problem.disabled.links(), 0.005

    def first_free(scale: float) -> float:
        for dz in np.arange(0.0, 0.2, 0.001):
            w = collision_world(robot, [_ball("ball", 0.01, p - [0.0, 0.0, dz])], links,
                                margin=margin_rule(robot, margin))
            assert w.certified
            if w.is_free(robot.q_rest, scale):
                return dz
        raise AssertionError("never free")

    assert first_free(4.0) - first_free(1.0) == pytest.approx(3 * margin, abs=0.0015)
