"""Time parameterisation of a piecewise-linear joint-space path under joint limits.

A planned path is a list of waypoints ``(n, d)`` in the robot's joint order (rad, or m for
prismatic joints) joined by straight segments in joint space, the local paths of the
roadmaps (:mod:`regrasp_cli.motion.local`).  This module gives it timing that respects
per-joint velocity limits ``v_max`` (d,) (rad/s or m/s) and acceleration limits ``a_max``
(d,) (rad/s^2 or m/s^2).

**Stop at every waypoint.**  Each segment ``q0 -> q1`` is traversed on its own, starting
and ending at rest.  The corners of a piecewise-linear path cannot be passed at non-zero
speed without leaving the path: the velocity direction would have to jump from one
segment direction to the next in zero time, which needs an unbounded acceleration, and any
finite-acceleration blend cuts the corner, i.e. leaves the straight segments that were
checked for collisions.  Stopping is therefore the safe and simple choice; it is slower
than blending but never executes a configuration that was not certified collision free.

**One segment.**  With ``dq = q1 - q0`` the motion is ``q(t) = q0 + s(t) dq`` with a path
scaling ``s`` going from 0 to 1.  Joint j moves at ``s_dot * dq_j`` and accelerates at
``s_ddot * dq_j``, so the limits on ``s`` come from the limiting joint::

    s_dot_max  = min_j v_max_j / |dq_j|        s_ddot_max = min_j a_max_j / |dq_j|

(joints with ``dq_j == 0`` impose nothing).  The time-optimal rest-to-rest profile of
``s`` is a trapezoid: accelerate at ``s_ddot_max`` up to ``s_dot_max``, cruise, decelerate
at ``s_ddot_max``; when ``s_dot_max**2 / s_ddot_max >= 1`` the cruise speed is never
reached and the profile is a triangle.  Durations::

    trapezoid: T = 1 / s_dot_max + s_dot_max / s_ddot_max
    triangle:  T = 2 / sqrt(s_ddot_max)

The computations use the reciprocals ``c_v = max_j |dq_j| / v_max_j`` (s) and
``c_a = max_j |dq_j| / a_max_j`` (s^2), which are 0, not infinite, for a zero-length
segment.  Because the same scaling drives every joint, the sampled path stays exactly on
the segment and every joint reaches its waypoint at the same time.

**Longer durations.**  :func:`evaluate_trajectory` and :func:`sample_trajectory` accept
waypoint times whose intervals are at least the minimal durations (e.g. to synchronise
with another arm): a segment of duration ``T >= T_min`` keeps the full acceleration
``1 / c_a`` and lowers the cruise rate to ``2 / (T + sqrt(T**2 - 4 c_a))``, the root of
``rate * T - rate**2 * c_a = 1``, which is at most ``s_dot_max``, so the limits still hold.
Intervals shorter than the minimum by more than a relative 1e-9 are rejected.

**Zero-length segments** (two consecutive waypoints equal in every joint, compared
exactly) are kept, not merged: they take 0 s, so :func:`time_parameterise` repeats the
time and ``times`` stays aligned one-to-one with the waypoints.  Given a positive interval
they are a dwell at rest.

Before the first waypoint time and after the last one the trajectory holds the end
waypoint at rest.  There are no tunable options besides the sampling period ``dt``; the
profile of a segment is returned as a frozen :class:`SegmentProfile`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

DURATION_RTOL = 1e-9  # relative slack on a given interval below the minimal duration
MAX_SAMPLES = 100_000_000  # guard of sample_trajectory against a tiny dt


@dataclass(frozen=True)
class SegmentProfile:
    """Rest-to-rest profile of the path scaling ``s`` on one segment.

    ``s`` rises as ``rate * tau**2 / (2 * ramp)`` for ``tau < ramp``, at ``rate`` until
    ``duration - ramp``, then mirrors the ramp down to 1 at ``duration``.
    """

    duration: float  # s: time to traverse the segment
    ramp: float  # s: length of the acceleration (and of the deceleration) phase; duration/2 for a triangle
    rate: float  # 1/s: peak value of s_dot (0 for a zero-length segment)
    accel: float  # 1/s^2: |s_ddot| during the ramps (0 for a zero-length segment)

    @property
    def triangular(self) -> bool:
        """True when there is no cruise phase."""
        return 2.0 * self.ramp >= self.duration


# ------------------------------------------------------------------------- validation


def _vector(x, name: str, d: int | None) -> np.ndarray:
    shape = "(d,)" if d is None else f"(d,) = ({d},)"
    try:
        a = np.asarray(x, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name}: expected a float array of shape {shape}: {exc}") from None
    if a.ndim != 1 or (d is not None and a.shape[0] != d) or a.shape[0] == 0:
        raise ValueError(f"{name}: expected shape {shape}, got {a.shape}")
    return a


def _limits(v_max, a_max, d: int | None) -> tuple[np.ndarray, np.ndarray]:
    v = _vector(v_max, "v_max", d)
    a = _vector(a_max, "a_max", v.shape[0])
    for name, x in (("v_max", v), ("a_max", a)):
        if not np.all(np.isfinite(x)) or not np.all(x > 0):
            raise ValueError(f"{name}: every limit must be finite and > 0, got {x.tolist()}")
    return v, a


def _waypoints(waypoints) -> np.ndarray:
    try:
        w = np.asarray(waypoints, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"waypoints: expected a float array of shape (n, d): {exc}") from None
    if w.ndim != 2 or w.shape[0] < 1 or w.shape[1] < 1:
        raise ValueError(f"waypoints: expected shape (n, d) with n >= 1, d >= 1, got {w.shape}")
    if not np.all(np.isfinite(w)):
        raise ValueError("waypoints: every coordinate must be finite")
    return w


def _scaling_reciprocals(dq: np.ndarray, v: np.ndarray, a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``c_v = 1 / s_dot_max`` (s) and ``c_a = 1 / s_ddot_max`` (s^2) of segments dq (k, d)."""
    adq = np.abs(dq)
    if not np.all(np.isfinite(adq)):
        raise ValueError("waypoints: a segment q1 - q0 overflows (coordinates too large)")
    return (adq / v).max(axis=-1), (adq / a).max(axis=-1)


def _min_durations(c_v: np.ndarray, c_a: np.ndarray) -> np.ndarray:
    """Minimal rest-to-rest durations (s) from the reciprocals (k,); 0 for zero segments."""
    triangle = c_a >= c_v * c_v  # s_dot_max**2 / s_ddot_max >= 1
    with np.errstate(divide="ignore", invalid="ignore"):
        trapezoid = c_v + c_a / c_v
    return np.where(triangle, 2.0 * np.sqrt(c_a), trapezoid)


def _profiles(durations: np.ndarray, c_a: np.ndarray, zero: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(rate (k,), ramp (k,)) of segments of the given durations (>= their minimum)."""
    disc = np.sqrt(np.maximum(durations * durations - 4.0 * c_a, 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):  # inf * 0 on zero segments, masked
        rate = 2.0 / (durations + disc)
        ramp = np.minimum(rate * c_a, 0.5 * durations)
    rate = np.where(zero, 0.0, rate)
    ramp = np.where(zero, 0.0, ramp)
    return rate, ramp


# ------------------------------------------------------------------------- one segment


def scaling_limits(dq, v_max, a_max) -> tuple[float, float]:
    """Limits ``(s_dot_max (1/s), s_ddot_max (1/s^2))`` of the path scaling of segment dq.

    Args:
        dq: (d,) joint displacement ``q1 - q0`` (rad or m).
        v_max: (d,) velocity limits (rad/s or m/s), finite and > 0.
        a_max: (d,) acceleration limits (rad/s^2 or m/s^2), finite and > 0.

    Returns:
        ``min_j v_max_j / |dq_j|`` and ``min_j a_max_j / |dq_j|`` over the joints that
        move; both ``inf`` for a zero-length segment.
    """
    v, a = _limits(v_max, a_max, None)
    d = _vector(dq, "dq", v.shape[0])
    if not np.all(np.isfinite(d)):
        raise ValueError("dq: every coordinate must be finite")
    c_v, c_a = _scaling_reciprocals(d, v, a)
    with np.errstate(divide="ignore"):
        return float(1.0 / c_v), float(1.0 / c_a)


def segment_profile(dq, v_max, a_max) -> SegmentProfile:
    """Time-optimal rest-to-rest profile of the straight segment dq (d,) under the limits
    v_max (d,) and a_max (d,); see the module docstring."""
    v, a = _limits(v_max, a_max, None)
    d = _vector(dq, "dq", v.shape[0])
    if not np.all(np.isfinite(d)):
        raise ValueError("dq: every coordinate must be finite")
    c_v, c_a = _scaling_reciprocals(d[None, :], v, a)
    zero = c_v == 0.0
    duration = _min_durations(c_v, c_a)
    rate, ramp = _profiles(duration, c_a, zero)
    accel = 0.0 if zero[0] else float(1.0 / c_a[0])
    return SegmentProfile(float(duration[0]), float(ramp[0]), float(rate[0]), accel)


def segment_duration(dq, v_max, a_max) -> float:
    """Minimal time (s) to traverse the straight segment dq (d,), rest to rest.

    Args:
        dq: (d,) joint displacement ``q1 - q0`` (rad or m).
        v_max: (d,) velocity limits (rad/s or m/s), finite and > 0.
        a_max: (d,) acceleration limits (rad/s^2 or m/s^2), finite and > 0.

    Returns:
        The duration of the trapezoidal (or triangular) profile of the limiting joint;
        0.0 when ``dq`` is zero in every joint.

    Raises:
        ValueError: on shapes other than (d,), non-finite ``dq``, or limits that are not
            finite and > 0.
    """
    return segment_profile(dq, v_max, a_max).duration


# ------------------------------------------------------------------------- a path


def time_parameterise(waypoints, v_max, a_max) -> np.ndarray:
    """Waypoint times (s) of the stop-at-every-waypoint trajectory through ``waypoints``.

    Args:
        waypoints: (n, d) configurations, n >= 1, in the robot's joint order (rad or m).
        v_max: (d,) velocity limits (rad/s or m/s), finite and > 0.
        a_max: (d,) acceleration limits (rad/s^2 or m/s^2), finite and > 0.

    Returns:
        times (n,): ``times[0] == 0``, nondecreasing, strictly increasing between
        consecutive waypoints that differ, repeated across a zero-length segment.
    """
    w = _waypoints(waypoints)
    v, a = _limits(v_max, a_max, w.shape[1])
    c_v, c_a = _scaling_reciprocals(np.diff(w, axis=0), v, a)
    times = np.zeros(w.shape[0])
    np.cumsum(_min_durations(c_v, c_a), out=times[1:])
    return times


def _check_times(times, w: np.ndarray, c_v: np.ndarray, c_a: np.ndarray) -> np.ndarray:
    n = w.shape[0]
    try:
        t = np.asarray(times, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"times: expected a float array of shape (n,) = ({n},): {exc}") from None
    if t.shape != (n,):
        raise ValueError(f"times: expected shape (n,) = ({n},), one per waypoint, got {t.shape}")
    if not np.all(np.isfinite(t)):
        raise ValueError("times: every time must be finite")
    intervals = np.diff(t)
    t_min = _min_durations(c_v, c_a)
    short = intervals < t_min * (1.0 - DURATION_RTOL)
    if np.any(short):
        i = int(np.flatnonzero(short)[0])
        raise ValueError(
            f"times: segment {i} -> {i + 1} is given {intervals[i]:.9g} s but needs at least "
            f"{t_min[i]:.9g} s under v_max and a_max (times must be nondecreasing)"
        )
    return t


def evaluate_trajectory(waypoints, times, v_max, a_max, t) -> tuple[np.ndarray, np.ndarray]:
    """Positions and velocities of the stop-at-every-waypoint trajectory at times t
    (:func:`evaluate_with_accelerations`, without the accelerations)."""
    q, qd, _ = evaluate_with_accelerations(waypoints, times, v_max, a_max, t)
    return q, qd


def evaluate_with_accelerations(waypoints, times, v_max, a_max, t) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Positions, velocities and accelerations of the stop-at-every-waypoint trajectory at
    times t.

    Args:
        waypoints: (n, d) configurations (rad or m).
        times: (n,) waypoint times (s), e.g. from :func:`time_parameterise`; each interval
            must be at least the minimal duration of its segment.
        v_max: (d,) velocity limits (rad/s or m/s), finite and > 0.
        a_max: (d,) acceleration limits (rad/s^2 or m/s^2), finite and > 0.
        t: (m,) query times (s), any order; clamped to ``[times[0], times[-1]]`` (the
            trajectory rests at its end waypoints outside).

    Returns:
        q (m, d) positions, qd (m, d) velocities (rad/s or m/s) and qdd (m, d)
        accelerations (rad/s^2 or m/s^2; on a ramp's ends, the ramp's).  At a waypoint
        time the position is exactly that waypoint and the velocity is zero.
    """
    w = _waypoints(waypoints)
    v, a = _limits(v_max, a_max, w.shape[1])
    dq = np.diff(w, axis=0)
    c_v, c_a = _scaling_reciprocals(dq, v, a)
    tt = _check_times(times, w, c_v, c_a)
    try:
        tq = np.asarray(t, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"t: expected a float array of shape (m,): {exc}") from None
    if tq.ndim != 1 or not np.all(np.isfinite(tq)):
        raise ValueError(f"t: expected finite times of shape (m,), got shape {tq.shape}")
    m, d = tq.shape[0], w.shape[1]
    if w.shape[0] == 1:
        return np.repeat(w, m, axis=0), np.zeros((m, d)), np.zeros((m, d))

    durations = np.diff(tt)
    zero = c_v == 0.0
    rate, ramp = _profiles(durations, c_a, zero)
    k = np.clip(np.searchsorted(tt, tq, side="right") - 1, 0, w.shape[0] - 2)
    T, V, R = durations[k], rate[k], ramp[k]
    tau = np.clip(tq - tt[k], 0.0, T)
    back = T - tau
    up, down = tau < R, back < R
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(up, V * tau * tau / (2.0 * R), V * (tau - 0.5 * R))
        u = np.where(down, V * back * back / (2.0 * R), 1.0 - s)  # 1 - s, exact near the end
        sd = np.where(up, V * tau / R, np.where(down, V * back / R, V))
        sdd = np.where(up, V / R, np.where(down, -V / R, 0.0))
    s = np.where(down, 1.0 - u, s)
    s, u, sd, sdd = (np.where(zero[k], z, x) for x, z in ((s, 0.0), (u, 1.0), (sd, 0.0), (sdd, 0.0)))
    first_half = (s <= 0.5)[:, None]
    q = np.where(first_half, w[k] + s[:, None] * dq[k], w[k + 1] - u[:, None] * dq[k])
    return q, sd[:, None] * dq[k], sdd[:, None] * dq[k]


def sample_trajectory(waypoints, times, v_max, a_max, dt: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The trajectory sampled at a fixed period, for checking and for export.

    Args:
        waypoints: (n, d) configurations (rad or m).
        times: (n,) waypoint times (s), see :func:`evaluate_trajectory`.
        v_max: (d,) velocity limits (rad/s or m/s), finite and > 0.
        a_max: (d,) acceleration limits (rad/s^2 or m/s^2), finite and > 0.
        dt: sampling period (s), finite and > 0.

    Returns:
        t (m,) = ``times[0] + k * dt`` for k = 0 .. ceil(duration / dt): the last sample is
        at or after ``times[-1]`` and is the final waypoint at rest; q (m, d) positions;
        qd (m, d) velocities.
    """
    try:
        step = float(dt)
    except (TypeError, ValueError):
        raise ValueError(f"dt: expected a float sampling period (s), got {dt!r}") from None
    if not np.isfinite(step) or step <= 0:
        raise ValueError(f"dt: the sampling period must be finite and > 0, got {dt!r}")
    w = _waypoints(waypoints)
    v, a = _limits(v_max, a_max, w.shape[1])
    tt = _check_times(times, w, *_scaling_reciprocals(np.diff(w, axis=0), v, a))
    span = float(tt[-1] - tt[0])
    count = int(np.ceil(span / step - 1e-9)) + 1 if span > 0 else 1
    if count > MAX_SAMPLES:
        raise ValueError(f"dt: {step:g} s gives {count} samples over {span:g} s (at most {MAX_SAMPLES})")
    t = tt[0] + step * np.arange(count)
    q, qd = evaluate_trajectory(w, tt, v, a, t)
    return t, q, qd
