"""Batched finger kinematics (model.chain) against pinocchio: tip frames and position
Jacobians of every finger of the shipped fingertip hands, in the grasp frame, at random
configurations within the limits."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from regrasp_cli.model.chain import read_chain, tip_frames_and_jacobian
from regrasp_cli.model.ik import arm_reachable
from regrasp_cli.model.robot import Kinematics, load_robot
from regrasp_cli.spatial import inverse

ROBOTS = Path(__file__).resolve().parents[2] / "configs" / "robots"


@pytest.mark.parametrize("name", ["humanoid43", "allegro", "hand4"])
def test_chain_matches_pinocchio(name):
    robot = load_robot(ROBOTS / name / "robot.yaml")
    kin = Kinematics(robot)
    rng = np.random.default_rng(0)
    for h in robot.hands.values():
        for f, idx in enumerate(h.finger_idx):
            chain = read_chain(robot, h.grasp_frame, h.tip_frames[f], idx, robot.q_rest)
            Q = rng.uniform(robot.lower[idx], robot.upper[idx], (4, len(idx)))
            p, J = chain.tip_and_jacobian(Q)
            _, X_GT = chain.forward(Q)
            for b in range(len(Q)):
                q = robot.q_rest.copy()
                q[idx] = Q[b]
                X_WG = kin.fk(q, h.grasp_frame)
                np.testing.assert_allclose(X_GT[b], inverse(X_WG) @ kin.fk(q, h.tip_frames[f]), atol=1e-12)
                pin.computeJointJacobians(robot.model, kin.data, robot.to_pin(q))
                pin.updateFramePlacements(robot.model, kin.data)
                J_W = pin.getFrameJacobian(robot.model, kin.data, h.tip_frames[f], pin.LOCAL_WORLD_ALIGNED)[:3]
                np.testing.assert_allclose(J[b], X_WG[:3, :3].T @ J_W[:, robot._idx_q[idx]], atol=1e-12)
                np.testing.assert_allclose(p[b], X_GT[b][:3, 3], atol=1e-15)


def test_chain_refuses_a_tip_outside_the_subtree(robot):
    h, other = robot.hands["right"], robot.hands["left"]
    with pytest.raises(ValueError, match="not below"):
        read_chain(robot, h.grasp_frame, other.tip_frames[0], other.finger_idx[0], robot.q_rest)


def test_arm_pose_jacobian_matches_pinocchio():
    """The torso + arm chain from the world to the grasp frame: tip frame and 6-row
    Jacobian (linear, angular; world axes, about the tip) as pinocchio's LOCAL_WORLD_ALIGNED."""
    robot = load_robot(ROBOTS / "humanoid43" / "robot.yaml")
    kin = Kinematics(robot)
    rng = np.random.default_rng(1)
    h = robot.hands["left"]
    dofs = np.concatenate([robot.groups["torso"], h.arm_idx])
    chain = read_chain(robot, 0, h.grasp_frame, dofs, robot.q_rest)
    Q = rng.uniform(robot.lower[dofs], robot.upper[dofs], (3, len(dofs)))
    X, J = tip_frames_and_jacobian(chain, Q)
    for b in range(len(Q)):
        q = robot.q_rest.copy()
        q[dofs] = Q[b]
        np.testing.assert_allclose(X[b], kin.fk(q, h.grasp_frame), atol=1e-12)
        pin.computeJointJacobians(robot.model, kin.data, robot.to_pin(q))
        pin.updateFramePlacements(robot.model, kin.data)
        J_W = pin.getFrameJacobian(robot.model, kin.data, h.grasp_frame, pin.LOCAL_WORLD_ALIGNED)
        np.testing.assert_allclose(J[b], J_W[:, robot._idx_q[dofs]], atol=1e-12)


def test_arm_reachable_finds_reached_poses_and_refuses_far_ones():
    """Poses the arm reaches (forward kinematics of random configurations near rest) are
    found by the batched IK; the same poses 3 m away are not."""
    robot = load_robot(ROBOTS / "humanoid43" / "robot.yaml")
    kin = Kinematics(robot)
    rng = np.random.default_rng(2)
    h = robot.hands["right"]
    poses = []
    for _ in range(12):
        q = robot.q_rest.copy()
        q[h.arm_idx] = np.clip(q[h.arm_idx] + rng.normal(0, 0.5, len(h.arm_idx)), robot.lower[h.arm_idx],
                               robot.upper[h.arm_idx])
        poses.append(kin.fk(q, h.grasp_frame))
    poses = np.array(poses)
    far = poses.copy()
    far[:, 1, 3] -= 3.0
    reached = arm_reachable(robot, "right", np.concatenate([poses, far]), np.random.default_rng(3))
    assert reached[:12].mean() >= 0.9 and not reached[12:].any()
