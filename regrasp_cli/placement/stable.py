"""Stable placements of an object on a horizontal support (the placement planner that
Harada et al. 2014, §III-C, rely on; issue 16, first step).

An object resting on a plane touches it with a face of its convex hull.  Each facet of the
hull (adjacent hull triangles whose normals are within ``facet_angle`` of the facet's
largest one merged: on an exact mesh its coplanar triangles, on a scan the slightly tilted
triangles of a flat base) is a candidate, resting on the plane the hull supports along
the facet's mean normal, the facet's vertices within ``flatness`` of that plane touching
it; it is stable
when the projection of the mass centre along the facet's normal falls inside the facet,
at least ``margin`` from its edges, and the object must turn by at least
``min_tipping_angle`` about the nearest edge before it tips over: ``atan(d / h)``, d the
projection's distance to that edge and h the mass centre's height above the facet.  The
placements are ranked by that angle, the most stable first.

A cylinder's side is a band of thin hull facets, each with a tipping angle of a few
degrees: it rolls.  Those are rejected by the angle, so a cylinder has its two caps only.
For a mesh that is not watertight (a scan), the mass centre is the surface centroid (see
:mod:`grasp.surface`) and the hull is that of the scanned points: placements are then as
good as that approximation.  A round object (a scanned apple) may have none: no facet is
large enough to hold it by the margin and angle, and it is reported as rolling.
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
    facet_angle: float = 0.05  # rad: hull faces this close to a facet's first face's normal join it
    flatness: float = 0.001  # m: hull vertices this close to the support plane touch it


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


def _facets(hull: trimesh.Trimesh, angle: float) -> list[np.ndarray]:
    """Face indices of each nearly planar facet of the hull: regions grown from the
    largest face left over adjacent faces whose normals are within ``angle`` (rad) of the
    region's first face.  With a small angle these are trimesh's coplanar facets on an exact
    mesh; on a scan, the many slightly tilted triangles of a flat base join."""
    normals, order = hull.face_normals, np.argsort(-hull.area_faces, kind="stable")
    neighbours = [[] for _ in range(len(hull.faces))]
    for a, b in hull.face_adjacency:
        neighbours[a].append(b)
        neighbours[b].append(a)
    group = np.full(len(hull.faces), -1)
    out, cos = [], np.cos(angle)
    for seed in order:
        if group[seed] >= 0:
            continue
        group[seed], todo, members = len(out), [seed], [seed]
        while todo:
            for b in neighbours[todo.pop()]:
                if group[b] < 0 and normals[b] @ normals[seed] >= cos:
                    group[b] = len(out)
                    todo.append(b)
                    members.append(b)
        out.append(np.array(sorted(members)))
    return out


def stable_placements(mesh: trimesh.Trimesh, mass_centre: np.ndarray,
                      options: PlacementOptions = PlacementOptions()) -> list[StablePlacement]:
    """The stable placements of ``mesh`` (frame O, metres) with its mass centre at
    ``mass_centre`` (3,), most stable first (see the module docstring)."""
    hull = mesh.convex_hull
    c = np.asarray(mass_centre, dtype=float)
    facets = []  # (normal, support offset, vertices on the plane, height of the mass centre)
    for faces in _facets(hull, options.facet_angle):
        n = hull.area_faces[faces] @ hull.face_normals[faces]
        n /= np.linalg.norm(n)
        d = float((hull.vertices @ n).max())  # the support plane: nothing of the object below it
        own = hull.vertices[np.unique(hull.faces[faces])]
        pts = own[own @ n >= d - options.flatness]  # the facet's vertices on the plane
        h = d - float(n @ c)
        if len(pts) >= 3 and h > 0:  # h <= 0: the mass centre outside the hull (a bad mass centre)
            facets.append((n, d, pts, h))
    if not facets:
        return []
    down = np.tile([0.0, 0.0, -1.0], (len(facets), 1))
    turns = rotation_aligning(np.array([f[0] for f in facets]), down)  # each facet facing down, in one call
    out = []
    for (n, d, pts, h), R in zip(facets, turns):
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
