"""Stable placements of an object on a horizontal support (the placement planner that
Harada et al. 2014, §III-C, rely on; issue 16, first step).

An object resting on a plane touches it with a face of its convex hull.  Each facet of the
hull (coplanar hull triangles merged, as trimesh groups them) is a candidate; it is stable
when the projection of the mass centre along the facet's normal falls inside the facet,
at least ``margin`` from its edges, and the object must turn by at least
``min_tipping_angle`` about the nearest edge before it tips over: ``atan(d / h)``, d the
projection's distance to that edge and h the mass centre's height above the facet.  The
placements are ranked by that angle, the most stable first.

A cylinder's side is a band of thin hull facets, each with a tipping angle of a few
degrees: it rolls.  Those are rejected by the angle, so a cylinder has its two caps only.
For a mesh that is not watertight (a scan), the mass centre is the surface centroid (see
:mod:`grasp.surface`) and the hull is that of the scanned points: placements are then as
good as that approximation.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh
from scipy.spatial import ConvexHull

from regrasp_cli.spatial import rotation_aligning


@dataclass(frozen=True)
class PlacementOptions:
    margin: float = 0.002  # m: the mass centre's projection at least this far inside the facet
    min_tipping_angle: float = 0.15  # rad: turn needed to tip over (below: it rolls)


@dataclass(frozen=True)
class StablePlacement:
    """The object resting on one hull facet.  Frame S: the support's surface, z up, the
    origin under the mass centre."""

    X_SO: np.ndarray  # (4, 4) object pose in S
    normal_O: np.ndarray  # (3,) outward normal of the facet in O (pointing down at rest)
    height: float  # m: mass centre above the support
    margin: float  # m: distance from the mass centre's projection to the facet's nearest edge
    tipping_angle: float  # rad: atan(margin / height)
    area: float  # m^2: the facet's area
    footprint: np.ndarray  # (k, 2) the facet's outline in S's xy plane, counter-clockwise


def _facets(hull: trimesh.Trimesh) -> list[np.ndarray]:
    """Face indices of each planar facet of the hull: trimesh's coplanar groups, and every
    triangle in none of them on its own."""
    groups = [np.asarray(f) for f in hull.facets]
    grouped = np.zeros(len(hull.faces), dtype=bool)
    for f in groups:
        grouped[f] = True
    return groups + [np.array([i]) for i in np.flatnonzero(~grouped)]


def stable_placements(mesh: trimesh.Trimesh, mass_centre: np.ndarray,
                      options: PlacementOptions = PlacementOptions()) -> list[StablePlacement]:
    """The stable placements of ``mesh`` (frame O, metres) with its mass centre at
    ``mass_centre`` (3,), most stable first (see the module docstring)."""
    hull = mesh.convex_hull
    c = np.asarray(mass_centre, dtype=float)
    out = []
    for faces in _facets(hull):
        n = hull.face_normals[faces[0]]
        pts = hull.vertices[np.unique(hull.faces[faces])]
        d = float(pts[0] @ n)
        h = d - float(n @ c)
        if h <= 0:
            continue  # the mass centre outside the hull (a bad mass centre): no rest on it
        R = rotation_aligning(n, np.array([0.0, 0.0, -1.0]))  # the facet faces down
        p2 = (pts @ R.T)[:, :2]
        q2 = (R @ c)[:2]
        try:
            poly = ConvexHull(p2)
        except Exception:  # degenerate (collinear) facet
            continue
        # equations: [a, b, e] with a x + b y + e <= 0 inside, (a, b) a unit normal
        inside = -(poly.equations[:, :2] @ q2 + poly.equations[:, 2]).max()  # to the nearest edge
        if inside < options.margin:
            continue
        angle = float(np.arctan2(inside, h))
        if angle < options.min_tipping_angle:
            continue
        X = np.eye(4)
        X[:3, :3] = R
        X[:3, 3] = [-q2[0], -q2[1], d]
        outline = p2[poly.vertices] - q2  # scipy lists 2-D hull vertices counter-clockwise
        out.append(StablePlacement(X, n.copy(), h, float(inside), angle, float(poly.volume), outline))
    return sorted(out, key=lambda p: -p.tipping_angle)
