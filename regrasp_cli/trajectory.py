"""The plan JSON (``format: regrasp.plan/2``): what `regrasp plan` writes and `regrasp
validate` and `regrasp show` read.

A plan is self-contained for an independent checker: besides the motion it records the
URDF and the object mesh it was planned for (paths and SHA-256), the obstacles as
resolved, the self-collision pairs that were disabled, the collision tolerances, the
grasps it uses (any number per hand, each with an ``id``: hand pose in the object frame,
finger values, contacts) and the ``placements`` where the object rests (``start``,
``goal``, and any intermediate one).

The motion is a list of phases, each a transition between manipulation modes
(:mod:`regrasp_cli.manip.modes`): ``kind`` (transit, transfer, grasp, release, handover,
inhand-transfer, inhand-regrasp), ``holding`` (hand -> grasp id: the hands that hold the
object rigidly during all of it), ``touching`` (the hands whose fingers close on, open
off or move on the object), ``placement`` (the placement id where the object rests, for
the kinds in which it rests, else null), its waypoints (full configurations in the order
of ``joint_names``, joined by straight joint-space segments) and their times (s from the
plan start at which the motion passes them), with ``blends`` (a radius per waypoint: the
corner cut by a parabolic blend, 0 at a stop) and ``timing`` (the path speed on a grid,
:mod:`regrasp_cli.motion.blend`), or without both (stop at every waypoint, trapezoids of
:mod:`regrasp_cli.motion.timing`), and optionally
per-waypoint ``object_poses`` (4x4 in W) and ``contacts`` (per waypoint, a list of
``{finger, point, normal}`` in the object frame) for motions where the object moves
relative to the palm.  The first waypoint of a phase equals the last of the previous
phase.  ``name`` is a label for people; no program reads meaning from it.

Poses are 4x4 nested lists (metres), configurations lists of floats in the units of the
joints (rad or m).  Floats are written with ``repr`` precision and keys in a fixed order,
so that the same plan gives the same bytes.  Plans of format ``regrasp.plan/1`` (before
manipulation modes) are refused with a line saying to plan again.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from regrasp_cli.errors import InputError, shown
from regrasp_cli.inputs import loads_json, read_text
from regrasp_cli.manip.modes import KIND_NAMES, Kind
from regrasp_cli.motion.blend import BlendedPath, Timing, blended_path, trajectory
from regrasp_cli.motion.timing import evaluate_trajectory
from regrasp_cli.store import atomic_write_text

FORMAT = "regrasp.plan/2"
OLD_FORMATS = ("regrasp.plan/1",)
MAX_PHASE_S = 3600.0  # s: longer phases are refused: the validator's and viewer's samples would not fit in memory
MAX_PLAN_S = 86400.0  # s: times past this are refused, for the same reason
MAX_MAGNITUDE = 1e9  # any number of a plan: the squares and cross products of the checks stay finite


@dataclass(frozen=True)
class PlanGrasp:
    id: str  # unique in the plan; phases name it in ``holding``
    hand: str
    X_OG: np.ndarray  # (4, 4) grasp frame G in the object frame O ("hand_in_object")
    finger_joints: tuple[str, ...]
    finger_values: np.ndarray  # (n,) closed on the object
    contacts: tuple[dict, ...]  # {finger, point (3,), normal (3,)} in frame O, fingers in contact
    quality: float  # the grasp list's total score
    list_index: int | None = None  # index in the cached grasp list it came from


@dataclass(frozen=True)
class Placement:
    id: str  # "start", "goal", or an intermediate placement's name
    X_WO: np.ndarray  # (4, 4) object pose in W where it rests


@dataclass(frozen=True)
class Phase:
    name: str  # a label for people
    kind: Kind
    holding: dict[str, str]  # hand -> grasp id, hands holding the object during the whole phase
    touching: tuple[str, ...]  # hands whose fingers move on the object
    placement: str | None  # where the object rests during the phase (kinds where it rests)
    waypoints: np.ndarray  # (k, nq)
    times: np.ndarray  # (k,) s from the plan start
    object_poses: np.ndarray | None = None  # (k, 4, 4) X_WO per waypoint, optional
    contacts: tuple[tuple[dict, ...], ...] | None = None  # per waypoint {finger, point, normal} in O
    blends: np.ndarray | None = None  # (k,) blend radius per waypoint, 0 at a stop (motion.blend); None: every one a stop
    timing: Timing | None = None  # path speed on a grid, with ``blends`` (motion.blend); None: stop-to-stop trapezoids

    def path(self) -> BlendedPath | None:
        """The geometric path with its blends, or None for a stop-at-every-waypoint phase."""
        return None if self.timing is None else blended_path(self.waypoints, self.blends)

    def evaluate(self, t, velocity: np.ndarray, acceleration: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Positions and velocities (m, nq) at plan times t (m,), clamped to the phase;
        ``velocity``, ``acceleration`` (nq,): the limits the trapezoids of a phase without
        ``timing`` were computed with.  Raises ValueError on inconsistent timing."""
        if self.timing is None:
            return evaluate_trajectory(self.waypoints, self.times, velocity, acceleration, t)
        q, qd, _ = trajectory(self.path(), self.timing, t)
        return q, qd


@dataclass(frozen=True)
class Plan:
    status: str  # "solved" or "failed"
    failure: dict | None  # {"stage", "reason"} when failed
    scene: dict  # {"file", "sha256"}
    robot: dict  # {"urdf", "urdf_sha256", "robot_yaml", "robot_yaml_sha256"}
    joint_names: tuple[str, ...]
    limits: dict  # {"lower", "upper", "velocity", "acceleration"} lists (nq,)
    object: dict  # {"name", "mesh", "sha256", "friction"}
    obstacles: tuple[dict, ...]  # {"name", "shape", "size", "pose" (4x4), "mesh"}
    collision: dict  # {"contact_tolerance", "support_tolerance", "disabled_pairs"}
    grasps: tuple[PlanGrasp, ...] = ()
    placements: tuple[Placement, ...] = ()
    phases: tuple[Phase, ...] = ()
    stats: dict = field(default_factory=dict)
    seed: int = 0
    planner: str = "roadmap"
    task: str = ""

    def grasp(self, gid: str) -> PlanGrasp | None:
        return next((g for g in self.grasps if g.id == gid), None)

    def placement(self, pid: str) -> Placement | None:
        return next((p for p in self.placements if p.id == pid), None)

    @property
    def duration(self) -> float:
        return float(self.phases[-1].times[-1]) if self.phases else 0.0


# ------------------------------------------------------------------ writing


def _num(x: Any) -> Any:
    """Plain JSON values: arrays to nested lists, numpy scalars to Python, -0.0 to 0.0."""
    if isinstance(x, np.ndarray):
        return _num(x.tolist())
    if isinstance(x, (list, tuple)):
        return [_num(v) for v in x]
    if isinstance(x, dict):
        return {k: _num(v) for k, v in x.items()}
    if isinstance(x, Kind):
        return x.value
    if isinstance(x, (np.floating, float)):
        v = float(x)
        if not math.isfinite(v):
            raise ValueError(f"non-finite number {v} in a plan")
        return v + 0.0
    if isinstance(x, (np.integer,)):
        return int(x)
    if isinstance(x, np.bool_):
        return bool(x)
    return x


def _phase_dict(p: Phase) -> dict:
    d = {"name": p.name, "kind": p.kind.value, "holding": dict(p.holding), "touching": list(p.touching),
         "placement": p.placement, "waypoints": p.waypoints, "times": p.times}
    if p.object_poses is not None:
        d["object_poses"] = p.object_poses
    if p.contacts is not None:
        d["contacts"] = [list(c) for c in p.contacts]
    if p.timing is not None:
        d["blends"] = p.blends
        d["timing"] = {"s": p.timing.s, "speed": p.timing.sd, "t": p.timing.t}
    return d


def plan_to_dict(plan: Plan) -> dict:
    return _num({
        "format": FORMAT,
        "status": plan.status,
        "failure": plan.failure,
        "planner": plan.planner,
        "task": plan.task,
        "seed": plan.seed,
        "scene": plan.scene,
        "robot": plan.robot,
        "joint_names": list(plan.joint_names),
        "limits": plan.limits,
        "object": plan.object,
        "obstacles": list(plan.obstacles),
        "collision": plan.collision,
        "grasps": [{"id": g.id, "hand": g.hand, "list_index": g.list_index, "hand_in_object": g.X_OG,
                    "finger_joints": list(g.finger_joints), "finger_values": g.finger_values,
                    "contacts": list(g.contacts), "quality": g.quality} for g in plan.grasps],
        "placements": [{"id": p.id, "pose": p.X_WO} for p in plan.placements],
        "phases": [_phase_dict(p) for p in plan.phases],
        "stats": plan.stats,
    })


def dumps(plan: Plan) -> str:
    return json.dumps(plan_to_dict(plan), indent=1, allow_nan=False) + "\n"


def write_plan(path: str | Path, plan: Plan) -> None:
    """Write atomically (temporary file renamed into place)."""
    atomic_write_text(path, dumps(plan))


def write_refused(path: str | Path, plan: Plan, failure: dict) -> None:
    """Write ``plan`` again with status ``failed`` and ``failure`` ({"stage", "reason", ...}):
    a plan that its validation refused never says ``solved``."""
    write_plan(path, replace(plan, status="failed", failure=failure))


# ------------------------------------------------------------------ reading


class _Reader:
    def __init__(self, file: Path):
        self.file = file

    def error(self, where: str, message: str) -> InputError:
        return InputError(self.file, where, message)

    def get(self, d: Any, key: str, where: str, kind: type | tuple[type, ...]) -> Any:
        if not isinstance(d, dict) or key not in d:
            raise self.error(f"{where}{key}", "missing")
        v = d[key]
        kinds = kind if isinstance(kind, tuple) else (kind,)
        if not isinstance(v, kinds) or isinstance(v, bool) and bool not in kinds:
            names = "/".join("null" if k is type(None) else k.__name__ for k in kinds)
            raise self.error(f"{where}{key}", f"expected {names}, found {type(v).__name__}")
        return v

    def array(self, v: Any, where: str, shape: tuple[int | None, ...]) -> np.ndarray:
        try:
            a = np.asarray(v, dtype=float)
        except (TypeError, ValueError):
            raise self.error(where, f"expected an array of numbers of shape {shape}") from None
        if a.ndim != len(shape) or any(s is not None and s != n for s, n in zip(shape, a.shape)):
            raise self.error(where, f"expected shape {tuple('n' if s is None else s for s in shape)}, found {a.shape}")
        if not np.all(np.isfinite(a)):
            raise self.error(where, "expected finite numbers")
        if a.size and np.abs(a).max() > MAX_MAGNITUDE:
            raise self.error(where, f"expected numbers within +-{MAX_MAGNITUDE:g}")
        return a


def _grasps(r: _Reader, d: dict) -> tuple[PlanGrasp, ...]:
    out, seen = [], set()
    for i, g in enumerate(r.get(d, "grasps", "", list)):
        w = f"grasps[{i}]."
        gid = r.get(g, "id", w, str)
        if gid in seen:
            raise r.error(w + "id", f"grasp id {shown(gid)} is used twice; ids must be unique")
        seen.add(gid)
        fj = tuple(r.get(g, "finger_joints", w, list))
        index = g.get("list_index")
        out.append(PlanGrasp(gid, r.get(g, "hand", w, str),
                             r.array(r.get(g, "hand_in_object", w, list), w + "hand_in_object", (4, 4)),
                             fj, r.array(r.get(g, "finger_values", w, list), w + "finger_values", (len(fj),)),
                             tuple(r.get(g, "contacts", w, list)), float(r.get(g, "quality", w, (int, float))),
                             index if isinstance(index, int) and not isinstance(index, bool) else None))
    return tuple(out)


def _placements(r: _Reader, d: dict) -> tuple[Placement, ...]:
    out = []
    for i, p in enumerate(r.get(d, "placements", "", list)):
        w = f"placements[{i}]."
        pid = r.get(p, "id", w, str)
        if any(q.id == pid for q in out):
            raise r.error(w + "id", f"placement id {shown(pid)} is used twice; ids must be unique")
        out.append(Placement(pid, r.array(r.get(p, "pose", w, list), w + "pose", (4, 4))))
    for need in ("start", "goal"):
        if not any(p.id == need for p in out):
            raise r.error("placements", f"expected a placement with id {shown(need)} (the object's {need} pose)")
    return tuple(out)


def _holding(r: _Reader, p: dict, w: str, grasps: dict[str, PlanGrasp]) -> dict[str, str]:
    holding = r.get(p, "holding", w, dict)
    for hand, gid in holding.items():
        if not isinstance(gid, str):
            raise r.error(f"{w}holding.{hand}", f"expected a grasp id (string), found {type(gid).__name__}")
        if gid not in grasps:
            known = ", ".join(repr(k) for k in grasps) or "none"
            raise r.error(f"{w}holding.{hand}", f"grasp id {shown(gid)} is not in grasps[] (ids: {known})")
        if grasps[gid].hand != hand:
            raise r.error(f"{w}holding.{hand}", f"grasp {shown(gid)} is a grasp of the {grasps[gid].hand} hand, "
                                                f"not of the {hand} hand")
    return dict(holding)


def _kind_rules(r: _Reader, w: str, kind: Kind, holding: dict, touching: tuple, placement: str | None,
                placements: tuple[Placement, ...]) -> None:
    """What a phase's kind says about who holds, who touches and where the object rests."""
    if kind.object_rests:
        if placement is None:
            raise r.error(w + "placement", f"a {kind.value} phase has the object resting: expected the id of "
                                           "one of placements[]")
        if holding:
            raise r.error(w + "holding", f"the object rests at placement {shown(placement)} in a {kind.value} phase, "
                                         f"so no hand can hold it; found {', '.join(holding)}")
    elif placement is not None:
        raise r.error(w + "placement", f"the object is not resting in a {kind.value} phase; expected null, "
                                       f"found {shown(placement)}")
    if placement is not None and not any(p.id == placement for p in placements):
        raise r.error(w + "placement", f"placement id {shown(placement)} is not in placements[] "
                                       f"(ids: {', '.join(repr(p.id) for p in placements)})")
    if kind in (Kind.TRANSFER, Kind.HANDOVER) and not holding:
        raise r.error(w + "holding", f"a {kind.value} phase needs a hand holding the object; found none")
    if kind.fingers_on_object and not touching:
        raise r.error(w + "touching", f"a {kind.value} phase moves some hand's fingers on the object; "
                                      "expected at least one hand")
    if kind in (Kind.TRANSIT, Kind.TRANSFER) and touching:
        raise r.error(w + "touching", f"no fingers move on the object in a {kind.value} phase; expected [], "
                                      f"found {list(touching)}")
    both = set(holding) & set(touching)
    if both:
        raise r.error(w + "touching", f"the {', '.join(sorted(both))} hand both holds and moves its fingers")


def _phase(r: _Reader, p: Any, i: int, nq: int, grasps: dict[str, PlanGrasp],
           placements: tuple[Placement, ...]) -> Phase:
    w = f"phases[{i}]."
    kind_name = r.get(p, "kind", w, str)
    if kind_name not in KIND_NAMES:
        raise r.error(w + "kind", f"expected one of {', '.join(KIND_NAMES)}, found {shown(kind_name)}")
    kind = Kind(kind_name)
    holding = _holding(r, p, w, grasps)
    touching = tuple(r.get(p, "touching", w, list))
    if not all(isinstance(h, str) for h in touching):
        raise r.error(w + "touching", "expected a list of hand names (strings)")
    placement = r.get(p, "placement", w, (str, type(None)))
    _kind_rules(r, w, kind, holding, touching, placement, placements)
    wp = r.array(r.get(p, "waypoints", w, list), w + "waypoints", (None, nq))
    if not len(wp):
        raise r.error(w + "waypoints", "expected at least one waypoint")
    times = r.array(r.get(p, "times", w, list), w + "times", (len(wp),))
    if np.ptp(times) > MAX_PHASE_S or np.abs(times).max() > MAX_PLAN_S:
        raise r.error(w + "times", f"times from {times.min():.6g} to {times.max():.6g} s; expected a phase of at "
                                   f"most {MAX_PHASE_S:g} s within {MAX_PLAN_S:g} s of the plan's start")
    poses = None
    if p.get("object_poses") is not None:
        poses = r.array(p["object_poses"], w + "object_poses", (len(wp), 4, 4))
    elif kind.inhand:
        raise r.error(w + "object_poses", f"a {kind.value} phase moves the object in the hand: expected its "
                                          "pose at every waypoint")
    contacts = _contacts(r, p, w, len(wp), kind)
    blends, timing = _timing(r, p, w, wp)
    return Phase(r.get(p, "name", w, str), kind, holding, touching, placement, wp, times, poses, contacts,
                 blends, timing)


def _contacts(r: _Reader, p: dict, w: str, k: int, kind: Kind) -> tuple[tuple[dict, ...], ...] | None:
    """A phase's ``contacts``: one list per waypoint (k) of ``{finger, point (3,), normal
    (3,)}`` in the object frame, each finger at most once; required in in-hand phases."""
    if p.get("contacts") is None:
        if kind.inhand:
            raise r.error(w + "contacts", f"an {kind.value} phase moves the object in the fingertips: expected "
                                          "their contacts at every waypoint")
        return None
    c = r.get(p, "contacts", w, list)
    if len(c) != k:
        raise r.error(w + "contacts", f"expected one list of contacts per waypoint ({k}), found {len(c)}")
    return tuple(_waypoint_contacts(r, x, f"{w}contacts[{i}]") for i, x in enumerate(c))


def _waypoint_contacts(r: _Reader, x: Any, w: str) -> tuple[dict, ...]:
    if not isinstance(x, list):
        raise r.error(w, f"expected a list of contacts, found {type(x).__name__}")
    out: list[dict] = []
    for j, c in enumerate(x):
        cw = f"{w}[{j}]"
        if not isinstance(c, dict):
            raise r.error(cw, f"expected a contact {{finger, point, normal}}, found {type(c).__name__}")
        finger = r.get(c, "finger", cw + ".", str)
        if any(o["finger"] == finger for o in out):  # one contact per finger: a second would go unchecked
            raise r.error(cw + ".finger", f"finger {shown(finger)} has two contacts at this waypoint")
        out.append({"finger": finger, **{key: r.array(r.get(c, key, cw + ".", list), f"{cw}.{key}", (3,))
                                         for key in ("point", "normal")}})
    return tuple(out)


def _timing(r: _Reader, p: dict, w: str, wp: np.ndarray) -> tuple[np.ndarray | None, Timing | None]:
    """A phase's ``blends`` and ``timing``: both or neither, of consistent shapes (a speed
    grid of g >= 2 points, s and t increasing); whether they fit the waypoints is the
    validator's business."""
    if p.get("timing") is None and p.get("blends") is None:
        return None, None
    blends = r.array(r.get(p, "blends", w, list), w + "blends", (len(wp),))
    tm = r.get(p, "timing", w, dict)
    s, sd, t = (r.array(r.get(tm, k, w + "timing.", list), f"{w}timing.{k}", (None,)) for k in ("s", "speed", "t"))
    if len(s) < 2 or sd.shape != s.shape or t.shape != s.shape:
        raise r.error(w + "timing", f"expected s, speed and t of one length >= 2, found {len(s)}, {len(sd)}, {len(t)}")
    if np.any(np.diff(s) <= 0) or np.any(np.diff(t) <= 0) or np.any(sd < 0):
        raise r.error(w + "timing", "expected s and t strictly increasing and speed >= 0")
    if t[-1] - t[0] > MAX_PHASE_S or np.abs(t).max() > MAX_PLAN_S:
        raise r.error(w + "timing.t", f"times from {t[0]:.6g} to {t[-1]:.6g} s; expected a phase of at most "
                                      f"{MAX_PHASE_S:g} s within {MAX_PLAN_S:g} s of the plan's start")
    return blends, Timing(s, sd, t)


def plan_from_dict(d: Any, file: Path) -> Plan:
    r = _Reader(file)
    if not isinstance(d, dict):
        raise r.error("", "expected a JSON object")
    fmt = r.get(d, "format", "", str)
    if fmt in OLD_FORMATS:
        raise r.error("format", f"{shown(fmt)} was written by an earlier regrasp; this one reads {shown(FORMAT)}: plan "
                                "again with `regrasp plan SCENE`")
    if fmt != FORMAT:
        raise r.error("format", f"expected '{FORMAT}', found {shown(fmt)}")
    status = r.get(d, "status", "", str)
    if status not in ("solved", "failed"):
        raise r.error("status", f"expected 'solved' or 'failed', found {shown(status)}")
    names = tuple(r.get(d, "joint_names", "", list))
    grasps = _grasps(r, d)
    placements = _placements(r, d)
    by_id = {g.id: g for g in grasps}
    phases = tuple(_phase(r, p, i, len(names), by_id, placements) for i, p in enumerate(r.get(d, "phases", "", list)))
    return Plan(status, d.get("failure"), r.get(d, "scene", "", dict), r.get(d, "robot", "", dict), names,
                r.get(d, "limits", "", dict), r.get(d, "object", "", dict), tuple(r.get(d, "obstacles", "", list)),
                r.get(d, "collision", "", dict), grasps, placements, phases, d.get("stats", {}),
                r.get(d, "seed", "", int) if "seed" in d else 0, str(d.get("planner", "roadmap")),
                str(d.get("task", "")))


def read_plan(path: str | Path) -> Plan:
    """Load a plan JSON; malformed content raises an InputError naming the field."""
    path = Path(path)
    return plan_from_dict(loads_json(read_text(path, "plan"), path), path)
