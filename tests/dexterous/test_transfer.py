"""A transfer path with fixed contacts (seed 003 §IV) keeps the fingertips on them: three
fingers of our humanoid's right hand (wrist fixed) hold a sphere that touches their
fingertip spheres by construction (its centre at the tips' circumcentre); the object turns
about its centre and every waypoint has each fingertip centre at the contact plus the tip
radius along the normal, i.e. touching the sphere at the same object-frame point; a move
beyond the fingers' reach fails instead of returning a path that slips."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from regrasp_cli.dexterous.contacts import closure
from regrasp_cli.dexterous.hand import InHand, tip_targets
from regrasp_cli.dexterous.transfer import TransferOptions, interpolate, transfer_path
from regrasp_cli.model.robot import Kinematics


@pytest.fixture(scope="module")
def held(robot):
    hand = robot.hands["right"]
    h = InHand(robot, "right", robot.q_rest.copy(), (0, 1, 3))  # thumb, index, ring
    q = robot.q_rest.copy()
    q[hand.finger_idx[0]] = [1.0, 0.0, 0.4, 0.4]
    q[hand.finger_idx[1]] = [0.15, 0.7, 0.6]
    q[hand.finger_idx[3]] = [-0.15, 0.7, 0.6]
    kin = Kinematics(robot)
    a, b, c = h.tips(kin, q)
    ab, ac = b - a, c - a
    m = np.cross(ab, ac)
    centre = a + (ac @ ac * np.cross(m, ab) + ab @ ab * np.cross(ac, m)) / (2 * m @ m)  # circumcentre
    d = np.linalg.norm(h.tips(kin, q) - centre, axis=1)
    radius = d[0] - h.radii[0]
    n_O = (h.tips(kin, q) - centre) / d[:, None]
    X = np.eye(4)
    X[:3, 3] = centre
    return h, kin, q, X, radius * n_O, n_O, radius


def test_the_fingertips_stay_on_the_contacts_while_the_sphere_turns(held, robot):
    h, kin, q, X, p_O, n_O, radius = held
    assert radius > 0.02 and closure(p_O, n_O, 0.8, np.zeros(3), radius) > 0  # a real grasp
    X_b = X.copy()
    X_b[:3, :3] = Rotation.from_rotvec([0.15, 0.0, 0.0]).as_matrix()
    path = transfer_path(h, q, X, X_b, p_O, n_O, np.random.default_rng(0))
    assert path is not None and len(path.q) >= 8
    assert np.allclose(path.X_WO[0], X) and np.allclose(path.X_WO[-1], X_b)
    for X_WO, q_k in zip(path.X_WO, path.q):
        tips = h.tips(kin, q_k)
        assert np.abs(tips - tip_targets(X_WO, p_O, n_O, h.radii)).max() < 2e-4
        # touching the sphere: the tip centre one tip radius outside its surface
        assert np.allclose(np.linalg.norm(tips - X_WO[:3, 3], axis=1), radius + h.radii, atol=2e-4)
        assert robot.within_limits(q_k)
    moved = np.abs(np.diff(path.q, axis=0))
    assert moved.max() <= TransferOptions().max_joint_step
    assert np.all(moved[:, np.setdiff1d(np.arange(robot.nq), np.concatenate(
        [robot.hands["right"].finger_idx[f] for f in h.fingers]))] == 0)  # nothing else moves


def test_a_move_beyond_the_fingers_reach_fails(held):
    h, kin, q, X, p_O, n_O, _ = held
    X_b = X.copy()
    X_b[:3, :3] = Rotation.from_rotvec([0.0, 0.0, 0.6]).as_matrix()
    assert transfer_path(h, q, X, X_b, p_O, n_O, np.random.default_rng(0)) is None


def test_interpolated_poses_are_evenly_spaced_and_bounded():
    X_b = np.eye(4)
    X_b[:3, :3] = Rotation.from_rotvec([0.0, 0.3, 0.0]).as_matrix()
    X_b[:3, 3] = [0.01, 0.0, 0.0]
    poses = interpolate(np.eye(4), X_b, 0.002, 0.02)
    assert len(poses) == 16  # max(0.01 / 0.002, 0.3 / 0.02) = 15 steps
    angles = [Rotation.from_matrix(a[:3, :3].T @ b[:3, :3]).magnitude() for a, b in zip(poses, poses[1:])]
    assert np.allclose(angles, 0.02) and np.allclose(np.diff(poses[:, 0, 3]), 0.01 / 15)
