"""A plan sampled for a controller (issue 43): what `regrasp export PLAN` writes.

The timed motion of a solved plan (:mod:`regrasp_cli.trajectory`) at a fixed rate: per
sample its time, every joint's position, velocity and acceleration, the phase, the hands
holding the object with their grasp ids, and the object's pose X_WO (where
:func:`regrasp_cli.replay.follow` puts it: at rest at its placement, held with the first
holding hand's grasp, in-hand between the phase's object poses as docs/FORMAT.md says:
the position linear and the rotation the slerp at the joints' fraction of each segment);
and the gripper events:
a hand's fingers closing on the object (``close``), opening off it (``open``) or moving
on it (``inhand``), each over one phase.

A phase with a speed grid is sampled on its blended path (:func:`.motion.blend.trajectory`),
one without on its stop-at-every-waypoint trapezoids
(:func:`.motion.timing.evaluate_with_accelerations`); a sample at a phase boundary belongs
to the phase that starts there, the plan's end to the last phase.

Files (by the output's name): ``.csv`` one row per sample (t, phase, holding, object
position and quaternion w x y z, then q, qd, qdd per joint), ``.npz`` the arrays,
``.json`` the samples with the phases and events (``format: regrasp.samples/1``), and a
name ending in ``.joint_trajectory.json`` a JSON shaped like ROS
``trajectory_msgs/JointTrajectory`` (joint_names, points of positions, velocities,
accelerations, time_from_start {sec, nanosec}), without any ROS dependency.

Units: s, m, rad (joints in the units of their type); poses 4x4 in the robot base frame W.
"""

from __future__ import annotations

import csv
import io
import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from regrasp_cli.errors import InputError
from regrasp_cli.model.robot import Kinematics
from regrasp_cli.motion.blend import trajectory
from regrasp_cli.motion.timing import evaluate_with_accelerations
from regrasp_cli.replay import Inputs, follow
from regrasp_cli.spatial import segment_poses
from regrasp_cli.store import atomic_write_bytes, atomic_write_text
from regrasp_cli.trajectory import Plan

FORMAT = "regrasp.samples/1"
MAX_SAMPLES = 10_000_000  # samples x joints past this are refused: the arrays would not fit in memory
SUFFIXES = (".joint_trajectory.json", ".csv", ".npz", ".json")


@dataclass(frozen=True)
class Samples:
    """A plan sampled at ``rate`` Hz (m samples, nq joints)."""

    rate: float
    joint_names: tuple[str, ...]
    t: np.ndarray  # (m,) s from the plan's start
    q: np.ndarray  # (m, nq)
    qd: np.ndarray  # (m, nq)
    qdd: np.ndarray  # (m, nq)
    phase: np.ndarray  # (m,) index into ``phases``
    X_WO: np.ndarray  # (m, 4, 4) the object
    phases: tuple[dict, ...]  # per phase: name, kind, holding (hand -> grasp id), touching, t0, t1
    events: tuple[dict, ...]  # {hand, event: close|open|inhand, grasp, t0, t1}


def _events(plan: Plan) -> tuple[dict, ...]:
    """The gripper events: each touching hand of a phase closes when it holds in the next
    phase, opens when it held in the previous one, else moves its fingers on the object."""
    out = []
    for k, p in enumerate(plan.phases):
        before = plan.phases[k - 1].holding if k else {}
        after = plan.phases[k + 1].holding if k + 1 < len(plan.phases) else {}
        for hand in p.touching:
            event, grasp = (("close", after[hand]) if hand in after and hand not in p.holding else
                            ("open", before[hand]) if hand in before and hand not in p.holding else
                            ("inhand", None))
            out.append({"hand": hand, "event": event, "grasp": grasp, "t0": float(p.times[0]),
                        "t1": float(p.times[-1])})
    return tuple(out)


def sample_times(plan: Plan, rate: float) -> np.ndarray:
    """k / rate for k = 0 .. floor(duration * rate), and the plan's end (s)."""
    n = int(math.floor(plan.duration * rate + 1e-9))
    if (n + 2) * len(plan.joint_names) > MAX_SAMPLES:
        raise ValueError(f"{n + 2} samples of {len(plan.joint_names)} joints: more than {MAX_SAMPLES:,} values")
    t = np.arange(n + 1) / rate
    return t if t[-1] >= plan.duration - 1e-12 else np.append(t, plan.duration)


def sample_plan(plan: Plan, file: Path, inputs: Inputs, rate: float, t: np.ndarray | None = None) -> Samples:
    """The plan ``plan`` (read from ``file``, its inputs loaded) sampled at ``rate`` Hz, or
    at the times ``t`` (m,) s when given (sorted, within the plan)."""
    if plan.status != "solved" or not plan.phases:
        raise InputError(file, "status", "expected a solved plan with phases (a failed plan has no motion to export)")
    t = sample_times(plan, rate) if t is None else np.asarray(t, float)
    kin = Kinematics(inputs.robot)
    carries, _ = follow(file, plan, kin)
    starts = np.array([p.times[0] for p in plan.phases])
    phase = np.clip(np.searchsorted(starts, t, side="right") - 1, 0, len(plan.phases) - 1)
    nq = len(plan.joint_names)
    q, qd, qdd = np.zeros((len(t), nq)), np.zeros((len(t), nq)), np.zeros((len(t), nq))
    X_WO = np.zeros((len(t), 4, 4))
    for k, p in enumerate(plan.phases):
        at = np.flatnonzero(phase == k)
        if not len(at):
            continue
        if p.timing is None:
            q[at], qd[at], qdd[at] = evaluate_with_accelerations(p.waypoints, p.times, inputs.velocity,
                                                                  inputs.acceleration, t[at])
        else:
            q[at], qd[at], qdd[at] = trajectory(p.path(), p.timing, t[at])
        X_WO[at] = (moved_poses(p.waypoints, p.times, p.object_poses, t[at], q[at]) if p.object_poses is not None
                    else [carries[k].X_WO(kin, x) for x in q[at]])
    phases = tuple({"name": p.name, "kind": p.kind.value, "holding": dict(p.holding), "touching": list(p.touching),
                    "t0": float(p.times[0]), "t1": float(p.times[-1])} for p in plan.phases)
    return Samples(float(rate), tuple(plan.joint_names), t, q, qd, qdd, phase, X_WO, phases, _events(plan))


def moved_poses(waypoints: np.ndarray, times: np.ndarray, poses: np.ndarray, t: np.ndarray,
                q: np.ndarray) -> np.ndarray:
    """The object's poses (m, 4, 4) at times t (m,) of a phase that gives them per
    waypoint (``poses`` (n, 4, 4), an in-hand phase), the joints then at q (m, nq): at the
    fraction f of its segment the joints have gone, the position linear in f and the
    rotation the slerp at f (docs/FORMAT.md, 4.3)."""
    if len(waypoints) == 1:
        return np.repeat(poses[:1], len(t), axis=0)
    k = np.clip(np.searchsorted(times, t, side="right") - 1, 0, len(waypoints) - 2)
    dq = waypoints[k + 1] - waypoints[k]
    dd = np.einsum("ij,ij->i", dq, dq)
    f = np.clip(np.einsum("ij,ij->i", q - waypoints[k], dq) / np.where(dd > 0, dd, 1.0), 0.0, 1.0)
    out = np.zeros((len(t), 4, 4))
    for i in np.unique(k):  # each segment's samples at once, as the validator interpolates them
        at = k == i
        out[at] = segment_poses(poses[i], poses[i + 1], f[at])
    return out


# ------------------------------------------------------------------ files


def _pose_columns(X: np.ndarray) -> np.ndarray:
    """(m, 7): position x y z and quaternion w x y z of poses X (m, 4, 4)."""
    xyzw = Rotation.from_matrix(X[:, :3, :3]).as_quat()
    return np.c_[X[:, :3, 3], xyzw[:, 3], xyzw[:, :3]]


def _holding(s: Samples, k: int) -> str:
    return " ".join(f"{hand}:{g}" for hand, g in sorted(s.phases[k]["holding"].items()))


def to_csv(s: Samples) -> str:
    out = io.StringIO()
    w = csv.writer(out, lineterminator="\n")
    w.writerow(["t", "phase", "holding", "object_x", "object_y", "object_z", "object_qw", "object_qx", "object_qy",
                "object_qz"] + [f"{kind}_{n}" for kind in ("q", "qd", "qdd") for n in s.joint_names])
    pose = _pose_columns(s.X_WO)
    for i in range(len(s.t)):
        k = int(s.phase[i])
        w.writerow([repr(float(s.t[i])), s.phases[k]["name"], _holding(s, k)] +
                   [repr(float(x)) for x in np.r_[pose[i], s.q[i], s.qd[i], s.qdd[i]]])
    return out.getvalue()


def to_npz(s: Samples) -> bytes:
    out = io.BytesIO()
    np.savez_compressed(out, t=s.t, q=s.q, qd=s.qd, qdd=s.qdd, phase=s.phase, X_WO=s.X_WO,
                        joint_names=np.array(s.joint_names), rate=np.array(s.rate),
                        phases=np.array(json.dumps(s.phases)), events=np.array(json.dumps(s.events)))
    return out.getvalue()


def to_json(s: Samples) -> str:
    return json.dumps({"format": FORMAT, "rate": s.rate, "joint_names": list(s.joint_names), "phases": list(s.phases),
                       "events": list(s.events), "t": s.t.tolist(), "phase": s.phase.tolist(), "q": s.q.tolist(),
                       "qd": s.qd.tolist(), "qdd": s.qdd.tolist(), "object_poses": s.X_WO.tolist()})


def to_joint_trajectory(s: Samples) -> str:
    """A JSON shaped like ROS ``trajectory_msgs/JointTrajectory``."""
    def stamp(t: float) -> dict:
        ns = int(round(t * 1e9))
        return {"sec": ns // 1_000_000_000, "nanosec": ns % 1_000_000_000}

    points = [{"positions": s.q[i].tolist(), "velocities": s.qd[i].tolist(), "accelerations": s.qdd[i].tolist(),
               "effort": [], "time_from_start": stamp(float(s.t[i]))} for i in range(len(s.t))]
    return json.dumps({"header": {"stamp": {"sec": 0, "nanosec": 0}, "frame_id": ""},
                       "joint_names": list(s.joint_names), "points": points})


def suffix_of(path: Path) -> str | None:
    """The export format a file name asks for (one of :data:`SUFFIXES`), or None."""
    return next((x for x in SUFFIXES if path.name.endswith(x)), None)


def write(s: Samples, path: Path) -> None:
    """Write ``s`` to ``path`` in the format its name asks for (atomically)."""
    kind = suffix_of(path)
    if kind == ".npz":
        atomic_write_bytes(path, to_npz(s))
        return
    text = {".csv": to_csv, ".json": to_json, ".joint_trajectory.json": to_joint_trajectory}[kind](s)
    atomic_write_text(path, text)
