"""A third-party URDF (Baxter, from example-robot-data) through the same robot.yaml."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import ROOT

from regrasp_cli.model.robot import Kinematics

BAXTER = ROOT / "configs" / "robots" / "baxter" / "robot.yaml"


@pytest.fixture(scope="module")
def baxter():
    pytest.importorskip("pinocchio")
    from regrasp_cli.model.robot import load_robot

    return load_robot(BAXTER)


def test_baxter_groups_and_hands(baxter):
    assert baxter.nq == 19  # head pan + 2 x (7 arm + 2 gripper fingers)
    assert [len(baxter.groups[g]) for g in ("torso", "right_arm", "left_arm")] == [0, 7, 7]
    for side in ("right", "left"):
        hand = baxter.hands[side]
        assert hand.spec.contact == "soft"
        assert [len(f) for f in hand.finger_idx] == [1, 1]
        assert baxter.within_limits(baxter.q_rest)


def test_baxter_rest_is_collision_free_with_srdf_matrix(baxter, tmp_path):
    from regrasp_cli.model.collision import collision_world
    from regrasp_cli.model.selfcollision import disabled_pairs

    pairs = disabled_pairs(baxter, tmp_path)
    assert pairs.count("user") > 0  # the SRDF's pairs were read
    world = collision_world(baxter, (), pairs.links())
    assert world.colliding_pairs(baxter.q_rest) == []
    # the right gripper sent where the left one is: the two hands collide
    from regrasp_cli.model.ik import arm_ik

    X_left = Kinematics(baxter).fk(baxter.q_rest, baxter.hands["left"].grasp_frame)
    res = arm_ik(baxter, "right", X_left, baxter.q_rest, np.random.default_rng(0))
    assert res.success
    assert not world.is_free(res.q)
    pairs = world.colliding_pairs(res.q)
    assert any({a[0], b[0]} == {"l", "r"} for a, b in pairs), pairs


def test_baxter_ik_round_trip(baxter):
    from regrasp_cli.model.ik import arm_ik
    from regrasp_cli.spatial import pose_error

    rng = np.random.default_rng(3)
    for side in ("right", "left"):
        hand = baxter.hands[side]
        for _ in range(5):
            q_target = baxter.sample(rng, hand.arm_idx)
            X = Kinematics(baxter).fk(q_target, hand.grasp_frame)
            res = arm_ik(baxter, side, X, baxter.q_rest, rng)
            assert res.success
            dp, dr = pose_error(Kinematics(baxter).fk(res.q, hand.grasp_frame), X)
            assert dp < 1e-3 and dr < 1e-2
