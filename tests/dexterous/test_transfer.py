"""A transfer path with fixed contacts (seed 003 §IV) keeps the fingertips on them: the
planner's :func:`gait.carry` turns a 7 cm sphere held by `builtin:hand4`'s four fingertips,
and at every waypoint each fingertip centre is at its contact plus the tip radius along the
normal, i.e. touching the sphere (its centre R + r from the sphere's) at the same
object-frame point, with the joints within their limits, no jump and no collision; a turn
beyond the fingers' reach fails instead of returning a path that slips."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from regrasp_cli.dexterous.gait import GaitOptions, carry
from regrasp_cli.dexterous.hand import tip_targets
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


def test_the_fingertips_stay_on_the_contacts_while_the_sphere_turns(held):
    s, c = held
    X_b = _turned(0.15, [0.0, 1.0, 0.0])  # about x or z the first step collides
    t = carry(s, c, X_b, np.random.default_rng(0), s.options.step_m, s.options.step_rad)
    assert t is not None and len(t.q) >= 4  # 0.15 rad in steps of 0.05 at most
    assert np.allclose(t.X_GO[0], c.X_GO) and np.allclose(t.X_GO[-1], X_b) and np.array_equal(t.q[0], c.q)
    assert np.array_equal(t.p, c.p) and np.array_equal(t.n, c.n)  # the contacts stay
    robot = s.hm.robot
    for X_GO, q in zip(t.X_GO, t.q):
        X_WO = s.X_WG @ X_GO
        tips = s.hand.tips(s.kin, q)
        assert np.abs(tips - tip_targets(X_WO, c.p, c.n, s.hand.radii)).max() < 3e-4
        # touching the sphere: the tip centre one tip radius outside its surface
        assert np.allclose(np.linalg.norm(tips - X_WO[:3, 3], axis=1), R + s.hand.radii, atol=3e-4)
        assert robot.within_limits(q) and not s.collides(X_GO, q)
    moved = np.abs(np.diff(t.q, axis=0))
    assert moved.max() <= GaitOptions().max_joint_step
    fingers = np.concatenate(s.hm.hand.finger_idx)
    assert np.all(moved[:, np.setdiff1d(np.arange(robot.nq), fingers)] == 0)  # nothing else moves


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
