"""What the viewer draws is where the plan says: shapes posed as pinocchio poses them, the
object at its recorded poses and riding with the holding hand, the sampled motion
through every waypoint, key frames at the plan's moments; and the pure helpers
(subdivision, animation keys) on tiny inputs with exact answers."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from regrasp_cli.show.geometry import Shape, hand_links, link_poses, robot_links, shape_triangles, subdivide
from regrasp_cli.show.html import pose_keys
from regrasp_cli.show.motion import KEY_FRAMES, frame_soup, key_frames, plan_soups, sample_motion, sample_times
from regrasp_cli.spatial import inverse, pose_error


def _area(tri: np.ndarray) -> float:
    return float(np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1).sum() / 2)


# ------------------------------------------------------------------ shapes


@pytest.mark.parametrize("source", ["visual", "collision"])
def test_link_shapes_are_where_pinocchio_puts_the_geometry(robot, source):
    """X_WL @ X_LS equals pinocchio's own geometry placement, at random configurations."""
    gmodel = robot.visual_model if source == "visual" else robot.collision_model
    links = robot_links(robot, source)
    assert sum(len(ls.shapes) for ls in links) == len(gmodel.geometryObjects)
    gdata = pin.GeometryData(gmodel)
    data = robot.model.createData()
    rng = np.random.default_rng(3)
    for _ in range(3):
        q = robot.sample(rng)
        pin.forwardKinematics(robot.model, data, robot.to_pin(q))
        pin.updateGeometryPlacements(robot.model, data, gmodel, gdata)
        for ls, X_WL in zip(links, link_poses(robot, links, q)):
            for s in ls.shapes:
                X_WS = gdata.oMg[gmodel.getGeometryId(s.name)].homogeneous
                np.testing.assert_allclose(X_WL @ s.X_PS, X_WS, atol=1e-12)


def test_primitive_triangles_fit_their_size():
    """Triangulated primitives span their nominal extents (cylinders and capsules along z)."""
    cases = [(Shape("b", "box", (0.1, 0.2, 0.3), np.eye(4), (1, 1, 1, 1)), [0.1, 0.2, 0.3]),
             (Shape("s", "sphere", (0.05,), np.eye(4), (1, 1, 1, 1)), [0.1, 0.1, 0.1]),
             (Shape("c", "cylinder", (0.05, 0.3), np.eye(4), (1, 1, 1, 1)), [0.1, 0.1, 0.3]),
             (Shape("k", "capsule", (0.05, 0.3), np.eye(4), (1, 1, 1, 1)), [0.1, 0.1, 0.4])]
    for shape, extents in cases:
        p = shape_triangles(shape).reshape(-1, 3)
        np.testing.assert_allclose(p.max(axis=0) - p.min(axis=0), extents, atol=6e-3, err_msg=shape.kind)
        np.testing.assert_allclose(p.max(axis=0) + p.min(axis=0), 0.0, atol=1e-9, err_msg=shape.kind)


def test_subdivide_keeps_the_surface_and_bounds_the_edges():
    tri = np.array([[[0, 0, 0], [1.0, 0, 0], [0, 2.0, 0]], [[0, 0, 1.0], [0.05, 0, 1], [0, 0.05, 1]]])
    out = subdivide(tri, 0.3)
    edges = np.linalg.norm(out - np.roll(out, -1, axis=1), axis=2)
    assert edges.max() <= 0.3
    assert _area(out) == pytest.approx(_area(tri), rel=1e-12)
    assert any(np.allclose(t, tri[1]) for t in out)  # a small triangle is kept as it is
    with pytest.raises(ValueError):
        subdivide(tri, 0.0)


def test_hand_links_are_the_palm_and_fingers(robot):
    links = robot_links(robot)
    for side, other in (("right", "left"), ("left", "right")):
        names = {ls.link for ls in hand_links(robot, links, side)}
        for finger in robot.hands[side].spec.fingers:
            assert finger.tip_link in names
        assert not any(f.tip_link in names for f in robot.hands[other].spec.fingers)
        assert not any("torso" in n for n in names)


# ------------------------------------------------------------------ the plan's motion


def test_key_frames_are_the_plan_moments(view):
    frames = key_frames(view)
    phases = view.plan.phases
    assert tuple(kf.name for kf in frames) == KEY_FRAMES
    assert [phases[kf.phase].name for kf in frames] == ["grasp", "close_right", "close_left", "place", "rest"]
    assert np.all(np.diff([kf.t for kf in frames]) > 0)
    np.testing.assert_array_equal(frames[0].q, phases[0].waypoints[0])
    np.testing.assert_array_equal(frames[-1].q, phases[-1].waypoints[-1])
    assert frames[-1].t == pytest.approx(view.duration)


@pytest.mark.parametrize("name, pose", [("start", "start"), ("pick", "start"), ("exchange", "exchange"),
                                        ("place", "goal"), ("end", "goal")])
def test_the_object_is_at_its_recorded_pose_in_the_key_frames(view, name, pose):
    kf = next(k for k in key_frames(view) if k.name == name)
    dp, da = pose_error(kf.X_WO, view.plan.object_poses[pose])
    assert dp < 1e-4 and da < 1e-3, (name, dp, da)  # the plan's IK is good to a few micrometres


def test_the_drawn_object_is_the_mesh_at_the_exchange_pose(view):
    """The triangles drawn for the exchange frame hold the object's mesh moved to
    object_poses.exchange (the object's triangles come last)."""
    kf = next(k for k in key_frames(view) if k.name == "exchange")
    soups = plan_soups(view)
    drawn = frame_soup(view, soups, kf.q, kf.X_WO).triangles[-len(view.inputs.mesh.faces):]
    X = view.plan.object_poses["exchange"]
    expected = view.inputs.mesh.triangles @ X[:3, :3].T + X[:3, 3]
    np.testing.assert_allclose(drawn, expected, atol=1e-4)


def test_the_sampled_motion_stops_at_every_waypoint(view):
    motion = sample_motion(view, fps=10)
    assert np.all(np.diff(motion.t) > 0) and np.diff(motion.t).max() <= 0.1 + 1e-9
    assert motion.t[0] == 0.0 and motion.t[-1] == pytest.approx(view.duration)
    for k, phase in enumerate(view.plan.phases):
        for t, q in zip(phase.times, phase.waypoints):
            i = int(np.argmin(np.abs(motion.t - t)))
            assert abs(motion.t[i] - t) < 1e-9
            np.testing.assert_allclose(motion.q[i], q, atol=1e-9, err_msg=f"{phase.name} at {t}")


def test_the_object_rests_or_rides_with_the_holding_hand(view):
    """Static while no hand holds it; fixed in the holding hand's grasp frame otherwise,
    where the plan's grasp puts it."""
    motion = sample_motion(view, fps=10)
    robot = view.inputs.robot
    for k, phase in enumerate(view.plan.phases):
        rows = np.flatnonzero(motion.phase == k)
        X = motion.X_WO[rows]
        if not phase.holding:
            np.testing.assert_allclose(X, np.broadcast_to(X[0], X.shape), atol=1e-12, err_msg=phase.name)
            continue
        hand = phase.holding[0]
        X_OG = view.plan.grasp(hand).X_OG
        for r, X_WO in zip(rows, X):
            X_GO = inverse(robot.fk(motion.q[r], robot.hands[hand].grasp_frame)) @ X_WO
            dp, da = pose_error(X_GO, inverse(X_OG))
            assert dp < 1e-3 and da < 1e-2, (phase.name, motion.t[r], dp, da)
    carried = [k for k, p in enumerate(view.plan.phases) if p.name == "carry"][0]
    X = motion.X_WO[motion.phase == carried]
    assert np.linalg.norm(X[-1, :3, 3] - X[0, :3, 3]) > 0.05  # it really travels


def test_sample_times_refuse_a_bad_rate(view):
    for fps in (0, -1, np.inf, 1000):
        with pytest.raises(ValueError):
            sample_times(view, fps)


# ------------------------------------------------------------------ animation keys


def test_pose_keys_drop_only_what_interpolation_restores():
    """A pose at rest, then moving, then at rest: the kept keys interpolate linearly back
    to every sample; quaternion signs stay continuous across a flip of the input."""
    t = np.linspace(0.0, 2.0, 21)
    X = np.tile(np.eye(4), (21, 1, 1))
    x = np.clip(t - 0.5, 0.0, 1.0)  # rest until 0.5 s, moves 1 m/s until 1.5 s, rests
    X[:, 0, 3] = x
    pos, quat = pose_keys(t, X, fps=1.0)
    assert len(pos["frames"]) < len(t)
    assert pos["frames"][0] == 0.0 and pos["frames"][-1] == 2.0
    back = np.interp(t, pos["frames"], np.array(pos["values"])[:, 0])
    np.testing.assert_allclose(back, x, atol=1e-12)
    assert len(quat["frames"]) == 2  # the orientation never changes

    from scipy.spatial.transform import Rotation

    angles = np.linspace(0.0, 2 * np.pi, 9)  # a full turn: scipy's quaternions flip sign on the way
    R = Rotation.from_rotvec(np.outer(angles, [0.0, 0.0, 1.0])).as_matrix()
    X = np.tile(np.eye(4), (9, 1, 1))
    X[:, :3, :3] = R
    _, quat = pose_keys(np.arange(9.0), X, fps=1.0)
    q = np.array(quat["values"])
    assert np.all(np.einsum("ij,ij->i", q[1:], q[:-1]) > 0)

