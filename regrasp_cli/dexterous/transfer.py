"""Transfer paths (seed 003 §IV): the object moves while the grasp stays the same.

"The object poses between initial and final ones are chosen along a linear path linking
them. The finger configurations are computed from their inverse geometric models as we
know the fingertips positions from object pose and contact positions."  The linear path
is position interpolated linearly and orientation along the shortest rotation (slerp),
in steps of at most ``step_m`` and ``step_rad``; each step's fingers are solved from the
last step's (no restart: a jump to another IK branch would not be a continuous path), and
a step where a joint would move more than ``max_joint_step`` fails the path.

Force closure does not change along a transfer: the contacts are fixed on the object, so
their wrenches in the object frame are too (the caller checks it once).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from regrasp_cli.dexterous.hand import InHand, reach, tip_targets


@dataclass(frozen=True)
class TransferOptions:
    step_m: float = 0.002  # object translation per step
    step_rad: float = 0.02  # object rotation per step
    max_joint_step: float = 0.15  # rad: more in one step is an IK branch jump
    tol: float = 1e-4  # m, fingertip centre on its target


@dataclass(frozen=True)
class TransferPath:
    X_WO: np.ndarray  # (k, 4, 4) object poses
    q: np.ndarray  # (k, nq) robot configurations


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


def transfer_path(h: InHand, q0: np.ndarray, X_a: np.ndarray, X_b: np.ndarray, p_O: np.ndarray, n_O: np.ndarray,
                  rng: np.random.Generator, options: TransferOptions = TransferOptions()) -> TransferPath | None:
    """The fingers of ``h`` on the contacts ``p_O`` (n, 3), normals ``n_O``, object frame,
    while the object moves from X_a to X_b; ``q0`` holds them at X_a.  None when a step's
    IK fails or jumps."""
    poses = interpolate(X_a, X_b, options.step_m, options.step_rad)
    qs = [q0]
    radii = h.radii
    for X in poses[1:]:
        q = reach(h, qs[-1], tip_targets(X, p_O, n_O, radii), rng, restarts=0, tol=options.tol)
        if q is None or np.abs(q - qs[-1]).max() > options.max_joint_step:
            return None
        qs.append(q)
    return TransferPath(poses, np.array(qs))
