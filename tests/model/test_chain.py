"""Batched finger kinematics (model.chain) against pinocchio: tip frames and position
Jacobians of every finger of the shipped fingertip hands, in the grasp frame, at random
configurations within the limits."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from regrasp_cli.model.chain import read_chain
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
