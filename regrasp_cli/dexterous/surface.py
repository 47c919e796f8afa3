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
from scipy.spatial import cKDTree

_INSIDE = 1e-6  # barycentric margin: a point on an edge or a vertex is moved this far inside


@dataclass(frozen=True)
class MeshSurface:
    """A triangulated surface, vertices merged (geodesics need shared edges)."""

    V: np.ndarray  # (m, 3) vertices, m
    F: np.ndarray  # (k, 3) triangles, vertex indices
    normals: np.ndarray  # (k, 3) outward unit normals of the triangles
    cumulative: np.ndarray  # (k,) cumulative area fractions, for sampling by area

    @classmethod
    def of(cls, mesh: trimesh.Trimesh) -> "MeshSurface":
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

    @cached_property
    def _vertex_tree(self) -> cKDTree:
        return cKDTree(self.V[np.unique(self.F)])

    @cached_property
    def _triangles(self) -> np.ndarray:
        return self.V[self.F]

    def locate(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The contacts nearest the points ``p`` (n, 3): (tri (n,), uv (n, 2)).

        The nearest point is on a triangle whose bounding box meets the box round ``p``
        that reaches its nearest vertex (trimesh's triangle tree); of two triangles as
        near (an edge, a vertex), the one that faces ``p`` more.  trimesh's own
        ``closest_point`` does the same but builds a vertex tree at every call, a
        tenth of a planning run on a scan."""
        p = np.asarray(p, float).reshape(-1, 3)
        if len(p) == 0:
            return np.zeros(0, np.intp), np.zeros((0, 2))
        reach = self._vertex_tree.query(p)[0][:, None] + trimesh.tol.merge
        hits, counts = self.mesh.triangles_tree.intersection_v(p - reach, p + reach)
        hits, counts = hits.astype(np.intp), counts.astype(np.intp)
        owner = np.repeat(np.arange(len(p)), counts)
        close = trimesh.triangles.closest_point(self._triangles[hits], p[owner])
        away = p[owner] - close
        d2 = np.dot(away * away, [1.0, 1.0, 1.0])  # as trimesh rounds it: ties on an edge break alike
        first = np.r_[0, np.cumsum(counts)[:-1]]
        # the two nearest of each point's triangles, sorted as trimesh sorts them (its
        # sort is not stable: a point on an edge must get the triangle trimesh gives)
        two = np.array([g.argsort()[:2] if len(g) > 1 else [0, 0] for g in np.split(d2, first[1:])]) + first[:, None]
        pick = two[:, 0].copy()
        tied = (np.ptp(d2[two], axis=1) < trimesh.tol.merge) & np.all(np.abs(d2[two]) > trimesh.tol.merge, axis=1)
        if tied.any():
            t2 = two[tied]
            facing = (self.mesh.face_normals[hits[t2]] * (away[t2] / d2[t2][..., None] ** 0.5)).sum(axis=2)
            pick[tied] = t2[np.arange(len(t2)), facing.argmax(axis=1)]
        tri = hits[pick]
        bary = trimesh.triangles.points_to_barycentric(self._triangles[tri], p)
        return tri, bary[:, 1:]

    def nearest(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The surface points nearest the points ``p`` (n, 3), off the surface or on it, and
        their triangles: ((n, 3), (n,)).  (:meth:`locate`'s (u, v) are those of ``p``
        projected on the triangle's plane: outside the triangle when the nearest point
        is on an edge.)"""
        tri, _ = self.locate(p)
        return trimesh.triangles.closest_point(self._triangles[tri], np.asarray(p, float).reshape(-1, 3)), tri


def geodesic(s: MeshSurface, tri: tuple[int, int], uv: tuple[np.ndarray, np.ndarray]) -> np.ndarray | None:
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
