"""A plan replayed: what it refers to, loaded and checked, and where the object is at
every moment.  Shared by `regrasp validate` (which checks the motion) and `regrasp show`
(which draws it); neither trusts the planner.

:func:`load_inputs` reloads the robot, object and obstacles a plan names, refusing stale
files by their SHA-256.  :func:`follow` tells where the object is in each phase, from the
phase's kind, holding and placement only (never its name): at rest it lies at the phase's
placement; held, it moves with the first holding hand, ``X_WO = X_WG(q) @ X_GO`` with X_GO
fixed where the phase starts (the object's pose at the end of the previous phase).

Poses are 4x4 in the robot base frame W (m); configurations (nq,) in the plan's order.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import trimesh

from regrasp_cli.config import SHAPES, ObstacleSpec
from regrasp_cli.errors import InputError, StaleArtefactError, shown
from regrasp_cli.model.collision import CollisionOptions
from regrasp_cli.model.objects import load_object_mesh
from regrasp_cli.model.robot import Kinematics, Robot, load_robot
from regrasp_cli.spatial import inverse, segment_poses
from regrasp_cli.store import sha256_file
from regrasp_cli.trajectory import MAX_MAGNITUDE, Plan

JOINT_TOL = 1e-9  # rad or m: limits of the plan against the URDF's

@dataclass(frozen=True)
class Contacts:
    """A grasp's contacts in the object frame O."""

    fingers: tuple[str, ...]  # (k,) finger names
    points: np.ndarray  # (k, 3) m
    normals: np.ndarray  # (k, 3) outward, as recorded (unit not guaranteed)


@dataclass(frozen=True)
class Inputs:
    """What a plan refers to, loaded and checked against the recorded hashes."""

    robot: Robot
    mesh: trimesh.Trimesh  # object, frame O, m
    friction: float
    obstacles: tuple[ObstacleSpec, ...]
    disabled: tuple[tuple[str, str], ...]
    options: CollisionOptions
    lower: np.ndarray  # (nq,) the tighter of the plan's and the URDF's limits
    upper: np.ndarray
    velocity: np.ndarray  # (nq,) > 0, the plan's
    acceleration: np.ndarray
    contacts: dict[str, Contacts]  # per plan grasp id
    notes: tuple[str, ...]  # what is doubtful but not malformed (the validator reports it)


def _get(file: Path, d: Any, key: str, where: str, kind: type | tuple[type, ...]) -> Any:
    if not isinstance(d, dict) or key not in d:
        raise InputError(file, where + key, "missing")
    v = d[key]
    kinds = kind if isinstance(kind, tuple) else (kind,)
    if not isinstance(v, kinds) or (isinstance(v, bool) and bool not in kinds):
        raise InputError(file, where + key, f"expected {'/'.join(k.__name__ for k in kinds)}, found {type(v).__name__}")
    return v


def _array(file: Path, v: Any, where: str, shape: tuple[int, ...]) -> np.ndarray:
    try:
        a = np.asarray(v, dtype=float)
    except (TypeError, ValueError):
        a = None
    if a is None or a.shape != shape or not np.all(np.isfinite(a)) or np.abs(a).max(initial=0.0) > MAX_MAGNITUDE:
        raise InputError(file, where, f"expected finite numbers within +-{MAX_MAGNITUDE:g} of shape {shape}")
    return a


def _pose(file: Path, v: Any, where: str) -> np.ndarray:
    """A 4x4 rigid transform, or InputError."""
    X = _array(file, v, where, (4, 4))
    R = X[:3, :3]
    if not (np.allclose(R.T @ R, np.eye(3), atol=1e-6) and np.linalg.det(R) > 0
            and np.allclose(X[3], [0, 0, 0, 1])):
        raise InputError(file, where, "expected a rigid transform (rotation block orthonormal, last row 0 0 0 1)")
    return X


def _path(file: Path, value: Any, where: str) -> Path:
    """A file named by the plan, relative to the plan's directory unless absolute."""
    if not isinstance(value, str) or not value:
        raise InputError(file, where, "expected a file path")
    p = Path(value) if Path(value).is_absolute() else file.parent / value
    if not p.is_file():
        raise InputError(file, where, f"no such file: {p}")
    return p.resolve()


def _fresh(file: Path, path: Path, where: str, recorded: Any) -> None:
    now = sha256_file(path)
    if now != recorded:
        raise StaleArtefactError(file, where, f"stale plan: {path} changed since planning (sha256 "
                                              f"{str(recorded)[:12]}... recorded, {now[:12]}... now); plan again")


def _contacts(file: Path, plan: Plan, robot: Robot) -> dict[str, Contacts]:
    out = {}
    for i, g in enumerate(plan.grasps):
        if g.hand not in robot.hands:
            raise InputError(file, f"grasps[{i}].hand", f"unknown hand {shown(g.hand)}; the robot has "
                                                        f"{', '.join(robot.hands)}")
        _pose(file, g.X_OG, f"grasps[{i}].hand_in_object")
        fingers, points, normals = [], [], []
        for j, c in enumerate(g.contacts):
            w = f"grasps[{i}].contacts[{j}]."
            fingers.append(_get(file, c, "finger", w, str))
            points.append(_array(file, _get(file, c, "point", w, list), w + "point", (3,)))
            normals.append(_array(file, _get(file, c, "normal", w, list), w + "normal", (3,)))
        out[g.id] = Contacts(tuple(fingers), np.reshape(points, (-1, 3)), np.reshape(normals, (-1, 3)))
    return out


def _obstacle(file: Path, d: Any, i: int) -> ObstacleSpec:
    w = f"obstacles[{i}]."
    shape = _get(file, d, "shape", w, str)
    if shape not in SHAPES:
        raise InputError(file, w + "shape", f"expected one of {', '.join(SHAPES)}, found {shown(shape)}")
    n = {"box": 3, "cylinder": 2, "sphere": 1, "mesh": 1}[shape]
    size = _array(file, _get(file, d, "size", w, list), w + "size", (n,))
    if np.any(size <= 0):
        raise InputError(file, w + "size", f"expected sizes > 0, found {size.tolist()}")
    mesh = None
    if shape == "mesh":  # loaded here too, so that a bad file is reported against the plan
        mesh = _path(file, d.get("mesh"), w + "mesh")
        load_object_mesh(str(mesh), base_dir=mesh.parent, scale=float(size[0]), file=str(file), field=w + "mesh")
    return ObstacleSpec(_get(file, d, "name", w, str), shape, tuple(size.tolist()),
                        _pose(file, _get(file, d, "pose", w, list), w + "pose"), mesh)


def load_inputs(plan: Plan, file: Path) -> Inputs:
    """Load what ``plan`` (read from ``file``) refers to; InputError when missing,
    malformed or stale (the scene, robot or object changed since planning)."""
    scene = _path(file, _get(file, plan.scene, "file", "scene.", str), "scene.file")
    _fresh(file, scene, "scene.file", _get(file, plan.scene, "sha256", "scene.", str))
    urdf = _path(file, _get(file, plan.robot, "urdf", "robot.", str), "robot.urdf")
    robot_yaml = _path(file, _get(file, plan.robot, "robot_yaml", "robot.", str), "robot.robot_yaml")
    urdf_sha = _get(file, plan.robot, "urdf_sha256", "robot.", str)
    _fresh(file, urdf, "robot.urdf", urdf_sha)
    _fresh(file, robot_yaml, "robot.robot_yaml", _get(file, plan.robot, "robot_yaml_sha256", "robot.", str))
    robot = load_robot(robot_yaml)
    if robot.urdf_sha256 != urdf_sha:
        raise StaleArtefactError(file, "robot.urdf", f"stale plan: {robot_yaml} now uses {robot.spec.urdf}, "
                                                     "not the URDF the plan was made for; plan again")
    if plan.joint_names != robot.joint_names:
        i = next((i for i, (a, b) in enumerate(zip(plan.joint_names, robot.joint_names)) if a != b),
                 min(len(plan.joint_names), robot.nq))
        raise InputError(file, "joint_names", f"expected the robot's {robot.nq} actuated joints in its order; "
                                              f"they differ from index {i}")

    nq, issues = robot.nq, []
    lim = {k: _array(file, _get(file, plan.limits, k, "limits.", list), f"limits.{k}", (nq,))
           for k in ("lower", "upper", "velocity", "acceleration")}
    for k in ("velocity", "acceleration"):
        if np.any(lim[k] <= 0):
            raise InputError(file, f"limits.{k}", "expected numbers > 0")
    wider = (lim["lower"] < robot.lower - JOINT_TOL) | (lim["upper"] > robot.upper + JOINT_TOL)
    faster = lim["velocity"] > robot.velocity * (1 + 1e-9)
    for i in np.flatnonzero(wider | faster):
        what = "position limits are wider" if wider[i] else "velocity limit is higher"
        issues.append(f"joint {robot.joint_names[i]}: the plan's {what} than the URDF's")

    obj = plan.object
    mesh_path = _path(file, _get(file, obj, "mesh", "object.", str), "object.mesh")
    _fresh(file, mesh_path, "object.mesh", _get(file, obj, "sha256", "object.", str))
    mesh = load_object_mesh(str(mesh_path), base_dir=mesh_path.parent, file=str(file), field="object.mesh").mesh
    friction = float(_get(file, obj, "friction", "object.", (int, float)))
    if not math.isfinite(friction) or friction < 0:
        raise InputError(file, "object.friction", f"expected a number >= 0, found {friction}")

    col = plan.collision
    tol = {k: float(_get(file, col, k, "collision.", (int, float))) for k in ("contact_tolerance", "support_tolerance")}
    if not all(math.isfinite(v) and v >= 0 for v in tol.values()):
        raise InputError(file, "collision", "expected tolerances >= 0 (m)")
    pairs = _get(file, col, "disabled_pairs", "collision.", list)
    if not all(isinstance(p, list) and len(p) == 2 and all(isinstance(s, str) for s in p) for p in pairs):
        raise InputError(file, "collision.disabled_pairs", "expected a list of [link_a, link_b]")

    for i, p in enumerate(plan.placements):
        _pose(file, p.X_WO, f"placements[{i}].pose")
    for i, p in enumerate(plan.phases):
        for role in ("holding", "touching"):
            for h in getattr(p, role):
                if not isinstance(h, str) or h not in robot.hands:
                    raise InputError(file, f"phases[{i}].{role}", f"unknown hand {shown(h)}; the robot has "
                                                                  f"{', '.join(robot.hands)}")
        if p.object_poses is not None:
            for k, X in enumerate(p.object_poses):
                _pose(file, X, f"phases[{i}].object_poses[{k}]")

    return Inputs(robot, mesh, friction, tuple(_obstacle(file, d, i) for i, d in enumerate(plan.obstacles)),
                  tuple(tuple(p) for p in pairs), CollisionOptions(**tol),
                  np.maximum(lim["lower"], robot.lower), np.minimum(lim["upper"], robot.upper),
                  lim["velocity"], lim["acceleration"], _contacts(file, plan, robot), tuple(issues))


@dataclass(frozen=True)
class Carry:
    """Where the object is during a phase: static at X_PO = X_WO (``hand`` None), or held
    by ``hand`` at X_PO = X_GO (object in that hand's grasp frame G)."""

    hand: str | None
    X_PO: np.ndarray  # (4, 4)

    def X_WO(self, kin: Kinematics, q: np.ndarray) -> np.ndarray:
        if self.hand is None:
            return self.X_PO
        return kin.fk(q, kin.robot.hands[self.hand].grasp_frame) @ self.X_PO


@dataclass(frozen=True)
class InHandCarry:
    """The object moved by the fingers (an in-hand phase): its pose X_WO given at each
    waypoint, ``poses`` (k, 4, 4), between them interpolated as the joints are along the
    straight segments of ``waypoints`` (k, nq)."""

    waypoints: np.ndarray
    poses: np.ndarray

    def X_WO(self, kin: Kinematics, q: np.ndarray) -> np.ndarray:
        """The pose at the point of the waypoint segments nearest ``q`` (nq,), at that
        fraction s of its segment: the position linear, the rotation the slerp
        (:func:`.spatial.segment_poses`, as the validator and the export move it)."""
        if len(self.waypoints) == 1:
            return self.poses[0]
        a, d = self.waypoints[:-1], np.diff(self.waypoints, axis=0)
        dd = np.einsum("ij,ij->i", d, d)
        s = np.clip(np.einsum("ij,ij->i", q - a, d) / np.where(dd > 0, dd, 1.0), 0.0, 1.0)
        j = int(np.argmin(np.linalg.norm(a + s[:, None] * d - q, axis=1)))
        return segment_poses(self.poses[j], self.poses[j + 1], s[j:j + 1])[0]


def carry_of(file: Path, plan: Plan, k: int, kin: Kinematics, X_WO: np.ndarray) -> Carry | InHandCarry:
    """How the object moves in phase ``k`` given its pose X_WO (4, 4) at the end of the
    previous phase (or the start placement): at the phase's placement when it rests, with
    the first holding hand (by name order) when held, as its ``object_poses`` say in an
    in-hand phase (InputError when it has none)."""
    phase = plan.phases[k]
    if phase.kind.inhand:
        if phase.object_poses is None:
            raise InputError(file, f"phases[{k}].object_poses", f"expected the object's pose at each waypoint of "
                                                                f"a {phase.kind.value} phase")
        return InHandCarry(np.asarray(phase.waypoints, float), np.asarray(phase.object_poses, float))
    if phase.placement is not None:
        return Carry(None, plan.placement(phase.placement).X_WO)
    hand = sorted(phase.holding)[0]
    return Carry(hand, inverse(kin.fk(phase.waypoints[0], kin.robot.hands[hand].grasp_frame)) @ X_WO)


def follow(file: Path, plan: Plan, kin: Kinematics) -> tuple[list[Carry], list[tuple[np.ndarray, np.ndarray]]]:
    """Per phase, its :class:`Carry` and the object's pose (X_WO at its first waypoint,
    X_WO at its last), starting from the ``start`` placement."""
    X_WO = plan.placement("start").X_WO
    carries, poses = [], []
    for k, phase in enumerate(plan.phases):
        carry = carry_of(file, plan, k, kin, X_WO)
        X_first = carry.X_WO(kin, phase.waypoints[0])
        X_WO = carry.X_WO(kin, phase.waypoints[-1])
        carries.append(carry)
        poses.append((X_first, X_WO))
    return carries, poses
