"""Serial chains of one-DoF joints, evaluated for many configurations at once (numpy).

A finger is a short chain hanging from the palm: a grasp search places thousands of
fingertips per second, and calling pinocchio once per configuration and iteration was a
third of its time.  :class:`Chain` reads the chain once from the pinocchio model; its
forward kinematics and position Jacobian then take a batch of configurations (B, n) at
a time.  Frames: every result is expressed in the chain's reference frame R (for a
finger, the hand's grasp frame G), metres and radians.  The values agree with
pinocchio's to rounding (tests/model/test_chain.py).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from regrasp_cli.model.robot import Robot
from regrasp_cli.spatial import inverse


@dataclass(frozen=True)
class Chain:
    """Joints from the frame R down to a tip frame T, for configurations of ``dofs``.

    The chain's joint values are ``q[..., dofs] @ A.T + b``: its own joints, mimic followers
    of them (multiplier and offset) and joints of other parts held at their value in the
    configuration the chain was read at (a row of A that is zero)."""

    X_RP: np.ndarray  # (4, 4) the first joint's parent-joint frame in R
    placements: np.ndarray  # (n, 4, 4) each joint's frame in its parent's, at zero
    axes: np.ndarray  # (n, 3) unit axis, joint frame
    prismatic: np.ndarray  # (n,) bool
    X_JT: np.ndarray  # (4, 4) tip frame in the last joint's frame
    dofs: np.ndarray  # (d,) indices in the robot's q of the values that drive the chain
    A: np.ndarray  # (n, d)
    b: np.ndarray  # (n,)
    joints: tuple[int, ...] = ()  # (n,) the pinocchio joint ids, root first

    def values(self, q_dofs: np.ndarray) -> np.ndarray:
        """Joint values (B, n) of the chain for ``q_dofs`` (B, d)."""
        return q_dofs @ self.A.T + self.b

    def forward(self, q_dofs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Joint frames (B, n, 4, 4) and tip frames (B, 4, 4) in R for ``q_dofs`` (B, d)."""
        v = self.values(np.atleast_2d(q_dofs))
        B, n = v.shape
        X = np.broadcast_to(self.X_RP, (B, 4, 4))
        frames = np.empty((B, n, 4, 4))
        for i in range(n):
            X = X @ self.placements[i] @ _motion(self.axes[i], self.prismatic[i], v[:, i])
            frames[:, i] = X
        return frames, X @ self.X_JT

    def tip_and_jacobian(self, q_dofs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Tip positions (B, 3) and their Jacobians d p / d q_dofs (B, 3, d), frame R."""
        frames, X_RT = self.forward(q_dofs)
        p = X_RT[:, :3, 3]
        axis_R = np.einsum("bnij,nj->bni", frames[:, :, :3, :3], self.axes)  # (B, n, 3)
        lever = p[:, None, :] - frames[:, :, :3, 3]
        cols = np.where(self.prismatic[None, :, None], axis_R, np.cross(axis_R, lever))  # (B, n, 3)
        return p, np.einsum("bni,nd->bid", cols, self.A)


def _motion(axis: np.ndarray, prismatic: bool, v: np.ndarray) -> np.ndarray:
    """The joint's motion (B, 4, 4) for values ``v`` (B,): a turn about or a slide along ``axis``."""
    M = np.zeros((len(v), 4, 4))
    M[:, 3, 3] = 1.0
    if prismatic:
        M[:, :3, :3] = np.eye(3)
        M[:, :3, 3] = v[:, None] * axis
        return M
    c, s = np.cos(v), np.sin(v)
    K, K2 = _cross_matrices(*axis)
    M[:, :3, :3] = _EYE3 + s[:, None, None] * K + (1 - c)[:, None, None] * K2  # Rodrigues
    return M


_EYE3 = np.eye(3)


@lru_cache(maxsize=256)
def _cross_matrices(x: float, y: float, z: float) -> tuple[np.ndarray, np.ndarray]:
    """The cross-product matrix K of the axis (x, y, z) and K @ K (a finger's IK asks for
    them thousands of times)."""
    K = np.array([[0, -z, y], [z, 0, -x], [-y, x, 0]])
    return K, K @ K


def read_chain(robot: Robot, reference_frame: int, tip_frame: int, dofs: np.ndarray, q: np.ndarray) -> Chain:
    """The chain from pinocchio frame ``reference_frame`` (R) down to ``tip_frame`` (T),
    driven by the robot joints ``dofs``; joints of the chain outside ``dofs`` are held at
    their value in ``q`` (nq,).  Raises ValueError when T does not hang below R's joint."""
    model = robot.model
    root = model.frames[reference_frame].parentJoint
    joints, j = [], model.frames[tip_frame].parentJoint
    while j != root:
        if j == 0:
            raise ValueError(f"frame {model.frames[tip_frame].name} is not below {model.frames[reference_frame].name}")
        joints.append(j)
        j = model.parents[j]
    joints.reverse()
    dofs = np.asarray(dofs, dtype=int)
    column = {int(i): k for k, i in enumerate(dofs)}
    q = robot.coupled(q)
    n = len(joints)
    placements, axes, prismatic = np.empty((n, 4, 4)), np.empty((n, 3)), np.zeros(n, dtype=bool)
    A, b = np.zeros((n, len(dofs))), np.zeros(n)
    for k, j in enumerate(joints):
        jm = model.joints[j]
        placements[k] = model.jointPlacements[j].homogeneous
        jd = jm.createData()
        jm.calc(jd, np.array([1.0, 0.0]) if jm.nq == 2 else np.zeros(1))
        S = np.asarray(jd.S).ravel()  # motion subspace (linear, angular)
        prismatic[k] = np.linalg.norm(S[:3]) > 0.5
        axes[k] = S[:3] if prismatic[k] else S[3:]
        i = j - 1  # our joint index (one DoF per joint, in model order)
        if i in column:
            A[k, column[i]] = 1.0
        elif i in robot.mimic and robot.mimic[i][0] in column:
            leader, mult, offset = robot.mimic[i]
            A[k, column[leader]], b[k] = mult, offset
        else:
            b[k] = q[i]
    X_RP = inverse(model.frames[reference_frame].placement.homogeneous)
    return Chain(X_RP, placements, axes, prismatic, model.frames[tip_frame].placement.homogeneous, dofs, A, b,
                 tuple(joints))


def tip_frames_and_jacobian(chain: Chain, q_dofs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Tip frames (B, 4, 4) and their geometric Jacobians (B, 6, d) (linear rows first,
    then angular; frame R, about the tip's origin) for ``q_dofs`` (B, d)."""
    frames, X_RT = chain.forward(q_dofs)
    axis_R = np.einsum("bnij,nj->bni", frames[:, :, :3, :3], chain.axes)  # (B, n, 3)
    lever = X_RT[:, None, :3, 3] - frames[:, :, :3, 3]
    linear = np.where(chain.prismatic[None, :, None], axis_R, np.cross(axis_R, lever))
    angular = np.where(chain.prismatic[None, :, None], 0.0, axis_R)
    return X_RT, np.einsum("bni,nd->bid", np.concatenate([linear, angular], axis=2), chain.A)


def pose_error(X: np.ndarray, X_target: np.ndarray) -> np.ndarray:
    """Errors (B, 6) from frames X to X_target (both (B, 4, 4), frame R): the position
    difference, then half the sum of the axes' cross products (the rotation vector's
    direction times the sine of the angle: zero only at the target, for angles below pi)."""
    e_p = X_target[:, :3, 3] - X[:, :3, 3]
    e_r = 0.5 * np.cross(X[:, :3, :3], X_target[:, :3, :3], axisa=1, axisb=1, axisc=1).sum(axis=2)
    return np.concatenate([e_p, e_r], axis=1)


def batch_dls(residual, measure, Q0: np.ndarray, lower: np.ndarray, upper: np.ndarray, iterations: int,
              damping: float, stall: float, max_step: float = np.inf) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Damped least squares, every row at once, joints clamped to [``lower``, ``upper``]
    (d,) after each step of at most ``max_step`` per joint.

    ``residual(Q, rows)`` gives the task errors e (b, m) and Jacobians (b, m, d) of the
    rows ``rows`` (b,) of the batch at their joint values Q (b, d); ``measure(e)`` their
    squared error (b,) and whether each has converged (b,).  A row succeeds once it has
    converged and gives up when an iteration does not cut its squared error below
    ``stall`` times the last (against a joint limit or out of reach) or after
    ``iterations``.  Returns the joint values (B, d), the success mask (B,) and the
    Jacobians at the solutions (B, m, d) (zero for the rows that failed)."""
    Q = np.array(Q0, dtype=float)
    B = len(Q)
    ok = np.zeros(B, dtype=bool)
    J_out = None
    live = np.arange(B)
    last = np.full(B, np.inf)
    for _ in range(iterations):
        if not len(live):
            break
        e, J = residual(Q[live], live)
        if J_out is None:
            J_out = np.zeros((B, *J.shape[1:]))
        err, done = measure(e)
        ok[live[done]] = True
        J_out[live[done]] = J[done]
        go = ~done & ~(err > stall * last[live])
        last[live] = err
        live, J, e = live[go], J[go], e[go]
        m = J.shape[1]
        JJt = J @ J.transpose(0, 2, 1)
        JJt[:, np.arange(m), np.arange(m)] += damping
        step = np.einsum("bid,bi->bd", J, np.linalg.solve(JJt, e[..., None])[..., 0])
        if np.isfinite(max_step):
            step = np.clip(step, -max_step, max_step)
        Q[live] = np.clip(Q[live] + step, lower, upper)
    return Q, ok, J_out


def batch_pose_ik(chain: Chain, lower: np.ndarray, upper: np.ndarray, Q0: np.ndarray, X_target: np.ndarray,
                  iterations: int = 60, tol_position: float = 1e-3, tol_rotation: float = 1e-2,
                  damping: float = 1e-4) -> tuple[np.ndarray, np.ndarray]:
    """Damped least squares on the tip pose (:func:`batch_dls`), steps of at most 0.5 rad.

    ``Q0`` (B, d) seeds, ``X_target`` (B, 4, 4) tip poses in R.  A row succeeds once its
    position error is below ``tol_position`` (m) and the sine of its rotation error below
    ``tol_rotation``; it gives up when an iteration does not cut its squared error by
    1 % (stalled against a limit or out of reach) or after ``iterations``.  Returns the
    joint values (B, d) and the success mask (B,)."""
    def residual(Q, rows):
        X, J = tip_frames_and_jacobian(chain, Q)
        return pose_error(X, X_target[rows]), J

    Q, ok, _ = batch_dls(residual, pose_measure(tol_position, tol_rotation), Q0, lower, upper, iterations, damping,
                         0.99, max_step=0.5)
    return Q, ok


def pose_measure(tol_position: float, tol_rotation: float):
    """``measure(e)`` of :func:`batch_dls` for pose errors e (b, 6) (position, then
    rotation): their squared norm (b,) and whether both parts are within tolerance (b,)."""
    def measure(e):
        e_p = np.einsum("bi,bi->b", e[:, :3], e[:, :3])
        e_r = np.einsum("bi,bi->b", e[:, 3:], e[:, 3:])
        return e_p + e_r, (e_p < tol_position**2) & (e_r < tol_rotation**2)
    return measure
