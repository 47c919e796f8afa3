"""Inverse kinematics: arm to a grasp-frame pose, finger to a fingertip position.

Damped least squares (Levenberg–Marquardt form) on pinocchio's frame Jacobians, with the
joints clamped to their limits after each step and random restarts drawn from an explicit
``np.random.Generator``.  The first attempt starts from the given seed configuration, so a
good seed (e.g. the rest configuration) gives natural solutions.  Used by Saut et al. 2010
§V-C (grasp, exchange and place configurations) and §IV-A-2 (finger IK for contacts).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from regrasp_cli.model.robot import Robot


@dataclass(frozen=True)
class IKOptions:
    """Tolerances in m and rad; ``damping`` is the DLS lambda^2; ``restarts`` counts the
    random restarts after the first attempt from the seed."""

    max_iters: int = 150
    tol_position: float = 1e-4
    tol_rotation: float = 1e-3
    damping: float = 1e-4
    max_step: float = 0.5  # rad (or m) per joint per iteration
    restarts: int = 20


@dataclass(frozen=True)
class IKResult:
    q: np.ndarray  # (nq,) full configuration (best found)
    success: bool
    position_error: float  # m
    rotation_error: float  # rad
    iterations: int  # total over all attempts


def _dls(J: np.ndarray, e: np.ndarray, damping: float) -> np.ndarray:
    JJt = J @ J.T
    JJt.flat[::len(JJt) + 1] += damping
    return J.T @ np.linalg.solve(JJt, e)


def _solve(robot: Robot, frame: int, q_seed: np.ndarray, idx: np.ndarray, rng: np.random.Generator,
           options: IKOptions, residual, reference, rows: slice) -> IKResult:
    """DLS with joint clamping and random restarts.  ``residual(X) -> (e, position error,
    rotation error)`` with ``e`` expressed in ``reference``, the frame of the Jacobian
    rows kept (``rows``)."""
    model, data = robot.model, robot.model.createData()
    lo, hi = robot.lower[idx], robot.upper[idx]
    best, iters = None, 0
    for attempt in range(options.restarts + 1):
        q = q_seed.copy()
        if attempt:
            q[idx] = rng.uniform(lo, hi)
        for _ in range(options.max_iters):
            iters += 1
            qp = robot.to_pin(q)
            pin.forwardKinematics(model, data, qp)
            e, ep, er = residual(pin.updateFramePlacement(model, data, frame))
            if ep < options.tol_position and er < options.tol_rotation:
                return IKResult(q, True, ep, er, iters)
            J = pin.computeFrameJacobian(model, data, qp, frame, reference)[rows]
            J = J[:, robot._idx_q[idx]] if robot._identity else _jacobian_columns(robot, J, idx)
            dq = np.clip(_dls(J, e, options.damping), -options.max_step, options.max_step)
            q[idx] = np.clip(q[idx] + dq, lo, hi)
        if best is None or ep + 0.1 * er < best.position_error + 0.1 * best.rotation_error:
            best = IKResult(q, False, ep, er, iters)
    return IKResult(best.q, False, best.position_error, best.rotation_error, iters)


def solve_pose(robot: Robot, frame: int, X_WT: np.ndarray, q_seed: np.ndarray, idx: np.ndarray,
               rng: np.random.Generator, options: IKOptions = IKOptions()) -> IKResult:
    """Move the joints ``idx`` so that frame ``frame`` reaches the pose ``X_WT`` (4, 4).

    The other joints keep their values from ``q_seed``.  Returns the best attempt; its
    ``success`` says whether both tolerances were met.
    """
    target = pin.SE3(X_WT[:3, :3].copy(), X_WT[:3, 3].copy())

    def residual(X):
        e = pin.log6(X.actInv(target)).vector  # in the local frame
        return e, float(np.linalg.norm(X.translation - target.translation)), float(np.linalg.norm(e[3:]))

    return _solve(robot, frame, q_seed, idx, rng, options, residual, pin.LOCAL, slice(None))


def solve_position(robot: Robot, frame: int, p_WT: np.ndarray, q_seed: np.ndarray, idx: np.ndarray,
                   rng: np.random.Generator, options: IKOptions = IKOptions()) -> IKResult:
    """Move the joints ``idx`` so that the origin of ``frame`` reaches the point ``p_WT`` (3,)."""

    def residual(X):
        e = p_WT - X.translation
        return e, float(np.linalg.norm(e)), 0.0

    return _solve(robot, frame, q_seed, idx, rng, options, residual, pin.LOCAL_WORLD_ALIGNED, slice(0, 3))


def _jacobian_columns(robot: Robot, J: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """Columns of a pinocchio Jacobian (over v) for our joints ``idx`` (all have nv = 1)."""
    model = robot.model
    cols = [model.joints[model.getJointId(robot.joint_names[i])].idx_v for i in idx]
    return J[:, cols]


def arm_ik(robot: Robot, hand: str, X_WG: np.ndarray, q_seed: np.ndarray, rng: np.random.Generator,
           with_torso: bool = False, options: IKOptions = IKOptions()) -> IKResult:
    """Arm joints (and the torso's if ``with_torso``) placing the hand's grasp frame G at X_WG."""
    h = robot.hands[hand]
    idx = np.concatenate([robot.groups["torso"], h.arm_idx]) if with_torso else h.arm_idx
    return solve_pose(robot, h.grasp_frame, X_WG, q_seed, idx, rng, options)


def finger_ik(robot: Robot, hand: str, finger: int, p_WT: np.ndarray, q_seed: np.ndarray,
              rng: np.random.Generator, options: IKOptions = IKOptions(restarts=3)) -> IKResult:
    """Finger joints placing the centre of the fingertip sphere at ``p_WT`` (3,), metres."""
    h = robot.hands[hand]
    return solve_position(robot, h.tip_frames[finger], p_WT, q_seed, h.finger_idx[finger], rng, options)
