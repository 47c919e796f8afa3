"""Sampled object surface: the point set, kd-tree, outward normals and curvature.

Saut et al. (2010), §IV-A-2, approximate the object surface "with a point set ... obtained
by a uniform sampling of the object surface.  The sampling step magnitude is chosen from
the fingertip radii.  A kd-tree is built upon the point set" so that the intersection of a
finger workspace (a hierarchy of spheres) with the surface is found quickly.  §IV-A-3
adds to the grasp quality "the sum of the object's surface inverse curvature at the
contact points", with "curvatures ... normalized over all the values on the sampled
object's surface".  :func:`build_surface` computes all of that once per object, in the
object frame O, in metres:

* **Sampling.**  The target count is ``N = max(MIN_SAMPLES, ceil(area / step**2))``: one
  sample per ``step x step`` patch of surface, so the mean spacing between neighbouring
  samples is about ``step`` (measured: nearest-neighbour distance ~0.7 ``step``, largest
  ~1.3-1.5 ``step``).  The samples come from :func:`trimesh.sample.sample_surface_even`
  (uniform random candidates thinned so that no two are closer than
  ``EVEN_RADIUS_FACTOR * step``, a Poisson-disk-like set); if that thinning leaves fewer
  than ``EVEN_MIN_FRACTION * N`` samples we fall back to plain area-uniform random
  sampling (:func:`trimesh.sample.sample_surface`) of ``N`` points.  trimesh's seed is an
  integer drawn from the caller's generator, so the result is deterministic.  The face
  each sample lies on is kept (``Surface.face_index``).
* **Step rule** (:func:`sampling_step`): ``step = tip radius`` (the smallest fingertip
  radius of the hand), so neighbouring samples are at most about one fingertip radius
  apart and a fingertip touching the surface always has samples under it.
* **Outward normals.**  Each sample takes the normal of its face (coincident vertices
  merged first).  For a watertight mesh (every edge shared by exactly two faces,
  enclosing a positive volume) the winding is made consistent and outward by
  :func:`trimesh.repair.fix_normals` and trusted.  Otherwise (open meshes, inconsistent
  winding, e.g. scans) normals are oriented by *ray parity*: rays are cast from just off
  the surface at each sample (``p + eps n`` on the normal's side, ``p - eps n`` on the
  other) in ``RAYS_PER_SIDE`` directions per side (the normal itself and jittered
  directions around it), all samples in one batched query of trimesh's rtree-based ray
  tracer (all hits, deterministic); a ray crossing the mesh an odd number of times
  starts inside, so each ray votes "n points outward" or "inward".
  The votes are pooled per *orientation patch*: the winding is first made as consistent
  as possible (:func:`trimesh.repair.fix_winding`), then the faces are split into
  connected patches over the shared edges that are consistently wound; a patch's
  normals are all outward or all inward, so the patch's majority flips or keeps all of
  them (a tie keeps the face normals).  Pooling makes the result robust to the rays
  that escape through holes or graze edges, as long as most rays of the patch behave.
  Limitations: parity needs a closed surface, so on open meshes this is a heuristic (a
  patch seen mostly through a large hole can come out inverted); an open sheet (no
  inside at all) keeps its face normals; samples on a shell that lies inside another
  shell (interpenetrating parts, self-intersections) vote for the orientation relative to
  the enclosing shell, which is arbitrary for them (they are interior to the union and
  should not be used as contacts); non-manifold edges (shared by more than two faces)
  split patches.
* **Curvature.**  PCA "surface variation" (Pauly, Gross & Kobbelt 2002): with
  ``l0 <= l1 <= l2`` the eigenvalues of the covariance of the ``CURVATURE_K`` = 16
  nearest samples (the sample included), ``sigma = l0 / (l0 + l1 + l2)`` (0 on a plane,
  at most 1/3).  16 neighbours span a disc of radius ~2.3 ``step``: enough for a stable
  plane fit, small enough to stay local.  ``sigma`` is then normalised over the object by
  dividing by its 95th percentile and clipping to [0, 1] (robust to a few spikes at sharp
  tips, which would otherwise squash every other value towards 0).  Flat regions -> ~0,
  edges and tips -> 1.  An object with no curved sample at all gets 0 everywhere.
* **Mass centre.**  Watertight: :attr:`trimesh.Trimesh.center_mass`,
  the volume centroid for uniform density.  Otherwise the area-weighted centroid of the
  surface triangles, exact for a thin uniform shell and only approximate for a solid;
  a :class:`UserWarning` says so.

Bad input raises :class:`~regrasp_cli.errors.InputError`: a mesh without area (field
``object.mesh``), a step that is not finite and > 0 or that would give more than
``MAX_SAMPLES`` samples (field ``step``), a tip radius that is not finite and > 0 (field
``tip_radius``).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np
import trimesh
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree
from trimesh.ray.ray_triangle import ray_triangle_id

from regrasp_cli.errors import InputError

#: Fewest samples of any object (PCA curvature needs a neighbourhood).
MIN_SAMPLES = 32
#: Most samples :func:`build_surface` accepts (guards against a step in the wrong units).
MAX_SAMPLES = 2_000_000
#: Poisson-disk rejection radius of the even sampling, in units of ``step``.  0.6 keeps
#: the full count (0.7 already loses ~20 % with trimesh's 3x oversampling).
EVEN_RADIUS_FACTOR = 0.6
#: Below this fraction of the target count, even sampling falls back to random sampling.
EVEN_MIN_FRACTION = 0.9
#: Neighbours (sample included) of the PCA surface-variation estimate.
CURVATURE_K = 16
#: Percentile of surface variation that maps to curvature 1.
CURVATURE_PERCENTILE = 95.0
#: Rays cast on each side of a sample to orient its normal (non-watertight meshes).
RAYS_PER_SIDE = 3
#: Samples of a consistently wound patch that vote on its side (its first, in sample order).
VOTERS_PER_PATCH = 200


@dataclass(frozen=True, eq=False)
class Surface:
    """Sampled surface of an object, in the object frame O, metres.

    Attributes:
        points: (n, 3) samples on the surface.
        normals: (n, 3) unit outward surface normals at ``points``.
        curvature: (n,) PCA surface variation normalised over the object to [0, 1]
            (0: flat, 1: edges and tips; see the module docstring).
        face_index: (n,) index of the mesh face each sample lies on.
        tree: kd-tree over ``points`` (indices into the arrays above).
        mass_centre: (3,) centre of mass (uniform density; see ``watertight``).
        step: sampling step, m (about one sample per ``step**2`` of area).
        watertight: the mesh is closed with consistent winding and encloses a positive
            volume (after :func:`trimesh.repair.fix_normals`), so normals come from
            the mesh orientation and ``mass_centre`` is the volume centroid; otherwise
            normals were oriented by ray parity and ``mass_centre`` is the surface
            (thin-shell) centroid.
    """

    points: np.ndarray
    normals: np.ndarray
    curvature: np.ndarray
    face_index: np.ndarray
    tree: cKDTree
    mass_centre: np.ndarray
    step: float
    watertight: bool
    face_flip: np.ndarray | None = None  # (n_faces,) bool: faces whose normal was turned round (None: none)

    def __len__(self) -> int:
        return int(len(self.points))

    def subset(self, idx: np.ndarray) -> "Surface":
        """The samples of index ``idx`` only (same mass centre, curvature scale, step)."""
        idx = np.asarray(idx, dtype=np.int64)
        return Surface(self.points[idx], self.normals[idx], self.curvature[idx], self.face_index[idx],
                       cKDTree(self.points[idx]), self.mass_centre, self.step, self.watertight, self.face_flip)

    def plus(self, points: np.ndarray, normals: np.ndarray, curvature: np.ndarray) -> "Surface":
        """These samples and the given ones ((k, 3), (k, 3), (k,); face index -1)."""
        return Surface(np.vstack([self.points, points]), np.vstack([self.normals, normals]),
                       np.concatenate([self.curvature, curvature]),
                       np.concatenate([self.face_index, np.full(len(points), -1, dtype=self.face_index.dtype)]),
                       cKDTree(np.vstack([self.points, points])), self.mass_centre, self.step, self.watertight,
                       self.face_flip)

    def under(self, w: np.ndarray, k: int = 8) -> int:
        """The sample (index) whose tangent plane passes nearest to w (3,), a point of the
        surface, among its ``k`` nearest: near an edge the nearest sample may lie on the
        other face, whose normal is off w's face by the edge's angle."""
        idx = np.atleast_1d(self.tree.query(w, k=min(k, len(self)))[1])
        return int(idx[np.argmin(np.abs(np.einsum("ij,ij->i", w - self.points[idx], self.normals[idx])))])

    def within(self, centre, radius: float) -> np.ndarray:
        """Sorted indices of the samples within ``radius`` (m) of ``centre`` ((3,), m)."""
        idx = self.tree.query_ball_point(np.asarray(centre, dtype=float), float(radius))
        return np.asarray(sorted(idx), dtype=np.int64)


def sampling_step(tip_radius: float) -> float:
    """Sampling step (m) for fingertips of radius ``tip_radius`` (m).

    The paper chooses the step "from the fingertip radii"; the rule here is
    ``step = tip_radius`` (pass the smallest fingertip radius of the hand): neighbouring
    samples are then at most about one fingertip radius apart, so a fingertip touching
    the surface always has samples under it.

    Raises:
        InputError: ``tip_radius`` is not a finite number > 0 (field ``tip_radius``).
    """
    try:
        r = float(tip_radius)
    except (TypeError, ValueError):
        r = math.nan
    if not (math.isfinite(r) and r > 0.0):
        raise InputError(None, "tip_radius", f"fingertip radius must be a finite number > 0 (m), got {tip_radius!r}")
    return r


def build_surface(mesh: trimesh.Trimesh, step: float, rng: np.random.Generator,
                  like: Surface | None = None) -> Surface:
    """Sample ``mesh`` (object frame, metres) every ``step`` m; see the module docstring.

    ``mesh`` is not modified.  The result depends only on the mesh, ``step`` and the
    state of ``rng`` (from which the sampling seed and the ray jitter are drawn).  With
    ``like`` (a surface of the same mesh), its faces' orientation is taken instead of
    casting rays again (the ray votes are most of the time on a scanned mesh).

    Raises:
        InputError: the mesh has no faces, non-finite vertices or zero area (field
            ``object.mesh``); ``step`` is not finite and > 0, or gives more than
            :data:`MAX_SAMPLES` samples (field ``step``).

    Warns:
        UserWarning: the mesh is not watertight, so the mass centre is the surface
            centroid.
    """
    try:
        step_f = float(step)
    except (TypeError, ValueError):
        step_f = math.nan
    if not (math.isfinite(step_f) and step_f > 0.0):
        raise InputError(None, "step", f"sampling step must be a finite number > 0 (m), got {step!r}")
    if len(mesh.faces) == 0:
        raise InputError(None, "object.mesh", "mesh has no faces, so it has no surface to sample")
    if not np.all(np.isfinite(mesh.vertices)):
        raise InputError(None, "object.mesh", "mesh has non-finite vertex coordinates")
    area = float(mesh.area)
    if not area > 0.0:
        raise InputError(None, "object.mesh", "mesh has zero surface area, so it has no surface to sample")
    target = max(MIN_SAMPLES, math.ceil(area / step_f**2))
    if target > MAX_SAMPLES:
        raise InputError(
            None,
            "step",
            f"sampling step {step_f:g} m gives {target} samples on {area:g} m^2 of surface "
            f"(limit {MAX_SAMPLES}); is the step or the mesh in the wrong units?",
        )

    m = mesh.copy()
    # Merging coincident vertices (files like STL store each triangle separately) keeps
    # the faces and their order, so face indices still refer to ``mesh.faces``.
    # Degenerate (zero-area) faces have no normal and are never sampled; dropping them
    # would renumber faces, so they are just left in place.
    m.merge_vertices()
    watertight = bool(m.is_watertight)
    if watertight:
        trimesh.repair.fix_normals(m, multibody=True)
        watertight = bool(m.is_watertight and m.is_winding_consistent and float(m.volume) > 0.0)

    points, face_index = _sample(m, target, step_f, rng)

    if not watertight:
        trimesh.repair.fix_winding(m)  # flips faces in place, keeps their order
    normals = np.asarray(m.face_normals, dtype=float)[face_index].copy()
    face_flip = None
    if not watertight:
        if like is not None and like.face_flip is not None:
            face_flip = like.face_flip
        else:
            groups = _orientation_groups(m)  # per face
            inward = _inward_votes(m, points, normals, rng, _voters(groups[face_index]))  # (n,) in [-R, R]
            face_flip = (np.bincount(groups[face_index], weights=inward, minlength=groups.max() + 1) > 0.0)[groups]
        normals[face_flip[face_index]] *= -1.0

    tree = cKDTree(points)
    curvature = _curvature(points, tree)
    mass_centre = mass_centre_of(m, watertight)

    for a in (points, normals, curvature, face_index, mass_centre):
        a.setflags(write=False)
    return Surface(
        points=points,
        normals=normals,
        curvature=curvature,
        face_index=face_index,
        tree=tree,
        mass_centre=mass_centre,
        step=step_f,
        watertight=watertight,
        face_flip=face_flip,
    )


# --------------------------------------------------------------------------- helpers


def _sample(m: trimesh.Trimesh, count: int, step: float, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """(count', 3) points and (count',) face indices: even sampling, random fallback."""
    seed = int(rng.integers(0, 2**63 - 1))
    points, index = trimesh.sample.sample_surface_even(m, count, radius=EVEN_RADIUS_FACTOR * step, seed=seed)
    if len(points) < EVEN_MIN_FRACTION * count:
        points, index = trimesh.sample.sample_surface(m, count, seed=seed)
    return (
        np.ascontiguousarray(points, dtype=float),
        np.ascontiguousarray(index, dtype=np.int64),
    )


def _voters(patch: np.ndarray) -> np.ndarray:
    """The samples that vote on their patch's side (:func:`_inward_votes`), given each
    sample's patch (n,): the first :data:`VOTERS_PER_PATCH` of each patch, in sample
    order (a scan's one big patch needs no thousands of votes; the rays are most of a
    surface's cost: 1.1 s of the cracker box's)."""
    order = np.argsort(patch, kind="stable")
    first = np.searchsorted(patch[order], patch[order], side="left")
    return np.sort(order[np.arange(len(order)) - first < VOTERS_PER_PATCH])


def _inward_votes(m: trimesh.Trimesh, points: np.ndarray, normals: np.ndarray, rng: np.random.Generator,
                  voters: np.ndarray) -> np.ndarray:
    """(n,) int in [-RAYS_PER_SIDE, RAYS_PER_SIDE]: ray-parity votes that the normal at
    each sample of ``voters`` (indices) points into the object (> 0) or out of it (< 0);
    0 for the others.  The random directions are drawn for every sample, so that a voter's
    rays do not depend on which others vote.

    For each sample, ``RAYS_PER_SIDE`` rays leave ``p + eps n`` into the half-space of
    ``n`` and as many leave ``p - eps n`` into the other half-space: the normal itself,
    then directions jittered around it (at least ~45 degrees off the tangent plane).  A
    ray with an odd number of crossings starts inside the object.  A ray on the ``+n``
    side votes "inward" when it starts inside, a ray on the ``-n`` side when it starts
    outside.  All rays go in one batched query.
    """
    total = len(points)
    jitter = rng.normal(size=(total, 2, RAYS_PER_SIDE, 3))[voters]
    points, normals = points[voters], normals[voters]
    n = len(points)
    diag = float(np.linalg.norm(m.extents))
    eps = max(1e-5, 1e-5 * diag)  # > trimesh's 1e-6 "behind the origin" tolerance
    sides = np.array([1.0, -1.0])
    # directions: (n, 2, R, 3) = side x ray
    base = normals[:, None, None, :] * sides[None, :, None, None]
    jitter /= np.linalg.norm(jitter, axis=-1, keepdims=True)
    jitter[:, :, 0, :] = 0.0  # the first ray of each side is along +-n exactly
    dirs = base + 0.7 * jitter
    dirs /= np.linalg.norm(dirs, axis=-1, keepdims=True)
    origins = points[:, None, None, :] + eps * base
    origins = np.broadcast_to(origins, dirs.shape)

    o = origins.reshape(-1, 3)
    d = dirs.reshape(-1, 3)
    tol = 1e-7 * max(diag, 1e-9)
    # ray_triangle_id, not intersects_location: the latter drops hits at the same place
    # on coincident faces, which are real crossings of a zero-thickness double sheet.
    index_tri, index_ray, locations = ray_triangle_id(
        triangles=m.triangles,
        ray_origins=o,
        ray_directions=d,
        triangles_normal=m.face_normals,
        tree=m.triangles_tree,
        multiple_hits=True,
    )
    crossings = _count_crossings(index_tri, index_ray, locations, o, d, _face_keys(m, tol), len(o), tol)
    starts_inside = (crossings % 2 == 1).reshape(n, 2, RAYS_PER_SIDE)
    # +n side: inside => inward vote; -n side: outside => inward vote.
    votes = np.zeros(total, dtype=np.int64)
    votes[voters] = starts_inside[:, 0, :].sum(axis=1) + (~starts_inside[:, 1, :]).sum(axis=1) - RAYS_PER_SIDE
    return votes


def _orientation_groups(m: trimesh.Trimesh) -> np.ndarray:
    """(F,) int labels: connected patches of faces whose winding is consistent (every
    shared edge of two adjacent faces of a patch is traversed in opposite directions),
    so each patch's face normals are either all outward or all inward."""
    n_faces = len(m.faces)
    pairs = np.asarray(m.face_adjacency, dtype=np.int64).reshape(-1, 2)
    if len(pairs) == 0:
        return np.arange(n_faces, dtype=np.int64)
    shared = np.asarray(m.face_adjacency_edges, dtype=np.int64).reshape(-1, 2)
    faces = np.asarray(m.faces, dtype=np.int64)

    def forward(f: np.ndarray) -> np.ndarray:
        # does face f traverse its shared edge as u -> v?
        tri = faces[f]
        nxt = np.roll(tri, -1, axis=1)
        return ((tri == shared[:, :1]) & (nxt == shared[:, 1:])).any(axis=1)

    ok = forward(pairs[:, 0]) != forward(pairs[:, 1])
    graph = coo_matrix(
        (np.ones(int(ok.sum())), (pairs[ok, 0], pairs[ok, 1])), shape=(n_faces, n_faces)
    )
    _, labels = connected_components(graph, directed=False)
    return np.asarray(labels, dtype=np.int64)


def _face_keys(m: trimesh.Trimesh, tol: float) -> np.ndarray:
    """(F,) int: equal for faces with the same three corners (within ``tol``), whatever
    their winding or vertex numbering (duplicated faces, double-sided sheets)."""
    corners = np.round(np.asarray(m.triangles, dtype=float).reshape(-1, 3) / tol)
    _, vid = np.unique(corners, axis=0, return_inverse=True)
    ids = np.sort(vid.reshape(-1, 3), axis=1)
    _, key = np.unique(ids, axis=0, return_inverse=True)
    return key.reshape(-1)


def _count_crossings(
    index_tri: np.ndarray,
    index_ray: np.ndarray,
    locations: np.ndarray,
    origins: np.ndarray,
    dirs: np.ndarray,
    face_key: np.ndarray,
    n_rays: int,
    tol: float,
) -> np.ndarray:
    """(n_rays,) surface crossings per ray.

    Hits of one ray closer than ``tol`` along it form a cluster.  A cluster counts as
    many crossings as the largest number of its hits on geometrically identical faces:
    a ray through an edge or vertex hits every (different) triangle around it once ->
    1 crossing; a ray through a double-sided sheet (two coincident faces) -> 2.
    """
    if len(index_ray) == 0:
        return np.zeros(n_rays, dtype=np.int64)
    index_ray = np.asarray(index_ray, dtype=np.int64)
    keys = face_key[np.asarray(index_tri, dtype=np.int64)]
    t = np.einsum("ij,ij->i", np.asarray(locations, dtype=float) - origins[index_ray], dirs[index_ray])
    order = np.lexsort((t, index_ray))
    r, t, keys = index_ray[order], t[order], keys[order]
    new = np.ones(len(r), dtype=bool)
    new[1:] = (r[1:] != r[:-1]) | (np.diff(t) > tol)
    cluster = np.cumsum(new) - 1
    pairs, mult = np.unique(np.column_stack([cluster, keys]), axis=0, return_counts=True)
    per_cluster = np.zeros(int(cluster[-1]) + 1, dtype=np.int64)
    np.maximum.at(per_cluster, pairs[:, 0], mult)
    return np.bincount(r[new], weights=per_cluster, minlength=n_rays).astype(np.int64)


def _curvature(points: np.ndarray, tree: cKDTree) -> np.ndarray:
    """(n,) PCA surface variation of the CURVATURE_K-neighbourhoods, normalised to [0, 1]."""
    k = min(CURVATURE_K, len(points))
    _, idx = tree.query(points, k=k)
    nbrs = points[np.asarray(idx).reshape(len(points), k)]
    centred = nbrs - nbrs.mean(axis=1, keepdims=True)
    cov = np.einsum("nki,nkj->nij", centred, centred) / k
    eig = np.linalg.eigvalsh(cov)  # ascending
    total = eig.sum(axis=1)
    sigma = np.where(total > 0.0, np.clip(eig[:, 0], 0.0, None) / np.where(total > 0.0, total, 1.0), 0.0)
    scale = float(np.percentile(sigma, CURVATURE_PERCENTILE))
    # Below ~1e-9 the variation is round-off on a flat neighbourhood, not curvature.
    if not scale > 1e-9:
        return np.zeros(len(points), dtype=float)
    return np.clip(sigma / scale, 0.0, 1.0)


def mass_centre_of(m: trimesh.Trimesh, watertight: bool) -> np.ndarray:
    """Volume centroid of a watertight mesh, else area-weighted surface centroid (warns)."""
    if watertight:
        return np.array(m.center_mass, dtype=float)
    areas = np.asarray(m.area_faces, dtype=float)
    centre = (areas[:, None] * np.asarray(m.triangles_center, dtype=float)).sum(axis=0) / areas.sum()
    warnings.warn(
        "object mesh is not watertight: its mass centre is "
        "taken as the area-weighted centroid of its surface, exact for a thin uniform "
        "shell but only approximate for a solid object",
        UserWarning,
        stacklevel=3,
    )
    return centre


#: Most cells of a :class:`DistanceGrid` (the resolution grows to stay below it).
MAX_GRID_CELLS = 400_000
#: Samples whose tangent planes decide a :class:`DistanceGrid` cell's side.
NEIGHBOURS = 4


@dataclass(frozen=True)
class DistanceGrid:
    """An estimate of the signed distance to an object's surface (m, negative inside) on a
    voxel grid over its bounding box grown by ``margin``, frame O (:func:`distance_grid`):
    within a few millimetres of the true distance, what :mod:`.fingertips` skips hopeless
    checks by, never a collision verdict."""

    origin: np.ndarray  # (3,) centre of cell (0, 0, 0)
    resolution: float  # m
    values: np.ndarray  # (nx, ny, nz) float32
    margin: float  # m: the value of every point off the grid

    def __call__(self, p_O: np.ndarray) -> np.ndarray:
        """The signed distance at each point (..., 3) (shape (...))."""
        p = np.asarray(p_O).reshape(-1, 3)
        ijk = np.rint((p - self.origin) / self.resolution).astype(np.intp)
        shape = np.array(self.values.shape)
        inside = np.all((ijk >= 0) & (ijk < shape), axis=1)
        out = np.full(len(p), self.margin, dtype=np.float32)
        i = ijk[inside]
        out[inside] = self.values[i[:, 0], i[:, 1], i[:, 2]]
        return out.reshape(np.shape(p_O)[:-1])


def distance_grid(surface: Surface, margin: float, resolution: float = 0.002) -> DistanceGrid:
    """The :class:`DistanceGrid` of ``surface`` over its samples' bounding box grown by
    ``margin`` (m, more than two steps), at ``resolution`` (m) or coarser (at most
    :data:`MAX_GRID_CELLS` cells).

    A cell within two steps of a sample is inside when it lies behind the tangent planes of
    its :data:`NEIGHBOURS` nearest samples, by the least of those depths, else outside by
    its distance to the nearest sample (one sample's plane put cells just above a rim, where
    fingers pass, 2-4 mm inside: a cup's rim pinches were lost).  Farther, two steps plus the distance to the nearest such cell, negative in the regions
    of such cells that do not reach the grid's border: the side of a scanned mesh's
    tangent planes is wrong beyond its edges and rims (a cell 4 cm off a can's rim read
    8 mm inside), whereas open space, a cup's or a bowl's inside included, is connected."""
    from scipy.ndimage import distance_transform_edt, label

    lo, hi = surface.points.min(axis=0) - margin, surface.points.max(axis=0) + margin
    volume = float(np.prod(hi - lo))
    resolution = max(resolution, (volume / MAX_GRID_CELLS) ** (1 / 3))
    shape = tuple(np.ceil((hi - lo) / resolution).astype(int) + 1)
    axes = [lo[d] + resolution * np.arange(shape[d]) for d in range(3)]
    X = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    near = 2 * surface.step
    # the cell's NEIGHBOURS nearest samples and their tangent planes, only for the cells
    # within ``near`` plus a cell of a sample's cell (the others are far: querying them was
    # half the grid's time)
    occupied = np.zeros(shape, dtype=bool)
    ijk = np.clip(np.rint((surface.points - lo) / resolution).astype(np.intp), 0, np.array(shape) - 1)
    occupied[ijk[:, 0], ijk[:, 1], ijk[:, 2]] = True
    maybe = np.flatnonzero(resolution * distance_transform_edt(~occupied).ravel() < near + resolution)
    dist, i = surface.tree.query(X[maybe], k=NEIGHBOURS, distance_upper_bound=near)
    found = np.isfinite(dist)
    i[~found] = 0
    plane = np.einsum("ijk,ijk->ij", X[maybe, None] - surface.points[i], surface.normals[i])
    plane[~found] = -np.inf
    # inside only behind every neighbour's tangent plane (a point above a rim is in front of
    # the rim's top samples, behind the wall's): by the least deep of them; outside, the
    # distance to the nearest sample
    shallowest = plane.max(axis=1)
    far = np.ones(len(X), dtype=bool)
    far[maybe] = ~found[:, 0]
    values = np.zeros(len(X))
    values[maybe] = np.where(shallowest < 0, shallowest, np.where(found[:, 0], dist[:, 0], 0.0))
    regions, _ = label(far.reshape(shape))
    border = np.unique(np.concatenate([regions[0].ravel(), regions[-1].ravel(), regions[:, 0].ravel(),
                                       regions[:, -1].ravel(), regions[:, :, 0].ravel(), regions[:, :, -1].ravel()]))
    outside = np.isin(regions, border[border > 0]).ravel()
    # a far cell: two steps plus its distance to the nearest near cell
    depth = near + resolution * distance_transform_edt(far.reshape(shape)).ravel()
    values[far] = np.where(outside[far], depth[far], -depth[far])
    return DistanceGrid(lo, resolution, values.astype(np.float32).reshape(shape), float(margin))
