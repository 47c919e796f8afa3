"""Checks shared by the validators of every task (:mod:`regrasp_cli.validate`,
:mod:`regrasp_cli.validate_inhand`): what an issue and a report are, the tolerances, and
the checks of any phase whatever its kind (continuity, timing, joint limits), with two
geometric helpers (pose differences, the distance to a mesh).  Like the validators it
trusts nothing the planner computed and imports nothing of it."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh

from regrasp_cli.motion.blend import grid_times, trajectory
from regrasp_cli.motion.timing import segment_duration
from regrasp_cli.replay import JOINT_TOL
from regrasp_cli.spatial import pose_error
from regrasp_cli.trajectory import Phase

CHECKS = ("input", "continuity", "limits", "timing", "collision", "attachment", "kind", "grasp", "status")
TIME_TOL = 1e-9  # s: phase start times
DURATION_RTOL = 1e-6  # relative slack of a segment's duration below its minimum
TIME_ULPS = 4  # absolute slack of a duration, in ulps of its end time: times are stored from the plan start
POSE_TOL = (0.001, 0.01)  # m, rad: object poses
FINGER_TOL = 1e-6  # rad: holding fingers at their grasp values
SURFACE_TOL = 0.001  # m: contact point to the mesh surface
NORMAL_TOL = 0.35  # rad: contact normal to the surface normal
TIP_TOL = 0.002  # m: fingertip sphere centre to where the contact puts it
CONE_EDGES = 8  # linearised friction cone, as the grasp search (grasp/single.py)


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
    kind: str
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

    def refusal(self) -> str | None:
        """Why a plan with issues is refused, in one line (None when valid): the reason
        `regrasp plan` and a benchmark run give at stage ``validation``."""
        if self.valid:
            return None
        return f"the written plan fails {len(self.issues)} check(s); first: {self.issues[0]}"


# ------------------------------------------------------------------ checks of any phase


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
    if phase.timing is not None:
        if np.any(np.diff(t) < 0):
            out.append(Issue(phase.name, int(np.argmax(np.diff(t) < 0)) + 1, "timing", "time goes back"))
        return out
    # A difference of two times 300 s from the start is known to ~1e-13 s only, more
    # than DURATION_RTOL of a segment that moves one joint by one ulp.
    slack = TIME_ULPS * np.spacing(np.abs(t[1:]))
    for i, (dq, dt) in enumerate(zip(np.diff(phase.waypoints, axis=0), np.diff(t))):
        need = segment_duration(dq, velocity, acceleration)
        if dt < 0:
            out.append(Issue(phase.name, i + 1, "timing", f"time goes back by {-dt:.6g} s"))
        elif dt < need * (1 - DURATION_RTOL) - slack[i]:
            out.append(Issue(phase.name, i + 1, "timing", f"segment {i}->{i + 1} lasts {dt:.6g} s but needs "
                                                          f"{need:.6g} s under the velocity and acceleration limits"))
    return out


def smooth_timing_issues(phase: Phase, velocity: np.ndarray, acceleration: np.ndarray, dt: float,
                         names: tuple[str, ...]) -> list[Issue]:
    """A phase with blends: its grid's times follow from its speeds (constant path
    acceleration between grid points), the speed is 0 at its stops, the waypoint times
    are those of their knots, and the joint velocities and accelerations are within the
    limits at every ``dt`` and at both sides of every grid point."""
    tm, out = phase.timing, []
    issue = lambda i, msg: out.append(Issue(phase.name, i, "timing", msg))  # noqa: E731
    try:
        path = phase.path()
    except ValueError as exc:
        issue(None, f"the blends do not fit the waypoints: {exc}")
        return out
    if abs(tm.s[0]) > 1e-9 or abs(tm.s[-1] - path.length) > 1e-6 * max(1.0, path.length):
        issue(None, f"the speed grid spans s in [{tm.s[0]:.9g}, {tm.s[-1]:.9g}], but the path through the "
                    f"waypoints is {path.length:.9g} long")
        return out
    expected = grid_times(tm.s, tm.sd)
    if not np.all(np.isfinite(expected)) or np.max(np.abs(expected + tm.t[0] - tm.t)) > 1e-6 * max(1.0, tm.duration):
        issue(None, "the speed grid's times do not follow from its speeds (constant path acceleration between "
                    "grid points)")
        return out
    if abs(tm.t[0] - phase.times[0]) > TIME_TOL or abs(tm.t[-1] - phase.times[-1]) > 1e-6:
        issue(None, f"the speed grid spans [{tm.t[0]:.6g}, {tm.t[-1]:.6g}] s, not the phase's "
                    f"[{phase.times[0]:.6g}, {phase.times[-1]:.6g}] s")
    stops = path.starts[path.stops]
    sd_at = np.interp(stops, tm.s, tm.sd)
    if np.any(sd_at > 1e-9):
        i = int(np.searchsorted(path.knots, stops[int(np.argmax(sd_at))] - 1e-9))
        issue(i, f"passes a stop (a corner without a blend) at speed {float(sd_at.max()):.3g}")
    knot_t = np.interp(path.knots, tm.s, tm.t)
    bad = np.flatnonzero(np.abs(knot_t - phase.times) > 1e-6)
    if len(bad):
        issue(int(bad[0]), f"time {phase.times[bad[0]]:.6g} s, but the motion passes it at {knot_t[bad[0]]:.6g} s")
    t = np.concatenate([np.arange(tm.t[0], tm.t[-1], dt), tm.t, np.nextafter(tm.t[1:], -np.inf)])
    _, qd, qdd = trajectory(path, tm, t)
    for what, x, lim in (("velocity", qd, velocity), ("acceleration", qdd, acceleration)):
        ratio = np.abs(x) / lim
        if ratio.max() > 1 + DURATION_RTOL:
            k, j = np.unravel_index(int(np.argmax(ratio)), ratio.shape)
            i = int(np.searchsorted(phase.times, t[k], side="right") - 1)
            issue(i, f"{names[j]} {what} {abs(x[k, j]):.6g} exceeds its limit {lim[j]:.6g} at {t[k]:.6g} s")
    return out


def phase_timing_issues(phase: Phase, previous: Phase | None, velocity: np.ndarray, acceleration: np.ndarray,
                        dt: float, names: tuple[str, ...]) -> list[Issue]:
    """Every timing check of a phase, whatever its kind: :func:`timing_issues`, and
    :func:`smooth_timing_issues` (sampled every ``dt`` s) when it has blends and a speed grid."""
    found = timing_issues(phase, previous, velocity, acceleration)
    if phase.timing is not None:
        found += smooth_timing_issues(phase, velocity, acceleration, dt, names)
    return found


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


def pose_differs(X_A: np.ndarray, X_B: np.ndarray) -> str | None:
    """How far apart two poses (4, 4) are ("3 mm, 0.02 rad"), or None within :data:`POSE_TOL`."""
    dp, da = pose_error(X_A, X_B)
    return f"{dp * 1000:.3g} mm, {da:.3g} rad" if dp > POSE_TOL[0] or da > POSE_TOL[1] else None


def surface_distance(mesh: trimesh.Trimesh, p: np.ndarray) -> tuple[float, np.ndarray]:
    """Distance (m) from p (3,) to the mesh and the normals (f, 3) of the closest faces
    (several at an edge or a vertex, where any of them is as right as another)."""
    faces = np.asarray(trimesh.proximity.nearby_faces(mesh, p[None])[0])
    closest = trimesh.triangles.closest_point(mesh.triangles[faces], np.repeat(p[None], len(faces), axis=0))
    d = np.linalg.norm(closest - p, axis=1)
    return float(d.min()), mesh.face_normals[faces[d <= d.min() + 1e-7]]
