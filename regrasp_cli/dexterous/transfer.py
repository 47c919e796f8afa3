"""The object poses of a transfer path (seed 003 §IV): the object moves while the grasp
stays the same.

"The object poses between initial and final ones are chosen along a linear path linking
them. The finger configurations are computed from their inverse geometric models as we
know the fingertips positions from object pose and contact positions."  The linear path
is position interpolated linearly and orientation along the shortest rotation (slerp),
in steps of at most ``step_m`` and ``step_rad``; :func:`gait.carry` solves each step's
fingers from the last step's and checks it.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation, Slerp


def interpolate(X_a: np.ndarray, X_b: np.ndarray, step_m: float, step_rad: float) -> np.ndarray:
    """(k, 4, 4) poses from X_a to X_b (both included), position linear and rotation
    slerp, at most ``step_m`` and ``step_rad`` apart."""
    angle = Rotation.from_matrix(X_a[:3, :3].T @ X_b[:3, :3]).magnitude()
    k = max(1, int(np.ceil(max(np.linalg.norm(X_b[:3, 3] - X_a[:3, 3]) / step_m, angle / step_rad))))
    return poses_between(X_a, X_b, k)


def poses_between(X_a: np.ndarray, X_b: np.ndarray, k: int) -> np.ndarray:
    """(k + 1, 4, 4) poses from X_a to X_b in ``k`` equal steps (linear, slerp)."""
    R = Rotation.from_matrix(np.stack([X_a[:3, :3], X_b[:3, :3]]))
    t = np.linspace(0.0, 1.0, k + 1)
    X = np.repeat(np.eye(4)[None], k + 1, axis=0)
    X[:, :3, :3] = Slerp([0.0, 1.0], R)(t).as_matrix()
    X[:, :3, 3] = (1 - t)[:, None] * X_a[:3, 3] + t[:, None] * X_b[:3, 3]
    return X
