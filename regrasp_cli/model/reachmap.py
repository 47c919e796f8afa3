"""Where each arm's hand gets to, and from which directions: the reachable workspace of a
hand's grasp frame G as a voxel map, computed once per robot and cached.

Saut et al. 2010 (§V-C, Fig. 6) place the object's exchange position on a grid near the
wrists and the object's start and goal; on a robot whose arms meet far from where they
rest (PR2: 0.45 m in front of the base they cannot) most of that grid is out of reach of
one arm or the other.  The map tells where both arms reach and with which approach
directions, so that the exchange search looks there (:mod:`manip.tasks.handover`).

Built by sampling: ``samples`` configurations of the torso and the hand's arm drawn
uniformly within the joint limits (the other joints at rest), their grasp frames by
batched forward kinematics (:mod:`model.chain`), binned into cubes of ``voxel`` m in the
robot base frame W; each cube records, as a bit mask, which of the 26 directions of
:data:`DIRECTIONS` the hand's approach axis (wrist to G, :func:`approach_axis`) pointed
nearest to.  Kinematics only: a sample's arm may pass through the robot's own body, and a
direction missing from a cube may still be reached (sampling is finite); the map ranks
and prunes candidates, the arm IK and the collision checks decide.
"""

from __future__ import annotations

import itertools
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from regrasp_cli.model.chain import read_chain
from regrasp_cli.model.robot import Robot
from regrasp_cli.store import Provenance, is_fresh, read_artefact, robot_identity, sha256_params, write_artefact

FORMAT, FORMAT_VERSION = "regrasp.reach", 1
DIRECTIONS = np.array([d for d in itertools.product((-1, 0, 1), repeat=3) if any(d)], dtype=float)
DIRECTIONS /= np.linalg.norm(DIRECTIONS, axis=1, keepdims=True)  # (26, 3) unit, the cube grid's
_CHUNK = 50_000  # configurations per batch of forward kinematics (memory ~ 60 MB)


@dataclass(frozen=True)
class ReachOptions:
    samples: int = 400_000  # torso + arm configurations drawn per hand
    voxel: float = 0.05  # m, cube edge
    seed: int = 0


@dataclass(frozen=True)
class ReachMap:
    """Cubes of ``voxel`` m from ``origin`` (3,) (frame W), ``masks`` (nx, ny, nz) uint32:
    bit i set when the hand's approach axis was seen nearest to DIRECTIONS[i] with G in
    that cube; 0 where G never was."""

    hand: str
    origin: np.ndarray
    voxel: float
    masks: np.ndarray

    def cells(self, p_W: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(k, 3) int cube indices of the points p_W (k, 3) and (k,) bool: inside the map."""
        c = np.floor((np.asarray(p_W, float) - self.origin) / self.voxel).astype(int)
        inside = np.all((c >= 0) & (c < np.array(self.masks.shape)), axis=1)
        return np.where(inside[:, None], c, 0), inside

    def mask(self, p_W: np.ndarray) -> np.ndarray:
        """(k,) uint32: the directions seen in the cube of each point p_W (k, 3)."""
        c, inside = self.cells(p_W)
        return np.where(inside, self.masks[c[:, 0], c[:, 1], c[:, 2]], 0).astype(np.uint32)

    def reaches(self, p_W: np.ndarray, a_W: np.ndarray | None = None, cone: float = np.radians(50)) -> np.ndarray:
        """(k,) bool: G was seen in the cube of each point p_W (k, 3), and, with ``a_W``
        (k, 3) unit approach directions, pointing within ``cone`` rad of it (one of the
        cube's directions there)."""
        m = self.mask(p_W)
        if a_W is None:
            return m > 0
        near = (np.asarray(a_W, float) @ DIRECTIONS.T) >= np.cos(cone)  # (k, 26)
        bits = (near * (1 << np.arange(len(DIRECTIONS), dtype=np.int64))).sum(axis=1)
        return (m.astype(np.int64) & bits) != 0

    def centres(self) -> np.ndarray:
        """(m, 3) centres of the cubes G was seen in, frame W."""
        return (np.argwhere(self.masks > 0) + 0.5) * self.voxel + self.origin


def approach_axis(robot: Robot, hand: str) -> np.ndarray:
    """Unit vector (3,) in the grasp frame G from the wrist (the joint carrying G) to G."""
    X_JG = robot.model.frames[robot.hands[hand].grasp_frame].placement.homogeneous
    a = X_JG[:3, :3].T @ X_JG[:3, 3]
    n = np.linalg.norm(a)
    return a / n if n > 1e-9 else np.array([0.0, 0.0, 1.0])


def arm_dofs(robot: Robot, hand: str) -> np.ndarray:
    """Indices in q of the joints a reach map samples: the torso's, then the hand's arm's."""
    return np.concatenate([robot.groups["torso"], robot.hands[hand].arm_idx]).astype(int)


def reach_map_of(robot: Robot, hand: str, Q: np.ndarray, voxel: float) -> ReachMap:
    """The map of the configurations Q (B, d) of :func:`arm_dofs` (the other joints at rest)."""
    h = robot.hands[hand]
    chain = read_chain(robot, 0, h.grasp_frame, arm_dofs(robot, hand), robot.q_rest)
    a_G = approach_axis(robot, hand)
    points, bins = [], []
    for start in range(0, len(Q), _CHUNK):
        _, X = chain.forward(Q[start:start + _CHUNK])
        points.append(X[:, :3, 3])
        bins.append(np.argmax((X[:, :3, :3] @ a_G) @ DIRECTIONS.T, axis=1))
    p, b = np.concatenate(points), np.concatenate(bins)
    origin = np.floor(p.min(axis=0) / voxel) * voxel
    c = np.floor((p - origin) / voxel).astype(int)
    masks = np.zeros(c.max(axis=0) + 1, dtype=np.uint32)
    np.bitwise_or.at(masks, (c[:, 0], c[:, 1], c[:, 2]), (np.uint32(1) << b.astype(np.uint32)))
    return ReachMap(hand, origin, voxel, masks)


def build_reach_map(robot: Robot, hand: str, options: ReachOptions = ReachOptions()) -> ReachMap:
    """The map of the module docstring, from ``options.samples`` configurations drawn
    uniformly within the joint limits."""
    dofs = arm_dofs(robot, hand)
    rng = np.random.default_rng([options.seed, 41, ("right", "left").index(hand)])
    Q = rng.uniform(robot.lower[dofs], robot.upper[dofs], (options.samples, len(dofs)))
    return reach_map_of(robot, hand, Q, options.voxel)


def reach_map(robot: Robot, hand: str, cache_dir: Path | None = None,
              options: ReachOptions = ReachOptions()) -> ReachMap:
    """The hand's map, read from ``cache_dir/reach/`` or built (seconds) and written there.

    It depends on the URDF, the hand's grasp frame and arm, the torso joints, the rest
    configuration (the joints not sampled) and ``options``: not on any scene."""
    h = robot.hands[hand]
    inputs = {"urdf": robot.urdf_sha256,
              "robot": sha256_params({"hand": hand, "grasp_frame": int(h.grasp_frame),
                                      "dofs": [robot.joint_names[i] for i in arm_dofs(robot, hand)],
                                      "rest": np.round(robot.q_rest, 12).tolist()}),
              "params": sha256_params(asdict(options))}
    expected = Provenance(FORMAT, FORMAT_VERSION, inputs)
    path = None if cache_dir is None else \
        Path(cache_dir) / "reach" / f"{robot_identity(robot)}-{hand}-{sha256_params(inputs)[:12]}.h5"
    if path is not None and path.is_file() and is_fresh(path, expected):
        a = read_artefact(path, expected)
        return ReachMap(hand, a["origin"], float(a.attrs["voxel"]), a["masks"])
    m = build_reach_map(robot, hand, options)
    if path is not None:
        write_artefact(path, expected, {"origin": m.origin, "masks": m.masks}, {"voxel": m.voxel})
    return m
