"""The plan's motion as the viewer draws it: the object at its recorded poses and riding
with the holding hand, the sampled motion through every waypoint, the key frames at the
plan's moments."""

from __future__ import annotations

import numpy as np
import pytest

from regrasp_cli.show.motion import KEY_FRAMES, frame_soup, key_frames, plan_soups, sample_motion, sample_times
from regrasp_cli.spatial import inverse, pose_error


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
