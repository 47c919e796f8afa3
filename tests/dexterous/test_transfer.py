"""A transfer path (seed 003 §IV) with fingertips that roll: the planner's
:func:`gait.carry` turns a 7 cm sphere held by `builtin:hand4`'s four fingertips, and at
every waypoint each fingertip centre is at its contact plus the tip radius along the
normal, touching the sphere (its centre R + r from the sphere's), with the joints within
their limits, no jump and no collision; between waypoints each fingertip rolls without
slipping, checked here on the sphere itself (a ball of radius r that turns by phi
relative to the object moves its centre by r phi x n), where seed 003's fixed contacts
slip by millimetres; a turn beyond the fingers' reach fails instead of returning a path."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from regrasp_cli.dexterous.gait import GaitOptions, carry
from regrasp_cli.dexterous.hand import reach, tip_targets
from regrasp_cli.dexterous.roadmap import GaitTreeOptions, start_config
from regrasp_cli.dexterous.transfer import interpolate

R = 0.035  # the sphere of tests/dexterous/conftest.py


@pytest.fixture(scope="module")
def held(hand4_ball):
    s = hand4_ball
    c = start_config(s, np.eye(4), np.random.default_rng(0), GaitTreeOptions(start_samples=10))
    assert c is not None and s.closure(c.p, c.n) > 0  # a real grasp
    return s, c


def _turned(angle: float, axis) -> np.ndarray:
    X = np.eye(4)
    X[:3, :3] = Rotation.from_rotvec(angle * np.asarray(axis, float) / np.linalg.norm(axis)).as_matrix()
    return X


def _slips(s, X_GO: np.ndarray, q: np.ndarray) -> np.ndarray:
    """(n,) how far each fingertip slipped on the sphere along the motion (m): the sum over
    the steps of |dc - r phi x n|, c the tip centre and phi the tip's turn, object frame,
    n the sphere's normal towards the tip (the sphere's geometry, not the planner's)."""
    frames = [s.hm.hand.tip_frames[f] for f in range(len(s.hand.fingers))]
    c, R_O = [], []
    for X, qi in zip(X_GO, q):
        X_WO = s.X_WG @ X
        T = [s.kin.fk(qi, fr) for fr in frames]
        c.append([X_WO[:3, :3].T @ (t[:3, 3] - X_WO[:3, 3]) for t in T])
        R_O.append([X_WO[:3, :3].T @ t[:3, :3] for t in T])
    c, R_O = np.array(c), np.array(R_O)
    slip = np.zeros(len(frames))
    for k in range(len(c) - 1):
        for f in range(len(frames)):
            phi = Rotation.from_matrix(R_O[k + 1, f] @ R_O[k, f].T).as_rotvec()
            n = c[k, f] + c[k + 1, f]
            n /= np.linalg.norm(n)
            slip[f] += np.linalg.norm(c[k + 1, f] - c[k, f] - s.hand.radii[f] * np.cross(phi, n))
    return slip


def test_the_fingertips_roll_on_the_sphere_without_slipping(held):
    s, c = held
    X_b = _turned(0.15, [0.0, 1.0, 0.0])  # about x or z the first step collides
    t = carry(s, c, X_b, np.random.default_rng(0), s.options.step_m, s.options.step_rad)
    assert t is not None and len(t.q) >= 4  # 0.15 rad in steps of 0.05 at most
    assert np.allclose(t.X_GO[0], c.X_GO) and np.allclose(t.X_GO[-1], X_b) and np.array_equal(t.q[0], c.q)
    assert np.array_equal(t.p[0], c.p) and np.array_equal(t.n[0], c.n)
    assert np.abs(t.p[-1] - c.p).max() > 1e-4  # the contacts rolled on
    robot = s.hm.robot
    for X_GO, q, p, n in zip(t.X_GO, t.q, t.p, t.n):
        X_WO = s.X_WG @ X_GO
        tips = s.hand.tips(s.kin, q)
        assert np.abs(tips - tip_targets(X_WO, p, n, s.hand.radii)).max() < 3e-4
        # touching the sphere: the tip centre one tip radius outside its surface
        assert np.allclose(np.linalg.norm(tips - X_WO[:3, 3], axis=1), R + s.hand.radii, atol=3e-4)
        assert robot.within_limits(q) and not s.collides(X_GO, q) and s.closure(p, n) > 0
    assert _slips(s, t.X_GO, t.q).max() < 2e-4  # the mesh is a polyhedron: its contacts sit up to 0.1 mm inside
    moved = np.abs(np.diff(t.q, axis=0))
    assert moved.max() <= GaitOptions().max_joint_step
    fingers = np.concatenate(s.hm.hand.finger_idx)
    assert np.all(moved[:, np.setdiff1d(np.arange(robot.nq), fingers)] == 0)  # nothing else moves


def test_fingertips_held_on_fixed_contacts_slip(held):
    """Seed 003's transfer, the contacts fixed on the object and the fingers by IK: the
    fingertips turn relative to the sphere, so they slip on it (millimetres)."""
    s, c = held
    X_b = _turned(0.15, [0.0, 1.0, 0.0])
    poses = interpolate(c.X_GO, X_b, s.options.step_m, s.options.step_rad)
    q, rng = [c.q], np.random.default_rng(0)
    for X in poses[1:]:
        q.append(reach(s.hand, q[-1], tip_targets(s.X_WG @ X, c.p, c.n, s.hand.radii), rng, restarts=0, kin=s.kin))
        assert q[-1] is not None
    assert _slips(s, poses, np.array(q)).max() > 2e-3  # 2.7 mm


def test_a_turn_beyond_the_fingers_reach_fails(held):
    s, c = held
    assert carry(s, c, _turned(2.5, [0.0, 1.0, 0.0]), np.random.default_rng(0), s.options.step_m,
                 s.options.step_rad) is None


def test_interpolated_poses_are_evenly_spaced_and_bounded():
    X_b = np.eye(4)
    X_b[:3, :3] = Rotation.from_rotvec([0.0, 0.3, 0.0]).as_matrix()
    X_b[:3, 3] = [0.01, 0.0, 0.0]
    poses = interpolate(np.eye(4), X_b, 0.002, 0.02)
    assert len(poses) == 16  # max(0.01 / 0.002, 0.3 / 0.02) = 15 steps
    angles = [Rotation.from_matrix(a[:3, :3].T @ b[:3, :3]).magnitude() for a, b in zip(poses, poses[1:])]
    assert np.allclose(angles, 0.02) and np.allclose(np.diff(poses[:, 0, 3]), 0.01 / 15)
