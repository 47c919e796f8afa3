"""An in-hand planning run as a plan/2 (:mod:`regrasp_cli.trajectory`, task ``inhand``).

Each transfer is an ``inhand-transfer`` phase and each finger regrasp an ``inhand-regrasp``
phase, ``touching`` the hand, holding nothing rigidly (the fingers move the object), with
the object's pose (in the robot base frame W) and the fingertip contacts (finger name,
point and outward normal in the object frame) at every waypoint: every finger during a
transfer, every finger but the moving one while it is lifted in a regrasp.  Waypoints are
joined by straight joint-space segments, each timed rest to rest within the joint limits
(a stop at every waypoint: a fingertip leaves no contact between two).  The ``start`` and
``goal`` placements are the object's poses in the hand at the two ends (it never rests).
"""

from __future__ import annotations

from pathlib import Path
from typing import NamedTuple

import numpy as np

from regrasp_cli import __version__
from regrasp_cli.dexterous.gait import Regrasp, Transfer
from regrasp_cli.dexterous.task import CONTACT_TOLERANCE, InhandOutcome, InhandProblem
from regrasp_cli.manip.modes import Kind
from regrasp_cli.manip.record import export_object, obstacle_records, relative_path
from regrasp_cli.motion.timing import segment_duration
from regrasp_cli.store import sha256_file
from regrasp_cli.trajectory import Phase, Placement, Plan

ACCELERATION = 2.0  # rad/s^2 of every joint (the fingers)


def _contacts(names: list[str], p: np.ndarray, n: np.ndarray, skip: int | None = None) -> tuple[dict, ...]:
    return tuple({"finger": names[f], "point": p[f], "normal": n[f]} for f in range(len(names)) if f != skip)


def _times(q: np.ndarray, t0: float, velocity: np.ndarray, acceleration: np.ndarray) -> np.ndarray:
    d = [segment_duration(b - a, velocity, acceleration) for a, b in zip(q, q[1:])]
    return t0 + np.r_[0.0, np.cumsum(d)]


class FingerMotion(NamedTuple):
    """One piece of finger gaiting as a phase: its kind and label, waypoints (k, nq), the
    object's poses (k, 4, 4) in W and the contacts at each waypoint."""

    kind: Kind
    label: str
    q: np.ndarray
    X_WO: np.ndarray
    contacts: tuple


def piece_motions(pieces, names: list[str], X_WG: np.ndarray) -> list[FingerMotion]:
    """Per piece (:class:`~dexterous.gait.Transfer` or :class:`~dexterous.gait.Regrasp`),
    its :class:`FingerMotion`, the object's poses in W (the hand's grasp frame at ``X_WG``),
    the contacts of the fingers ``names``."""
    out = []
    for k, piece in enumerate(pieces):
        if isinstance(piece, Transfer):
            X = X_WG @ piece.X_GO
            c = _contacts(names, piece.p, piece.n)
            out.append(FingerMotion(Kind.INHAND_TRANSFER, f"turn {k}", piece.q, X, tuple(c for _ in X)))
        else:
            assert isinstance(piece, Regrasp)
            X = np.repeat((X_WG @ piece.before.X_GO)[None], len(piece.q), axis=0)
            before, after = piece.before, piece.after
            lifted = _contacts(names, before.p, before.n, skip=piece.finger)
            contacts = (_contacts(names, before.p, before.n),) + (lifted,) * (len(piece.q) - 2) + (
                _contacts(names, after.p, after.n),)
            out.append(FingerMotion(Kind.INHAND_REGRASP, f"{names[piece.finger]} steps {k}", piece.q, X, contacts))
    return out


def phases(problem: InhandProblem, out: InhandOutcome) -> tuple[Phase, ...]:
    robot, hand = problem.robot, problem.hand
    names = [f.name for f in robot.hands[hand].spec.fingers]
    acc = np.full(robot.nq, ACCELERATION)
    result, t = [], 0.0
    for kind, label, q, X, contacts in piece_motions(out.pieces, names, out.X_WG):
        times = _times(q, t, robot.velocity, acc)
        result.append(Phase(label, kind, {}, (hand,), None, q, times, X, contacts))
        t = float(times[-1])
    return tuple(result)


def make_inhand_plan(problem: InhandProblem, out: InhandOutcome, seed: int, out_file: Path, cache_dir: Path,
                     timings: bool) -> Plan:
    """The plan of ``out``; paths in it relative to ``out_file``'s folder.  Without
    ``timings`` it holds no wall-clock time (the same seed gives the same bytes)."""
    robot, spec = problem.robot, problem.spec
    base = Path(out_file).resolve().parent
    mesh = export_object(problem, cache_dir)
    stats = {k: v for k, v in out.stats.items() if timings or not k.endswith("_s")}
    stats["software_version"] = __version__
    return Plan(
        status="failed" if out.failure else "solved",
        failure=None if out.failure is None else {"stage": out.failure.stage.value, "reason": out.failure.reason},
        scene={"file": relative_path(spec.file, base), "sha256": sha256_file(spec.file)},
        robot={"urdf": relative_path(robot.spec.urdf, base), "urdf_sha256": robot.urdf_sha256,
               "robot_yaml": relative_path(robot.spec.file, base), "robot_yaml_sha256": robot.robot_yaml_sha256},
        joint_names=robot.joint_names,
        limits={"lower": robot.lower, "upper": robot.upper, "velocity": robot.velocity,
                "acceleration": np.full(robot.nq, ACCELERATION)},
        object={"name": problem.object.name, "mesh": relative_path(mesh, base), "sha256": sha256_file(mesh),
                "friction": spec.object.friction},
        obstacles=obstacle_records(problem.obstacles, base),
        collision={"contact_tolerance": CONTACT_TOLERANCE, "support_tolerance": CONTACT_TOLERANCE,
                   "disabled_pairs": sorted(list(p) for p in problem.disabled.links())},
        placements=(Placement("start", out.X_WG @ spec.X_GO_start), Placement("goal", out.X_WG @ spec.X_GO_goal)),
        phases=phases(problem, out) if out.failure is None else (),
        stats=stats, seed=seed, planner="gsn-tree", task="inhand")
