"""A multi-fingered hand whose wrist is fixed in space, holding an object with its
fingertips (seed 003 §IV): the fingers' joints are the robot's only free joints.

A grasping finger touches its contact with its fingertip sphere: the sphere's centre is
``p + r n`` for the contact ``p`` with outward normal ``n`` and the tip radius ``r``, and the
finger's joints follow by inverse kinematics (§IV: "finger configurations are computed
from their inverse geometric models").  The paper restricts each finger to one IK
solution; here IK is warm-started from the previous configuration along a path and the
step is bounded, which keeps one branch.

Frames: the world (robot base) frame W, the object frame O; metres, radians.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from regrasp_cli.model.ik import IKOptions, finger_ik
from regrasp_cli.model.robot import Kinematics, Robot

# Finger IK gives an attempt up after this many iterations without progress: from a seed
# near the answer (the previous step's joints) it converges in 3-14 iterations, and the
# 1 in 10 targets out of reach or past a limit spent 84 % of all iterations (150 each).
IK_PATIENCE = 8


@dataclass(frozen=True)
class InHand:
    """The robot at ``q_fixed`` (its arm and the other hand's joints never move), and the
    fingers of ``hand`` that grasp, in order (default: all)."""

    robot: Robot
    hand: str
    q_fixed: np.ndarray  # (nq,)
    fingers: tuple[int, ...]

    @classmethod
    def of(cls, robot: Robot, hand: str, q_fixed: np.ndarray | None = None) -> "InHand":
        q = robot.q_rest.copy() if q_fixed is None else np.asarray(q_fixed, float).copy()
        return cls(robot, hand, q, tuple(range(len(robot.hands[hand].finger_idx))))

    @property
    def radii(self) -> np.ndarray:
        """(n,) fingertip radii of the grasping fingers, metres."""
        spec = self.robot.hands[self.hand].spec
        return np.array([spec.fingers[f].tip_radius for f in self.fingers])

    def tips(self, kin: Kinematics, q: np.ndarray) -> np.ndarray:
        """(n, 3) world positions of the fingertip sphere centres at ``q``."""
        frames = self.robot.hands[self.hand].tip_frames
        return np.array([kin.fk(q, frames[f])[:3, 3] for f in self.fingers])


def tip_targets(X_WO: np.ndarray, p_O: np.ndarray, n_O: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """(n, 3) world positions where the fingertip centres touch the contacts ``p_O`` (n, 3)
    with outward normals ``n_O`` (n, 3), object frame, when the object is at ``X_WO``."""
    c_O = p_O + radii[:, None] * n_O
    return c_O @ X_WO[:3, :3].T + X_WO[:3, 3]


def reach(h: InHand, q_seed: np.ndarray, targets: np.ndarray, rng: np.random.Generator,
          fingers: tuple[int, ...] | None = None, restarts: int = 3, tol: float = 1e-4,
          kin: Kinematics | None = None, points: np.ndarray | None = None) -> np.ndarray | None:
    """Joint values putting each finger of ``fingers`` (positions in ``h.fingers``; default
    all) at its target (n, 3), the other joints as in ``q_seed``; None when one cannot.
    The fingertip centres reach the targets, or the points ``points`` (n, 3) of the tip
    frames, in their coordinates.  ``kin``: scratch the IK overwrites (a fresh one per
    finger when None)."""
    q = q_seed.copy()
    options = IKOptions(restarts=restarts, tol_position=tol, patience=IK_PATIENCE)
    data = None if kin is None else kin.data
    for k in range(len(h.fingers)) if fingers is None else fingers:
        r = finger_ik(h.robot, h.hand, h.fingers[k], targets[k], q, rng, options, data,
                      None if points is None else points[k])
        if not r.success:
            return None
        q = r.q
    return q
