"""Grasp frame sampling: Saut et al. 2010, §IV-A-1.

"We set as an input the numbers of positions and orientations, each pair position-orientation
defining a frame.  The positions are uniformly sampled in the object axis-aligned bounding box
with a step computed to fit the desired number of position samples.  The orientations are
computed with an incremental grid as in [16]" (Yershova & LaValle, "Deterministic sampling
methods for spheres and SO(3)", ICRA 2004).

Orientation grid (:func:`so3_grid`)
-----------------------------------
SO(3) is the unit 3-sphere S³ of quaternions with antipodes identified (q ~ -q).  S³ is covered
by the radial projection of the 8 faces of the hypercube [-1, 1]^4; since face ``x_i = -1`` is
the antipodal image of face ``x_i = +1``, the 4 faces ``x_i = +1`` (i = 0..3) cover SO(3)
exactly once up to measure-zero face boundaries.  (For any q, let i = argmax |q_i|; then
``sign(q_i) q / |q_i|`` lies on face i.  Two points p on face i and p' on face j give the same
rotation iff p/|p| = ±p'/|p'|: with "+", p and p' are on one ray, so i = j or the point is on
the shared edge of the faces; with "-", p = -c p' (c > 0) forces p_i = 1 = -c p'_i and
p_j = -c >= -1, so c = 1 and p'_i = -1, i.e. p' is on the boundary of face j; i = j is
impossible because p_i = 1 = -c.)

Level l places on each face the regular Sukharev grid of 2^l cells per axis (cell centres at
``-1 + (2a + 1) / 2^l``, a = 0..2^l-1) and projects it radially onto S³: 4·8^l rotations.
Cell centres of different levels never coincide (every coordinate of a level-l centre has
denominator exactly 2^l), and are never on a face boundary, so no rotation is repeated.

The sequence is *incremental* in the sense of Yershova–LaValle (the layered Sukharev grid
sequence of Lindemann & LaValle, spread over the faces): all of level 0, then all of level 1,
then level 2, ..., and ``so3_grid(n)`` is the first n terms.  Within a level, cells are ordered
by the bit-reversed Morton (Z-order) index of (i, j, k) — a van der Corput ordering in 3-D, so
that the first 8^m cells of a face (m < l) are a regular, shifted grid of 2^m cells per axis —
with the 4 faces interleaved fastest (face order w, x, y, z, so the first rotation is the
identity).  Hence every prefix of a level is spread over all faces and the whole face.  The
order of each face is mirrored along a face-dependent set of cell axes (none, all three, k,
j and k for faces w, x, y, z): with one common order, the 4 cells taken at the same step would
all touch the same corner of the faces (the 4 faces share each of the 8 corner rotations, the
120° turns), so a prefix would leave one hole seen from every face — without the mirrors the
dispersion at n = 32 is 1.92 rad instead of 1.27 rad, and 0.90 instead of 0.73 at n = 256.
With them, the 4 cells of each level-1 step touch 4 different corners.

Note on the choice: taking "the single level L with 4·8^L >= n, truncated to n" would give a
pure grid for n = 4·8^L but breaks the prefix property (level-L centres are not those of level
L+1), so ``so3_grid(m)[:n] != so3_grid(n)``.  Concatenating the levels keeps every prefix a
prefix, costs 1/7 extra samples before a level is complete (4·(8^(L+1) - 1)/7 samples contain
levels 0..L), and makes the dispersion non-increasing in n (the point sets are nested).

Dispersion (largest geodesic rotation angle from any rotation to its nearest sample), measured
with :func:`so3_dispersion_estimate` (200 000 random probes, seed 0; a lower estimate of the true
value): n = 4: 2.09 rad (the exact value is 2π/3), n = 32: 1.27 rad, n = 36: 1.26 rad,
n = 256: 0.73 rad, n = 292: 0.71 rad, n = 2048: 0.46 rad, n = 2340: 0.40 rad.  Rigorous
upper bound once levels 0..L are complete (:func:`so3_covering_radius_bound`): every rotation lies in some cell
of level L whose half-diagonal √3/2^L, seen from the origin across the face plane (distance
>= 1), subtends at most 2·atan(√3/2^(L+1)) on S³, i.e. a rotation angle of at most
4·atan(√3/2^(L+1)) (2.86, 1.63, 0.85, 0.43 rad for L = 0, 1, 2, 3).

Quaternions are ``[x, y, z, w]`` (scipy's order) with the canonical sign w > 0, or w = 0 and the
first non-zero of x, y, z positive (w = 0 only for the level-0 half-turns).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial.transform import Rotation

# Quaternion component fixed to +1 on each hypercube face, in the order faces are interleaved.
_FACES = (3, 0, 1, 2)  # w, x, y, z: the first sample is the identity
# Per face, the cell axes (i, j, k) whose order is mirrored (bits 4, 2, 1): see the docstring.
_FACE_MIRRORS = (0b000, 0b111, 0b001, 0b011)


def _level_size(level: int) -> int:
    return 4 * 8**level


def _bit_reverse(p: np.ndarray, nbits: int) -> np.ndarray:
    r = np.zeros_like(p)
    for b in range(nbits):
        r |= ((p >> b) & 1) << (nbits - 1 - b)
    return r


def _level_points(level: int, count: int) -> np.ndarray:
    """First ``count`` samples of grid level ``level`` as canonical unit quaternions (count, 4)."""
    n_cells = -(-count // 4)  # cells per face needed (faces interleaved fastest)
    p = np.arange(n_cells, dtype=np.int64)
    m = _bit_reverse(p, 3 * level)  # Morton index: bits (i_b, j_b, k_b) at 3b+2, 3b+1, 3b
    ijk = np.zeros((n_cells, 3), dtype=np.int64)
    for b in range(level):
        for axis in range(3):
            ijk[:, axis] |= ((m >> (3 * b + 2 - axis)) & 1) << b
    q = np.empty((n_cells, 4, 4))  # (cell, face, component)
    for f, comp in enumerate(_FACES):
        mirror = np.array([(_FACE_MIRRORS[f] >> (2 - a)) & 1 for a in range(3)]) * (2**level - 1)
        uvw = (2 * (ijk ^ mirror) + 1) / float(2**level) - 1.0  # cell centres in [-1, 1]^3
        others = [c for c in range(4) if c != comp]
        q[:, f, comp] = 1.0
        q[:, f, others] = uvw
    q = q.reshape(-1, 4)[:count]
    return _canonical(q / np.linalg.norm(q, axis=1, keepdims=True))


def _canonical(q: np.ndarray) -> np.ndarray:
    """Flip signs so that w > 0, or w == 0 and the first non-zero of x, y, z is positive."""
    lead = q[:, 3]
    for c in (0, 1, 2):  # first non-zero among x, y, z when w == 0
        lead = np.where(lead == 0.0, q[:, c], lead)
    return np.where(lead[:, None] < 0.0, -q, q)


def so3_grid(n: int) -> np.ndarray:
    """The first ``n`` rotations of the incremental SO(3) grid, as unit quaternions (n, 4).

    Quaternions are ``[x, y, z, w]`` with the canonical sign (w > 0, or w == 0 and the first
    non-zero component positive).  ``so3_grid(m)[:n] == so3_grid(n)`` for m >= n; levels
    0..L are complete once n >= 4·(8^(L+1) - 1)/7 (4, 36, 292, 2340, ...).  See the module
    docstring for the construction and its dispersion.
    """
    n = int(n)
    if n < 0:
        raise ValueError(f"so3_grid: n must be >= 0, got {n}")
    parts, level, left = [], 0, n
    while left > 0:
        take = min(left, _level_size(level))
        parts.append(_level_points(level, take))
        left -= take
        level += 1
    return np.concatenate(parts, axis=0) if parts else np.zeros((0, 4))


def so3_covering_radius_bound(n: int) -> float:
    """Upper bound (rad) on the dispersion of ``so3_grid(n)``: 4·atan(√3/2^(L+1)) where L is
    the finest level fully contained in the first n samples (π if none is)."""
    n, level, total = int(n), -1, 0
    while total + _level_size(level + 1) <= n:
        level += 1
        total += _level_size(level)
    if level < 0:
        return math.pi
    return 4.0 * math.atan(math.sqrt(3.0) / 2 ** (level + 1))


def so3_dispersion_estimate(quats: np.ndarray, n_probe: int = 20000, rng=None) -> float:
    """Estimate of the dispersion of a rotation set: the largest, over ``n_probe`` uniformly
    random probe rotations, of the geodesic angle (rad, in [0, π]) to the nearest rotation of
    ``quats`` (m, 4), ``[x, y, z, w]``.  A lower estimate of the true dispersion.

    ``rng``: a :class:`numpy.random.Generator`, a seed, or ``None``.
    """
    Q = np.asarray(quats, dtype=float).reshape(-1, 4)
    if len(Q) == 0:
        return math.pi
    Q = Q / np.linalg.norm(Q, axis=1, keepdims=True)
    rng = np.random.default_rng(rng)
    P = Rotation.random(int(n_probe), random_state=rng).as_quat()
    worst = 1.0
    chunk = max(1, 2_000_000 // len(Q))
    for s in range(0, len(P), chunk):
        best = np.abs(P[s : s + chunk] @ Q.T).max(axis=1)  # |<p, q>| = cos(angle / 2)
        worst = min(worst, float(best.min()))
    return 2.0 * math.acos(min(1.0, worst))


def position_grid(bounds, n: int) -> np.ndarray:
    """About ``n`` positions filling the axis-aligned box ``bounds`` = [[xmin, ymin, zmin],
    [xmax, ymax, zmax]] as cell centres of a regular grid, (m, 3), x slowest, z fastest.

    The step is ``(volume / n)^(1/3)`` and each axis gets ``max(1, round(extent / step))``
    cells (round half up), so m is exactly the product of the per-axis counts and m ≈ n (each
    axis count is within a factor [2/3, 2] of extent/step, and tends to it as n grows).  An
    axis too thin for one step (extent/step < 1/2, including zero extent) gets one cell and
    the step is recomputed over the remaining axes (area/n)^(1/2) or length/n, so that flat or
    degenerate boxes still get about n points.
    """
    b = np.asarray(bounds, dtype=float)
    if b.shape != (2, 3) or not np.all(np.isfinite(b)) or np.any(b[1] < b[0]):
        raise ValueError(f"position_grid: bounds must be finite (2, 3) [min, max], got {b.tolist()}")
    n = int(n)
    if n < 1:
        raise ValueError(f"position_grid: n must be >= 1, got {n}")
    lo, ext = b[0], b[1] - b[0]
    counts = np.ones(3, dtype=np.int64)
    active = ext > 0.0
    while active.any():
        step = (float(np.prod(ext[active])) / n) ** (1.0 / int(active.sum()))
        thin = active & (ext / step < 0.5)
        if not thin.any():
            counts[active] = np.maximum(1, np.floor(ext[active] / step + 0.5)).astype(np.int64)
            break
        active &= ~thin
    axes = [lo[a] + (np.arange(counts[a]) + 0.5) * ext[a] / counts[a] for a in range(3)]
    grid = np.meshgrid(*axes, indexing="ij")
    return np.stack([g.ravel() for g in grid], axis=1)


def grasp_frames(bounds, n_positions: int, n_orientations: int) -> np.ndarray:
    """Grasp frames ``X_OG`` (k, 4, 4): every pair of a position of
    ``position_grid(bounds, n_positions)`` and an orientation of ``so3_grid(n_orientations)``,
    positions in the outer loop, orientations in the inner one (frame ``ip * n_orientations +
    io``), with ``bounds`` the object's axis-aligned bounding box in the object frame O."""
    P = position_grid(bounds, n_positions)
    Q = so3_grid(n_orientations)
    R = Rotation.from_quat(Q).as_matrix() if len(Q) else np.zeros((0, 3, 3))
    X = np.zeros((len(P), len(Q), 4, 4))
    X[:, :, :3, :3] = R[None]
    X[:, :, :3, 3] = P[:, None]
    X[:, :, 3, 3] = 1.0
    return X.reshape(-1, 4, 4)
