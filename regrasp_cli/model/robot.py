"""The robot: a pinocchio model of any URDF, with the groups and hands of its robot.yaml.

Configurations ``q`` are 1-D float arrays with one value per actuated joint, in the order
of :attr:`Robot.joint_names` (revolute and continuous joints in rad, prismatic in m).
For URDFs whose joints all have one coordinate this is pinocchio's own order and
:meth:`Robot.to_pin` is free; continuous joints (two coordinates, cos/sin, in pinocchio)
are converted.  The groups follow Saut et al. 2010, §V-A (Fig. 4): the torso is the
*common* part, each arm (+ its hand) an *independent* part.

A :class:`Robot` is immutable once built and holds no scratch: like pinocchio's Model/Data
split, forward kinematics goes through a :class:`Kinematics` (one pinocchio ``Data``),
which each worker or query makes for itself.  A Robot may be shared freely.
"""

from __future__ import annotations

import contextlib
import os
import sys
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Callable, Mapping, TypeVar

import coal
import numpy as np
import pinocchio as pin
import trimesh

from regrasp_cli.config import HandSpec, RobotSpec, load_robot_spec
from regrasp_cli.errors import InputError, shown
from regrasp_cli.spatial import pose_matrix
from regrasp_cli.store import sha256_file, sha256_params

GROUP_NAMES = ("torso", "right_arm", "left_arm")


@contextlib.contextmanager
def _quiet_stderr():
    """urdfdom prints parse errors to the C-level stderr; we report them ourselves."""
    try:
        fd = sys.stderr.fileno()
    except (AttributeError, OSError, ValueError):
        yield
        return
    saved = os.dup(fd)
    try:
        with open(os.devnull, "w") as null:
            os.dup2(null.fileno(), fd)
            yield
    finally:
        os.dup2(saved, fd)
        os.close(saved)


@dataclass(frozen=True)
class Hand:
    """A hand resolved against the model: indices into ``q`` and frame ids."""

    spec: HandSpec
    arm_idx: np.ndarray  # (7,) indices of the arm joints in q
    finger_idx: tuple[np.ndarray, ...]  # per finger, indices of its joints in q
    tip_frames: tuple[int, ...]  # per finger, pinocchio frame id of the tip link
    grasp_frame: int  # pinocchio frame id of the grasp frame G
    open: np.ndarray  # (n_hand_joints,) open configuration, in the order of ``idx``
    kind: str = "fingertips"  # "fingertips", "jaw" or "pads": how its grasps are found (HandSpec.kind)
    opposing: int = 0  # index of the finger opposing the others (HandSpec.opposing; the first when unstated)

    @property
    def side(self) -> str:
        return self.spec.side

    @property
    def idx(self) -> np.ndarray:
        """Indices in q of all the hand's finger joints."""
        return np.concatenate(self.finger_idx)


class Robot:
    """A URDF robot with groups and hands.  Build with :func:`load_robot`."""

    def __init__(self, spec: RobotSpec):
        self.spec = spec
        model = _from_urdf(spec, lambda: pin.buildModelFromUrdf(str(spec.urdf)))
        collision = self._geometry(model, pin.GeometryType.COLLISION)
        self.model: pin.Model = model
        self._visual: pin.GeometryModel | None = None
        if spec.collision_from_visual:
            _collision_from_visual(spec, model, collision, self.visual_model)
        if not collision.ngeoms:
            raise InputError(spec.file, "urdf", f"{spec.urdf} has no <collision> geometry in any link; expected "
                                                "collision geometry (or `collision_from_visual: [LINK, ...]` here)")
        if spec.convex_hulls:
            _convexify(spec, model, collision)
        self.collision_model: pin.GeometryModel = collision

        names, idx_q, nqs = [], [], []
        for j in range(1, model.njoints):
            jm = model.joints[j]
            if jm.nv != 1:
                raise InputError(spec.urdf, f"joint {model.names[j]}",
                                 f"unsupported joint type {jm.shortname()} (expected revolute, "
                                 "continuous or prismatic)")
            names.append(model.names[j])
            idx_q.append(jm.idx_q)
            nqs.append(jm.nq)
        self.joint_names: tuple[str, ...] = tuple(names)
        self._idx_q = np.array(idx_q, dtype=int)
        self._continuous = np.array([n == 2 for n in nqs], dtype=bool)
        self._identity = not self._continuous.any()
        n = len(names)
        lo, hi = np.empty(n), np.empty(n)
        for i, j in enumerate(range(1, model.njoints)):
            if self._continuous[i]:
                lo[i], hi[i] = -np.pi, np.pi
            else:
                lo[i] = model.lowerPositionLimit[idx_q[i]]
                hi[i] = model.upperPositionLimit[idx_q[i]]
        self.lower, self.upper = lo, hi
        self.velocity = np.array([model.velocityLimit[model.joints[j].idx_v] for j in range(1, model.njoints)])
        self.velocity[self.velocity <= 0] = 1.0  # URDFs without limits: a cautious default

        self.prismatic = np.array([model.joints[j].shortname().startswith("JointModelP")
                                   for j in range(1, model.njoints)], dtype=bool)
        # URDF mimic joints: follower index -> (leader index, multiplier, offset), a chain of
        # followers composed down to the joint that follows none; the leader's limits bind
        self.mimic: dict[int, tuple[int, float, float]] = {
            names.index(f): (names.index(l), m, o) for f, (l, m, o) in _checked_mimic(spec, names).items()}
        self._bind_follower_limits()
        self._mimic = np.array([(f, l) for f, (l, _, _) in self.mimic.items()], dtype=int).reshape(-1, 2)
        self._mimic_mo = np.array([(m, o) for _, m, o in self.mimic.values()], dtype=float).reshape(-1, 2)
        self.groups: dict[str, np.ndarray] = {
            g: self._indices(spec.groups[g], f"groups.{g}") for g in GROUP_NAMES}
        self.hands: dict[str, Hand] = {s: self._hand(h) for s, h in spec.hands.items()}
        self.q_rest = self.coupled(self.configuration(spec.rest, "rest", base=np.clip(np.zeros(n), lo, hi)))

    @property
    def visual_model(self) -> pin.GeometryModel:
        """The URDF's visual geometry, read when first asked for: only `regrasp show` and
        ``collision_from_visual`` use it, and its meshes are most of a URDF's load time
        (Baxter's: 1.8 of 1.9 s)."""
        if self._visual is None:
            self._visual = self._geometry(self.model, pin.GeometryType.VISUAL)
        return self._visual

    def _geometry(self, model: pin.Model, kind: pin.GeometryType) -> pin.GeometryModel:
        """The URDF's collision or visual geometry (``kind``) of ``model``'s links."""
        spec = self.spec
        return _from_urdf(spec, lambda: pin.buildGeomFromUrdf(model, str(spec.urdf), kind,
                                                              package_dirs=[str(d) for d in spec.package_dirs]))

    def _bind_follower_limits(self) -> None:
        """A follower's limits become its leader's range mapped through the mimic: its value
        always comes from the leader, so the leader's limits bind.  Where the URDF's own
        limits of the follower cut that range (PR2's gripper joints of multiplier -1 and
        limits [0, 0.548] are outside them at every leader value but 0), a warning says so
        at load, and the planner and the validator both use the mapped range."""
        for f, (lead, m, o) in self.mimic.items():
            a, b = sorted((m * self.lower[lead] + o, m * self.upper[lead] + o))
            if a < self.lower[f] - 1e-9 or b > self.upper[f] + 1e-9:
                _warn_once(f"{self.spec.urdf}: joint {self.joint_names[f]} follows {self.joint_names[lead]} "
                              f"(mimic multiplier {m:g}, offset {o:g}) over [{a:.4g}, {b:.4g}], outside its own "
                              f"limits [{self.lower[f]:.4g}, {self.upper[f]:.4g}]; the leader's limits bind")
            self.lower[f], self.upper[f] = a, b

    def driver(self, i: int) -> int:
        """Index in q of the joint that moves joint ``i``: its mimic leader, or itself."""
        return self.mimic[i][0] if i in self.mimic else int(i)

    def hand_joints(self, hand: str) -> dict[int, int]:
        """Pinocchio joint id -> finger index (robot.yaml order) of every joint that moves
        with a hand's fingers: each finger's joints, the joints that follow them through
        URDF mimics (a jaw's other side, PR2's parallel links) and every joint below those
        (a fingertip on a mimic joint of its own).  The palm's joint is not one of them."""
        model, h = self.model, self.hands[hand]
        out: dict[int, int] = {}

        def below(i: int, f: int) -> None:
            for j in model.subtrees[model.getJointId(self.joint_names[i])]:
                out.setdefault(int(j), f)

        for f, idx in enumerate(h.finger_idx):  # a finger's own joints first: a jaw's follower is a finger
            for i in idx:
                below(int(i), f)
        for f, idx in enumerate(h.finger_idx):  # then the followers no finger lists, with their leader's finger
            for k, (lead, _, _) in sorted(self.mimic.items()):
                if lead in idx:
                    below(k, f)
        return out

    # ------------------------------------------------------------------ names and indices

    @property
    def nq(self) -> int:
        return len(self.joint_names)

    def joint_index(self, name: str, field: str = "joint") -> int:
        try:
            return self.joint_names.index(name)
        except ValueError:
            raise InputError(self.spec.file, field, f"unknown joint {shown(name)} (not an actuated joint of "
                                                    f"{self.spec.urdf.name})") from None

    def _indices(self, names, field: str) -> np.ndarray:
        return np.array([self.joint_index(n, field) for n in names], dtype=int)

    def frame_id(self, name: str, field: str = "link") -> int:
        if not self.model.existFrame(name):
            raise InputError(self.spec.file, field, f"unknown link or frame {shown(name)} in {self.spec.urdf.name}")
        if self.model.existFrame(name, pin.FrameType.BODY):  # a link named like a joint: the link
            return self.model.getFrameId(name, pin.FrameType.BODY)
        return self.model.getFrameId(name)

    def _hand(self, h: HandSpec) -> Hand:
        where = f"hands.{h.side}"
        finger_idx = tuple(self._indices(f.joints, f"{where}.fingers[{i}].joints") for i, f in enumerate(h.fingers))
        tips = tuple(self.frame_id(f.tip_link, f"{where}.fingers[{i}].tip_link") for i, f in enumerate(h.fingers))
        open_ = np.array(h.open, dtype=float)
        idx = np.concatenate(finger_idx)
        bad = (open_ < self.lower[idx] - 1e-9) | (open_ > self.upper[idx] + 1e-9)
        if bad.any():
            k = int(np.argmax(bad))
            raise InputError(self.spec.file, f"{where}.fingers",
                             f"open value {open_[k]} of joint {self.joint_names[idx[k]]} is outside its "
                             f"limits [{self.lower[idx[k]]:.3f}, {self.upper[idx[k]]:.3f}]")
        for f, o in self.mimic.items():
            k = np.flatnonzero(idx == f)
            lead = np.flatnonzero(idx == o[0])
            if k.size and lead.size and abs(open_[k[0]] - (o[1] * open_[lead[0]] + o[2])) > 1e-6:
                raise InputError(self.spec.file, f"{where}.fingers",
                                 f"open value {open_[k[0]]} of joint {self.joint_names[f]} does not follow its URDF "
                                 f"mimic of {self.joint_names[o[0]]} (expected {o[1] * open_[lead[0]] + o[2]:g})")
        opposing = 0 if h.opposing is None else [f.name for f in h.fingers].index(h.opposing)
        for i, f in enumerate(h.fingers):
            c = np.array(f.closed if f.closed is not None else f.open)
            lo, hi = self.lower[finger_idx[i]], self.upper[finger_idx[i]]
            if np.any(c < lo - 1e-9) or np.any(c > hi + 1e-9):
                limits = ", ".join(f"{a:.4g}..{b:.4g}" for a, b in zip(lo, hi))
                raise InputError(self.spec.file, f"{where}.fingers[{i}].closed",
                                 f"expected values within the joint limits ({limits}), found {c.tolist()}")
        return Hand(h, self.groups[h.arm], finger_idx, tips, self._grasp_frame(h), open_,
                    self._hand_kind(h, finger_idx), opposing)

    def _grasp_frame(self, h: HandSpec) -> int:
        """The frame id of the hand's grasp frame: the named link, or a frame added at the
        stated offset from it."""
        field = f"hands.{h.side}.grasp_frame" + ("" if h.grasp_offset is None else ".link")
        parent = self.frame_id(h.grasp_frame, field)
        if h.grasp_offset is None:
            return parent
        f = self.model.frames[parent]
        X = f.placement * pin.SE3(pose_matrix(*h.grasp_offset))
        name = f"regrasp_{h.side}_grasp_frame"
        return self.model.addFrame(pin.Frame(name, f.parentJoint, parent, X, pin.FrameType.OP_FRAME))

    def _hand_kind(self, h: HandSpec, finger_idx: tuple[np.ndarray, ...]) -> str:
        """``jaw`` for two fingers each closed by one joint (prismatic or revolute; the
        finger's joints that follow it through URDF mimics, a fingertip on a mimic joint,
        do not count), ``pads`` when a finger has fewer than three joints, else
        ``fingertips`` (unless robot.yaml states it; a stated jaw must be such a hand)."""
        drivers = [{self.driver(int(i)) for i in idx} for idx in finger_idx]
        jaw = len(finger_idx) == 2 and all(len(d) == 1 for d in drivers)
        if h.kind == "jaw" and not jaw:
            raise InputError(self.spec.file, f"hands.{h.side}.kind",
                             "a jaw needs two fingers each closed by one joint (prismatic or revolute, or one its "
                             "other joints follow through URDF mimics)")
        few = any(len(i) < 3 for i in finger_idx)
        kind = ("jaw" if jaw else "pads" if few else "fingertips") if h.kind == "auto" else h.kind
        if kind == "fingertips" and len(finger_idx) > 2 and h.opposing is None:
            raise InputError(self.spec.file, f"hands.{h.side}.opposing",
                             "missing: name the finger that opposes the others (the thumb), e.g. "
                             f"opposing: {h.fingers[0].name}")
        return kind

    def configuration(self, values: Mapping[str, float], field: str, base: np.ndarray | None = None) -> np.ndarray:
        """A full configuration from ``joint -> value`` (others from ``base``, default rest),
        with hands at their open configuration unless given; values are checked against limits."""
        q = (self.q_rest if base is None else base).copy()
        if base is not None:
            for hand in getattr(self, "hands", {}).values():
                q[hand.idx] = hand.open
        for name, v in values.items():
            i = self.joint_index(name, f"{field}.{name}")
            if not self.lower[i] - 1e-9 <= v <= self.upper[i] + 1e-9:
                raise InputError(self.spec.file if field == "rest" else None, f"{field}.{name}",
                                 f"value {v} outside the joint limits [{self.lower[i]:.4f}, {self.upper[i]:.4f}]")
            q[i] = v
        return q

    # ------------------------------------------------------------------ kinematics

    def coupled(self, q: np.ndarray) -> np.ndarray:
        """``q`` (nq,) or (k, nq) with every mimic joint set from its leader (a copy when
        the URDF has mimic joints)."""
        if not self.mimic:
            return q
        q = np.array(q, dtype=float)
        f, l = self._mimic[:, 0], self._mimic[:, 1]
        q[..., f] = self._mimic_mo[:, 0] * q[..., l] + self._mimic_mo[:, 1]
        return q

    def to_pin(self, q: np.ndarray) -> np.ndarray:
        """Our configuration -> pinocchio's (cos/sin for continuous joints, mimic joints
        from their leaders)."""
        q = self.coupled(q)
        if self._identity:
            return q
        qp = np.empty(self.model.nq)
        c = self._continuous
        qp[self._idx_q[~c]] = q[~c]
        qp[self._idx_q[c]] = np.cos(q[c])
        qp[self._idx_q[c] + 1] = np.sin(q[c])
        return qp

    def within_limits(self, q: np.ndarray, tol: float = 1e-9) -> bool:
        return bool(np.all(q >= self.lower - tol) and np.all(q <= self.upper + tol))

    def sample(self, rng: np.random.Generator, idx: np.ndarray | None = None, base: np.ndarray | None = None) -> np.ndarray:
        """Uniform random configuration within limits for the joints ``idx`` (all by default);
        the other joints keep the values of ``base`` (rest by default)."""
        q = (self.q_rest if base is None else base).copy()
        idx = np.arange(self.nq) if idx is None else idx
        q[idx] = rng.uniform(self.lower[idx], self.upper[idx])
        return self.coupled(q)

    @cached_property
    def urdf_sha256(self) -> str:
        return sha256_file(self.spec.urdf)

    @cached_property
    def robot_yaml_sha256(self) -> str:
        return sha256_file(self.spec.file)

    @cached_property
    def spec_sha256(self) -> str:
        """What the robot.yaml says, parsed: its comments, layout and file name left out,
        so that artefacts of the whole robot (roadmaps) survive a reformatted file."""
        from dataclasses import fields

        return sha256_params({f.name: repr(getattr(self.spec, f.name)) for f in fields(self.spec)
                              if f.name not in ("file", "urdf", "package_dirs", "srdf")})

    def link_of_geometry(self, gid: int) -> str:
        """Name of the URDF link a collision geometry belongs to."""
        return self.model.frames[self.collision_model.geometryObjects[gid].parentFrame].name


def carries(model: pin.Model, j: int, k: int) -> bool:
    """Pinocchio joint j moves joint k: j is k, one of its ancestors, or the root (0)."""
    while k > 0:
        if k == j:
            return True
        k = model.parents[k]
    return j == 0


T = TypeVar("T")


def _from_urdf(spec: RobotSpec, build: Callable[[], T]) -> T:
    """``build()``'s result: a model or geometry read from the spec's URDF.

    Raises:
        InputError: pinocchio cannot read it (its first line, naming the URDF).
    """
    try:
        with _quiet_stderr():
            return build()
    except (RuntimeError, ValueError) as exc:
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise InputError(spec.file, "urdf", f"cannot parse URDF {spec.urdf}: {first}") from None


def _collision_from_visual(spec: RobotSpec, model: pin.Model, collision: pin.GeometryModel,
                           visual: pin.GeometryModel) -> None:
    """The collision geometry of robot.yaml's ``collision_from_visual`` links replaced by
    their visual geometry: many URDFs carry coarse boxes (the Allegro hand's distal boxes
    reach 11 mm past the link, to the fingertip's centre, and stick out of the tip)."""
    for link in spec.collision_from_visual:
        if not model.existFrame(link) or model.frames[model.getFrameId(link)].type != pin.FrameType.BODY:
            raise InputError(spec.file, "collision_from_visual", f"expected links of {spec.urdf.name}, found {shown(link)}")
        fid = model.getFrameId(link)
        shapes = [go for go in visual.geometryObjects if go.parentFrame == fid]
        if not shapes:
            raise InputError(spec.file, "collision_from_visual", f"link {link} has no visual geometry")
        for name in [go.name for go in collision.geometryObjects if go.parentFrame == fid]:
            collision.removeGeometryObject(name)
        for go in shapes:
            go = go.copy()
            go.name = f"{go.name}_from_visual"
            collision.addGeometryObject(go)


def _convexify(spec: RobotSpec, model: pin.Model, gm: pin.GeometryModel) -> None:
    """Every mesh geometry of ``gm`` replaced by its convex hull (robot.yaml's
    ``convex_hulls``, on by default): it contains the mesh, so a configuration free with
    hulls is free with the meshes, and a scanned link of 20,000 triangles becomes a hull
    of a few hundred points that coal checks 10-50x faster.  The ``exact_meshes`` links
    keep their meshes: a finger that curls in behind its pad (PR2's) has a hull that
    fills the space the jaw closes on."""
    for link in spec.exact_meshes:
        if not model.existFrame(link):
            raise InputError(spec.file, "exact_meshes", f"expected links of {spec.urdf.name}, found {shown(link)}")
    for go in gm.geometryObjects:
        if isinstance(go.geometry, coal.BVHModelBase) and model.frames[go.parentFrame].name not in spec.exact_meshes:
            hull = trimesh.convex.convex_hull(np.asarray(go.geometry.vertices()))
            go.geometry = coal.Convex.convexHull(list(hull.vertices), False, None)


def _mimic_joints(spec: RobotSpec) -> dict[str, tuple[str, float, float]]:
    """``<mimic joint= multiplier= offset=>`` of the URDF's joints: follower name ->
    (leader name, multiplier, offset).  pinocchio reads a mimic joint as a free one."""
    import xml.etree.ElementTree as ET

    try:
        root = ET.parse(spec.urdf).getroot()
    except (ET.ParseError, OSError):
        return {}  # pinocchio parsed it: a file ElementTree cannot read has no mimic we could honour
    out = {}
    for j in root.iter("joint"):
        m = j.find("mimic")
        if m is not None and j.get("name") and m.get("joint"):
            try:
                out[j.get("name")] = (m.get("joint"), float(m.get("multiplier", 1.0)), float(m.get("offset", 0.0)))
            except ValueError:
                raise InputError(spec.urdf, f"joint {j.get('name')}.mimic",
                                 "expected numbers for multiplier and offset") from None
    return out


_SAID: set[str] = set()  # the URDF's warnings said in this process (a command loads its robot more than once)


def _warn_once(message: str) -> None:
    import warnings

    if message not in _SAID:
        _SAID.add(message)
        warnings.warn(message, stacklevel=3)


def _checked_mimic(spec: RobotSpec, names: list[str]) -> dict[str, tuple[str, float, float]]:
    """:func:`_mimic_joints` between joints of the model, each follower of a follower
    composed down to the joint that follows none (q_f = m_f (m_l q_r + o_l) + o_f).  A mimic
    naming a joint the URDF does not have is said in a warning (the follower then moves
    as a joint of its own); a cycle of mimics (a joint following itself) is refused."""
    found = _mimic_joints(spec)
    for f, (leader, _, _) in found.items():
        if f in names and leader not in names:
            _warn_once(f"{spec.urdf}: joint {f}.mimic names joint {shown(leader)}, which the URDF has not (or "
                          f"not as a moving joint); {f} moves as a joint of its own")
    direct = {f: v for f, v in found.items() if f in names and v[0] in names}
    out = {}
    for f in direct:
        seen, (root, m, o) = [f], direct[f]
        while root in direct:
            if root in seen:
                cycle = " -> ".join(seen[seen.index(root):] + [root])
                raise InputError(spec.urdf, f"joint {root}.mimic", f"the mimic joints form a cycle ({cycle}); "
                                                                   "expected each follower to end at a joint that "
                                                                   "follows none")
            seen.append(root)
            root, m2, o2 = direct[root][0], direct[root][1], direct[root][2]
            m, o = m * m2, m * o2 + o
        out[f] = (root, m, o)
    return out


class Kinematics:
    """Forward-kinematics scratch of one worker or query: a pinocchio ``Data`` of a shared
    :class:`Robot` (~0.4 ms to make, ~2 us per FK), overwritten by every call."""

    __slots__ = ("robot", "data")

    def __init__(self, robot: Robot):
        self.robot = robot
        self.data = robot.model.createData()

    def fk(self, q: np.ndarray, frame: str | int) -> np.ndarray:
        """X_WF: pose (4, 4) of a frame (link or joint name, or frame id) in the base frame W."""
        r = self.robot
        fid = frame if isinstance(frame, (int, np.integer)) else r.frame_id(frame)
        pin.forwardKinematics(r.model, self.data, r.to_pin(q))
        return pin.updateFramePlacement(r.model, self.data, int(fid)).homogeneous.copy()

    def fk_many(self, q: np.ndarray, frames) -> list[np.ndarray]:
        """Poses X_WF (4, 4) of several frame ids for one configuration (one FK pass)."""
        r = self.robot
        pin.framesForwardKinematics(r.model, self.data, r.to_pin(q))
        return [self.data.oMf[int(f)].homogeneous.copy() for f in frames]


def load_robot(path: str | Path) -> Robot:
    """Load robot.yaml and its URDF into a :class:`Robot`."""
    return Robot(load_robot_spec(path))
