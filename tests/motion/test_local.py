"""Local planner of the roadmaps (regrasp_cli.motion.local): the step count of the
certified straight-line planner, the soundness of the per-joint reach bound, and the
Cartesian spacing of the configurations it checks on the default robot."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from regrasp_cli.model.collision import segment_samples
from regrasp_cli.motion.local import LocalPlanner, distance, joint_reach, joint_weights


# --------------------------------------------------------------------------- steps


def test_steps_cartesian_bound_dominates():
    # |dq| . reach = 0.5 * 1 + 0.25 * 2 = 1 m; 2 * margin = 1/32 m -> 32 intervals;
    # the joint bound is 0.5 / 0.125 = 4
    p = LocalPlanner(resolution=0.125, margin=1 / 64, reach=np.array([1.0, 2.0]))
    assert p.steps(np.zeros(2), np.array([0.5, -0.25])) == 32


def test_steps_joint_bound_dominates():
    # joint bound 0.5 / (1/256) = 128; Cartesian bound 1 / (2 * 0.125) = 4
    p = LocalPlanner(resolution=1 / 256, margin=0.125, reach=np.array([1.0, 2.0]))
    assert p.steps(np.zeros(2), np.array([-0.5, 0.25])) == 128


def test_steps_rounds_up_and_is_at_least_one():
    p = LocalPlanner(resolution=0.25, margin=0.5, reach=np.array([1.0, 1.0]))
    # joint: 0.625 / 0.25 = 2.5 -> 3; Cartesian: (0.625 + 0.125) / 1 = 0.75 -> 1
    assert p.steps(np.zeros(2), np.array([0.625, 0.125])) == 3
    # Cartesian: (0.625 + 0.625) / 1 = 1.25 -> 2 < 3
    assert p.steps(np.zeros(2), np.array([0.625, -0.625])) == 3
    q = np.array([0.3, -0.2])
    assert p.steps(q, q.copy()) == 1


def test_steps_depend_only_on_the_difference():
    p = LocalPlanner(resolution=0.125, margin=1 / 64, reach=np.array([1.0, 2.0]))
    q0 = np.array([1.0, -2.0])
    assert p.steps(q0, q0 + np.array([0.5, -0.25])) == 32
    assert p.steps(q0 + np.array([0.5, -0.25]), q0) == 32


def test_segment_free_passes_resolution_and_steps_to_the_world():
    calls = []

    class FakeWorld:
        def segment_free(self, q0, q1, resolution, min_steps=1, limit=None):
            calls.append((q0.copy(), q1.copy(), resolution, min_steps, limit))
            return True

    p = LocalPlanner(resolution=0.125, margin=1 / 64, reach=np.array([1.0, 2.0]))
    q0, q1 = np.zeros(2), np.array([0.5, -0.25])
    assert p.segment_free(FakeWorld(), q0, q1) is True
    assert p.segment_free(FakeWorld(), q0, q1, limit=16) is True
    assert len(calls) == 2
    a, b, res, n, limit = calls[0]
    assert np.array_equal(a, q0) and np.array_equal(b, q1) and res == 0.125 and n == 32 and limit is None
    assert calls[1][3:] == (32, 16)  # the cheap test: same cut, only the first 16 samples


# --------------------------------------------------------------------------- distance


def test_distance_weighted_euclidean_single_and_stacked():
    w = np.array([1.0, 0.25])
    q0 = np.array([0.0, 0.0])
    assert distance(q0, np.array([3.0, 8.0]), w) == pytest.approx(5.0)  # sqrt(9 + 0.25 * 64)
    d = distance(q0, np.array([[3.0, 8.0], [0.0, 2.0], [0.0, 0.0]]), w)
    assert d.shape == (3,)
    assert np.allclose(d, [5.0, 1.0, 0.0])


def test_joint_weights_in_range_and_torso_weighs_most(robot):
    w = joint_weights(robot)
    assert w.shape == (robot.nq,)
    assert np.all(w >= 0.05 - 1e-12) and np.all(w <= 1.0 + 1e-12)
    assert w.max() == pytest.approx(1.0)
    torso_yaw = robot.joint_names.index("torso_yaw")
    assert w[torso_yaw] == pytest.approx(1.0)
    wrist = robot.joint_names.index("r_arm_j7")
    assert w[wrist] < w[torso_yaw]


# --------------------------------------------------------------------------- joint_reach


def _descendant_frames(robot, j: int) -> list[int]:
    sub = set(robot.model.subtrees[j])
    return [f for f, fr in enumerate(robot.model.frames) if fr.parentJoint in sub]


def test_joint_reach_bounds_the_distance_to_every_descendant_frame(robot):
    """Soundness: for every joint, the reach is >= the largest distance from the joint's
    origin to any frame it carries, over 50 random configurations."""
    reach = joint_reach(robot)
    assert reach.shape == (robot.nq,)
    assert np.all(reach > 0)
    model, data = robot.model, robot.model.createData()
    jids = [model.getJointId(n) for n in robot.joint_names]
    frames = [_descendant_frames(robot, j) for j in jids]
    prismatic = [model.joints[j].shortname().startswith("JointModelP") for j in jids]
    rng = np.random.default_rng(1)
    worst = np.zeros(robot.nq)
    for _ in range(50):
        pin.framesForwardKinematics(model, data, robot.to_pin(robot.sample(rng)))
        for i, j in enumerate(jids):
            origin = data.oMi[j].translation
            for f in frames[i]:
                worst[i] = max(worst[i], float(np.linalg.norm(data.oMf[f].translation - origin)))
    for i, name in enumerate(robot.joint_names):
        if prismatic[i]:
            assert reach[i] == 1.0
        else:
            assert reach[i] >= worst[i], (name, reach[i], worst[i])


# --------------------------------------------------------------------------- certified spacing


def test_checked_configurations_are_at_most_two_margins_apart_in_cartesian_space(robot):
    """Between consecutive configurations checked by the certified planner, no robot
    frame moves more than 2 * margin (measured with FK of all frames)."""
    from regrasp_cli.roadmap.build import RoadmapOptions

    margin, resolution = RoadmapOptions().margin, RoadmapOptions().resolution  # what the build uses
    planner = LocalPlanner(resolution, margin, joint_reach(robot))
    idx = np.concatenate([robot.groups["torso"], robot.groups["right_arm"], robot.groups["left_arm"]])
    model, data = robot.model, robot.model.createData()
    rng = np.random.default_rng(7)
    largest = 0.0
    for k in range(4):
        q0 = robot.sample(rng, idx)
        q1 = robot.sample(rng, idx) if k < 3 else q0 + rng.uniform(-0.05, 0.05, robot.nq) * np.isin(
            np.arange(robot.nq), idx)  # a short segment too
        n = planner.steps(q0, q1)
        ts = np.sort(segment_samples(q0, q1, resolution, n))
        assert ts[0] == 0.0 and ts[-1] == 1.0 and len(ts) == n + 1
        assert np.all(np.diff(ts) > 0)
        prev = None
        for t in ts:
            pin.framesForwardKinematics(model, data, robot.to_pin(q0 + t * (q1 - q0)))
            X = np.array([data.oMf[f].translation for f in range(len(model.frames))])
            if prev is not None:
                largest = max(largest, float(np.linalg.norm(X - prev, axis=1).max()))
            prev = X
        # the joint bound holds too
        assert np.max(np.abs(np.diff(ts)[:, None] * (q1 - q0)[None, :])) <= resolution + 1e-12
    assert 0.0 < largest <= 2 * margin, largest


def test_arm_chains_of_the_humanoid_and_what_they_save(robot):
    """Torso + one side (arm and hand), and both sides without the torso: every joint in
    some set, the torso never with both arms.  A segment that moves the torso and both
    arms gets fewer samples than with the sum over every joint, one that moves one arm
    only the same number."""
    from regrasp_cli.motion.local import arm_chains

    chains = arm_chains(robot)
    t, r, l = robot.groups["torso"], robot.groups["right_arm"], robot.groups["left_arm"]
    sets = [set(c.tolist()) for c in chains]
    assert sets[0] == set(t) | set(r) | set(robot.hands["right"].idx)
    assert sets[1] == set(t) | set(l) | set(robot.hands["left"].idx)
    assert sets[2] == set(r) | set(l) | set(robot.hands["right"].idx) | set(robot.hands["left"].idx)
    assert set().union(*sets) == set(range(robot.nq))
    planner = LocalPlanner(0.02, 0.005, joint_reach(robot))
    dq = np.zeros(robot.nq)
    dq[np.r_[t, r, l]] = 0.3
    assert planner.steps(np.zeros(robot.nq), dq, chains) < planner.steps(np.zeros(robot.nq), dq)
    one = np.zeros(robot.nq)
    one[r] = 0.3
    assert planner.steps(np.zeros(robot.nq), one, chains) == planner.steps(np.zeros(robot.nq), one)
