"""YAML configuration files -> frozen dataclasses, with precise errors.

Two formats (see DESIGN.md): ``regrasp.robot/1`` (robot.yaml: URDF, joint groups, hands,
rest configuration, extra disabled collision pairs) and ``regrasp.scene/1`` (scene.yaml:
robot, object, static obstacles, task, planning options).  Parsing checks only the shape
of the data; names are checked against the URDF when the robot is built
(:mod:`regrasp_cli.model.robot`).  Every error is an :class:`InputError` naming the file,
the dotted field and what was expected.  Relative paths are resolved against the
directory of the file that names them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import numpy as np
import yaml

from regrasp_cli.errors import InputError, shown
from regrasp_cli.inputs import check_expansion, read_text, regular_file
from regrasp_cli.examples import BUILTIN_PREFIX, builtin_robot
from regrasp_cli.spatial import pose_matrix

ROBOT_FORMAT = "regrasp.robot/1"
SCENE_FORMAT = "regrasp.scene/1"
HAND_SIDES = ("right", "left")
# Coulomb coefficients of real contact pairs stay below about 2 (rubber on dry rough
# surfaces); at 5 the friction cone's half-angle is 79 degrees and almost any grasp is
# force-closure, so a larger value is a typo, not a material
MAX_FRICTION = 5.0
ARM_OF_HAND = {"right": "right_arm", "left": "left_arm"}
MAX_LENGTH = 1000.0  # m: positions and sizes in a scene (coal's bounding volumes overflow near 1e308)
# budgets a file may ask for: past these a run would last days, not a typo's worth
MAX_SAMPLES = 100_000  # self_collision.samples (3000: about 10 s)
MAX_NODES = 1_000_000  # in-hand planning.nodes (6000: a failed run of 60-110 s)
MAX_RESTARTS = 1000  # planning.ik_restarts
#: PyYAML's safe loader, in C where libyaml is present (a robot.yaml reads in a tenth of the time)
SAFE_LOADER = getattr(yaml, "CSafeLoader", yaml.SafeLoader)


# --------------------------------------------------------------------------- reading


def read_yaml(path: str | Path) -> tuple[Path, dict]:
    """Read a YAML mapping; errors name the file (and the line for syntax errors).  Only
    a regular file of bounded size is read, and a document whose aliases expand to too
    many values is refused (:mod:`regrasp_cli.inputs`)."""
    path = Path(path)
    text = read_text(path, "YAML file")
    try:
        data = yaml.load(text, Loader=SAFE_LOADER)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise InputError(path, None, f"YAML syntax error{where}: {problem}") from None
    except RecursionError:
        raise InputError(path, None, "nested too deeply; expected a configuration file") from None
    check_expansion(data, path)
    if not isinstance(data, dict):
        raise InputError(path, None, f"expected a YAML mapping at the top level, found {_kind(data)}")
    return path.resolve(), data


def _number_text(s: str) -> bool:
    """A string YAML 1.1 left as text although Python reads it as a number (``1.0e9``)."""
    try:
        return math.isfinite(float(s))
    except ValueError:
        return False


def _number_hint(s: str) -> str:
    """How to write the text ``s`` so that YAML 1.1 reads a number."""
    if "e" not in s.lower():
        return "write it without quotes"
    mantissa, _, exponent = f"{float(s):e}".partition("e")
    mantissa = mantissa.rstrip("0")
    mantissa += "0" if mantissa.endswith(".") else ""
    return f"YAML 1.1 reads an exponent without a sign or a number without a dot as text; write {mantissa}e{int(exponent):+d}"


def _kind(v: Any) -> str:
    return "nothing" if v is None else type(v).__name__


class Fields:
    """Typed access to one mapping of a YAML file; every error names file and field."""

    def __init__(self, file: Path, data: Any, where: str = ""):
        self.file, self.where = file, where
        if not isinstance(data, dict):
            raise InputError(file, where or None, f"expected a mapping, found {_kind(data)}")
        self.data = data

    def path(self, key: str) -> str:
        return f"{self.where}.{key}" if self.where else key

    def error(self, key: str | None, message: str) -> InputError:
        return InputError(self.file, self.path(key) if key else (self.where or None), message)

    def has(self, key: str) -> bool:
        return key in self.data

    def only(self, *allowed: str) -> None:
        unknown = sorted(set(map(str, self.data)) - set(allowed))
        if unknown:
            raise self.error(unknown[0], f"unknown key; expected one of: {', '.join(allowed)}")

    def raw(self, key: str) -> Any:
        if key not in self.data:
            raise self.error(key, "missing required key")
        return self.data[key]

    def sub(self, key: str) -> "Fields":
        return Fields(self.file, self.raw(key), self.path(key))

    def str(self, key: str, default: Any = ...) -> str:
        if default is not ... and key not in self.data:
            return default
        v = self.raw(key)
        if not isinstance(v, str) or not v:
            raise self.error(key, f"expected a non-empty string, found {_kind(v)}")
        return v

    def bool(self, key: str, default: Any = ...) -> bool:
        if default is not ... and key not in self.data:
            return default
        v = self.raw(key)
        if not isinstance(v, bool):
            raise self.error(key, f"expected true or false, found {_kind(v)}")
        return v

    def int(self, key: str, default: Any = ..., minimum: int | None = None, maximum: int | None = None) -> int:
        if default is not ... and key not in self.data:
            return default
        v = self.raw(key)
        if isinstance(v, bool) or not isinstance(v, int):
            raise self.error(key, f"expected an integer, found {_kind(v)}")
        if minimum is not None and v < minimum:
            raise self.error(key, f"expected an integer >= {minimum}, found {shown(v)}")
        if maximum is not None and v > maximum:
            raise self.error(key, f"expected an integer <= {maximum:,}, found {shown(v)}")
        return v

    def float(self, key: str, default: Any = ..., positive: bool = False, maximum: float | None = None) -> float:
        if default is not ... and key not in self.data:
            return default
        v = self.raw(key)
        if isinstance(v, str) and _number_text(v):
            raise self.error(key, f"expected a number, found the text {shown(v)} ({_number_hint(v)})")
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise self.error(key, f"expected a finite number, found {shown(v)}")
        if positive and v <= 0:
            raise self.error(key, f"expected a number > 0, found {v}")
        if maximum is not None and v > maximum:
            raise self.error(key, f"expected a number <= {maximum:g}, found {v:g}")
        return float(v)

    def vector(self, key: str, n: int | None = None, positive: bool = False,
               bound: float | None = None) -> tuple[float, ...]:
        return as_vector(self.file, self.path(key), self.raw(key), n, positive, bound)

    def names(self, key: str, default: Any = ...) -> tuple[str, ...]:
        if default is not ... and key not in self.data:
            return default
        v = self.raw(key)
        if not isinstance(v, list) or not all(isinstance(s, str) and s for s in v):
            raise self.error(key, "expected a list of names (strings)")
        return tuple(v)


def as_vector(file, where: str, v: Any, n: int | None = None, positive: bool = False,
              bound: float | None = None) -> tuple[float, ...]:
    """A list of (``n``) finite numbers (> 0 with ``positive``, within +-``bound``)."""
    ok = isinstance(v, list) and all(
        isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) for x in v
    )
    if not ok or (n is not None and len(v) != n):
        shape = f"a list of {n} numbers" if n else "a list of numbers"
        raise InputError(file, where, f"expected {shape}, found {shown(v)}")
    if positive and any(x <= 0 for x in v):
        raise InputError(file, where, f"expected numbers > 0, found {shown(v)}")
    if bound is not None and any(abs(x) > bound for x in v):
        raise InputError(file, where, f"expected numbers within +-{bound:g}, found {shown(v)}")
    return tuple(float(x) for x in v)


def parse_pose(fields: Fields, key: str) -> np.ndarray:
    """``{xyz: [x,y,z], rpy: [r,p,y]}`` or ``{xyz, quat: [x,y,z,w]}`` -> 4x4 (m, rad)."""
    f = fields.sub(key)
    f.only("xyz", "rpy", "quat")
    xyz = f.vector("xyz", 3, bound=MAX_LENGTH)
    if f.has("rpy") and f.has("quat"):
        raise f.error("quat", "give either rpy or quat, not both")
    if f.has("quat"):
        quat = np.array(f.vector("quat", 4))
        m = float(np.abs(quat).max())  # scaled first: the norm of [1e308, 1e308, 0, 0] overflows
        if m == 0.0 or m * float(np.linalg.norm(quat / m)) < 1e-9:
            raise f.error("quat", "quaternion of zero norm; expected [x, y, z, w] with norm 1")
        return pose_matrix(xyz, quat=quat / m / np.linalg.norm(quat / m))
    rpy = f.vector("rpy", 3) if f.has("rpy") else (0.0, 0.0, 0.0)
    return pose_matrix(xyz, rpy=rpy)


def resolve_path(file: Path, where: str, value: str, must_exist: bool = True) -> Path:
    """A path relative to the directory of ``file``; ``package://`` URIs pass through.
    With ``must_exist``, it must name a regular file (a FIFO would block its reader, a
    device never end)."""
    if value.startswith("package://"):
        return Path(value)
    p = Path(value)
    p = p if p.is_absolute() else (file.parent / p)
    try:
        exists = p.exists()
    except OSError as exc:  # a name too long, a loop of links
        raise InputError(file, where, f"cannot use the path {shown(str(p))}: {exc.strerror or exc}") from None
    if must_exist and not exists:
        raise InputError(file, where, f"no such file: {p}")
    if must_exist:
        try:
            regular_file(p)
        except InputError as exc:
            raise InputError(file, where, f"{p} {exc.message}") from None
    return p.resolve() if exists else p


# --------------------------------------------------------------------------- robot.yaml


@dataclass(frozen=True)
class FingerSpec:
    """One finger: its joint chain (root to tip), the fingertip link and sphere radius (m)."""

    name: str
    joints: tuple[str, ...]
    tip_link: str
    tip_radius: float
    open: tuple[float, ...]
    closed: tuple[float, ...] | None = None  # pads hands: where closing ends (default: the far limits)


HAND_KINDS = ("auto", "fingertips", "jaw", "pads")


@dataclass(frozen=True)
class HandSpec:
    """A hand: its side, the arm group it is mounted on, grasp frame and fingers.

    ``grasp_frame`` names a URDF link, or a link and an offset (``{link, xyz, rpy}``: the
    frame is added to the model, so the URDF need not be edited).  ``opposing`` names the
    finger that opposes the others (the thumb), which the fingertip search places first.

    ``contact`` is the contact model for force closure: ``point`` (point contact with
    friction) or ``soft`` (soft finger, for parallel-jaw grippers).  ``kind`` says how
    its grasps are found: ``fingertips`` (seed 000: fingertip IK on surface points, for
    fingers of three or more joints), ``jaw`` (two fingers each closed by one prismatic or
    revolute joint, or following one through URDF mimics: antipodal pairs of surface
    points, closing until contact), ``pads`` (fingers of one or
    two joints: approach along a surface normal, each finger closed from ``open`` to
    ``closed`` until it touches) or ``auto`` (``jaw`` when the fingers are so, else
    ``pads`` when a finger has fewer than three joints, else ``fingertips``;
    :class:`regrasp_cli.model.robot.Hand`).  ``tip_patch`` is what the fingertips are made
    of for `regrasp simulate`: the radius of their contact patch, whose torsional friction
    resists a fingertip spinning on the object (soft tips, 5 mm by default), or 0 for
    rigid tips that touch at a point (seed 003's hand: its fingertips roll and spin on the
    object as they turn it).
    """

    side: str
    arm: str
    grasp_frame: str  # a URDF link or frame
    fingers: tuple[FingerSpec, ...]
    contact: str = "point"
    kind: str = "auto"
    grasp_offset: tuple[tuple[float, ...], tuple[float, ...]] | None = None  # (xyz m, rpy rad) from grasp_frame
    opposing: str | None = None  # the finger that opposes the others (the thumb), by name
    tip_patch: float = 0.005  # m: radius of a fingertip's contact patch in simulation (0: rigid tips)

    @property
    def joints(self) -> tuple[str, ...]:
        return tuple(j for f in self.fingers for j in f.joints)

    @property
    def open(self) -> tuple[float, ...]:
        return tuple(v for f in self.fingers for v in f.open)


@dataclass(frozen=True)
class SelfCollisionOptions:
    """Automatic disabling of self-collision pairs (as MoveIt's setup assistant)."""

    samples: int = 3000
    seed: int = 0
    never_margin: float = 0.02  # m


@dataclass(frozen=True)
class RobotSpec:
    """The content of a robot.yaml file (names not yet checked against the URDF)."""

    file: Path
    urdf: Path
    package_dirs: tuple[Path, ...]
    groups: Mapping[str, tuple[str, ...]]
    hands: Mapping[str, HandSpec]
    rest: Mapping[str, float]
    disabled_collisions: tuple[tuple[str, str], ...]
    self_collision: SelfCollisionOptions = field(default_factory=SelfCollisionOptions)
    srdf: Path | None = None  # a MoveIt SRDF whose disable_collisions pairs are added
    srdf_disabled: tuple[tuple[str, str], ...] = ()
    convex_hulls: bool = True  # mesh collision geometries replaced by their convex hulls
    collision_from_visual: tuple[str, ...] = ()  # links whose visual geometry is their collision geometry
    exact_meshes: tuple[str, ...] = ()  # links that keep their meshes when convex_hulls is on (curled fingers)


def _find_package_share(package: str) -> list[Path]:
    """Directories holding ``<package>/`` from installed data wheels (cmeel layout)."""
    import site
    import sys

    roots = [*site.getsitepackages(), site.getusersitepackages(), *sys.path]
    found = []
    for root in roots:
        share = Path(root) / "cmeel.prefix" / "share"
        if (share / package).is_dir() and share not in found:
            found.append(share)
    return found


def resolve_urdf(file: Path, where: str, value: str) -> tuple[Path, tuple[Path, ...]]:
    """The URDF path and the package directories its ``package://`` URIs need."""
    if value.startswith("package://"):
        package, _, rest = value[len("package://"):].partition("/")
        for share in _find_package_share(package):
            if (share / package / rest).is_file():
                return (share / package / rest), (share,)
        raise InputError(file, where, f"cannot find {value}: is the Python package that ships "
                                      f"'{package}' installed (e.g. pip install {package})?")
    path = resolve_path(file, where, value)
    dirs = [path.parent, *(_find_package_share("example-robot-data"))]
    return path, tuple(dirs)


def load_robot_spec(path: str | Path) -> RobotSpec:
    file, data = read_yaml(path)
    f = Fields(file, data)
    f.only("format", "urdf", "srdf", "groups", "hands", "rest", "disabled_collisions", "self_collision",
           "convex_hulls", "collision_from_visual", "exact_meshes")
    if f.str("format") != ROBOT_FORMAT:
        raise f.error("format", f"expected '{ROBOT_FORMAT}', found {shown(f.data['format'])}")
    urdf, package_dirs = resolve_urdf(file, "urdf", f.str("urdf"))

    g = f.sub("groups")
    g.only("torso", "right_arm", "left_arm")
    if not g.data:  # a hand alone (the wrist is the base): for in-hand planning only
        groups = {name: () for name in ("torso", "right_arm", "left_arm")}
    else:
        groups = {name: g.names(name) for name in ("torso", "right_arm", "left_arm")}
        for name in ("right_arm", "left_arm"):
            if not groups[name]:
                raise g.error(name, "expected at least one joint")

    h = f.sub("hands")
    h.only(*HAND_SIDES)
    hands = {side: _hand(h.sub(side), side) for side in HAND_SIDES if h.has(side)}
    if not hands:
        raise h.error(None, "expected at least one of: right, left")

    rest: dict[str, float] = {}
    if f.has("rest"):
        r = f.sub("rest")
        rest = {str(k): r.float(k) for k in r.data}

    pairs = []
    if f.has("disabled_collisions"):
        raw = f.raw("disabled_collisions")
        if not isinstance(raw, list):
            raise f.error("disabled_collisions", "expected a list of [link_a, link_b] pairs")
        for i, pair in enumerate(raw):
            if not (isinstance(pair, list) and len(pair) == 2 and all(isinstance(s, str) for s in pair)):
                raise f.error(f"disabled_collisions[{i}]", f"expected [link_a, link_b], found {shown(pair)}")
            pairs.append((pair[0], pair[1]))

    sc = SelfCollisionOptions()
    if f.has("self_collision"):
        s = f.sub("self_collision")
        s.only("samples", "seed", "never_margin")
        sc = SelfCollisionOptions(samples=s.int("samples", sc.samples, minimum=1, maximum=MAX_SAMPLES),
                                  seed=s.int("seed", sc.seed),
                                  never_margin=s.float("never_margin", sc.never_margin))

    srdf, srdf_pairs = None, ()
    if f.has("srdf"):
        srdf, _ = resolve_urdf(file, "srdf", f.str("srdf"))
        srdf_pairs = tuple(_srdf_disabled(srdf, file))
    hulls = f.data.get("convex_hulls", True)
    if not isinstance(hulls, bool):
        raise f.error("convex_hulls", f"expected true or false, found {shown(hulls)}")
    return RobotSpec(file, urdf, package_dirs, groups, hands, rest, tuple(pairs), sc, srdf, srdf_pairs, hulls,
                     f.names("collision_from_visual", ()), f.names("exact_meshes", ()))


def _srdf_disabled(srdf: Path, file: Path) -> list[tuple[str, str]]:
    """``<disable_collisions link1= link2=>`` pairs of a MoveIt SRDF."""
    import xml.etree.ElementTree as ET

    try:
        root = ET.parse(srdf).getroot()
    except (ET.ParseError, OSError) as exc:
        raise InputError(file, "srdf", f"cannot parse SRDF {srdf}: {exc}") from None
    return [(e.get("link1", ""), e.get("link2", "")) for e in root.iter("disable_collisions")]


def _hand(h: Fields, side: str) -> HandSpec:
    h.only("grasp_frame", "fingers", "contact", "kind", "opposing", "tip_patch")
    raw = h.raw("fingers")
    if not isinstance(raw, list) or not raw:
        raise h.error("fingers", "expected a non-empty list of fingers")
    fingers = []
    for i, _ in enumerate(raw):
        fi = Fields(h.file, raw[i], h.path(f"fingers[{i}]"))
        fi.only("name", "joints", "tip_link", "tip_radius", "open", "closed")
        joints = fi.names("joints")
        if not joints:
            raise fi.error("joints", "expected at least one joint")
        opened = fi.vector("open", len(joints)) if fi.has("open") else (0.0,) * len(joints)
        closed = fi.vector("closed", len(joints)) if fi.has("closed") else None
        fingers.append(FingerSpec(fi.str("name", f"finger{i}"), joints, fi.str("tip_link"),
                                  fi.float("tip_radius", positive=True), opened, closed))
    contact = h.str("contact", "point")
    if contact not in ("point", "soft"):
        raise h.error("contact", f"expected 'point' or 'soft', found {shown(contact)}")
    kind = h.str("kind", "auto")
    if kind not in HAND_KINDS:
        raise h.error("kind", f"expected one of {', '.join(HAND_KINDS)}, found {shown(kind)}")
    names = [f.name for f in fingers]
    if len(set(names)) != len(names):
        raise h.error("fingers", f"finger names must differ, found {names}")
    opposing = h.str("opposing", None)
    if opposing is not None and opposing not in names:
        raise h.error("opposing", f"expected the name of one of the fingers ({', '.join(names)}), found {shown(opposing)}")
    tip_patch = h.float("tip_patch", HandSpec.tip_patch, maximum=0.05)
    if tip_patch < 0:
        raise h.error("tip_patch", f"expected a radius >= 0 (m; 0: rigid fingertips), found {tip_patch:g}")
    link, offset = _grasp_frame(h)
    return HandSpec(side, ARM_OF_HAND[side], link, tuple(fingers), contact, kind, offset, opposing, tip_patch)


def _grasp_frame(h: Fields) -> tuple[str, tuple[tuple[float, ...], tuple[float, ...]] | None]:
    """``grasp_frame: LINK`` or ``grasp_frame: {link: LINK, xyz: [..], rpy: [..]}``."""
    if not isinstance(h.raw("grasp_frame"), dict):
        return h.str("grasp_frame"), None
    g = h.sub("grasp_frame")
    g.only("link", "xyz", "rpy")
    xyz = g.vector("xyz", 3) if g.has("xyz") else (0.0, 0.0, 0.0)
    rpy = g.vector("rpy", 3) if g.has("rpy") else (0.0, 0.0, 0.0)
    return g.str("link"), (xyz, rpy)


# --------------------------------------------------------------------------- scene.yaml

SHAPES = ("box", "cylinder", "sphere", "mesh")


@dataclass(frozen=True)
class ObstacleSpec:
    """A static obstacle in the robot base frame W.

    ``size``: box (x, y, z) side lengths; cylinder (radius, length) along its z;
    sphere (radius,); mesh (scale,).  ``mesh`` is the mesh file for ``shape == 'mesh'``.
    """

    name: str
    shape: str
    size: tuple[float, ...]
    X_WO: np.ndarray  # (4, 4) pose of the obstacle frame O in W
    mesh: Path | None = None


@dataclass(frozen=True)
class ObjectSpec:
    mesh: str  # 'builtin:NAME' or a path resolved against the scene file
    scale: float = 1.0
    friction: float = 0.5


@dataclass(frozen=True)
class TaskSpec:
    X_WO_start: np.ndarray  # (4, 4) object start pose in W
    X_WO_goal: np.ndarray  # (4, 4) object goal pose in W
    robot_start: str | Mapping[str, float]  # 'rest' or joint -> value (others at rest)
    robot_goal: str | Mapping[str, float]


@dataclass(frozen=True)
class PlanningOptions:
    """Options shared by the planning stages (metres, radians)."""

    seed: int = 0
    segment_resolution: float = 0.02  # rad: largest joint step when checking a segment
    contact_tolerance: float = 0.002  # m: fingertip-object penetration allowed in a grasp
    ik_restarts: int = 30


@dataclass(frozen=True)
class SceneSpec:
    file: Path
    robot: Path
    object: ObjectSpec
    obstacles: tuple[ObstacleSpec, ...]
    task: TaskSpec
    planning: PlanningOptions
    supports: tuple[str, ...] | None = None  # obstacles whose tops may hold the object (None: any top)


def load_scene_spec(path: str | Path) -> SceneSpec:
    file, data = read_yaml(path)
    f = Fields(file, data)
    f.only("format", "robot", "object", "obstacles", "task", "planning", "supports")
    if f.str("format") != SCENE_FORMAT:
        raise f.error("format", f"expected '{SCENE_FORMAT}', found {shown(f.data['format'])}")
    robot = _robot_path(f)
    obj = _object(f, 0.5)

    obstacles = _obstacles(f)

    t = f.sub("task")
    t.only("object_start", "object_goal", "robot_start", "robot_goal")
    task = TaskSpec(parse_pose(t, "object_start"), parse_pose(t, "object_goal"),
                    _robot_conf(t, "robot_start"), _robot_conf(t, "robot_goal"))

    planning = PlanningOptions()
    if f.has("planning"):
        p = f.sub("planning")
        p.only("seed", "segment_resolution", "contact_tolerance", "ik_restarts")
        planning = PlanningOptions(
            seed=p.int("seed", planning.seed, minimum=0),
            segment_resolution=p.float("segment_resolution", planning.segment_resolution, positive=True),
            contact_tolerance=p.float("contact_tolerance", planning.contact_tolerance, positive=True),
            ik_restarts=p.int("ik_restarts", planning.ik_restarts, minimum=1, maximum=MAX_RESTARTS),
        )
    return SceneSpec(file, robot, obj, obstacles, task, planning, _supports(f, obstacles))


def _robot_path(f: Fields) -> Path:
    """``robot``: ``builtin:NAME`` or a robot.yaml path relative to the file."""
    value = f.str("robot")
    return builtin_robot(f.file, "robot", value) if value.startswith(BUILTIN_PREFIX) else \
        resolve_path(f.file, "robot", value)


def _object(f: Fields, friction: float) -> ObjectSpec:
    """``object``: ``mesh`` (``builtin:NAME`` or a path relative to the file), ``scale``,
    ``friction`` (default ``friction``)."""
    o = f.sub("object")
    o.only("mesh", "scale", "friction")
    mesh = o.str("mesh")
    if not mesh.startswith("builtin:"):
        mesh = str(resolve_path(f.file, "object.mesh", mesh))
    return ObjectSpec(mesh, o.float("scale", 1.0, positive=True),
                      o.float("friction", friction, positive=True, maximum=MAX_FRICTION))


def _obstacles(f: Fields) -> tuple[ObstacleSpec, ...]:
    """``obstacles``: a list of obstacles with distinct names (default none)."""
    raw = f.data.get("obstacles", []) or []
    if not isinstance(raw, list):
        raise f.error("obstacles", "expected a list of obstacles")
    obstacles = tuple(_obstacle(Fields(f.file, item, f"obstacles[{i}]")) for i, item in enumerate(raw))
    names = [ob.name for ob in obstacles]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise f.error("obstacles", f"duplicate obstacle name {shown(dup[0])}")
    return obstacles


def _supports(f: Fields, obstacles: tuple[ObstacleSpec, ...]) -> tuple[str, ...] | None:
    """``supports``: names of box or cylinder obstacles whose tops may hold the object
    (Harada et al. 2014 §III-C: placements on the environment's surfaces)."""
    if not f.has("supports"):
        return None
    names = f.names("supports")
    shapes = {ob.name: ob.shape for ob in obstacles}
    for i, name in enumerate(names):
        if name not in shapes:
            raise InputError(f.file, f"supports[{i}]", f"no obstacle named {shown(name)} (obstacles: "
                                                       f"{', '.join(shapes) or 'none'})")
        if shapes[name] not in ("box", "cylinder"):
            raise InputError(f.file, f"supports[{i}]", f"obstacle {shown(name)} is a {shapes[name]}: expected a box "
                                                       "or a cylinder, whose flat top can hold the object")
    return names


def _obstacle(f: Fields) -> ObstacleSpec:
    f.only("name", "pose", *SHAPES)
    name = f.str("name")
    given = [s for s in SHAPES if f.has(s)]
    if len(given) != 1:
        raise f.error(None, f"obstacle {shown(name)}: expected exactly one of {', '.join(SHAPES)}")
    shape = given[0]
    X = parse_pose(f, "pose")
    g = f.sub(shape)
    mesh = None
    if shape == "box":
        g.only("size")
        size = g.vector("size", 3, positive=True, bound=MAX_LENGTH)
    elif shape == "cylinder":
        g.only("radius", "length")
        size = (g.float("radius", positive=True, maximum=MAX_LENGTH),
                g.float("length", positive=True, maximum=MAX_LENGTH))
    elif shape == "sphere":
        g.only("radius")
        size = (g.float("radius", positive=True, maximum=MAX_LENGTH),)
    else:
        g.only("file", "scale")
        mesh = resolve_path(f.file, g.path("file"), g.str("file"))
        size = (g.float("scale", 1.0, positive=True),)
    return ObstacleSpec(name, shape, size, X, mesh)


def _robot_conf(t: Fields, key: str) -> str | Mapping[str, float]:
    v = t.data.get(key, "rest")
    if v == "rest":
        return "rest"
    if isinstance(v, dict):
        c = t.sub(key)
        return {str(k): c.float(k) for k in c.data}
    raise t.error(key, f"expected 'rest' or a mapping joint -> value (rad or m), found {shown(v)}")


# --------------------------------------------------------------------------- inhand.yaml

INHAND_FORMAT = "regrasp.inhand/1"


def scene_files(spec: "SceneSpec | InhandSpec") -> tuple[Path, ...]:
    """The files a scene (pick-and-place or in-hand) reads: itself, its robot.yaml, the
    robot's URDF and SRDF, the object's and the obstacles' meshes.  A command's output
    must be none of them (:func:`regrasp_cli.store.check_writable`)."""
    robot = load_robot_spec(spec.robot)
    meshes = [ob.mesh for ob in spec.obstacles if ob.mesh is not None]
    if not spec.object.mesh.startswith(BUILTIN_PREFIX):
        meshes.append(Path(spec.object.mesh))
    return (spec.file, robot.file, robot.urdf, *((robot.srdf,) if robot.srdf else ()), *meshes)


INHAND_MODES = ("single-query", "multi-query")


@dataclass(frozen=True)
class InhandPlanning:
    """Options of the in-hand planner (seed 003): ``nodes`` the tree's budget of
    expansions, ``step_rad`` the object's turn per edge, ``gait_m`` the contact drift
    before a finger steps (metres, radians), ``smooth`` whether runs of finger steps are
    shortened (:mod:`regrasp_cli.dexterous.smooth`); ``mode`` single-query (trees from
    the start and the goal) or multi-query (the learned roadmap of
    :mod:`regrasp_cli.dexterous.multiquery`, built and cached when missing)."""

    seed: int = 0
    nodes: int = 6000  # a failed run: about 60-110 s on hand4 (docs/DESIGN-NOTES.md, "Budget and restarts")
    step_rad: float = 0.35
    gait_m: float = 0.012
    smooth: bool = True
    mode: str = "single-query"
    contact_tolerance: float = 0.002  # m: fingertip-object penetration at a contact (the grasp search's; not a field)


@dataclass(frozen=True)
class InhandSpec:
    """An in-hand problem (``format: regrasp.inhand/1``): the hand's wrist is fixed (the
    robot at ``robot_config``, the hand open), poses are in the hand's grasp frame G."""

    file: Path
    robot: Path
    hand: str  # "right" or "left": a hand of the robot.yaml
    robot_config: str | Mapping[str, float]  # 'rest' or joint -> value: where the arm holds the wrist
    object: ObjectSpec
    X_GO_start: np.ndarray  # (4, 4) object start pose in G
    X_GO_goal: np.ndarray  # (4, 4) object goal pose in G (its position the start's when not given)
    start_grasp: Mapping[str, tuple[float, ...]] | None  # finger name -> contact point in O; None: find one
    planning: InhandPlanning
    obstacles: tuple[ObstacleSpec, ...] = ()  # poses (X_WO) in G as read; in W in a loaded problem


def load_inhand_spec(path: str | Path) -> InhandSpec:
    """Read an in-hand scene; bad input raises InputError naming the file and field."""
    file, data = read_yaml(path)
    f = Fields(file, data)
    f.only("format", "robot", "hand", "robot_config", "object", "object_start", "object_goal", "start_grasp",
           "planning", "obstacles")
    if f.str("format") != INHAND_FORMAT:
        raise f.error("format", f"expected '{INHAND_FORMAT}', found {shown(f.data['format'])}")
    robot = _robot_path(f)
    hand = f.str("hand", "right")
    if hand not in ("right", "left"):
        raise f.error("hand", f"expected 'right' or 'left', found {shown(hand)}")
    obj = _object(f, 0.8)  # fingertips: rubber on the object
    start = parse_pose(f, "object_start")
    g = f.sub("object_goal")
    g.only("xyz", "rpy", "quat")
    xyz = {} if g.has("xyz") else {"xyz": [float(x) for x in start[:3, 3]]}  # the object turns where it is
    goal = parse_pose(Fields(file, {"object_goal": {**g.data, **xyz}}), "object_goal")
    grasp = None
    v = f.data.get("start_grasp", "find")
    if v != "find":
        if not isinstance(v, dict) or not v:
            raise f.error("start_grasp", f"expected 'find' or a mapping finger name -> contact point [x, y, z] "
                                         f"in the object frame, found {shown(v)}")
        s = f.sub("start_grasp")
        grasp = {str(k): s.vector(k, 3) for k in s.data}
    planning = InhandPlanning()
    if f.has("planning"):
        p = f.sub("planning")
        p.only("seed", "nodes", "step_rad", "gait_m", "smooth", "mode")
        mode = p.str("mode", planning.mode)
        if mode not in INHAND_MODES:
            raise p.error("mode", f"expected one of {', '.join(INHAND_MODES)}, found {shown(mode)}")
        planning = InhandPlanning(p.int("seed", planning.seed, minimum=0),
                                  p.int("nodes", planning.nodes, minimum=1, maximum=MAX_NODES),
                                  p.float("step_rad", planning.step_rad, positive=True, maximum=3.2),
                                  p.float("gait_m", planning.gait_m, positive=True),
                                  p.bool("smooth", planning.smooth), mode)
    return InhandSpec(file, robot, hand, _robot_conf(f, "robot_config"), obj, start, goal, grasp, planning,
                      _obstacles(f))
