"""Rigid transforms as 4x4 float arrays, in the monogram notation (``X_AB``: pose of B in A)."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation


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
    """Inverse of a rigid transform (4, 4)."""
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
