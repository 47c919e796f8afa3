"""Independent checker of a plan JSON (``regrasp.plan/1``, :mod:`regrasp_cli.trajectory`).

It trusts nothing the planner computed: it reloads the robot, object and obstacles the plan
names (refusing stale files by their SHA-256) and re-checks the motion:

* **continuity**: each phase starts where the previous one ended;
* **timing**: times start at 0, never decrease, join up between phases, and give every
  straight segment at least its minimal stop-to-stop duration (:mod:`plan.timing`);
* **limits**: joint position limits at the waypoints (segments are straight in joint
  space, so the end points bound them);
* **attachment**: the object's world pose X_WO, followed through the phases, is where the
  holding hand's grasp says it is, the holding fingers stay closed, and the object ends at
  the exchange pose (after ``carry``) and at the goal;
* **grasp**: contacts on the object surface, normals along the surface normal, force
  closure (Saut et al. 2010, §IV-A-3), fingertip spheres on their contacts when the hand
  takes the object;
* **collision**: every segment sampled finely enough that no joint moves more than
  ``resolution`` and no robot point more than ``cartesian_step`` between samples (the
  bound of :mod:`roadmap.local`), against the robot itself, the obstacles and the object.
  Where every joint carried by the holding hand's grasp-frame joint (its fingers) keeps
  its value through a phase, the held object and the links of that hand keep their
  relative pose: those pairs are checked once, at the phase's first waypoint, not at every
  sample (they are the costliest: the object's mesh against fingertips in contact).

Malformed, incomplete or stale input raises :class:`~regrasp_cli.errors.InputError`;
everything else wrong with the plan is an :class:`Issue` of the returned report.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from time import perf_counter
from typing import Any

import numpy as np
import trimesh
from rich.console import Console
from rich.markup import escape
from rich.table import Table

from regrasp_cli.config import SHAPES, ObstacleSpec
from regrasp_cli.errors import InputError, StaleArtefactError
from regrasp_cli.grasp.quality import force_closure, primitive_wrenches
from regrasp_cli.model.collision import CollisionOptions, CollisionWorld, ObjectPlacement
from regrasp_cli.model.objects import load_object_mesh
from regrasp_cli.model.robot import Robot, load_robot
from regrasp_cli.parallel import ordered_map, shared
from regrasp_cli.plan.timing import segment_duration
from regrasp_cli.roadmap.local import held_reach, joint_reach
from regrasp_cli.spatial import inverse, pose_error
from regrasp_cli.store import sha256_file
from regrasp_cli.trajectory import Phase, Plan, read_plan

CHECKS = ("input", "continuity", "limits", "timing", "collision", "attachment", "grasp", "status")
JOINT_TOL = 1e-9  # rad or m: waypoint continuity and joint limits
TIME_TOL = 1e-9  # s: phase start times
DURATION_RTOL = 1e-6  # relative slack of a segment's duration below its minimum
POSE_TOL = (0.001, 0.01)  # m, rad: object poses
FINGER_TOL = 1e-6  # rad: holding fingers at their grasp values
SURFACE_TOL = 0.001  # m: contact point to the mesh surface
NORMAL_TOL = 0.35  # rad: contact normal to the surface normal
TIP_TOL = 0.002  # m: fingertip sphere centre to where the contact puts it
CONE_EDGES = 8  # linearised friction cone, as the grasp search (grasp/single.py)
MAX_COLLISIONS = 3  # per phase: then the phase's collision check stops


@dataclass(frozen=True)
class Issue:
    """One thing wrong with a plan; ``check`` is one of :data:`CHECKS`."""

    phase: str | None
    waypoint: int | None  # index in the phase's waypoints
    check: str
    message: str

    def __str__(self) -> str:
        where = "" if self.phase is None else f" {self.phase}" + ("" if self.waypoint is None else f"[{self.waypoint}]")
        return f"{self.check}{where}: {self.message}"


@dataclass(frozen=True)
class PhaseSummary:
    name: str
    waypoints: int
    configurations: int  # checked for collision
    seconds: float


@dataclass(frozen=True)
class ValidationReport:
    issues: tuple[Issue, ...]
    configurations_checked: int
    seconds: dict[str, float]  # per phase name (summed over phases of one name) and "grasps"
    phases: tuple[PhaseSummary, ...] = ()

    @property
    def valid(self) -> bool:
        return not self.issues


# ------------------------------------------------------------------ reading the inputs


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
    contacts: tuple[Contacts, ...]  # per plan grasp
    issues: tuple[Issue, ...]  # "input" issues found while loading


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
    if a is None or a.shape != shape or not np.all(np.isfinite(a)):
        raise InputError(file, where, f"expected finite numbers of shape {shape}")
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


def _contacts(file: Path, plan: Plan, robot: Robot) -> tuple[Contacts, ...]:
    out = []
    for i, g in enumerate(plan.grasps):
        if g.hand not in robot.hands:
            raise InputError(file, f"grasps[{i}].hand", f"unknown hand {g.hand!r}; the robot has "
                                                        f"{', '.join(robot.hands)}")
        _pose(file, g.X_OG, f"grasps[{i}].hand_in_object")
        fingers, points, normals = [], [], []
        for j, c in enumerate(g.contacts):
            w = f"grasps[{i}].contacts[{j}]."
            fingers.append(_get(file, c, "finger", w, str))
            points.append(_array(file, _get(file, c, "point", w, list), w + "point", (3,)))
            normals.append(_array(file, _get(file, c, "normal", w, list), w + "normal", (3,)))
        out.append(Contacts(tuple(fingers), np.reshape(points, (-1, 3)), np.reshape(normals, (-1, 3))))
    return tuple(out)


def _obstacle(file: Path, d: Any, i: int) -> ObstacleSpec:
    w = f"obstacles[{i}]."
    shape = _get(file, d, "shape", w, str)
    if shape not in SHAPES:
        raise InputError(file, w + "shape", f"expected one of {', '.join(SHAPES)}, found {shape!r}")
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
    malformed or stale."""
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
        issues.append(Issue(None, None, "input", f"joint {robot.joint_names[i]}: the plan's {what} than the URDF's"))

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

    for key in ("start", "goal"):
        if key not in plan.object_poses:
            raise InputError(file, f"object_poses.{key}", "missing")
    for key, X in plan.object_poses.items():
        _pose(file, X, f"object_poses.{key}")
    for i, p in enumerate(plan.phases):
        for role in ("holding", "touching"):
            for h in getattr(p, role):
                if not isinstance(h, str) or h not in robot.hands:
                    raise InputError(file, f"phases[{i}].{role}", f"unknown hand {h!r}; the robot has "
                                                                  f"{', '.join(robot.hands)}")

    return Inputs(robot, mesh, friction, tuple(_obstacle(file, d, i) for i, d in enumerate(plan.obstacles)),
                  tuple(tuple(p) for p in pairs), CollisionOptions(**tol),
                  np.maximum(lim["lower"], robot.lower), np.minimum(lim["upper"], robot.upper),
                  lim["velocity"], lim["acceleration"], _contacts(file, plan, robot), tuple(issues))


# ------------------------------------------------------------------ motion checks


def continuity_issues(phase: Phase, previous: Phase | None, joint_names: tuple[str, ...]) -> list[Issue]:
    """The phase's first waypoint equals the previous phase's last one."""
    if previous is None:
        return []
    d = np.abs(phase.waypoints[0] - previous.waypoints[-1])
    j = int(np.argmax(d))
    if d[j] <= JOINT_TOL:
        return []
    return [Issue(phase.name, 0, "continuity", f"starts away from the end of phase {previous.name} "
                                               f"({joint_names[j]} differs by {d[j]:.4g})")]


def timing_issues(phase: Phase, previous: Phase | None, velocity: np.ndarray, acceleration: np.ndarray) -> list[Issue]:
    """Times from 0, joined between phases, each segment at least its minimal duration."""
    t, out = phase.times, []
    t0 = 0.0 if previous is None else float(previous.times[-1])
    if abs(t[0] - t0) > TIME_TOL:
        what = "the plan's start (0 s)" if previous is None else f"the end of phase {previous.name}"
        out.append(Issue(phase.name, 0, "timing", f"starts at {t[0]:.6g} s, not at {what} ({t0:.6g} s)"))
    for i, (dq, dt) in enumerate(zip(np.diff(phase.waypoints, axis=0), np.diff(t))):
        need = segment_duration(dq, velocity, acceleration)
        if dt < 0:
            out.append(Issue(phase.name, i + 1, "timing", f"time goes back by {-dt:.6g} s"))
        elif dt < need * (1 - DURATION_RTOL):
            out.append(Issue(phase.name, i + 1, "timing", f"segment {i}->{i + 1} lasts {dt:.6g} s but needs "
                                                          f"{need:.6g} s under the velocity and acceleration limits"))
    return out


def limit_issues(phase: Phase, joint_names: tuple[str, ...], lower: np.ndarray, upper: np.ndarray) -> list[Issue]:
    """Joint position limits at every waypoint; one issue per joint out of its range."""
    q = phase.waypoints
    out = []
    bad = (q < lower - JOINT_TOL) | (q > upper + JOINT_TOL)  # (k, nq)
    for j in np.flatnonzero(bad.any(axis=0)):
        rows = np.flatnonzero(bad[:, j])
        out.append(Issue(phase.name, int(rows[0]), "limits",
                         f"{joint_names[j]} = {q[rows[0], j]:.6g} outside [{lower[j]:.6g}, {upper[j]:.6g}]"
                         + (f" (at {len(rows)} waypoints)" if len(rows) > 1 else "")))
    return out


@dataclass(frozen=True)
class Carry:
    """Where the object is during a phase: static at X_PO = X_WO (``hand`` None), or held
    by ``hand`` at X_PO = X_GO (object in that hand's grasp frame G)."""

    hand: str | None
    X_PO: np.ndarray  # (4, 4)

    def X_WO(self, robot: Robot, q: np.ndarray) -> np.ndarray:
        if self.hand is None:
            return self.X_PO
        return robot.fk(q, robot.hands[self.hand].grasp_frame) @ self.X_PO


def _pose_differs(X_A: np.ndarray, X_B: np.ndarray) -> str | None:
    dp, da = pose_error(X_A, X_B)
    return f"{dp * 1000:.3g} mm, {da:.3g} rad" if dp > POSE_TOL[0] or da > POSE_TOL[1] else None


def attachment_issues(plan: Plan, phase: Phase, robot: Robot, X_WO: np.ndarray) -> tuple[Carry, list[Issue]]:
    """How the object moves in ``phase`` given its pose X_WO (4, 4) at the phase start,
    and whether the holding hands agree with their grasps (pose, closed fingers)."""
    if not phase.holding:
        return Carry(None, X_WO), []
    out, q = [], phase.waypoints
    hand0 = phase.holding[0]
    carry = Carry(hand0, inverse(robot.fk(q[0], robot.hands[hand0].grasp_frame)) @ X_WO)
    for hand in dict.fromkeys(phase.holding):
        grasp = plan.grasp(hand)
        if grasp is None:
            out.append(Issue(phase.name, None, "attachment",
                             f"the {hand} hand holds the object but the plan has no grasp for it"))
            continue
        # the first holder carries the object, so it only needs checking where it takes it;
        # any other holder must keep agreeing with it at every waypoint
        for i in range(1 if hand == hand0 else len(q)):
            X_WO_grasp = robot.fk(q[i], robot.hands[hand].grasp_frame) @ inverse(grasp.X_OG)
            off = _pose_differs(X_WO_grasp, carry.X_WO(robot, q[i]))
            if off:
                out.append(Issue(phase.name, i, "attachment", f"the {hand} hand's grasp puts the object {off} "
                                                              "away from where it is"))
                break
        idx = [robot.joint_names.index(n) for n in grasp.finger_joints if n in robot.joint_names]
        if len(idx) != len(grasp.finger_joints):
            continue  # reported by the grasp check
        d = np.abs(q[:, idx] - grasp.finger_values)
        rows = np.flatnonzero(d.max(axis=1) > FINGER_TOL)
        if rows.size:
            j = int(np.argmax(d[rows[0]]))
            out.append(Issue(phase.name, int(rows[0]), "attachment",
                             f"the {hand} hand's {grasp.finger_joints[j]} is {d[rows[0], j]:.4g} off its grasp value "
                             f"(at {rows.size} waypoints)"))
    return carry, out


def segment_steps(dq: np.ndarray, reach: np.ndarray, resolution: float, cartesian_step: float) -> int:
    """Intervals cutting segment dq (nq,) so that no joint moves more than ``resolution``
    and no robot point more than ``cartesian_step`` (m; ``reach`` (nq,) m/rad) per interval."""
    d = np.abs(dq)
    return max(int(np.ceil(d.max() / resolution)), int(np.ceil(float(reach @ d) / cartesian_step)), 1)


def _where(i: int, s: float) -> tuple[int, str]:
    """(waypoint index, words) of the point at parameter s in (0, 1] of segment i -> i + 1."""
    if s == 1.0:
        return i + 1, f"at waypoint {i + 1}"
    return i, f"between waypoints {i} and {i + 1} (s = {s:.3f})"


def collision_issues(phase: Phase, world: CollisionWorld, reach: np.ndarray, resolution: float,
                     cartesian_step: float) -> tuple[list[Issue], int]:
    """The first waypoint, then the samples of each segment in order (its end included);
    the first colliding sample of a segment is reported with its colliding pairs, at most
    :data:`MAX_COLLISIONS` per phase.  Returns (issues, configurations checked)."""
    q, out = phase.waypoints, []
    if not world.is_free(q[0]):
        out.append(_collision(phase, world, q[0], 0, "at waypoint 0"))
    n_checked = 1
    for i in range(len(q) - 1):
        if len(out) >= MAX_COLLISIONS:
            break
        n = segment_steps(q[i + 1] - q[i], reach, resolution, cartesian_step)
        for k in range(1, n + 1):
            qs = q[i] + (k / n) * (q[i + 1] - q[i]) if k < n else q[i + 1]
            n_checked += 1
            if not world.is_free(qs):
                out.append(_collision(phase, world, qs, *_where(i, k / n)))
                break  # one issue per segment
    return out, n_checked


def _collision(phase: Phase, world: CollisionWorld, q: np.ndarray, waypoint: int, where: str) -> Issue:
    pairs = world.colliding_pairs(q)  # every pair, unlike the early-exit check
    names = ", ".join(f"{a} - {b}" for a, b in pairs[:4]) + (" ..." if len(pairs) > 4 else "")
    return Issue(phase.name, waypoint, "collision", f"{where}: {names or 'collision'}")


def phase_world(inputs: Inputs, phase: Phase, carry: Carry, pair_filter=None) -> CollisionWorld:
    """Robot, obstacles and the object, static or held, for ``phase`` (the pairs
    ``pair_filter(a, b)`` accepts, see :class:`CollisionWorld`)."""
    touching = tuple(dict.fromkeys(phase.holding + phase.touching))
    obj = ObjectPlacement(inputs.mesh, carry.X_PO, carry.hand, touching)
    return CollisionWorld(inputs.robot, inputs.obstacles, inputs.disabled, obj, inputs.options,
                          pair_filter=pair_filter)


def rigid_links(robot: Robot, phase: Phase, carry: Carry) -> frozenset[str]:
    """Links whose pose relative to the held object is the same at every point of the
    phase: those carried by the holding hand's grasp-frame joint, when every joint they
    hang from below it keeps its value at every waypoint (segments are straight, so it
    keeps it between them too); empty when the object is not held or a joint moves."""
    if carry.hand is None:
        return frozenset()
    model = robot.model
    j = model.frames[robot.hands[carry.hand].grasp_frame].parentJoint
    below = [model.names[k] for k in model.subtrees[j] if k != j]
    idx = [robot.joint_names.index(n) for n in below if n in robot.joint_names]
    q = phase.waypoints
    if idx and np.abs(q[:, idx] - q[0, idx]).max() > FINGER_TOL:
        return frozenset()
    return frozenset(f.name for f in model.frames if f.parentJoint in model.subtrees[j])


# ------------------------------------------------------------------ grasp checks


def _surface(mesh: trimesh.Trimesh, p: np.ndarray) -> tuple[float, np.ndarray]:
    """Distance (m) from p (3,) to the mesh and the normals (f, 3) of the closest faces
    (several at an edge or a vertex, where any of them is as right as another)."""
    faces = np.asarray(trimesh.proximity.nearby_faces(mesh, p[None])[0])
    closest = trimesh.triangles.closest_point(mesh.triangles[faces], np.repeat(p[None], len(faces), axis=0))
    d = np.linalg.norm(closest - p, axis=1)
    return float(d.min()), mesh.face_normals[faces[d <= d.min() + 1e-7]]


def contact_issues(plan: Plan, inputs: Inputs) -> list[Issue]:
    """Each grasp: contacts on the surface, normals along it, force closure."""
    mesh, robot, out = inputs.mesh, inputs.robot, []
    # a closed, consistently wound mesh defines outward; otherwise only the normal's line is known
    oriented = bool(mesh.is_watertight and mesh.is_winding_consistent)
    centre = np.asarray(mesh.center_mass if oriented else mesh.centroid, dtype=float)
    rho = float(np.linalg.norm(mesh.extents) / 2)  # as the grasp search
    for g, c in zip(plan.grasps, inputs.contacts):
        hand = robot.hands[g.hand]
        name = f"grasp {g.hand} #{g.id}"

        def issue(msg: str) -> None:
            out.append(Issue(None, None, "grasp", f"{name}: {msg}"))

        if sorted(g.finger_joints) != sorted(robot.joint_names[i] for i in hand.idx):
            issue(f"finger_joints {list(g.finger_joints)} are not the {g.hand} hand's finger joints")
        fingers = [f.name for f in hand.spec.fingers]
        for f in c.fingers:
            if f not in fingers:
                issue(f"contact of unknown finger {f!r} (the hand has {', '.join(fingers)})")
        if len(set(c.fingers)) != len(c.fingers):
            issue("two contacts of one finger")
        units = np.linalg.norm(c.normals, axis=1)
        for f, p, n, u in zip(c.fingers, c.points, c.normals, units):
            d, face_normals = _surface(mesh, p)
            if d > SURFACE_TOL:
                issue(f"{f} contact {d * 1000:.3g} mm off the object surface")
            if abs(u - 1) > 1e-3:
                issue(f"{f} contact normal has norm {u:.4g}, not 1")
            elif d <= SURFACE_TOL:
                cos = face_normals @ (n / u)
                angle = float(np.arccos(np.clip((cos if oriented else np.abs(cos)).max(), -1, 1)))
                if angle > NORMAL_TOL:
                    issue(f"{f} contact normal is {angle:.3g} rad off the surface normal")
        if np.all(units > 1e-12):
            W = primitive_wrenches(c.points, c.normals, inputs.friction, centre, rho,
                                   contact=hand.spec.contact, n_edges=CONE_EDGES)
            if not force_closure(W)[0]:
                issue(f"the {len(c.points)} contacts are not force closure (friction {inputs.friction:g}, "
                      f"{hand.spec.contact} contacts)")
    return out


def fingertip_issues(plan: Plan, inputs: Inputs, poses: list[tuple[np.ndarray, np.ndarray]]) -> list[Issue]:
    """Fingertip sphere centres at ``p + r_tip n`` (as the grasp search puts them) where the
    hand takes the object: first waypoint of its first holding phase, else the last of
    ``close_<hand>``.  ``poses`` holds X_WO at the start and end of each phase."""
    robot, out = inputs.robot, []
    for g, c in zip(plan.grasps, inputs.contacts):
        hand = robot.hands[g.hand]
        where = next(((k, 0) for k, p in enumerate(plan.phases) if g.hand in p.holding), None)
        if where is None:
            where = next(((k, -1) for k, p in enumerate(plan.phases) if p.name == f"close_{g.hand}"), None)
        if where is None:
            continue
        k, i = where
        phase = plan.phases[k]
        q, X_WO = phase.waypoints[i], poses[k][0 if i == 0 else 1]
        fingers = {f.name: j for j, f in enumerate(hand.spec.fingers)}
        for f, p, n in zip(c.fingers, c.points, c.normals):
            if f not in fingers or not np.linalg.norm(n) > 1e-12:
                continue  # reported by contact_issues
            j = fingers[f]
            target_O = p + hand.spec.fingers[j].tip_radius * n / np.linalg.norm(n)
            p_W = X_WO[:3, :3] @ target_O + X_WO[:3, 3]
            d = float(np.linalg.norm(robot.fk(q, hand.tip_frames[j])[:3, 3] - p_W))
            if d > TIP_TOL:
                out.append(Issue(phase.name, i % len(phase.waypoints), "grasp",
                                 f"grasp {g.hand} #{g.id}: the {f} fingertip is {d * 1000:.3g} mm from its contact"))
    return out


# ------------------------------------------------------------------ the whole plan


def _phase_collisions(k: int) -> tuple[list[Issue], int, float]:
    j = shared()
    t0 = perf_counter()
    phase, carry, inputs = j["plan"].phases[k], j["carries"][k], j["inputs"]
    reach = j["reach"]
    if carry.hand is not None:  # the held object reaches farther than the robot
        reach = held_reach(inputs.robot, reach, carry.hand, np.asarray(inputs.mesh.vertices), carry.X_PO)
    rigid = rigid_links(inputs.robot, phase, carry)

    def moving(a: str, b: str) -> bool:  # not the object against a link rigid with it
        return not ("object" in (a, b) and (a in rigid or b in rigid))

    found, n = collision_issues(phase, phase_world(inputs, phase, carry, moving), reach, j["resolution"],
                                j["cartesian_step"])
    if rigid:
        once = phase_world(inputs, phase, carry, lambda a, b: not moving(a, b))
        if not once.is_free(phase.waypoints[0]):
            found.insert(0, _collision(phase, once, phase.waypoints[0], 0,
                                       "the held object against its hand (the same all phase)"))
    return found, n, perf_counter() - t0


def validate_plan(path: str | Path, resolution: float = 0.01, cartesian_step: float = 0.005,
                  jobs: int = 2) -> ValidationReport:
    """Check the plan file ``path`` (see the module docstring).

    Args:
        path: plan JSON; the files it names are relative to its directory unless absolute.
        resolution: largest joint step (rad or m) between two collision-checked samples.
        cartesian_step: largest displacement (m) of any robot point between two samples.
        jobs: processes for the collision checks of the phases (the report is the same).

    Raises:
        InputError: the plan is malformed or incomplete, a file it names is missing, or
            stale (:class:`~regrasp_cli.errors.StaleArtefactError`: its SHA-256 changed).
    """
    if not (resolution > 0 and cartesian_step > 0):
        raise ValueError("resolution and cartesian_step must be > 0")
    path = Path(path)
    plan = read_plan(path)
    if plan.status == "failed":
        f = plan.failure if isinstance(plan.failure, dict) else {}
        msg = f"the planner failed at stage {f.get('stage', '?')}: {f.get('reason', 'no reason given')}"
        return ValidationReport((Issue(None, None, "status", msg),), 0, {})

    inputs = load_inputs(plan, path)
    robot, reach = inputs.robot, joint_reach(inputs.robot)
    issues, seconds = list(inputs.issues), {}
    per_phase: list[list[Issue]] = []
    X_WO = plan.object_poses["start"]
    poses, carries, dts = [], [], []  # X_WO at (start, end) of each phase
    for k, phase in enumerate(plan.phases):
        t0 = perf_counter()
        previous = plan.phases[k - 1] if k else None
        found = continuity_issues(phase, previous, robot.joint_names)
        found += timing_issues(phase, previous, inputs.velocity, inputs.acceleration)
        found += limit_issues(phase, robot.joint_names, inputs.lower, inputs.upper)
        carry, more = attachment_issues(plan, phase, robot, X_WO)
        found += more
        carries.append(carry)
        X_end = carry.X_WO(robot, phase.waypoints[-1])
        poses.append((X_WO, X_end))
        X_WO = X_end
        if phase.name == "carry":
            if "exchange" not in plan.object_poses:
                found.append(Issue(phase.name, None, "input", "a carry phase but no object_poses.exchange"))
            elif off := _pose_differs(X_WO, plan.object_poses["exchange"]):
                found.append(Issue(phase.name, len(phase.waypoints) - 1, "attachment",
                                   f"the object ends the carry {off} away from the exchange pose"))
        per_phase.append(found)
        dts.append(perf_counter() - t0)
    job = {"plan": plan, "inputs": inputs, "carries": carries, "reach": reach, "resolution": resolution,
           "cartesian_step": cartesian_step}
    # longest phases first, so that two workers finish together
    order = sorted(range(len(plan.phases)), key=lambda k: -len(plan.phases[k].waypoints))
    results = dict(zip(order, ordered_map(_phase_collisions, order, jobs, job)))
    summaries = []
    for k, phase in enumerate(plan.phases):
        found, n, dt = results[k]
        issues += per_phase[k] + found
        seconds[phase.name] = seconds.get(phase.name, 0.0) + dts[k] + dt
        summaries.append(PhaseSummary(phase.name, len(phase.waypoints), n, dts[k] + dt))
    if off := _pose_differs(X_WO, plan.object_poses["goal"]):
        where = (plan.phases[-1].name, len(plan.phases[-1].waypoints) - 1) if plan.phases else (None, None)
        issues.append(Issue(*where, "attachment", f"the object ends {off} away from its goal pose"))

    t0 = perf_counter()
    issues += contact_issues(plan, inputs) + fingertip_issues(plan, inputs, poses)
    seconds["grasps"] = perf_counter() - t0
    return ValidationReport(tuple(issues), sum(s.configurations for s in summaries), seconds, tuple(summaries))


def print_validation(report: ValidationReport, console: Console) -> None:
    """A table per phase (waypoints, configurations checked, seconds, issues), the issues
    one per line, and a last line ``valid`` or ``INVALID: N issues``."""
    count = {}
    for i in report.issues:
        count[i.phase] = count.get(i.phase, 0) + 1
    t = Table(title="Plan validation")
    for col, justify in (("phase", "left"), ("waypoints", "right"), ("configurations", "right"),
                         ("seconds", "right"), ("issues", "right")):
        t.add_column(col, justify=justify)
    for s in report.phases:
        t.add_row(s.name, str(s.waypoints), str(s.configurations), f"{s.seconds:.3f}", str(count.get(s.name, 0)))
    grasp_issues = sum(1 for i in report.issues if i.check == "grasp" and i.phase is None)
    if "grasps" in report.seconds:
        t.add_row("grasps", "", "", f"{report.seconds['grasps']:.3f}", str(grasp_issues))
    console.print(t)
    for i in report.issues:
        console.print(escape(str(i)))
    n = len(report.issues)
    console.print("valid" if report.valid else f"INVALID: {n} issue{'s' * (n != 1)}")
