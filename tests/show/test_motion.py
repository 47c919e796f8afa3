"""The plan's motion as the viewer draws it: the object at its placements and riding with
the holding hand where its grasp puts it, the sampled motion through every waypoint, the
key frames at the plan's moments (found from the phases' kinds)."""

from __future__ import annotations

import numpy as np
import pytest

from regrasp_cli.manip.modes import Kind
from regrasp_cli.model.robot import Kinematics
from regrasp_cli.show.motion import KEY_FRAMES, frame_soup, key_frames, plan_soups, sample_motion, sample_times
from regrasp_cli.spatial import inverse, pose_error


def held_poses(view, phase: int, q: np.ndarray) -> dict[str, np.ndarray]:
    """Per hand holding the object in ``phase``: where its grasp puts the object (4, 4) at q."""
    robot = view.inputs.robot
    return {hand: Kinematics(robot).fk(q, robot.hands[hand].grasp_frame) @ inverse(view.plan.grasp(gid).X_OG)
            for hand, gid in view.plan.phases[phase].holding.items()}


# ------------------------------------------------------------------ the plan's motion


def test_key_frames_are_the_plan_moments(view):
    frames = key_frames(view)
    phases = view.plan.phases
    assert tuple(kf.name for kf in frames) == KEY_FRAMES
    assert [phases[kf.phase].name for kf in frames] == ["grasp", "close_right", "close_left", "place", "rest"]
    assert [phases[kf.phase].kind for kf in frames] == [Kind.TRANSIT, Kind.GRASP, Kind.HANDOVER, Kind.TRANSFER,
                                                         Kind.TRANSIT]
    assert np.all(np.diff([kf.t for kf in frames]) > 0)
    np.testing.assert_array_equal(frames[0].q, phases[0].waypoints[0])
    np.testing.assert_array_equal(frames[-1].q, phases[-1].waypoints[-1])
    assert frames[-1].t == pytest.approx(view.duration)


def exchange_pose(view, kf) -> np.ndarray:
    """Where the giving hand's grasp puts the object at the exchange key frame, after
    checking that the taking hand's grasp (it holds in the next phase) puts it there too."""
    given = held_poses(view, kf.phase, kf.q)
    taken = held_poses(view, kf.phase + 1, kf.q)
    assert set(given) == {"right"} and set(taken) == {"left"}
    dp, da = pose_error(given["right"], taken["left"])
    assert dp < 2e-4 and da < 2e-3, (dp, da)  # each hand's arm IK is within 1e-4 m and 1e-3 rad
    return given["right"]


@pytest.mark.parametrize("name, pose", [("start", "start"), ("pick", "start"), ("exchange", "exchange"),
                                        ("place", "goal"), ("end", "goal")])
def test_the_object_is_at_its_placement_or_grasp_pose_in_the_key_frames(view, name, pose):
    """At its start and goal placements, and at the exchange where both hands' grasps put it."""
    kf = next(k for k in key_frames(view) if k.name == name)
    expected = exchange_pose(view, kf) if pose == "exchange" else view.plan.placement(pose).X_WO
    dp, da = pose_error(kf.X_WO, expected)
    # the plan's arm IK: 0.1 mm and 1 mrad at the hand (model.ik), the object's origin within
    # 10 cm of the grasp frame, so within 0.2 mm and 1 mrad of where it should be
    assert dp < 2e-4 and da < 1e-3, (name, dp, da)


def test_the_drawn_object_is_the_mesh_at_the_exchange_pose(view):
    """The triangles drawn for the exchange frame hold the object's mesh moved to where
    the hands' grasps put it (the object's triangles come last)."""
    kf = next(k for k in key_frames(view) if k.name == "exchange")
    soups = plan_soups(view)
    drawn = frame_soup(view, soups, kf.q, kf.X_WO).triangles[-len(view.inputs.mesh.faces):]
    X = exchange_pose(view, kf)
    expected = view.inputs.mesh.triangles @ X[:3, :3].T + X[:3, 3]
    np.testing.assert_allclose(drawn, expected, atol=1e-4)


def test_the_sampled_motion_passes_every_waypoint(view):
    """Exactly through a stop (blend 0); within the blend's bound ``r |d_i - d_(i-1)| / 4``
    of a corner it cuts (motion/blend.py)."""
    motion = sample_motion(view, fps=10)
    assert np.all(np.diff(motion.t) > 0) and np.diff(motion.t).max() <= 0.1 + 1e-9
    assert motion.t[0] == 0.0 and motion.t[-1] == pytest.approx(view.duration)
    cut = 0
    for k, phase in enumerate(view.plan.phases):
        w = phase.waypoints
        r = phase.blends if phase.blends is not None else np.zeros(len(w))
        for i, (t, q) in enumerate(zip(phase.times, w)):
            j = int(np.argmin(np.abs(motion.t - t)))
            assert abs(motion.t[j] - t) < 1e-9
            bound = 0.0
            if r[i] > 0:
                d0, d1 = w[i] - w[i - 1], w[i + 1] - w[i]
                bound = r[i] * np.linalg.norm(d1 / np.linalg.norm(d1) - d0 / np.linalg.norm(d0)) / 4
                cut += 1
            assert np.linalg.norm(motion.q[j] - q) <= bound + 1e-7, f"{phase.name} waypoint {i} at {t}"
    assert cut > 0  # the plan cuts corners


def test_the_object_rests_or_rides_with_the_holding_hand(view):
    """At its placement while it rests; fixed in each holding hand's grasp frame otherwise,
    where the plan's grasp (the one ``holding`` names) puts it."""
    motion = sample_motion(view, fps=10)
    robot = view.inputs.robot
    for k, phase in enumerate(view.plan.phases):
        rows = np.flatnonzero(motion.phase == k)
        X = motion.X_WO[rows]
        if not phase.holding:
            assert phase.placement is not None, phase.name
            X_rest = view.plan.placement(phase.placement).X_WO
            np.testing.assert_allclose(X, np.broadcast_to(X_rest, X.shape), atol=1e-12, err_msg=phase.name)
            continue
        for hand, gid in phase.holding.items():
            X_OG = view.plan.grasp(gid).X_OG
            assert view.plan.grasp(gid).hand == hand
            for r, X_WO in zip(rows, X):
                X_GO = inverse(Kinematics(robot).fk(motion.q[r], robot.hands[hand].grasp_frame)) @ X_WO
                dp, da = pose_error(X_GO, inverse(X_OG))
                assert dp < 1e-3 and da < 1e-2, (phase.name, hand, motion.t[r], dp, da)
    carried = next(k for k, p in enumerate(view.plan.phases) if p.kind == Kind.TRANSFER)
    X = motion.X_WO[motion.phase == carried]
    assert np.linalg.norm(X[-1, :3, 3] - X[0, :3, 3]) > 0.05  # it really travels


def test_sample_times_refuse_a_bad_rate(view):
    for fps in (0, -1, np.inf, 1000):
        with pytest.raises(ValueError):
            sample_times(view, fps)


def test_sample_times_end_at_the_plan_end_whatever_the_rounding(view, monkeypatch):
    """The last sample is the plan's end exactly, also when rounding to 1 ns lifts it
    (18.944347742811487 s -> 18.944347743 s was dropped, and the page ended 24 ms early)."""
    for T in (18.944347742811487, 18.944347742211487, 7.0):
        monkeypatch.setattr(type(view), "duration", property(lambda self, T=T: T))
        t = sample_times(view, 25.0)
        assert t[-1] == T and t[0] == 0.0 and np.all(np.diff(t) > 0)
