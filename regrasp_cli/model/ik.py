"""Inverse kinematics: arm to a grasp-frame pose, finger to a fingertip position.

Damped least squares (Levenberg–Marquardt form) on pinocchio's frame Jacobians, with the
joints clamped to their limits after each step and random restarts drawn from an explicit
``np.random.Generator``.  The first attempt starts from the given seed configuration, so a
good seed (e.g. the rest configuration) gives natural solutions.  Used by Saut et al. 2010
§V-C (grasp, exchange and place configurations) and §IV-A-2 (finger IK for contacts).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pinocchio as pin
from scipy.spatial.transform import Rotation

from regrasp_cli.model.chain import batch_dls, batch_pose_ik, pose_measure, read_chain, tip_frames_and_jacobian
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
    patience: int | None = None  # give an attempt up after this many iterations without 1 % less error


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


def _solve(robot: Robot, frames: tuple[int, ...], q_seed: np.ndarray, idx: np.ndarray, rng: np.random.Generator,
           options: IKOptions, residual, reference, rows: slice, data: pin.Data | None = None,
           point: np.ndarray | None = None) -> IKResult:
    """DLS with joint clamping and random restarts on the stacked tasks of ``frames``.
    ``residual(k, X) -> (e, position error, rotation error)`` for frame ``frames[k]`` at
    X, with ``e`` expressed in ``reference``, the frame of the Jacobian rows kept
    (``rows``); the errors reported are the largest over the frames.  ``point`` (3,): the
    task is the position of this point of the (one) frame, in its coordinates, not its
    origin's (world-aligned rows 0-5 are taken and turned into the point's velocity).
    ``data``: scratch to overwrite (a :class:`Kinematics`'s; made afresh when None, ~20-120 us)."""
    model = robot.model
    data = model.createData() if data is None else data
    lo, hi = robot.lower[idx], robot.upper[idx]
    cols = robot._idx_q[idx] if robot._identity else _jacobian_columns(robot, idx)
    best, iters = None, 0
    for attempt in range(options.restarts + 1):
        q = q_seed.copy()
        if attempt:
            q[idx] = rng.uniform(lo, hi)
        least, since = np.inf, 0
        for _ in range(options.max_iters):
            iters += 1
            qp = robot.to_pin(q)
            # a world-aligned Jacobian's pass places the joints of the frame's chain
            # (data.oMi): then no whole-body kinematics pass before it
            if reference != pin.LOCAL_WORLD_ALIGNED:
                pin.forwardKinematics(model, data, qp)
            Js = [pin.computeFrameJacobian(model, data, qp, f, reference)[rows] for f in frames]
            Xs = [pin.updateFramePlacement(model, data, f) for f in frames]
            res = [residual(k, X) for k, X in enumerate(Xs)]
            if point is not None:  # v_p = v - (R p) x w
                Js = [Js[0][:3] - pin.skew(Xs[0].rotation @ point) @ Js[0][3:]]
            ep, er = max(r[1] for r in res), max(r[2] for r in res)
            if ep < options.tol_position and er < options.tol_rotation:
                return IKResult(q, True, ep, er, iters)
            if options.patience is not None:  # stalled against a limit or out of reach
                least, since = (ep + er, 0) if ep + er < 0.99 * least else (least, since + 1)
                if since >= options.patience:
                    break
            e = res[0][0] if len(res) == 1 else np.concatenate([r[0] for r in res])
            J = (Js[0] if len(Js) == 1 else np.vstack(Js))[:, cols]
            # np.minimum/maximum: np.clip's own checks cost as much again here
            dq = np.minimum(np.maximum(_dls(J, e, options.damping), -options.max_step), options.max_step)
            q[idx] = np.minimum(np.maximum(q[idx] + dq, lo), hi)
        if best is None or ep + 0.1 * er < best.position_error + 0.1 * best.rotation_error:
            best = IKResult(q, False, ep, er, iters)
    return IKResult(best.q, False, best.position_error, best.rotation_error, iters)


def _pose_residual(targets: list[pin.SE3]):
    def residual(k: int, X):
        e = pin.log6(X.actInv(targets[k])).vector  # in the local frame
        return e, float(np.linalg.norm(X.translation - targets[k].translation)), float(np.linalg.norm(e[3:]))
    return residual


def solve_pose(robot: Robot, frame: int, X_WT: np.ndarray, q_seed: np.ndarray, idx: np.ndarray,
               rng: np.random.Generator, options: IKOptions = IKOptions()) -> IKResult:
    """Move the joints ``idx`` so that frame ``frame`` reaches the pose ``X_WT`` (4, 4).

    The other joints keep their values from ``q_seed``.  Returns the best attempt; its
    ``success`` says whether both tolerances were met.
    """
    return solve_poses(robot, (frame,), (X_WT,), q_seed, idx, rng, options)


def solve_poses(robot: Robot, frames: tuple[int, ...], X_WTs: tuple[np.ndarray, ...], q_seed: np.ndarray,
                idx: np.ndarray, rng: np.random.Generator, options: IKOptions = IKOptions()) -> IKResult:
    """Move the joints ``idx`` so that each frame of ``frames`` reaches its pose in
    ``X_WTs`` (each (4, 4)) at once: one least-squares problem over the stacked tasks (two
    hands on one object, sharing the torso)."""
    targets = [pin.SE3(X[:3, :3].copy(), X[:3, 3].copy()) for X in X_WTs]
    return _solve(robot, tuple(frames), q_seed, idx, rng, options, _pose_residual(targets), pin.LOCAL, slice(None))


def solve_position(robot: Robot, frame: int, p_WT: np.ndarray, q_seed: np.ndarray, idx: np.ndarray,
                   rng: np.random.Generator, options: IKOptions = IKOptions(),
                   data: pin.Data | None = None, p_F: np.ndarray | None = None) -> IKResult:
    """Move the joints ``idx`` so that the origin of ``frame`` (or its point ``p_F`` (3,),
    in its coordinates) reaches the point ``p_WT`` (3,)."""
    if p_F is None:
        def residual(k: int, X):
            e = p_WT - X.translation
            return e, math.sqrt(e @ e), 0.0  # np.linalg.norm's own sum, without its overhead

        return _solve(robot, (frame,), q_seed, idx, rng, options, residual, pin.LOCAL_WORLD_ALIGNED, slice(0, 3), data)

    def residual_point(k: int, X):
        e = p_WT - X.rotation @ p_F - X.translation
        return e, math.sqrt(e @ e), 0.0

    return _solve(robot, (frame,), q_seed, idx, rng, options, residual_point, pin.LOCAL_WORLD_ALIGNED, slice(0, 6),
                  data, point=np.asarray(p_F, float))


def _jacobian_columns(robot: Robot, idx: np.ndarray) -> list[int]:
    """Columns of a pinocchio Jacobian (over v) for our joints ``idx`` (all have nv = 1)."""
    model = robot.model
    return [model.joints[model.getJointId(robot.joint_names[i])].idx_v for i in idx]


def arm_ik(robot: Robot, hand: str, X_WG: np.ndarray, q_seed: np.ndarray, rng: np.random.Generator,
           with_torso: bool = False, options: IKOptions = IKOptions()) -> IKResult:
    """Arm joints (and the torso's if ``with_torso``) placing the hand's grasp frame G at X_WG."""
    h = robot.hands[hand]
    idx = np.concatenate([robot.groups["torso"], h.arm_idx]) if with_torso else h.arm_idx
    return solve_pose(robot, h.grasp_frame, X_WG, q_seed, idx, rng, options)


def two_arm_ik(robot: Robot, hands: tuple[str, str], X_WGs: tuple[np.ndarray, np.ndarray], q_seed: np.ndarray,
               rng: np.random.Generator, options: IKOptions = IKOptions()) -> IKResult:
    """Torso and both arms placing each hand's grasp frame G at its pose in ``X_WGs`` at
    once (both hands on one object: the CG_r∩CG_l mode)."""
    idx = np.concatenate([robot.groups["torso"], *(robot.hands[h].arm_idx for h in hands)])
    return solve_poses(robot, tuple(robot.hands[h].grasp_frame for h in hands), X_WGs, q_seed, idx, rng, options)


def finger_ik(robot: Robot, hand: str, finger: int, p_WT: np.ndarray, q_seed: np.ndarray,
              rng: np.random.Generator, options: IKOptions = IKOptions(restarts=3),
              data: pin.Data | None = None, p_T: np.ndarray | None = None) -> IKResult:
    """Finger joints placing the centre of the fingertip sphere (or its point ``p_T`` (3,),
    in the tip frame) at ``p_WT`` (3,), metres; ``data``: pinocchio scratch to overwrite
    (made afresh when None)."""
    h = robot.hands[hand]
    return solve_position(robot, h.tip_frames[finger], p_WT, q_seed, h.finger_idx[finger], rng, options, data, p_T)


def arm_reachable(robot: Robot, hand: str, X_WG: np.ndarray, rng: np.random.Generator, seeds: int = 4,
                  options: IKOptions = IKOptions(max_iters=60, tol_position=1e-3, tol_rotation=1e-2),
                  torso: bool = True) -> np.ndarray:
    """Which of the grasp-frame poses X_WG (B, 4, 4) the torso and the hand's arm together
    reach (B,) bool: a necessary condition of any arm IK of the hand, the torso fixed or
    leaning, checked for all poses at once by a batched DLS (:func:`.chain.batch_pose_ik`)
    from the rest configuration and ``seeds`` random postures (drawn from ``rng``), the
    other joints at rest.  Without ``torso``, the arm alone, the torso at rest.  Being a
    local method from a few seeds it can miss a reachable pose (1 grasp in 9 found by the
    full search on the default scene): it orders and prunes candidates before the costly
    search, it does not certify."""
    h = robot.hands[hand]
    dofs = np.concatenate([robot.groups["torso"], h.arm_idx]) if torso else np.asarray(h.arm_idx)
    chain = read_chain(robot, 0, h.grasp_frame, dofs, robot.q_rest)
    lo, hi = robot.lower[dofs], robot.upper[dofs]
    B = len(X_WG)
    Q0 = np.concatenate([np.tile(robot.q_rest[dofs], (B, 1)), rng.uniform(lo, hi, (seeds * B, len(dofs)))])
    _, ok = batch_pose_ik(chain, lo, hi, Q0, np.tile(X_WG, (seeds + 1, 1, 1)), options.max_iters,
                          options.tol_position, options.tol_rotation, options.damping)
    return ok.reshape(seeds + 1, B).any(axis=0)


def arm_ik_batch(robot: Robot, hand: str, X_WG: np.ndarray, Q_seed: np.ndarray, rng: np.random.Generator,
                 with_torso: bool = False, options: IKOptions = IKOptions()) -> tuple[np.ndarray, np.ndarray]:
    """:func:`arm_ik` of every pose X_WG[i] (B, 4, 4) from the configuration Q_seed[i]
    (B, nq), all at once (batched DLS on :mod:`.chain`): the arm's joints move (and the
    torso's with ``with_torso``), the others keep their seed values; the first attempt
    from the seed, then ``options.restarts`` from random values of the moving joints, to
    the same tolerances.  Returns (B, nq) configurations (the seed where none converged)
    and (B,) success, the first attempt that converged kept."""
    h = robot.hands[hand]
    torso, arm = np.asarray(robot.groups["torso"], dtype=int), np.asarray(h.arm_idx, dtype=int)
    dofs = np.concatenate([torso, arm])
    cols = np.arange(len(dofs)) if with_torso else np.arange(len(torso), len(dofs))  # moving, within dofs
    moving = dofs[cols]
    chain = read_chain(robot, 0, h.grasp_frame, dofs, robot.q_rest)
    lo, hi = robot.lower[moving], robot.upper[moving]
    B, tries = len(X_WG), options.restarts + 1
    fixed = np.tile(Q_seed[:, dofs], (tries, 1))
    Q0 = np.concatenate([Q_seed[:, moving], rng.uniform(lo, hi, ((tries - 1) * B, len(moving)))])
    targets = np.tile(X_WG, (tries, 1, 1))

    def residual(Q, rows):
        full = fixed[rows].copy()
        full[:, cols] = Q
        X, J = tip_frames_and_jacobian(chain, full)
        # the rotation error as a rotation vector (log map, frame W), as pinocchio's log6
        # in arm_ik: the sine of chain.pose_error steers large errors another way
        e_r = Rotation.from_matrix(targets[rows, :3, :3] @ X[:, :3, :3].transpose(0, 2, 1)).as_rotvec()
        return np.concatenate([targets[rows, :3, 3] - X[:, :3, 3], e_r], axis=1), J[:, :, cols]

    # no give-up on a stall (as arm_ik): a seed that stalls a while would lose to a contorted restart
    Q, ok, _ = batch_dls(residual, pose_measure(options.tol_position, options.tol_rotation), Q0, lo, hi,
                         options.max_iters, options.damping, np.inf, options.max_step)
    ok = ok.reshape(tries, B)
    first = np.argmax(ok, axis=0)  # the first attempt that converged (0 when none did)
    found = ok.any(axis=0)
    out = np.array(Q_seed, dtype=float)
    out[np.ix_(found, moving)] = Q.reshape(tries, B, -1)[first, np.arange(B)][found]
    return out, found
