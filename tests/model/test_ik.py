"""Tests of regrasp_cli.model.ik on the default robot: round trips FK(IK(T)) = T for
reachable targets (FK of random configurations, collisions not checked), finger IK round
trips, and failure on unreachable targets."""

from __future__ import annotations

import numpy as np
import pytest

from regrasp_cli.model.ik import IKOptions, arm_ik, arm_ik_batch, finger_ik, two_arm_ik
from regrasp_cli.model.robot import Kinematics
from regrasp_cli.spatial import pose_error

N_TARGETS = 12
POS_TOL, ROT_TOL = 1e-3, 1e-2  # m, rad


@pytest.mark.parametrize("hand", ["right", "left"])
def test_arm_ik_round_trip(robot, hand):
    h = robot.hands[hand]
    targets_rng = np.random.default_rng(123 if hand == "right" else 456)
    rng = np.random.default_rng(7)
    others = np.setdiff1d(np.arange(robot.nq), h.arm_idx)
    for k in range(N_TARGETS):
        q_target = robot.sample(targets_rng, h.arm_idx)
        X_WG = Kinematics(robot).fk(q_target, h.grasp_frame)
        res = arm_ik(robot, hand, X_WG, robot.q_rest, rng)
        assert res.success, f"target {k}: errors {res.position_error:.2g} m, {res.rotation_error:.2g} rad"
        dp, dr = pose_error(Kinematics(robot).fk(res.q, h.grasp_frame), X_WG)
        assert dp <= POS_TOL and dr <= ROT_TOL, (k, dp, dr)
        assert res.position_error == pytest.approx(dp, abs=1e-9)
        assert robot.within_limits(res.q)
        np.testing.assert_array_equal(res.q[others], robot.q_rest[others])  # only the arm moved


def test_arm_ik_with_torso_round_trip(robot):
    h = robot.hands["right"]
    idx = np.concatenate([robot.groups["torso"], h.arm_idx])
    targets_rng, rng = np.random.default_rng(11), np.random.default_rng(12)
    for k in range(N_TARGETS):
        X_WG = Kinematics(robot).fk(robot.sample(targets_rng, idx), h.grasp_frame)
        res = arm_ik(robot, "right", X_WG, robot.q_rest, rng, with_torso=True)
        assert res.success, k
        dp, dr = pose_error(Kinematics(robot).fk(res.q, h.grasp_frame), X_WG)
        assert dp <= POS_TOL and dr <= ROT_TOL
        assert robot.within_limits(res.q)
        np.testing.assert_array_equal(res.q[robot.groups["left_arm"]], robot.q_rest[robot.groups["left_arm"]])


def test_two_arm_ik_reaches_both_poses_at_once(robot):
    """Both grasp frames at the poses they have in one random configuration of the torso
    and both arms: one solve reaches both (the torso shared), nothing else moves."""
    idx = np.concatenate([robot.groups["torso"], robot.hands["right"].arm_idx, robot.hands["left"].arm_idx])
    frames = [robot.hands[h].grasp_frame for h in ("right", "left")]
    targets_rng, rng = np.random.default_rng(21), np.random.default_rng(22)
    for k in range(N_TARGETS):
        q_target = robot.sample(targets_rng, idx)
        X = tuple(Kinematics(robot).fk(q_target, f) for f in frames)
        res = two_arm_ik(robot, ("right", "left"), X, robot.q_rest, rng)
        assert res.success, (k, res.position_error, res.rotation_error)
        for f, X_WG in zip(frames, X):
            dp, dr = pose_error(Kinematics(robot).fk(res.q, f), X_WG)
            assert dp <= POS_TOL and dr <= ROT_TOL, (k, dp, dr)
        assert robot.within_limits(res.q)
        others = np.setdiff1d(np.arange(robot.nq), idx)
        np.testing.assert_array_equal(res.q[others], robot.q_rest[others])


def test_arm_ik_is_deterministic_for_a_seed(robot):
    h = robot.hands["left"]
    X_WG = Kinematics(robot).fk(robot.sample(np.random.default_rng(5), h.arm_idx), h.grasp_frame)
    a = arm_ik(robot, "left", X_WG, robot.q_rest, np.random.default_rng(3))
    b = arm_ik(robot, "left", X_WG, robot.q_rest, np.random.default_rng(3))
    np.testing.assert_array_equal(a.q, b.q)
    assert a.iterations == b.iterations


@pytest.mark.parametrize("hand", ["right", "left"])
def test_finger_ik_round_trip(robot, hand):
    h = robot.hands[hand]
    targets_rng, rng = np.random.default_rng(21), np.random.default_rng(22)
    n = 0
    for finger in range(len(h.finger_idx)):
        idx = h.finger_idx[finger]
        others = np.setdiff1d(np.arange(robot.nq), idx)
        for k in range(3):
            q_target = robot.sample(targets_rng, idx)
            p = Kinematics(robot).fk(q_target, h.tip_frames[finger])[:3, 3]
            res = finger_ik(robot, hand, finger, p, robot.q_rest, rng)
            assert res.success, (finger, k, res.position_error)
            err = np.linalg.norm(Kinematics(robot).fk(res.q, h.tip_frames[finger])[:3, 3] - p)
            assert err <= POS_TOL
            assert robot.within_limits(res.q)
            np.testing.assert_array_equal(res.q[others], robot.q_rest[others])  # only that finger moved
            n += 1
    assert n >= 10


def test_unreachable_arm_target(robot):
    h = robot.hands["right"]
    X = Kinematics(robot).fk(robot.q_rest, h.grasp_frame)
    X[:3, 3] += [3.0, 0.0, 0.0]
    res = arm_ik(robot, "right", X, robot.q_rest, np.random.default_rng(0))  # default: 20 restarts
    assert not res.success
    assert res.iterations == (IKOptions().restarts + 1) * IKOptions().max_iters
    assert res.position_error > 2.0
    assert robot.within_limits(res.q)
    res = arm_ik(robot, "right", X, robot.q_rest, np.random.default_rng(0), with_torso=True,
                 options=IKOptions(restarts=5))
    assert not res.success


def test_unreachable_finger_target(robot):
    h = robot.hands["left"]
    p = Kinematics(robot).fk(robot.q_rest, h.tip_frames[1])[:3, 3] + [0.0, 3.0, 0.0]
    res = finger_ik(robot, "left", 1, p, robot.q_rest, np.random.default_rng(0))
    assert not res.success
    assert res.position_error > 2.5
    assert robot.within_limits(res.q)


def test_finger_ik_on_a_reused_scratch_gives_what_a_fresh_one_gives(robot):
    """IK overwrites the pinocchio Data it is given: one left from other configurations
    and frames changes nothing, to the bit."""
    h = robot.hands["right"]
    kin, rng = Kinematics(robot), np.random.default_rng(5)
    for finger in range(len(h.finger_idx)):
        q = robot.sample(rng, h.finger_idx[finger])
        p = kin.fk(q, h.tip_frames[finger])[:3, 3] + rng.normal(0.0, 0.01, 3)  # some out of reach
        kin.fk(robot.sample(rng, h.arm_idx), h.grasp_frame)  # the scratch left elsewhere
        a = finger_ik(robot, "right", finger, p, robot.q_rest, np.random.default_rng(finger))
        b = finger_ik(robot, "right", finger, p, robot.q_rest, np.random.default_rng(finger), data=kin.data)
        np.testing.assert_array_equal(a.q, b.q)
        assert (a.success, a.iterations, a.position_error) == (b.success, b.iterations, b.position_error)


@pytest.mark.parametrize("with_torso", [False, True])
def test_batched_arm_ik_reaches_each_pose_from_its_own_seed(robot, with_torso):
    """Poses the arm (and torso) reach, each from its own seed configuration (the torso
    drawn differently in each), and the same poses 3 m away: the first are reached to
    arm_ik's tolerances with only the moving joints changed, the others are not."""
    h = robot.hands["right"]
    moving = np.concatenate([robot.groups["torso"], h.arm_idx]) if with_torso else h.arm_idx
    targets_rng, rng = np.random.default_rng(21), np.random.default_rng(22)
    seeds = np.array([robot.sample(targets_rng, robot.groups["torso"]) for _ in range(N_TARGETS)])
    X = np.array([Kinematics(robot).fk(robot.sample(targets_rng, h.arm_idx, base=q), h.grasp_frame) for q in seeds])
    far = X.copy()
    far[:, 0, 3] += 3.0
    Q, ok = arm_ik_batch(robot, "right", np.concatenate([X, far]), np.concatenate([seeds, seeds]), rng,
                         with_torso=with_torso, options=IKOptions(restarts=2, max_iters=60))
    assert ok[:N_TARGETS].mean() >= 0.9 and not ok[N_TARGETS:].any()
    others = np.setdiff1d(np.arange(robot.nq), moving)
    for k in np.flatnonzero(ok):
        dp, dr = pose_error(Kinematics(robot).fk(Q[k], h.grasp_frame), X[k])
        assert dp <= 1e-4 + 1e-9 and dr <= 2e-3, (k, dp, dr)
        assert robot.within_limits(Q[k])
        np.testing.assert_array_equal(Q[k, others], seeds[k, others])
    np.testing.assert_array_equal(Q[N_TARGETS:], seeds)  # none converged: the seeds back
