"""The plan JSON (``format: regrasp.plan/1``): what `regrasp plan` writes and `regrasp
validate` reads.

A plan is self-contained for an independent checker: besides the motion it records the
URDF and the object mesh it was planned for (paths and SHA-256), the obstacles as
resolved, the self-collision pairs that were disabled, the collision tolerances, the
grasps (hand pose in the object frame, finger values, contacts) and the object's start,
exchange and goal poses.  The motion is a list of phases; each phase has the hands that
hold the object during all of it (``holding``; the object is static in the world when
empty) and the hands whose fingertips may touch it (``touching``), its waypoints (full
configurations in the order of ``joint_names``, joined by straight joint-space segments)
and their times (s from the plan start; stop at every waypoint, :mod:`plan.timing`).  The
first waypoint of a phase equals the last of the previous phase.

Poses are 4x4 nested lists (metres), configurations lists of floats in the units of the
joints (rad or m).  Floats are written with ``repr`` precision and keys in a fixed order,
so that the same plan gives the same bytes.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from regrasp_cli.errors import InputError
from regrasp_cli.store import atomic_write_text

FORMAT = "regrasp.plan/1"
PHASES = ("grasp", "close_right", "carry", "close_left", "open_right", "place", "open_left", "rest")


@dataclass(frozen=True)
class PlanGrasp:
    hand: str
    id: int  # index in the cached grasp list (best first)
    X_OG: np.ndarray  # (4, 4) grasp frame G in the object frame O ("hand_in_object")
    finger_joints: tuple[str, ...]
    finger_values: np.ndarray  # (n,) closed on the object
    contacts: tuple[dict, ...]  # {finger, point (3,), normal (3,)} in frame O, fingers in contact
    quality: float  # the grasp list's total score


@dataclass(frozen=True)
class Phase:
    name: str
    holding: tuple[str, ...]  # hands holding the object during the whole phase
    touching: tuple[str, ...]  # further hands whose fingertips may touch it
    waypoints: np.ndarray  # (k, nq)
    times: np.ndarray  # (k,) s from the plan start


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
    object_poses: dict = field(default_factory=dict)  # start, exchange, goal: (4, 4)
    phases: tuple[Phase, ...] = ()
    stats: dict = field(default_factory=dict)
    seed: int = 0
    planner: str = "roadmap"

    def grasp(self, hand: str) -> PlanGrasp | None:
        return next((g for g in self.grasps if g.hand == hand), None)

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


def plan_to_dict(plan: Plan) -> dict:
    return _num({
        "format": FORMAT,
        "status": plan.status,
        "failure": plan.failure,
        "planner": plan.planner,
        "seed": plan.seed,
        "scene": plan.scene,
        "robot": plan.robot,
        "joint_names": list(plan.joint_names),
        "limits": plan.limits,
        "object": plan.object,
        "obstacles": list(plan.obstacles),
        "collision": plan.collision,
        "grasps": [{"hand": g.hand, "id": g.id, "hand_in_object": g.X_OG, "finger_joints": list(g.finger_joints),
                    "finger_values": g.finger_values, "contacts": list(g.contacts), "quality": g.quality}
                   for g in plan.grasps],
        "object_poses": plan.object_poses,
        "phases": [{"name": p.name, "holding": list(p.holding), "touching": list(p.touching),
                    "waypoints": p.waypoints, "times": p.times} for p in plan.phases],
        "stats": plan.stats,
    })


def dumps(plan: Plan) -> str:
    return json.dumps(plan_to_dict(plan), indent=1, allow_nan=False) + "\n"


def write_plan(path: str | Path, plan: Plan) -> None:
    """Write atomically (temporary file renamed into place)."""
    atomic_write_text(path, dumps(plan))


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
        if not isinstance(v, kind) or isinstance(v, bool) and bool not in (kind if isinstance(kind, tuple) else (kind,)):
            names = "/".join(k.__name__ for k in (kind if isinstance(kind, tuple) else (kind,)))
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
        return a


def plan_from_dict(d: Any, file: Path) -> Plan:
    r = _Reader(file)
    if not isinstance(d, dict):
        raise r.error("", "expected a JSON object")
    fmt = r.get(d, "format", "", str)
    if fmt != FORMAT:
        raise r.error("format", f"expected '{FORMAT}', found {fmt!r}")
    status = r.get(d, "status", "", str)
    if status not in ("solved", "failed"):
        raise r.error("status", f"expected 'solved' or 'failed', found {status!r}")
    names = tuple(r.get(d, "joint_names", "", list))
    nq = len(names)
    grasps = []
    for i, g in enumerate(r.get(d, "grasps", "", list)):
        w = f"grasps[{i}]."
        fj = tuple(r.get(g, "finger_joints", w, list))
        grasps.append(PlanGrasp(r.get(g, "hand", w, str), r.get(g, "id", w, int),
                                r.array(r.get(g, "hand_in_object", w, list), w + "hand_in_object", (4, 4)),
                                fj, r.array(r.get(g, "finger_values", w, list), w + "finger_values", (len(fj),)),
                                tuple(r.get(g, "contacts", w, list)), float(r.get(g, "quality", w, (int, float)))))
    phases = []
    for i, p in enumerate(r.get(d, "phases", "", list)):
        w = f"phases[{i}]."
        wp = r.array(r.get(p, "waypoints", w, list), w + "waypoints", (None, nq))
        times = r.array(r.get(p, "times", w, list), w + "times", (len(wp),))
        phases.append(Phase(r.get(p, "name", w, str), tuple(r.get(p, "holding", w, list)),
                            tuple(r.get(p, "touching", w, list)), wp, times))
    poses = {k: r.array(v, f"object_poses.{k}", (4, 4)) for k, v in r.get(d, "object_poses", "", dict).items()}
    return Plan(status, d.get("failure"), r.get(d, "scene", "", dict), r.get(d, "robot", "", dict), names,
                r.get(d, "limits", "", dict), r.get(d, "object", "", dict), tuple(r.get(d, "obstacles", "", list)),
                r.get(d, "collision", "", dict), tuple(grasps), poses, tuple(phases), d.get("stats", {}),
                int(d.get("seed", 0)), str(d.get("planner", "roadmap")))


def read_plan(path: str | Path) -> Plan:
    """Load a plan JSON; malformed content raises an InputError naming the field."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise InputError(path, None, f"cannot read the plan ({exc.strerror or exc})") from None
    try:
        d = json.loads(text)
    except json.JSONDecodeError as exc:
        raise InputError(path, None, f"not valid JSON (line {exc.lineno}: {exc.msg})") from None
    return plan_from_dict(d, path)
