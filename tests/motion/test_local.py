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


# --------------------------------------------------------------------------- tiered checks


class _LineWorld:
    """1-D joint space, reach 1: an obstacle occupies [lo, hi]; a configuration is free
    with clearance ``scale * margin`` when it is that far from the interval."""

    def __init__(self, lo: float, hi: float, margin: float, certified: bool = True):
        self.lo, self.hi, self.margin, self.certified = lo, hi, margin, certified
        self.calls = []

    def gap(self, q) -> float:
        x = float(q[0])
        return max(self.lo - x, x - self.hi, 0.0)

    def is_free(self, q, scale: float = 1.0) -> bool:
        self.calls.append((float(q[0]), scale))
        return self.gap(q) > scale * self.margin

    def segment_free(self, q0, q1, resolution, min_steps=1, limit=None):
        ts = segment_samples(q0, q1, resolution, min_steps)[:limit]
        return all(self.is_free(q0 + t * (q1 - q0)) for t in ts)


def test_tiered_check_far_from_everything_costs_a_quarter():
    # 1 m at a 2 cm step: 50 fine intervals; 13 coarse ones of 4 -> 14 checks, all at 4x
    p = LocalPlanner(resolution=1.0, margin=0.01, reach=np.array([1.0]), coarse=4)
    world = _LineWorld(5.0, 6.0, 0.01)
    assert p.steps(np.zeros(1), np.ones(1)) == 50
    assert p.segment_free(world, np.zeros(1), np.ones(1)) is True
    assert len(world.calls) == 14 and {s for _, s in world.calls} == {4.0}


def test_tiered_check_refines_only_near_the_obstacle():
    # obstacle 3 cm past the segment's end: the last coarse ends lack 4 cm of clearance,
    # the fine samples around them keep 1 cm
    p = LocalPlanner(resolution=1.0, margin=0.01, reach=np.array([1.0]), coarse=4)
    world = _LineWorld(1.03, 2.0, 0.01)
    assert p.segment_free(world, np.zeros(1), np.ones(1)) is True
    fine = [x for x, s in world.calls if s == 1.0]
    assert fine and min(fine) > 0.8  # only the last coarse intervals were refined
    assert len(world.calls) < 30  # instead of 51 fine checks


def test_tiered_check_is_a_certificate_and_keeps_what_the_plain_check_accepts():
    """On random segments and obstacles: True only when the segment misses the obstacle;
    True whenever the segment keeps the plain clearance everywhere (what a fine check
    needs), never False without a sample inside the plain clearance."""
    rng = np.random.default_rng(3)
    for coarse in (2, 3, 4, 7):
        p = LocalPlanner(resolution=1.0, margin=0.01, reach=np.array([1.0]), coarse=coarse)
        for _ in range(300):
            a, b = rng.uniform(-1, 1, 2)
            lo = rng.uniform(-1.2, 1.2)
            world = _LineWorld(lo, lo + rng.uniform(0.0, 0.05), 0.01)
            q0, q1 = np.array([a]), np.array([b])
            ok = p.segment_free(world, q0, q1)
            hits = not (max(a, b) < world.lo or min(a, b) > world.hi)
            clearance = 0.0 if hits else min(world.gap(q0), world.gap(q1))
            if ok:
                assert not hits
            if clearance > 0.01:
                assert ok
            if not ok:
                assert any(s == 1.0 and world.gap([x]) <= 0.01 for x, s in world.calls)


def test_tiered_check_only_where_clearances_are_kept():
    # a world without clearances (an approach line's) is sampled at the fine step, and
    # a cheap test (limit) stays the plain one
    p = LocalPlanner(resolution=1.0, margin=0.01, reach=np.array([1.0]), coarse=4)
    world = _LineWorld(5.0, 6.0, 0.01, certified=False)
    assert p.segment_free(world, np.zeros(1), np.ones(1)) is True
    assert len(world.calls) == 51 and {s for _, s in world.calls} == {1.0}
    world = _LineWorld(5.0, 6.0, 0.01)
    assert p.segment_free(world, np.zeros(1), np.ones(1), limit=3) is True
    assert len(world.calls) == 3 and {s for _, s in world.calls} == {1.0}


def test_tiered_blend_check_is_a_certificate():
    # a blend curve cutting into the disc (its midpoint is 0.18 from the centre) is
    # refused, one around it accepted
    p = LocalPlanner(resolution=1.0, margin=0.01, reach=np.array([1.0, 1.0]), coarse=4)

    class Disc(_LineWorld):
        def gap(self, q):
            return max(float(np.linalg.norm(np.asarray(q) - [0.5, 0.5])) - 0.2, 0.0)  # a disc of radius 0.2

    A, C, B = np.array([0.0, 0.5]), np.array([0.5, 0.5]), np.array([0.5, 1.0])
    assert p.blend_free(Disc(0, 0, 0.01), A, C, B) is False
    A2, C2, B2 = np.array([0.0, 0.8]), np.array([0.2, 0.8]), np.array([0.2, 1.0])
    assert p.blend_free(Disc(0, 0, 0.01), A2, C2, B2) is True
