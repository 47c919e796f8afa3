"""Contact points on a triangulated surface and the geodesics between them (seed 003 §VI).

A contact on a polyhedral object is (triangle, u, v): the point ``(1 - u - v) a + u b + v
c`` of triangle ``(a, b, c)`` (§VI's (tr_i, u, v)).  A continuous contact trajectory
between two contacts is the geodesic between them on the surface, a sequence of line
segments across triangles (§VI).  It comes from potpourri3d's edge-flip geodesics (Sharp
and Crane 2020) after both points are inserted in the mesh as vertices: the result is a
locally shortest path, started from the shortest path along edges, which is the shortest
one on the meshes we use for contacts (convex or nearly so, between nearby contacts).

Frames: the mesh's (the object's); metres.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
import potpourri3d as pp3d
import trimesh

_INSIDE = 1e-6  # barycentric margin: a point on an edge or a vertex is moved this far inside


@dataclass(frozen=True)
class Surface:
    """A triangulated surface, vertices merged (geodesics need shared edges)."""

    V: np.ndarray  # (m, 3) vertices, m
    F: np.ndarray  # (k, 3) triangles, vertex indices
    normals: np.ndarray  # (k, 3) outward unit normals of the triangles
    cumulative: np.ndarray  # (k,) cumulative area fractions, for sampling by area

    @classmethod
    def of(cls, mesh: trimesh.Trimesh) -> "Surface":
        m = mesh.copy()
        m.merge_vertices()
        m.update_faces(m.nondegenerate_faces())
        area = m.area_faces
        return cls(np.asarray(m.vertices, float), np.asarray(m.faces, int), np.asarray(m.face_normals, float),
                   np.cumsum(area) / area.sum())

    def points(self, tri: np.ndarray, uv: np.ndarray) -> np.ndarray:
        """(n, 3) points of the contacts ``tri`` (n,), ``uv`` (n, 2)."""
        a, b, c = (self.V[self.F[tri, i]] for i in range(3))
        u, v = uv[:, :1], uv[:, 1:]
        return (1 - u - v) * a + u * b + v * c

    def sample(self, rng: np.random.Generator, count: int) -> tuple[np.ndarray, np.ndarray]:
        """``count`` contacts uniform by area: (tri (count,), uv (count, 2))."""
        tri = np.minimum(np.searchsorted(self.cumulative, rng.random(count)), len(self.F) - 1)
        uv = rng.random((count, 2))
        flip = uv.sum(axis=1) > 1
        uv[flip] = 1 - uv[flip]
        return tri, uv

    @cached_property
    def mesh(self) -> trimesh.Trimesh:
        return trimesh.Trimesh(self.V, self.F, process=False)

    def locate(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The contacts nearest the points ``p`` (n, 3): (tri (n,), uv (n, 2))."""
        _, _, tri = trimesh.proximity.closest_point(self.mesh, p)
        bary = trimesh.triangles.points_to_barycentric(self.V[self.F[tri]], p)
        return tri, bary[:, 1:]


def geodesic(s: Surface, tri: tuple[int, int], uv: tuple[np.ndarray, np.ndarray]) -> np.ndarray | None:
    """The surface path from contact ``(tri[0], uv[0])`` to ``(tri[1], uv[1])``: (k, 3)
    points, the first and last the contacts, each segment inside one triangle; None where
    the mesh is not manifold (the solver's requirement)."""
    p = s.points(np.asarray(tri), np.asarray(uv, float).reshape(2, 2))
    if tri[0] == tri[1]:
        return p
    V, F = s.V, s.F
    new_faces, keep = [], np.ones(len(F), bool)
    ids = []
    for k, t in enumerate(tri):
        w = np.clip(np.r_[1 - uv[k][0] - uv[k][1], uv[k][0], uv[k][1]], _INSIDE, 1.0)
        w /= w.sum()
        i = len(V) + k
        ids.append(i)
        a, b, c = F[t]
        new_faces += [(a, b, i), (b, c, i), (c, a, i)]
        keep[t] = False
        p[k] = w @ s.V[F[t]]
    V2 = np.vstack([V, p])
    F2 = np.vstack([F[keep], np.array(new_faces)])
    try:
        path = pp3d.EdgeFlipGeodesicSolver(V2, F2).find_geodesic_path(ids[0], ids[1])
    except RuntimeError:  # geometry-central refuses a mesh that is not manifold there (scans)
        return None
    return np.asarray(path, float)


def along(path: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Points at arc-length fractions ``t`` (m,) in [0, 1] of the polyline ``path`` (k, 3)."""
    seg = np.linalg.norm(np.diff(path, axis=0), axis=1)
    s = np.r_[0.0, np.cumsum(seg)]
    if s[-1] <= 0:
        return np.repeat(path[:1], len(t), axis=0)
    return np.stack([np.interp(np.asarray(t) * s[-1], s, path[:, i]) for i in range(3)], axis=1)


def length(path: np.ndarray) -> float:
    return float(np.linalg.norm(np.diff(path, axis=0), axis=1).sum())
