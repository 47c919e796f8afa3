"""Fingertip contacts and the stability of a grasp in GS_n (seed 003 §IV).

Contacts are points with Coulomb friction (§IV, eqs. 1-2): a fingertip pushes along the
inward normal with a tangential part of at most ``mu`` times the normal one.  A grasp is
stable, quasi-statically, when it is force closure (§IV): the test and its Ferrari-Canny
epsilon are :func:`grasp.quality.force_closure` over linearised friction cones.

For finger gaiting the paper asks more of a configuration of GS_n: *every* grasp of n-1
of its fingers must be force closure too, so that any finger may let go and move to a
new contact while the others hold the object (§IV, last paragraph; this is what makes a
path in GS_n reducible to regrasping and transfer paths).  :func:`gaitable` tests it.

Frames: points, normals and the centre in one frame (the object's, normally); normals
outward; metres.
"""

from __future__ import annotations

import itertools

import numpy as np

from regrasp_cli.grasp.quality import force_closure, is_force_closure, origin_inside, primitive_wrenches


def closure(p: np.ndarray, n: np.ndarray, mu: float, centre: np.ndarray, rho: float) -> float:
    """Ferrari-Canny epsilon of point contacts with friction at ``p`` (k, 3) with outward
    normals ``n`` (k, 3), torques about ``centre`` (3,) divided by ``rho`` (m, the object's
    radius); 0.0 when the grasp is not force closure."""
    if len(p) < 2:
        return 0.0
    return force_closure(primitive_wrenches(p, n, mu, centre, rho))[1]


def closed(p: np.ndarray, n: np.ndarray, mu: float, centre: np.ndarray, rho: float) -> bool:
    """:func:`closure` > 0, mostly without the hull (:func:`grasp.quality.is_force_closure`)."""
    return len(p) >= 2 and is_force_closure(primitive_wrenches(p, n, mu, centre, rho))


def holds(p: np.ndarray, n: np.ndarray, mu: float, centre: np.ndarray, rho: float) -> bool:
    """Force closure, as :func:`closure` > 0 decides it but at the very boundary (epsilon
    under its 1e-6 margin), without the epsilon: no 6-D hull, most of the cost
    (:func:`grasp.quality.origin_inside`)."""
    return len(p) >= 2 and origin_inside(primitive_wrenches(p, n, mu, centre, rho))


def normals_meet(p: np.ndarray, n: np.ndarray) -> float:
    """How far (m, root mean square) the contact normals' lines (through ``p`` (k, 3) along
    ``n`` (k, 3)) pass from the point nearest all of them: 0 when they meet in one point
    (every contact on a sphere: its centre), as then the normal forces have no moment about
    that point, and only friction keeps the object from turning about it."""
    n = n / np.linalg.norm(n, axis=1, keepdims=True)
    M = np.eye(3)[None] - n[:, :, None] * n[:, None, :]  # projections across each line
    x = np.linalg.lstsq(M.sum(axis=0), np.einsum("kij,kj->i", M, p), rcond=None)[0]
    return float(np.sqrt(np.mean(np.sum(np.einsum("kij,kj->ki", M, p - x) ** 2, axis=1))))


def gaitable(p: np.ndarray, n: np.ndarray, mu: float, centre: np.ndarray, rho: float) -> float:
    """The least epsilon over the grasps that leave one finger out (each finger may be
    lifted for a regrasp), 0.0 when one of them is not force closure; the whole grasp is
    force closure then as well (a superset of contacts)."""
    worst = np.inf
    for keep in itertools.combinations(range(len(p)), len(p) - 1):
        eps = closure(p[list(keep)], n[list(keep)], mu, centre, rho)
        if eps <= 0.0:
            return 0.0
        worst = min(worst, eps)
    return float(worst) if np.isfinite(worst) else 0.0
