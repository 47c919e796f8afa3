"""Smooth, time-optimal motion through waypoints: straight segments joined by parabolic
blends, timed by TOPP-RA.

:mod:`regrasp_cli.motion.timing` stops at every waypoint, because the corner of a
piecewise-linear path cannot be passed at speed without leaving it.  Here the corners are
cut, by as little as the collision checks allow, and the motion is timed as fast as the
joint limits allow:

**Path.**  Waypoints ``(n, d)`` (rad or m) and a blend radius ``r_i`` (n,) per waypoint,
measured in joint-space Euclidean length along each of its two segments (0 at the ends).
With ``d_i`` the unit direction of segment i (waypoint i to i + 1), the blend at waypoint
i is the quadratic Bézier curve with control points ``A = w_i - r_i d_{i-1}``, ``C = w_i``,
``B = w_i + r_i d_i``; the rest of each segment stays straight, and the segment's
blends must fit on it (``r_i + r_{i+1} <= |w_{i+1} - w_i|``).  Every piece, straight or
not, is stored as a quadratic Bézier (a straight piece has ``C = (A + B) / 2``) over a
path parameter ``s`` of length ``|B - A|`` for a straight piece and ``2 r`` for a blend,
so that ``dq/ds`` is continuous: the unit direction on straight pieces, ``d_{i-1}`` and
``d_i`` at a blend's ends.  ``d2q/ds2`` is constant on each piece (0 on straight ones).
A blend stays in the convex hull of A, C, B: within the joint position limits when the
waypoints are, and within ``r_i |d_i - d_{i-1}| / 4`` of the corner.  A waypoint with
``r_i = 0`` is a **stop**: the motion reaches it at rest (always the first and last).

**Timing.**  TOPP-RA (Pham & Pham 2018, the ``toppra`` library) gives the fastest path
speed ``sd`` on a grid of ``s`` under the joint velocity and acceleration limits, from
rest to rest between stops.  The grid holds every piece end (and a point just before it,
where the acceleration jumps), every waypoint's knot and points at most ``GRID_STEP``
apart.  Between grid points ``s`` has a constant acceleration, so the trajectory is
exactly: ``s(t) = s_k + sd_k tau + u_k tau^2 / 2``, ``u_k = (sd_{k+1}^2 - sd_k^2) / (2 (s_{k+1} - s_k))``,
``q = P(s)``, ``qd = P'(s) sd``, ``qdd = P''(s) sd^2 + P'(s) u``.  TOPP-RA meets the
limits at its grid points only; the peaks over every interval are computed
(:func:`peaks`) and the whole timing slowed uniformly if they exceed the limits.

Units: rad (or m), rad/s, rad/s^2, s.  The knot of a waypoint is the ``s`` where the
motion passes it (the blend's middle, exactly the waypoint at a stop).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Callable

import numpy as np
import toppra
import toppra.algorithm
import toppra.constraint

logging.getLogger("toppra").setLevel(logging.WARNING)

GRID_STEP = 0.05  # path parameter (rad) between TOPP-RA grid points, beside the piece ends
EDGE = 1e-4  # relative position, in its piece, of the grid point just before a piece end
LIMIT_SLACK = 1.0 - 5e-3  # TOPP-RA gets the limits scaled by this, and the sampled peaks are brought under
# them too: between samples a peak can be higher (0.05 % measured on a HiroNX finger), still under the limit
TINY = 1e-12
MERGE = 1e-9  # relative: grid points closer than this are merged


@dataclass(frozen=True)
class BlendedPath:
    """Pieces (m) as quadratic Béziers ``A, C, B`` (m, d) over ``starts`` (m + 1,) of the
    path parameter s; ``stops`` (m + 1,) bool, True where the speed must be 0 (the ends
    and the corners without a blend); ``knots`` (n,) s of each waypoint."""

    A: np.ndarray
    C: np.ndarray
    B: np.ndarray
    starts: np.ndarray
    stops: np.ndarray
    knots: np.ndarray

    @property
    def length(self) -> float:
        return float(self.starts[-1])

    def evaluate(self, s, order: int = 0, left=None) -> np.ndarray:
        """q (order 0), dq/ds (1) or d2q/ds2 (2) at s (k,) -> (k, d); at a piece end the
        piece that starts there (the last piece at the path's end), or the one that ends
        there where ``left`` (k,) bool says so (a one-sided derivative from below)."""
        s = np.asarray(s, float)
        k = np.searchsorted(self.starts, s, side="right") - 1
        if left is not None:
            k = np.where(left, np.searchsorted(self.starts, s, side="left") - 1, k)
        k = np.clip(k, 0, len(self.A) - 1)
        return bezier(self.A[k], self.C[k], self.B[k], self.starts[k + 1] - self.starts[k],
                      (s - self.starts[k]) / (self.starts[k + 1] - self.starts[k]), order)


def bezier(A, C, B, lam, u, order: int = 0) -> np.ndarray:
    """Quadratic Bézier ``A, C, B`` (k, d) at fraction u (k,), or its derivatives with
    respect to ``s = u * lam`` (k,)."""
    u, lam = np.clip(np.asarray(u, float), 0.0, 1.0)[:, None], np.asarray(lam, float)[:, None]
    if order == 0:
        return (1 - u) ** 2 * A + 2 * u * (1 - u) * C + u * u * B
    if order == 1:
        return 2 * ((1 - u) * (C - A) + u * (B - C)) / lam
    return np.broadcast_to(2 * (A - 2 * C + B) / (lam * lam), np.shape(A)).copy()


def _directions(w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    dq = np.diff(w, axis=0)
    L = np.linalg.norm(dq, axis=1)
    if np.any(L <= TINY):
        raise ValueError("waypoints: consecutive waypoints must differ")
    return dq / L[:, None], L


def corner(w: np.ndarray, i: int, r: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Control points (A, C, B) (d,) of the blend of radius r at interior waypoint i."""
    a, b = w[i] - w[i - 1], w[i + 1] - w[i]
    return w[i] - r * a / np.linalg.norm(a), w[i].copy(), w[i] + r * b / np.linalg.norm(b)


def blended_path(waypoints, radii) -> BlendedPath:
    """The path of the module docstring through ``waypoints`` (n, d), n >= 2, consecutive
    ones distinct, with blend radii (n,): 0 at both ends, ``r_i + r_{i+1}`` at most the
    length of segment i."""
    w = np.asarray(waypoints, float)
    r = np.asarray(radii, float)
    if w.ndim != 2 or len(w) < 2 or r.shape != (len(w),):
        raise ValueError(f"waypoints (n, d) with n >= 2 and radii (n,), got {w.shape} and {r.shape}")
    d, L = _directions(w)
    if r[0] != 0 or r[-1] != 0 or np.any(r < 0) or np.any(r[:-1] + r[1:] > L * (1 + 1e-9)):
        raise ValueError("radii: 0 at the ends, >= 0, and the blends of a segment must fit on it")
    pieces, knots, s = [], [0.0], 0.0  # pieces: (A, C, B, length, is_blend)
    for i in range(len(w) - 1):
        if i > 0:
            knots.append(s + r[i])
            if r[i] > 0:
                pieces.append((w[i] - r[i] * d[i - 1], w[i], w[i] + r[i] * d[i], 2 * r[i], True))
                s += 2 * r[i]
        p0 = w[i] + r[i] * d[i] if r[i] > 0 else w[i]
        p1 = w[i + 1] - r[i + 1] * d[i] if r[i + 1] > 0 else w[i + 1]
        n = float(np.linalg.norm(p1 - p0))
        if n > TINY * max(1.0, L[i]):  # else two blends meet: no straight piece between them
            pieces.append((p0, 0.5 * (p0 + p1), p1, n, False))
            s += n
    knots.append(s)
    A, C, B, lam, blend = (list(x) for x in zip(*pieces))
    # a corner between two straight pieces is a stop; every other piece end is smooth
    stops = [True] + [not (blend[j - 1] or blend[j]) for j in range(1, len(pieces))] + [True]
    starts = np.concatenate([[0.0], np.cumsum(lam)])
    return BlendedPath(np.array(A), np.array(C), np.array(B), starts, np.array(stops), np.array(knots))


# ------------------------------------------------------------------ blend radii


def choose_radii(waypoints, blend_free: Callable[[int, np.ndarray, np.ndarray, np.ndarray], bool],
                 fraction: float = 0.5, shrink: float = 0.25, tries: int = 2) -> np.ndarray:
    """Blend radii (n,): at each interior waypoint i, ``fraction`` of its shorter segment,
    shrunk by ``shrink`` while ``blend_free(i, A, C, B)`` says the curve collides, at most
    ``tries`` times, then 0 (a stop).  ``fraction`` <= 0.5 lets every blend fit."""
    w = np.asarray(waypoints, float)
    _, L = _directions(w)
    r = np.zeros(len(w))
    for i in range(1, len(w) - 1):
        radius = fraction * min(L[i - 1], L[i])
        for _ in range(tries):
            if blend_free(i, *corner(w, i, radius)):
                r[i] = radius
                break
            radius *= shrink
    return r


def bezier_steps(A, C, B, reach: np.ndarray, resolution: float, step: float,
                 chains: tuple[np.ndarray, ...] | None = None) -> int:
    """Intervals k cutting the curve A, C, B (d,) at evenly spaced u so that between two
    samples no joint moves more than ``resolution`` and no point of the robot more than
    ``step`` (m; ``reach`` (d,) m/rad bounds how far a point moves per radian of each
    joint, :func:`motion.local.joint_reach`): a joint's speed
    ``|dq/du| <= 2 max(|C - A|, |B - C|)`` bounds its move over an interval; ``chains``
    as in :meth:`motion.local.LocalPlanner.steps`."""
    V = 2 * np.maximum(np.abs(C - A), np.abs(B - C))
    w = reach * V
    cart = w.sum() if chains is None else max(float(w[c].sum()) for c in chains)
    return max(1, int(np.ceil(V.max() / resolution)), int(np.ceil(cart / step)))


def bezier_points(A, C, B, u) -> np.ndarray:
    """Points (k, d) of the curve A, C, B (d,) at fractions u (k,)."""
    u = np.asarray(u, float)
    return bezier(*(np.broadcast_to(x, (len(u), len(x))) for x in (A, C, B)), np.ones(len(u)), u)


# ------------------------------------------------------------------ timing


@dataclass(frozen=True)
class Timing:
    """Path speed at grid points: s (g,), sd (g,) >= 0, and their times t (g,) (s, from
    any origin); constant path acceleration between grid points (module docstring)."""

    s: np.ndarray
    sd: np.ndarray
    t: np.ndarray

    @property
    def duration(self) -> float:
        return float(self.t[-1] - self.t[0])

    def shifted(self, t0: float) -> "Timing":
        return Timing(self.s, self.sd, self.t + t0)

    def at(self, t) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """s, sd, sdd (k,) at times t (k,), clamped to the grid's span, and whether s is
        at the end of its grid interval (k,) bool (reached from below: the path's
        derivatives there are those of the piece that ends there)."""
        t = np.clip(np.asarray(t, float), self.t[0], self.t[-1])
        i = np.clip(np.searchsorted(self.t, t, side="right") - 1, 0, len(self.t) - 2)
        u = accelerations(self.s, self.sd)[i]
        tau = t - self.t[i]
        s = np.minimum(self.s[i] + self.sd[i] * tau + 0.5 * u * tau * tau, self.s[i + 1])
        end = t >= self.t[-1]
        s = np.where(end, self.s[-1], s)  # the end exactly, and its speed (at rest: 0, not a rounding error)
        sd = np.where(end, self.sd[-1], np.maximum(self.sd[i] + u * tau, 0.0))
        return s, sd, u, s >= self.s[i + 1]


def accelerations(s: np.ndarray, sd: np.ndarray) -> np.ndarray:
    """Constant path acceleration (g - 1,) of each grid interval."""
    return (sd[1:] ** 2 - sd[:-1] ** 2) / (2 * np.diff(s))


def grid_times(s: np.ndarray, sd: np.ndarray) -> np.ndarray:
    """Times (g,) of the grid points, from 0."""
    return np.concatenate([[0.0], np.cumsum(2 * np.diff(s) / (sd[:-1] + sd[1:]))])


def trajectory(path: BlendedPath, timing: Timing, t) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Positions, velocities, accelerations (k, d) at times t (k,)."""
    s, sd, u, left = timing.at(t)
    d1, d2 = path.evaluate(s, 1, left), path.evaluate(s, 2, left)
    return path.evaluate(s), d1 * sd[:, None], d2 * (sd * sd)[:, None] + d1 * u[:, None]


def peaks(path: BlendedPath, s: np.ndarray, sd: np.ndarray, per_interval: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """Peaks (d,) of |velocity| and |acceleration| over every grid interval, sampled at
    ``per_interval + 1`` points of each (both ends, with the interval's own piece and
    acceleration: the one-sided values at a piece end are both seen).  Grid points must
    include the piece ends, so that P', P'' are polynomials on each interval."""
    u = accelerations(s, sd)
    f = np.linspace(0.0, 1.0, per_interval + 1)
    i = np.repeat(np.arange(len(s) - 1), len(f))
    ss = s[i] + np.tile(f, len(s) - 1) * (s[i + 1] - s[i])
    x = np.maximum(sd[i] ** 2 + 2 * u[i] * (ss - s[i]), 0.0)  # sd^2, linear in s
    k = np.clip(np.searchsorted(path.starts, 0.5 * (s[i] + s[i + 1]), side="right") - 1, 0, len(path.A) - 1)
    lam = path.starts[k + 1] - path.starts[k]
    frac = (ss - path.starts[k]) / lam
    d1 = bezier(path.A[k], path.C[k], path.B[k], lam, frac, 1)
    d2 = bezier(path.A[k], path.C[k], path.B[k], lam, frac, 2)
    vel = np.abs(d1) * np.sqrt(x)[:, None]
    acc = np.abs(d2 * x[:, None] + d1 * u[i][:, None])
    return vel.max(axis=0), acc.max(axis=0)


class _TopprPath:
    """One section of a BlendedPath between two stops, as toppra evaluates it."""

    def __init__(self, path: BlendedPath, lo: float, hi: float):
        self.path, self.lo, self.hi = path, lo, hi

    def __call__(self, s, order: int = 0) -> np.ndarray:
        s = np.atleast_1d(np.asarray(s, float))
        # at the section's last point, the piece that ends there (not the next section's)
        s_eval = np.where(s >= self.hi, np.nextafter(self.hi, self.lo), s)
        out = self.path.evaluate(s_eval, order)
        if order == 0:
            out[s >= self.hi] = self.path.evaluate(np.array([self.hi]), 0)[0]
        return out

    @property
    def dof(self) -> int:
        return self.path.A.shape[1]

    @property
    def path_interval(self) -> np.ndarray:
        return np.array([self.lo, self.hi])

    @property
    def waypoints(self):
        return None


def _grid(path: BlendedPath, lo: float, hi: float, extra: np.ndarray) -> np.ndarray:
    ends = path.starts[(path.starts >= lo) & (path.starts <= hi)]
    lam = np.diff(path.starts)
    before = path.starts[1:] - EDGE * lam
    before = before[(before > lo) & (before < hi)]
    even = np.linspace(lo, hi, int(np.ceil((hi - lo) / GRID_STEP)) + 1)
    g = np.unique(np.concatenate([ends, before, even, extra[(extra >= lo) & (extra <= hi)], [lo, hi]]))
    g = g[(g >= lo) & (g <= hi)]
    # points closer than MERGE are one (the first): a vanishing interval would have an absurd acceleration
    keep = np.concatenate([[True], np.diff(g) > MERGE * max(1.0, hi)])
    keep[-1] = True
    keep[-2] &= g[-1] - g[-2] > MERGE * max(1.0, hi) or len(g) == 2
    return g[keep]


def _topp(path: BlendedPath, lo: float, hi: float, v: np.ndarray, a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    grid = _grid(path, lo, hi, path.knots)
    cons = [toppra.constraint.JointVelocityConstraint(np.column_stack([-v, v])),
            toppra.constraint.JointAccelerationConstraint(np.column_stack([-a, a]))]
    algo = toppra.algorithm.TOPPRA(cons, _TopprPath(path, lo, hi), gridpoints=grid)
    _, sd, _, _ = algo.compute_parameterization(0.0, 0.0, return_data=True)
    if sd is None or not np.all(np.isfinite(sd)):
        raise RuntimeError(f"TOPP-RA found no parameterisation of the path section s in [{lo:g}, {hi:g}]")
    sd = np.maximum(np.asarray(sd, float), 0.0)
    sd[0] = sd[-1] = 0.0
    return grid, sd


def time_optimal(path: BlendedPath, v_max, a_max) -> Timing:
    """The fastest rest-to-rest timing of ``path`` between its stops under the velocity
    and acceleration limits (d,) less :data:`LIMIT_SLACK`, uniformly slowed where TOPP-RA's
    grid missed a peak."""
    v, a = np.asarray(v_max, float), np.asarray(a_max, float)
    bounds = path.starts[path.stops]
    s_parts, sd_parts = [], []
    for lo, hi in zip(bounds[:-1], bounds[1:]):
        g, sd = _topp(path, lo, hi, v * LIMIT_SLACK, a * LIMIT_SLACK)
        s_parts.append(g if not s_parts else g[1:])
        sd_parts.append(sd if not sd_parts else sd[1:])
    s, sd = np.concatenate(s_parts), np.concatenate(sd_parts)
    # a speed 0 inside a section (TOPP-RA's rounding) would need an infinite time there
    inner = np.ones(len(sd), bool)
    inner[np.searchsorted(s, bounds)] = False
    sd[inner] = np.maximum(sd[inner], 1e-9)
    vel, acc = peaks(path, s, sd)
    v, a = v * LIMIT_SLACK, a * LIMIT_SLACK
    scale = max(1.0, float(np.max(vel / v)), float(np.sqrt(np.max(acc / a))))
    sd = sd / scale
    return Timing(s, sd, grid_times(s, sd))
