"""Rigid transforms as 4x4 float arrays, in the monogram notation (``X_AB``: pose of B in A)."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation, Slerp


def pose_matrix(xyz, rpy=None, quat=None) -> np.ndarray:
    """4x4 transform from a translation (m) and either roll-pitch-yaw (rad, fixed axes x-y-z,
    as in URDF) or a unit quaternion ``[x, y, z, w]``."""
    X = np.eye(4)
    X[:3, 3] = xyz
    if quat is not None:
        X[:3, :3] = Rotation.from_quat(quat).as_matrix()
    elif rpy is not None:
        X[:3, :3] = Rotation.from_euler("xyz", rpy).as_matrix()
    return X


def inverse(X: np.ndarray) -> np.ndarray:
    """Inverse of a rigid transform (4, 4), or of each of a batch (B, 4, 4)."""
    if X.ndim == 3:
        Xi = np.zeros_like(X, dtype=float)
        Xi[:, :3, :3] = X[:, :3, :3].transpose(0, 2, 1)
        Xi[:, :3, 3] = -np.einsum("bji,bj->bi", X[:, :3, :3], X[:, :3, 3])
        Xi[:, 3, 3] = 1.0
        return Xi
    Xi = np.eye(4)
    R = X[:3, :3]
    Xi[:3, :3] = R.T
    Xi[:3, 3] = -R.T @ X[:3, 3]
    return Xi


def transform_points(X_AB: np.ndarray, p_B: np.ndarray) -> np.ndarray:
    """Points (n, 3) in frame B -> frame A."""
    return p_B @ X_AB[:3, :3].T + X_AB[:3, 3]


def rotation_angle(R: np.ndarray) -> float:
    """Angle (rad) of a rotation matrix (3, 3)."""
    return float(np.arccos(np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0)))


def pose_error(X_A: np.ndarray, X_B: np.ndarray) -> tuple[float, float]:
    """(translation distance in m, rotation angle in rad) between two poses."""
    return float(np.linalg.norm(X_A[:3, 3] - X_B[:3, 3])), rotation_angle(X_A[:3, :3].T @ X_B[:3, :3])


def pose_to_dict(X: np.ndarray) -> dict:
    """``{xyz, quat: [x, y, z, w]}`` for YAML/JSON output."""
    return {"xyz": [float(v) for v in X[:3, 3]],
            "quat": [float(v) for v in Rotation.from_matrix(X[:3, :3]).as_quat()]}


def rotation_aligning(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Rotations turning unit vectors a onto b ((3,) -> (3, 3), or (k, 3) -> (k, 3, 3)):
    the shortest arc, a half turn about an axis perpendicular to a when they are opposite."""
    single = np.ndim(a) == 1
    a, b = np.atleast_2d(a).astype(float), np.atleast_2d(b).astype(float)
    v = np.cross(a, b)
    s, c = np.linalg.norm(v, axis=1), np.einsum("ij,ij->i", a, b)
    k = np.where(s[:, None] > 1e-9, v / np.maximum(s, 1e-12)[:, None], 0.0)
    flip = (s <= 1e-9) & (c < 0)
    if flip.any():  # any axis perpendicular to a
        ref = np.where((np.abs(a[flip, 0]) < 0.9)[:, None], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
        p = np.cross(a[flip], ref)
        k[flip] = p / np.linalg.norm(p, axis=1, keepdims=True)
    R = Rotation.from_rotvec(k * np.arctan2(s, c)[:, None]).as_matrix()
    return R[0] if single else R


def segment_poses(X_a: np.ndarray, X_b: np.ndarray, ts: np.ndarray) -> np.ndarray:
    """(k, 4, 4) object poses at the fractions ``ts`` (k,) of the way from ``X_a`` to ``X_b``
    (4, 4): position linear, rotation slerp; all ``X_b`` when the two are equal.  All at
    once: a Slerp call costs ~0.3 ms, whatever its number of times."""
    Xs = np.repeat(X_b[None], len(ts), axis=0)
    if not np.array_equal(X_a, X_b):
        Xs[:, :3, :3] = Slerp([0, 1], Rotation.from_matrix(np.stack([X_a[:3, :3], X_b[:3, :3]])))(ts).as_matrix()
        Xs[:, :3, 3] = (1 - ts)[:, None] * X_a[:3, 3] + ts[:, None] * X_b[:3, 3]
    return Xs
