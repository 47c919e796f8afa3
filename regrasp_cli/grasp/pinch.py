"""Pinch frames: grasp frames that put the opposing finger and one other across an
antipodal pair of the object's surface (fingertip hands).

The grid of §IV-A-1 (Saut et al. 2010) places the grasp frame at a few positions of the
object's bounding box.  On a thin feature (the handle of a flat tool lying on a desk, the
rim of a bowl) almost no grid frame brings two opposed fingertips onto it: a 14 mm thick
spanner gets no force-closure grasp at all from the 16,384 grid frames.  A pinch frame
starts from the contacts instead, as the antipodal sampling of parallel-jaw grasps does
(:func:`grasp.jaw.antipodal_pairs`): for a pair (p1, n1), (p2, n2) it picks two workspace
samples, one of the opposing finger (the thumb) and one of another finger, whose
fingertip centres are as far apart as the targets ``p1 + r n1`` and ``p2 + r n2`` and
which close towards each other, and maps them onto the targets (turned about the pair's
axis by a few rolls).  The usual search of :mod:`.single` then runs from that frame,
trying the pair's two contacts first for those two fingers, so a pinch frame yields a
grasp only on the same terms as a grid frame.  They are tried before the grid
(:mod:`.build`).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from regrasp_cli.grasp.workspace import FingerWorkspace
from regrasp_cli.spatial import rotation_aligning

PAIR_SAMPLES = 400  # workspace samples per finger from which tip pairs are drawn
CLOSING_COS = 0.3  # both fingertips close towards each other at least this squarely


def tip_pairs(thumb: FingerWorkspace, finger: FingerWorkspace, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Pairs of interior samples (thumb, finger), as sample indices (m,) of each, whose
    fingertip centres close towards each other, drawn from up to :data:`PAIR_SAMPLES`
    samples of each finger."""
    it = rng.choice(len(thumb.samples), size=min(PAIR_SAMPLES, len(thumb.samples)), replace=False)
    jf = rng.choice(len(finger.samples), size=min(PAIR_SAMPLES, len(finger.samples)), replace=False)
    a, b = thumb.samples[it], finger.samples[jf]
    u = b[None] - a[:, None]  # (nt, nf, 3) thumb -> finger
    d = np.linalg.norm(u, axis=2)
    u = u / np.maximum(d, 1e-12)[..., None]
    ok = (np.einsum("ijk,ik->ij", u, thumb.sample_closing[it]) > CLOSING_COS) \
        & (-np.einsum("ijk,jk->ij", u, finger.sample_closing[jf]) > CLOSING_COS) & (d > 1e-6)
    i, j = np.nonzero(ok)
    return it[i], jf[j]


def pinch_frames(thumb: FingerWorkspace, fingers: list[FingerWorkspace], radii: tuple[float, list[float]],
                 p1: np.ndarray, n1: np.ndarray, p2: np.ndarray, n2: np.ndarray,
                 rng: np.random.Generator, rolls: int = 8) -> tuple[np.ndarray, ...]:
    """Grasp frames X_OG (k, 4, 4), ``rolls`` per antipodal pair (p1, n1), (p2, n2) (each
    (k, 3), frame O) that some tip pair can span within 3 mm: the thumb's tip centre on
    ``p1 + r n1``, a finger's (the fingers taken in turn) on ``p2 + r n2``, up to the
    mismatch of their distances, split evenly; the hand turned about the pair's axis by
    evenly spaced angles from a random one; the first turn of every pair first, then the
    second, and so on.  ``radii`` = (thumb tip radius, finger tip
    radii).  Also returns, per frame, the index of its pair and of its finger (in
    ``fingers``): the contacts the search tries first (:func:`.fingertips.grasps_for_frames`);
    and the indices of the thumb's and the finger's workspace samples put on the targets."""
    r_thumb, r_fingers = radii
    k = len(p1)
    f_of = np.arange(k) % max(len(fingers), 1)  # the fingers taken in turn
    frames, which, finger, samples, turn = [], [], [], [], []
    for f, ws in enumerate(fingers):
        ia, ib = tip_pairs(thumb, ws, rng)
        a, b = thumb.samples[ia], ws.samples[ib]
        j = np.flatnonzero(f_of == f)
        if not len(a) or not len(j):
            continue
        spans = np.linalg.norm(b - a, axis=1)
        order = np.argsort(spans, kind="stable")  # sorted by span, for a binary search per target
        a, b, ia, ib, spans = a[order], b[order], ia[order], ib[order], spans[order]
        c1, c2 = p1[j] + r_thumb * n1[j], p2[j] + r_fingers[f] * n2[j]
        span = np.linalg.norm(c2 - c1, axis=1)
        lo, hi = np.searchsorted(spans, span - 0.003), np.searchsorted(spans, span + 0.003)
        ok = (hi > lo) & (span > 1e-9)
        j, c1, c2, span, lo, hi = j[ok], c1[ok], c2[ok], span[ok], lo[ok], hi[ok]
        m = lo + np.minimum((rng.random(len(j)) * (hi - lo)).astype(int), hi - lo - 1)  # a tip pair at random
        u_G = (b[m] - a[m]) / np.linalg.norm(b[m] - a[m], axis=1, keepdims=True)
        u_O = (c2 - c1) / span[:, None]
        roll = rng.uniform(0, 2 * np.pi, len(j))[:, None] + np.arange(rolls) * 2 * np.pi / rolls  # (m, rolls)
        R = Rotation.from_rotvec((roll[..., None] * u_O[:, None]).reshape(-1, 3)).as_matrix() \
            @ np.repeat(rotation_aligning(u_G, u_O).reshape(-1, 3, 3), rolls, axis=0)
        X = np.tile(np.eye(4), (len(R), 1, 1))
        X[:, :3, :3] = R
        mid_G = np.repeat((a[m] + b[m]) / 2, rolls, axis=0)
        X[:, :3, 3] = np.repeat((c1 + c2) / 2, rolls, axis=0) - np.einsum("nij,nj->ni", R, mid_G)
        frames.append(X)
        which.append(np.repeat(j, rolls))
        turn.append(np.tile(np.arange(rolls), len(j)))
        finger.append(np.full(len(X), f))
        samples.append(np.repeat(np.column_stack([ia[m], ib[m]]), rolls, axis=0))
    if not frames:
        return np.zeros((0, 4, 4)), np.zeros(0, np.intp), np.zeros(0, np.intp), np.zeros(0, np.intp), \
            np.zeros(0, np.intp)
    # one turn of every pair, in the order of the pairs, then the next turn of every pair:
    # a search stopped early has spread over the pairs
    which, finger, frames, samples, turn = map(np.concatenate, (which, finger, frames, samples, turn))
    order = np.lexsort((which, turn))
    return frames[order], which[order], finger[order], samples[order, 0], samples[order, 1]
