"""Can an arm reach an object pose?  A quick kinematic test for `regrasp info`.

The grasp frame G is placed at the centre of the object's bounding box with its approach
axis z_G along each of the directions of a cube grid that does not come from below the
object (a support is under it), with two rolls about z_G; arm (+ torso) IK from the rest
configuration, then a collision check of the robot against itself and the static
obstacles (the object itself is ignored: the fingers would wrap it).  This is the test
behind Saut et al. 2010 §III's premise that q_o^i is reachable by one arm only and q_o^f
by the other.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from regrasp_cli.model.collision import CollisionWorld
from regrasp_cli.model.ik import IKOptions, arm_ik, solve_position
from regrasp_cli.model.robot import Robot


@dataclass(frozen=True)
class Reach:
    hand: str
    orientations_tried: int
    ik_solutions: int  # orientations with an IK solution
    collision_free: int  # of those, collision-free against self and obstacles
    q: np.ndarray | None  # one collision-free solution, if any

    @property
    def reachable(self) -> bool:
        return self.collision_free > 0


def approach_frames(p_W: np.ndarray) -> list[np.ndarray]:
    """Grasp frames X_WG at ``p_W`` (3,) with z_G along cube-grid directions not pointing up
    (an approach from below would go through the support), two rolls each."""
    frames = []
    for d in itertools.product((-1, 0, 1), repeat=3):
        z = np.array(d, dtype=float)
        if not z.any() or z[2] > 0:
            continue
        z /= np.linalg.norm(z)
        helper = np.array([0.0, 0.0, 1.0]) if abs(z[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
        x = np.cross(helper, z)
        x /= np.linalg.norm(x)
        for roll in (0.0, np.pi / 2):
            xr = np.cos(roll) * x + np.sin(roll) * np.cross(z, x)
            X = np.eye(4)
            X[:3, :3] = np.column_stack([xr, np.cross(z, xr), z])
            X[:3, 3] = p_W
            frames.append(X)
    return frames


def reach(robot: Robot, world: CollisionWorld, hand: str, p_W: np.ndarray, rng: np.random.Generator,
          q_seed: np.ndarray | None = None, attempts: int = 6) -> Reach:
    """Try every approach frame at ``p_W`` with up to ``attempts`` IK seeds each."""
    q0 = robot.q_rest if q_seed is None else q_seed
    h = robot.hands[hand]
    frames = approach_frames(p_W)
    idx = np.concatenate([robot.groups["torso"], h.arm_idx])
    # Position first: if the grasp frame cannot even get there, no orientation will.
    pos = solve_position(robot, h.grasp_frame, p_W, q0, idx, rng, IKOptions(restarts=8))
    if not pos.success:
        return Reach(hand, len(frames), 0, 0, None)
    n_ik = n_free = 0
    found = None
    for X in frames:
        solved = free = False
        for attempt in range(attempts):  # IK solutions differ by seed; some collide
            seed = pos.q if attempt == 0 else robot.sample(rng, idx, base=pos.q)
            res = arm_ik(robot, hand, X, seed, rng, with_torso=True, options=IKOptions(restarts=0))
            if res.success:
                solved = True
                if world.is_free(res.q):
                    free = True
                    found = res.q if found is None else found
                    break
        n_ik += solved
        n_free += free
    return Reach(hand, len(frames), n_ik, n_free, found)
