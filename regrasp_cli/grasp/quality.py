"""Grasp stability filter and quality score (Saut et al. 2010, §IV-A-3).

Saut, Gharbi, Cortés, Sidobre and Siméon, "Planning Pick-and-Place tasks with two-hand
regrasping" (IROS 2010), §IV-A-3 "Stability filter and quality score":

* the stability test uses the *point contact with friction* model: from the contact
  positions and normals a force-closure score is computed and every grasp that is not
  force closure is discarded;
* the surviving grasps are ranked by a weighted sum of four scores: the force-closure
  score, the distance from the contact centroid to the object's mass centre, the angles
  between each contact normal and the force-ellipsoid major axis of its finger, and the
  object's surface "inverse curvature" at the contacts (curvatures normalised over the
  sampled surface), with weights (1.0, 1.0, 1.0, 6.0).

Methods used here (all pure functions over numpy arrays):

* **Linearised Coulomb cone** (:func:`friction_cone_edges`): ``n_edges`` forces on the
  boundary of the cone of half-angle ``atan(mu)``, each with a *unit normal component*.
  The polyhedral cone they span is inscribed in the true cone (conservative).
* **Primitive contact wrenches** (:func:`primitive_wrenches`): for each contact and each
  cone edge ``f`` the wrench ``[f, (p - c) x f / rho]``; for the soft-finger model also the
  two torsional wrenches ``[f_n, ((p - c) x f_n ± gamma n) / rho]`` (Murray, Li & Sastry
  1994, §5.2).  ``rho`` is a characteristic length making torques commensurate with forces.
* **Force closure and epsilon quality** (:func:`force_closure`): the grasp is force
  closure iff the origin of wrench space lies strictly inside the convex hull of the
  primitive wrenches (Mishra, Schwartz & Sharir 1987; Murray-Li-Sastry Prop. 5.2); the
  score is the Ferrari–Canny (1992) L1 epsilon, the radius of the largest origin-centred
  ball inside that hull (the hull of the *union* of the primitive wrenches is the
  wrench set reachable with a unit *sum* of normal forces, hence "L1").  Hulls are
  computed by Qhull (``scipy.spatial.ConvexHull``); the nearest facet is found on a hull
  of a few of the wrenches, grown until its nearest facet is the whole hull's
  (:func:`_nearest_facet`).  The paper cites Bounab et al. 2008
  (central-axis method) for its force-closure test; the convex-hull test decides the
  same property exactly for the linearised cones and also yields a metric score.
* **Force ellipsoid** (:func:`force_ellipsoid_axis`): with ``tau = J^T f`` the fingertip
  forces reachable with ``||tau|| <= 1`` form the ellipsoid ``f^T (J J^T) f <= 1``; its
  major axis (largest force) is the eigenvector of ``J J^T`` of smallest *nonzero*
  eigenvalue (Yoshikawa 1985).

Conventions shared by all functions:

* **Frame**: every point, normal, centre, Jacobian and axis passed to one call must be
  expressed in the same frame (typically the object frame); results are in that frame.
* **Units**: positions and lengths in metres; forces are dimensionless (each contact's
  normal force component is 1, so the wrench set is the one of Ferrari–Canny's L1 unit
  grasp); torques are divided by ``rho`` (m), so every wrench coordinate is a force.
* **Normals** are *outward* unit surface normals of the object at the contacts.  The
  force a finger applies pushes *into* the object: it is ``-n`` plus a tangential part of
  norm at most ``mu``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np
from scipy.optimize import nnls
from scipy.spatial import ConvexHull, QhullError

#: Contact-patch radius (m) used for the default torsional friction of soft-finger
#: contacts: a soft robotic or human fingertip pressed with a few newtons makes a
#: patch of a few millimetres radius.
DEFAULT_PATCH_RADIUS = 0.005

#: Absolute tolerance (wrench units: unit normal force, torque / rho) of the
#: strict-interior test of :func:`force_closure`: the origin must be at least this far
#: inside every hull facet, so grasps with epsilon <= 1e-6 count as *not* force closure.
#: Such a grasp resists only disturbances a millionth of its grip force, which is
#: physically nothing, and the margin keeps Qhull round-off on nearly flat wrench sets
#: (~1e-12 here) from deciding the test.  Example: three contacts 120 deg apart on a
#: sphere's equator are force closure in exact arithmetic for *any* mu > 0, with
#: epsilon ~ 0.45 mu for small mu (rho = radius, 8 cone edges), so mu = 1e-6 (epsilon
#: ~ 4.5e-7) is rejected as frictionless.  Pass ``tol`` explicitly for the exact test.
FORCE_CLOSURE_TOL = 1e-6


# --------------------------------------------------------------------------- contacts


def _unit_rows(v: np.ndarray, name: str) -> np.ndarray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    if np.any(n < 1e-12):
        raise ValueError(f"{name}: zero-length vector")
    return v / n


def _tangent_basis(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors (3,) completing the unit vector ``n`` to a right-handed frame."""
    helper = np.zeros(3)
    helper[int(np.argmin(np.abs(n)))] = 1.0  # axis least aligned with n
    t1 = np.cross(n, helper)
    t1 /= np.linalg.norm(t1)
    t2 = np.cross(n, t1)
    return t1, t2


def friction_cone_edges(normal, mu: float, n_edges: int = 8) -> np.ndarray:
    """Edges of the linearised Coulomb friction cone of one contact.

    Args:
        normal: (3,) *outward* surface normal of the object at the contact (need not be
            unit; it is normalised).
        mu: Coulomb friction coefficient (>= 0, dimensionless).
        n_edges: number of edges (>= 3) of the inscribed polyhedral cone.

    Returns:
        (n_edges, 3) forces ``f_j = -n + mu (cos a_j t1 + sin a_j t2)``, ``a_j = 2 pi j /
        n_edges``, with ``n`` the unit normal and ``(t1, t2)`` a tangent basis.  Each has
        a unit component along the *inward* normal ``-n`` (the direction a finger
        pushes), so ``|f_j| = sqrt(1 + mu^2)``; the edges lie on the true cone, so the
        polyhedral cone they span is inscribed in it.  For even ``n_edges`` opposite edges
        are symmetric about ``-n``.  Same frame as ``normal``.
    """
    if mu < 0:
        raise ValueError(f"mu must be >= 0, got {mu}")
    if n_edges < 3:
        raise ValueError(f"n_edges must be >= 3, got {n_edges}")
    n = _unit_rows(np.asarray(normal, dtype=float).reshape(3), "normal")
    t1, t2 = _tangent_basis(n)
    a = 2.0 * np.pi * np.arange(n_edges) / n_edges
    return -n + mu * (np.cos(a)[:, None] * t1 + np.sin(a)[:, None] * t2)


def default_torque_scale(points, centre) -> float:
    """Default ``rho`` (m): the largest distance from ``centre`` (3,) to a contact of
    ``points`` (k, 3); 1.0 if every contact is at the centre."""
    d = np.linalg.norm(np.asarray(points, float).reshape(-1, 3) - np.asarray(centre, float), axis=1)
    r = float(d.max()) if d.size else 0.0
    return r if r > 1e-12 else 1.0


def default_torsion_mu(mu: float, patch_radius: float = DEFAULT_PATCH_RADIUS) -> float:
    """Default torsional friction coefficient ``gamma`` (m) of a soft-finger contact.

    ``gamma`` bounds the torque about the normal per unit normal force,
    ``|tau_n| <= gamma f_n``.  For a circular patch of radius ``a`` under uniform pressure
    with Coulomb friction ``mu`` the maximal friction torque is ``(2/3) mu a f_n``, hence
    ``gamma = (2/3) mu a`` with ``a = patch_radius`` (default :data:`DEFAULT_PATCH_RADIUS`).
    """
    return 2.0 / 3.0 * mu * patch_radius


def primitive_wrenches(
    points,
    normals,
    mu: float,
    centre,
    torque_scale: float | None = None,
    contact: str = "point",
    n_edges: int = 8,
    torsion_mu: float | None = None,
) -> np.ndarray:
    """Primitive wrenches of a grasp: the generators of its grasp wrench space.

    Args:
        points: (k, 3) contact positions (m).
        normals: (k, 3) *outward* surface normals at the contacts (normalised here).
        mu: Coulomb friction coefficient (>= 0).
        centre: (3,) point about which torques are taken (m), normally the mass centre.
        torque_scale: ``rho`` (m), the characteristic length dividing torques so that they
            are commensurate with forces (a torque ``rho`` N m counts like 1 N).  The
            epsilon quality depends on it, so compare grasps of one object with one
            ``rho``: pass the object's radius (max distance from ``centre`` to its
            surface).  Default: :func:`default_torque_scale` of the contacts.
        contact: ``"point"`` (point contact with friction, the paper's model) or
            ``"soft"`` (soft finger: adds torsional friction about the normal).
        n_edges: edges per linearised friction cone (see :func:`friction_cone_edges`).
        torsion_mu: soft-finger torsional friction coefficient ``gamma`` (m): torque
            about the normal per unit normal force.  Default: :func:`default_torsion_mu`.

    Returns:
        (m, 6) wrenches ``[f, (p - c) x f / rho]`` (force first), ``m = k n_edges`` for
        point contacts, ``k (n_edges + 2)`` for soft ones (contact-major order; a soft
        contact's two torsional wrenches ``[-n, ((p - c) x (-n) ± gamma n) / rho]`` follow
        its cone edges).  All with unit normal force.
    """
    P = np.asarray(points, dtype=float).reshape(-1, 3)
    N = _unit_rows(np.asarray(normals, dtype=float).reshape(-1, 3), "normals")
    if P.shape != N.shape:
        raise ValueError(f"points {P.shape} and normals {N.shape} differ")
    if contact not in ("point", "soft"):
        raise ValueError(f"contact must be 'point' or 'soft', got {contact!r}")
    c = np.asarray(centre, dtype=float).reshape(3)
    rho = default_torque_scale(P, c) if torque_scale is None else float(torque_scale)
    if rho <= 0:
        raise ValueError(f"torque_scale must be > 0, got {rho}")
    if contact == "soft":
        gamma = default_torsion_mu(mu) if torsion_mu is None else float(torsion_mu)
        if gamma < 0:
            raise ValueError(f"torsion_mu must be >= 0, got {gamma}")
    if contact == "point":
        return _point_wrenches(P, N, mu, c, rho, n_edges)
    out = []
    for p, n in zip(P, N):
        f = friction_cone_edges(n, mu, n_edges)
        r = p - c
        if contact == "soft":
            fn = -n
            f = np.vstack([f, fn, fn])
            extra = np.vstack([gamma * n, -gamma * n])
        tau = np.cross(r, f)
        if contact == "soft":
            tau[-2:] += extra
        out.append(np.hstack([f, tau / rho]))
    return np.vstack(out) if out else np.zeros((0, 6))


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``np.cross`` of 3-vectors along the last axis (broadcast), the same products and
    differences in the same order, so bit for bit the same: without its axis handling,
    a third of the time (the in-hand planner builds wrenches at every closure test)."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-1)


def _point_wrenches(P: np.ndarray, N: np.ndarray, mu: float, c: np.ndarray, rho: float,
                    n_edges: int) -> np.ndarray:
    """:func:`primitive_wrenches` of point contacts, all contacts at once (the same
    tangent bases as :func:`_tangent_basis`, the same edges as :func:`friction_cone_edges`)."""
    if mu < 0:
        raise ValueError(f"mu must be >= 0, got {mu}")
    if n_edges < 3:
        raise ValueError(f"n_edges must be >= 3, got {n_edges}")
    k = len(P)
    helper = np.zeros((k, 3))
    helper[np.arange(k), np.argmin(np.abs(N), axis=1)] = 1.0
    t1 = _cross(N, helper)
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    t2 = _cross(N, t1)
    a = 2.0 * np.pi * np.arange(n_edges) / n_edges
    F = -N[:, None] + mu * (np.cos(a)[None, :, None] * t1[:, None] + np.sin(a)[None, :, None] * t2[:, None])
    tau = _cross((P - c)[:, None], F)
    return np.concatenate([F, tau / rho], axis=2).reshape(k * n_edges, 6)


# ----------------------------------------------------------------------- force closure


def _positive_null_combination(W: np.ndarray) -> bool:
    """Is there lambda > 0 (every component) with W^T lambda = 0?  Then the origin is in
    the relative interior of the hull of W.  Such a lambda exists iff -sum(w_i) is in the
    cone of the w_i (lambda = 1 + mu for -sum w_i = W^T mu, mu >= 0; conversely scale
    lambda to min 1): one non-negative least-squares solve, its residual zero."""
    b = -W.sum(axis=0)
    _, residual = nnls(W.T, b)
    return residual <= 1e-9 * max(float(np.linalg.norm(b)), 1.0)


def origin_inside(wrenches) -> bool:
    """Is the origin strictly inside the convex hull of the wrenches (m, 6), i.e. force
    closure, without the margin and the epsilon of :func:`force_closure` (no 6-D hull,
    most of its cost)?  The points must affinely span R^6 and a strictly positive
    combination of them vanish (a non-negative least-squares solve, tens of
    microseconds): with full rank the origin is then interior, not on the boundary."""
    W = np.asarray(wrenches, dtype=float)
    if W.ndim != 2 or W.shape[1] != 6:
        raise ValueError(f"wrenches must have shape (m, 6), got {W.shape}")
    if not np.all(np.isfinite(W)):
        raise ValueError("wrenches contain non-finite values")
    # The origin can only be interior if the points affinely span R^6.
    return _spans(W) and _positive_null_combination(W)


def _spans(W: np.ndarray) -> bool:
    """Do the points (m, 6) affinely span R^6 (a 6-D hull)?"""
    if W.shape[0] < 7:  # a 6-simplex needs 7 vertices
        return False
    s = np.linalg.svd(W - W.mean(axis=0), compute_uv=False)
    return bool(s[-1] > 1e-12 * max(s[0], 1.0))


def contains_ball(wrenches, radius: float) -> bool:
    """A sufficient test that the ball of ``radius`` about the origin lies strictly inside
    the convex hull of the wrenches (m, 6), without the hull: the cross-polytope with
    vertices ``+-sqrt(6) radius e_k`` (k = 1..6) has that ball inscribed, and it is inside
    the hull when each of its 12 vertices is interior (:func:`origin_inside` of the
    shifted points: one non-negative least-squares solve each, ~10 us).  False says
    nothing: the ball may still be inside."""
    W = np.asarray(wrenches, dtype=float)
    if not _spans(W):
        return False
    r = math.sqrt(6.0) * radius
    return all(_positive_null_combination(W - sign * r * e) for e in np.eye(6) for sign in (1.0, -1.0))


def is_force_closure(wrenches, tol: float = FORCE_CLOSURE_TOL) -> bool:
    """``force_closure(wrenches, tol)[0]``, the same answer, mostly without the hull (an
    eighth of the time for three contacts' 24 wrenches): a ball of twice ``tol`` inside
    it (:func:`contains_ball`) puts every facet farther than ``tol``; otherwise
    :func:`force_closure` decides (the origin not interior, without the hull either).
    Twice: a grasp whose nearest facet is within ``tol`` leaves a vertex of the
    cross-polytope outside by ``tol`` at least, a million times what the least-squares
    residual test can mistake."""
    W = np.asarray(wrenches, dtype=float)
    return contains_ball(W, 2.0 * tol) or force_closure(W, tol)[0]


def _hull(W: np.ndarray) -> ConvexHull:
    """The convex hull of the points W (m, 6): Qhull without merging coplanar facets first
    ("Q0"), a third of the time of its default exact merging ("Qx") for a grasp's 24-32
    wrenches and the same facet planes; its default when that meets a precision error
    (a few sets in a hundred, most with contacts on parallel faces)."""
    try:
        return ConvexHull(W, qhull_options="Q0")
    except QhullError:
        return ConvexHull(W)


#: Directions whose support points seed :func:`_nearest_facet`'s sub-hull: the twelve
#: coordinate half-axes; then, if those points lie flat, twelve more (fixed: deterministic).
_SEED_DIRECTIONS = np.vstack([np.eye(6), -np.eye(6)])
_MORE_DIRECTIONS = np.vstack([np.eye(6) + np.roll(np.eye(6), 1, axis=1), np.eye(6) - np.roll(np.eye(6), 1, axis=1)])
_NEAREST_FACETS = 4  # the sub-hull's facets whose support points join it at each round
_SUPPORT_TOL = 1e-12  # wrench units: a facet whose plane no wrench passes by more is the hull's


def _nearest_facet(W: np.ndarray) -> float | None:
    """The distance from the origin to the nearest facet of the hull of W (m, 6), the
    origin strictly inside (:func:`origin_inside`), without the whole hull: the expanding
    polytope idea (van den Bergen 2001) on the wrench set.  A hull of some of the points
    (seeded with the support points along the axes) holds the origin's nearest facet of
    the whole hull once the plane of its own nearest facet supports every point: then
    that facet's distance is at most epsilon (the sub-hull is inside the hull) and at
    least epsilon (no point lies beyond the plane), to :data:`_SUPPORT_TOL`.  Until then
    the support points of its nearest facets' normals join it.  Half the time of the
    whole hull (a few rounds of 12-16 points against 24-32 points and ~700 facets), the
    same epsilon to 1e-15.  None when Qhull cannot build a sub-hull or a round adds no
    point (rounding): the whole hull decides."""
    chosen = set(np.argmax(W @ _SEED_DIRECTIONS.T, axis=0).tolist())
    more = [_MORE_DIRECTIONS]
    while True:
        try:
            hull = _hull(W[sorted(chosen)]) if len(chosen) > 6 else None
        except QhullError:  # the chosen points lie flat
            hull = None
        if hull is None:
            if not more:
                return None
            chosen |= set(np.argmax(W @ more.pop().T, axis=0).tolist())
            continue
        offsets = hull.equations[:, -1]
        near = np.argsort(-offsets, kind="stable")[:_NEAREST_FACETS]
        distance = -offsets[near]
        support = W @ hull.equations[near, :6].T  # (m, k)
        best = np.argmax(support, axis=0)
        beyond = support[best, np.arange(len(near))] > distance + _SUPPORT_TOL
        if not beyond[0]:
            return float(distance[0])
        new = set(best[beyond].tolist()) - chosen
        if not new:
            return None
        chosen |= new


def force_closure(wrenches, tol: float = FORCE_CLOSURE_TOL) -> tuple[bool, float]:
    """Exact force-closure test and Ferrari–Canny L1 epsilon quality.

    Args:
        wrenches: (m, 6) primitive wrenches (from :func:`primitive_wrenches`).
        tol: the origin must lie at least ``tol`` inside every facet (wrench units);
            default :data:`FORCE_CLOSURE_TOL` = 1e-6, see there.

    Returns:
        ``(is_fc, epsilon)``.  ``is_fc`` is True iff the origin is strictly inside the
        convex hull of the wrenches: the hull must be 6-dimensional (fewer than 7 points,
        a rank-deficient set or a Qhull failure on a flat set mean "not force closure")
        and every facet ``a.x + b <= 0`` of ``hull.equations`` (unit ``a``) must have
        offset ``b < -tol``.  ``epsilon = min(-b)`` is then the distance from the origin
        to the hull boundary, i.e. the largest wrench (any direction) the grasp resists
        with a unit sum of normal forces; it is 0.0 when not force closure.
    """
    W = np.asarray(wrenches, dtype=float)
    if not origin_inside(W):
        return False, 0.0
    epsilon = _nearest_facet(W)
    if epsilon is None:
        try:
            epsilon = float(-_hull(W).equations[:, -1].max())
        except QhullError:  # flat or otherwise degenerate set
            return False, 0.0
    return (True, epsilon) if epsilon > tol else (False, 0.0)


# ---------------------------------------------------------------------- force ellipsoid


def force_ellipsoid_axis(J, rtol: float = 1e-9) -> np.ndarray:
    """Major axis of a finger's force ellipsoid at its fingertip.

    Args:
        J: (3, n) translational Jacobian of the fingertip (m/rad for revolute joints),
            expressed in the frame of the result (e.g. the object frame); or a batch of
            them (B, 3, n).
        rtol: singular values below ``rtol * max`` count as zero.

    Returns:
        (3,) unit vector ((B, 3) for a batch): the direction of largest fingertip force for
        unit joint torques (``tau = J^T f``, ``||tau|| <= 1``  <=>  ``f^T J J^T f <= 1``),
        i.e. the eigenvector of ``J J^T`` with the smallest *nonzero* eigenvalue (left
        singular vector of the smallest nonzero singular value of ``J``).  Directions in
        the null space of ``J^T`` are held by the structure, not the joints, and are
        excluded: for a rank-1 finger (one joint) the axis is the joint's direction of
        motion, for a full-rank finger it is the classic force-ellipsoid major axis.  An
        axis has no sign; the result's largest-magnitude component is made positive for
        determinism.
    """
    J = np.asarray(J, dtype=float)
    if J.ndim == 1:
        J = J.reshape(3, 1)
    if J.ndim not in (2, 3) or J.shape[-2] != 3:
        raise ValueError(f"J must have shape (3, n) or (B, 3, n), got {J.shape}")
    if J.ndim == 2:
        return force_ellipsoid_axis(J[None], rtol)[0]
    if not len(J):
        return np.zeros((0, 3))
    U, s, _ = np.linalg.svd(J, full_matrices=False)  # (B, 3, k), (B, k)
    if s.shape[1] == 0 or np.any(s[:, 0] <= 0.0):
        raise ValueError("J is zero: the finger cannot apply any force")
    rank = np.sum(s > rtol * s[:, :1], axis=1)
    rows = np.arange(len(J))
    a = U[rows, :, rank - 1]
    return a * np.where(a[rows, np.argmax(np.abs(a), axis=1)] > 0, 1.0, -1.0)[:, None]


# ---------------------------------------------------------------------- quality scores


@dataclass(frozen=True)
class QualityWeights:
    """Weights of the four scores (paper: 1.0, 1.0, 1.0, 6.0)."""

    force_closure: float = 1.0
    centroid: float = 1.0
    ellipsoid: float = 1.0
    curvature: float = 6.0

    def as_array(self) -> np.ndarray:
        """(4,) weights in the order force_closure, centroid, ellipsoid, curvature."""
        return np.array([getattr(self, f.name) for f in fields(self)], dtype=float)


@dataclass(frozen=True)
class GraspScores:
    """The four scores of one grasp, each "higher is better" in [0, 1], and their
    weighted combination ``total`` in [0, 1] (see :func:`grasp_quality`)."""

    epsilon: float
    centroid: float
    ellipsoid: float
    curvature: float
    total: float

    @property
    def is_force_closure(self) -> bool:
        """True iff the grasp passed the stability filter (epsilon > 0)."""
        return self.epsilon > 0.0


def normalise_curvatures(contact_curvatures, surface_curvatures, percentile: float = 100.0) -> np.ndarray:
    """Curvatures at the contacts normalised over the object's sampled surface.

    Args:
        contact_curvatures: (k,) curvature magnitudes at the contacts (1/m; the sign is
            dropped), e.g. the largest absolute principal curvature.
        surface_curvatures: (s,) the same quantity at the object's surface samples.
        percentile: normaliser = this percentile of ``|surface_curvatures|``; 100 (the
            maximum, as in the paper) or e.g. 99 to ignore a few sharp-edge outliers.

    Returns:
        (k,) ``kappa = clip(|c| / normaliser, 0, 1)``: 0 where flat, 1 at the sharpest
        surface samples.  All zeros if the whole surface is flat.
    """
    c = np.abs(np.asarray(contact_curvatures, dtype=float).reshape(-1))
    s = np.abs(np.asarray(surface_curvatures, dtype=float).reshape(-1))
    scale = float(np.percentile(s, percentile)) if s.size else 0.0
    if scale <= 0.0:
        return np.zeros_like(c)
    return np.clip(c / scale, 0.0, 1.0)


def _axis_angles(forces: np.ndarray, axes: np.ndarray) -> np.ndarray:
    """Angles (rad, in [0, pi/2]) between force directions and sign-free axes, row-wise."""
    f = _unit_rows(forces, "normals")
    a = _unit_rows(axes, "finger_axes")
    cos = np.abs(np.sum(f * a, axis=1))
    return np.arccos(np.clip(cos, 0.0, 1.0))


def quality_terms(
    epsilon: float,
    points,
    normals,
    mass_centre,
    finger_axes,
    curvatures,
    torque_scale: float | None = None,
) -> np.ndarray:
    """The paper's four scores, each mapped to "higher is better" in [0, 1].

    Args:
        epsilon: Ferrari–Canny epsilon from :func:`force_closure` (0 if not force closure).
        points: (k, 3) contact positions (m).
        normals: (k, 3) outward surface normals at the contacts.
        mass_centre: (3,) object's mass centre (m).
        finger_axes: (k, 3) force-ellipsoid major axis of the finger touching each contact
            (:func:`force_ellipsoid_axis`, same frame; sign-free).
        curvatures: (k,) normalised curvatures ``kappa`` in [0, 1] at the contacts
            (:func:`normalise_curvatures`).
        torque_scale: ``rho`` (m) used as the centroid-distance scale; default
            :func:`default_torque_scale` of the contacts about ``mass_centre``.

    Returns:
        (4,) array, in :class:`QualityWeights` order:

        * force closure: ``clip(epsilon, 0, 1)``;
        * centroid: ``1 - min(1, ||mean(points) - mass_centre|| / rho)`` (1 when the
          contact centroid is at the mass centre, 0 at distance >= rho);
        * ellipsoid: ``1 - mean_i angle(-n_i, axis_i) / (pi / 2)``, the angle between the
          applied force direction and the sign-free axis being in [0, pi/2] (1 when every
          finger pushes along its strongest direction, 0 when all push across it);
        * curvature: ``mean_i (1 - kappa_i)``, the paper's "inverse curvature" as a
          bounded flatness (1 when every contact is on a flat region).
    """
    P = np.asarray(points, dtype=float).reshape(-1, 3)
    N = np.asarray(normals, dtype=float).reshape(-1, 3)
    A = np.asarray(finger_axes, dtype=float).reshape(-1, 3)
    K = np.asarray(curvatures, dtype=float).reshape(-1)
    k = P.shape[0]
    if k == 0 or N.shape[0] != k or A.shape[0] != k or K.shape[0] != k:
        raise ValueError(
            f"need k >= 1 contacts with matching rows: points {P.shape}, normals {N.shape}, "
            f"finger_axes {A.shape}, curvatures {K.shape}"
        )
    c = np.asarray(mass_centre, dtype=float).reshape(3)
    rho = default_torque_scale(P, c) if torque_scale is None else float(torque_scale)
    if rho <= 0:
        raise ValueError(f"torque_scale must be > 0, got {rho}")
    s_fc = float(np.clip(epsilon, 0.0, 1.0))
    s_centroid = 1.0 - min(1.0, float(np.linalg.norm(P.mean(axis=0) - c)) / rho)
    s_ellipsoid = 1.0 - float(np.mean(_axis_angles(-N, A))) / (math.pi / 2.0)
    s_curvature = float(np.mean(1.0 - np.clip(K, 0.0, 1.0)))
    return np.clip(np.array([s_fc, s_centroid, s_ellipsoid, s_curvature]), 0.0, 1.0)


def combine_scores(terms, weights: QualityWeights = QualityWeights()) -> float:
    """Weighted sum of the (4,) ``terms`` divided by the sum of the weights, in [0, 1].

    Dividing by the weight total only rescales the paper's plain weighted sum, so the
    ranking of grasps is the paper's.
    """
    w = weights.as_array()
    if np.any(w < 0) or w.sum() <= 0:
        raise ValueError(f"weights must be >= 0 with a positive sum, got {weights}")
    return float(np.dot(w, np.asarray(terms, dtype=float).reshape(4)) / w.sum())


def grasp_quality(
    points,
    normals,
    mu: float,
    mass_centre,
    finger_axes,
    curvatures,
    torque_scale: float | None = None,
    weights: QualityWeights = QualityWeights(),
    contact: str = "point",
    n_edges: int = 8,
    torsion_mu: float | None = None,
) -> GraspScores:
    """Stability filter and quality score of one grasp (Saut et al. 2010, §IV-A-3).

    Args: as :func:`primitive_wrenches` (torques about ``mass_centre``) and
    :func:`quality_terms`; ``weights`` default to the paper's (1, 1, 1, 6).

    Returns:
        :class:`GraspScores` with ``epsilon`` the *unclipped* Ferrari–Canny epsilon (0 if
        not force closure), the three other terms of :func:`quality_terms` and
        ``total = combine_scores(terms, weights)``.  A grasp that is not force closure is
        rejected by the paper's stability filter: its ``total`` is 0.0 (its other terms
        are still reported) and ``is_force_closure`` is False.
    """
    c = np.asarray(mass_centre, dtype=float).reshape(3)
    P = np.asarray(points, dtype=float).reshape(-1, 3)
    rho = default_torque_scale(P, c) if torque_scale is None else float(torque_scale)
    W = primitive_wrenches(P, normals, mu, c, rho, contact=contact, n_edges=n_edges, torsion_mu=torsion_mu)
    is_fc, eps = force_closure(W)
    terms = quality_terms(eps, P, normals, c, finger_axes, curvatures, rho)
    total = combine_scores(terms, weights) if is_fc else 0.0
    return GraspScores(
        epsilon=eps,
        centroid=float(terms[1]),
        ellipsoid=float(terms[2]),
        curvature=float(terms[3]),
        total=total,
    )
