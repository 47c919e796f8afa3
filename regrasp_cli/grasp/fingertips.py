"""Fingertip grasps of grasp frames, many at once: Saut et al. 2010, §IV-A-2 and §IV-A-3.

For a grasp frame X_OG (the hand's grasp frame G in the object frame O) the grasp is
built finger by finger, the opposing finger (robot.yaml's ``opposing``, the thumb) first:
no stable grasp exists without it; then the others in robot.yaml order.  For each
finger, the contact candidates are the surface samples inside its workspace spheres
(:mod:`.workspace`, grown by the fingertip radius) whose outward normal faces the closing
fingertip, ranked (:func:`_candidates`); finger IK puts the fingertip-sphere centre at
``p + r_tip n``, seeded from a nearby workspace sample; the finger is checked against the
object (the fingertip may touch it within the contact tolerance), the palm and the
fingers placed.  The first candidate that passes is the finger's contact; a finger
without one stays open.  With enough contacts (3 point contacts, 2 soft ones) the whole
hand is checked against the object and the grasp goes to the force-closure test and the
quality score (:func:`.single.scored_grasp`).

A batch of frames goes finger by finger, so that everything that does not depend on a
frame's earlier verdicts is one numpy call for all of them:

* which fingers' workspaces hold each surface sample, in every frame: one lookup in one
  voxel map of finger bits (:class:`.workspace.HandVoxels`), which also gives the closing
  direction without a kd-tree query per candidate;
* finger IK (damped least squares) for every candidate of every frame at once, on the
  finger's chain in G (:mod:`model.chain`);
* only then, frame by frame, the exact collision checks (coal, through pinocchio's
  geometry model) over the candidates whose IK converged, best first.

Most exact checks used to fail (on a YCB can, 125,000 of 153,000: a middle or proximal
phalanx through the object).  With the object's signed-distance grid
(:class:`.surface.DistanceGrid`), spheres inside the palm's and phalanges' geometries
(:class:`.single.LinkProbes`) rule the hopeless ones out first, a few array lookups each:
a frame whose palm lies in the object is not searched, and an IK solution whose phalanges
do is not checked.  The grid is an estimate within a few millimetres, so it only decides
what is tried, not how candidates rank (ranking by it changed which grasps a list holds,
and cups lost the rim pinches their hand-overs need).

A frame's result does not depend on the other frames of its batch.  Verdicts are exact:
a contact needs the fingertip centre within ``ik_tolerance`` of its target, collisions
are coal's, force closure is the convex-hull test of :mod:`.quality`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from regrasp_cli.grasp.quality import force_ellipsoid_axis
from regrasp_cli.grasp.single import Grasp, GraspOptions, HandModel, LinkProbes, scored_grasp
from regrasp_cli.grasp.surface import DistanceGrid, Surface
from regrasp_cli.grasp.workspace import FingerWorkspace, HandVoxels
from regrasp_cli.model.chain import Chain, batch_dls

FACING_COS = 0.2  # a candidate's normal faces the closing fingertip at least this squarely
ALIGN_WEIGHT = 4.0  # weight of Nguyen's two-contact condition against the thumb (ranking)
SKIP_DEPTH = 0.002  # m: a link sphere deeper than this in the object: not worth the exact check
# a finger's candidates go to IK in rounds, by their place in their frame's order: the
# rows after a frame's first success are wasted work (most frames place a finger early)
IK_ROUNDS = ((0, 2), (2, 6), (6, 1_000_000))


@dataclass(frozen=True)
class Hints:
    """Contacts to try first, per frame of a batch (frame O): ``p1, n1`` (F, 3) for the
    opposing finger, ``p2, n2`` for finger ``finger`` (F,) (-1: no hint for that frame);
    and the workspace samples (indices (F,)) of the two fingers that reach them."""

    finger: np.ndarray
    p1: np.ndarray
    n1: np.ndarray
    p2: np.ndarray
    n2: np.ndarray
    thumb_sample: np.ndarray
    finger_sample: np.ndarray

    def rows(self, indices: np.ndarray) -> "Hints":
        """The hints of the frames ``indices``."""
        return Hints(*(x[indices] for x in (self.finger, self.p1, self.n1, self.p2, self.n2, self.thumb_sample,
                                            self.finger_sample)))


def batch_ik(chain: Chain, lower: np.ndarray, upper: np.ndarray, Q0: np.ndarray, p_G: np.ndarray,
             iterations: int, tolerance: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Damped least squares on the tip positions (:func:`~regrasp_cli.model.chain.batch_dls`).

    ``Q0`` (B, d) seeds, ``p_G`` (B, 3) targets in G.  A row succeeds once its error is
    below ``tolerance`` (m) and gives up when an iteration does not cut the squared error
    by a fifth (stalled, typically against a joint limit) or after ``iterations``.
    Returns the joint values (B, d), the success mask (B,) and the tip Jacobians at the
    solutions (B, 3, d), frame G."""
    def residual(Q, rows):
        p, J = chain.tip_and_jacobian(Q)
        return p_G[rows] - p, J

    def measure(e):
        err = np.einsum("bi,bi->b", e, e)
        return err, err < tolerance * tolerance

    Q, ok, J = batch_dls(residual, measure, Q0, lower, upper, iterations, 1e-6, 0.8)
    return Q, ok, np.zeros((len(Q), 3, Q.shape[1])) if J is None else J


def _candidates(voxels: HandVoxels, finger: int, ws: FingerWorkspace, inside: tuple[np.ndarray, np.ndarray],
                surface: Surface, in_G: tuple[np.ndarray, np.ndarray, np.ndarray], r_tip: float,
                anchor: tuple[np.ndarray, np.ndarray] | None, limit: int) -> tuple[np.ndarray, ...]:
    """Contact candidates of one finger in every frame of a batch, best first per frame.

    ``inside`` (frame (c,), surface sample (c,)): the surface samples in the voxel map of
    the finger's workspace spheres, frame by frame in surface order; ``in_G``: the samples'
    points and normals in G, (F0, S, 3) each, and the row there of each frame (F,).  Those
    whose normal faces the closing fingertip (cosine above 0.2, the closing direction of
    the workspace sample nearest to the tip centre's voxel) are ranked by how squarely the
    fingertip pushes and, after the opposing finger, by how well the contact lines up with
    its ``anchor`` contact (points, normals (F, 3), frame O): Nguyen's condition for two
    contacts, the line joining them inside both friction cones.  The paper tries the
    spheres biggest first; ranking every point in the spheres gave 1.4-1.6x more
    force-closure grasps per frame (docs/DESIGN-NOTES.md).  Returns, per candidate row, its
    frame (c,), surface sample (c,), nearest workspace sample (c,) and slot in its frame's
    order (c,), at most ``limit`` rows per frame, rows sorted by (frame, slot)."""
    fi, si = inside
    points_G, normals_G, at = in_G
    flat = at[fi] * points_G.shape[1] + si  # np.take of flat rows: a sixth of the time of (frame, sample) indexing
    n_G = np.take(normals_G.reshape(-1, 3), flat, axis=0)
    tips = np.take(points_G.reshape(-1, 3), flat, axis=0)
    tips += r_tip * n_G
    facing = -np.einsum("ij,ij->i", n_G, voxels.closing(finger, voxels.cells(tips)))  # zero off the finger's map
    keep = np.flatnonzero(facing > FACING_COS)
    fi, si, rank, tips = fi[keep], si[keep], facing[keep], tips[keep]
    if anchor is not None:
        a_p, a_n = anchor[0][fi], anchor[1][fi]
        p, n = surface.points[si], surface.normals[si]
        u = a_p - p
        u /= np.maximum(np.linalg.norm(u, axis=1, keepdims=True), 1e-12)
        rank = rank + ALIGN_WEIGHT * (-np.einsum("ij,ij->i", n, u) + np.einsum("ij,ij->i", u, a_n))
    order = _by_frame_then_rank(fi, rank)
    fi, si, tips = fi[order], si[order], tips[order]
    slot = np.arange(len(fi)) - np.searchsorted(fi, fi, side="left")
    top = slot < limit
    near = ws.tree.query(tips[top])[1] if top.any() else np.zeros(0, np.intp)  # the seeds: the nearest samples
    return fi[top], si[top], near, slot[top]


def _by_frame_then_rank(fi: np.ndarray, rank: np.ndarray) -> np.ndarray:
    """The order of rows by frame ``fi`` (c,), then by decreasing ``rank`` (c,), ties in
    row order (surface order, as the one-frame search): ``np.lexsort((-rank, fi))``, as
    two stable sorts, the second over 16-bit frame numbers (a radix sort), 1.5x faster."""
    by_rank = np.argsort(-rank, kind="stable")
    key = fi[by_rank]
    if len(fi) and fi.max() < np.iinfo(np.uint16).max:
        key = key.astype(np.uint16)
    return by_rank[np.argsort(key, kind="stable")]


def _buried(hm: HandModel, X_OG: np.ndarray, distance: DistanceGrid | None) -> np.ndarray:
    """Which frames X_OG (F, 4, 4) bury the palm's spheres (:meth:`.single.HandModel.palm_probes`)
    deeper than :data:`SKIP_DEPTH` in the object, by its ``distance`` grid (F,): not worth
    a search.  (Dropping the pinch frames whose pinching fingers do so at their workspace
    samples lost the rim pinches a cup needs, 1 of 8 tuning runs solved against 6: they
    go last instead, :func:`hints_clear`.)"""
    out = np.zeros(len(X_OG), dtype=bool)
    c, r = hm.palm_probes()
    if distance is None or not len(r):
        return out
    return np.max(r - distance(c @ X_OG[:, :3, :3].transpose(0, 2, 1) + X_OG[:, None, :3, 3]), axis=1) > SKIP_DEPTH


def hints_clear(hm: HandModel, workspaces: tuple[FingerWorkspace, ...], X_OG: np.ndarray, hints: Hints,
                distance: DistanceGrid) -> np.ndarray:
    """Which frames X_OG (F, 4, 4) leave the palm and both hinted fingers, posed at the
    hints' workspace samples, no deeper than :data:`SKIP_DEPTH` in the object by its
    ``distance`` grid (F,): the frames whose hinted contacts the search is likely to check
    exactly (a pinch frame puts both tips within 1.5 mm of their targets, so their IK
    solutions lie near the samples' postures).  An ordering, not a verdict: the others
    are searched last (:mod:`.build`)."""
    ok = ~_buried(hm, X_OG, distance)
    chains, probes = hm.chains(), hm.probes()
    thumb = hm.hand.opposing
    for f in range(len(chains)):
        rows = np.flatnonzero(ok & ((hints.finger == f) | (f == thumb)))
        if not len(rows) or not len(probes[f].radii):
            continue
        sample = (hints.thumb_sample if f == thumb else hints.finger_sample)[rows]
        used, at = np.unique(sample, return_inverse=True)  # the rolls of a pair share their samples
        joints_G = chains[f].forward(workspaces[f].sample_q[used])[0][at]
        ok[rows[_link_depth(probes[f], joints_G, X_OG[rows], distance) > SKIP_DEPTH]] = False
    return ok


def _link_depth(probes: LinkProbes, joints_G: np.ndarray, X_OG: np.ndarray, distance: DistanceGrid) -> np.ndarray:
    """How deep (m) a finger's deepest link sphere lies in the object (:meth:`.single.LinkProbes.depth`)
    for its joint frames ``joints_G`` (n, j, 4, 4) in G and the frames X_OG (n, 4, 4)."""
    c_O = np.einsum("nij,npj->npi", X_OG[:, :3, :3], probes.centres(joints_G)) + X_OG[:, None, :3, 3]
    return probes.depth(c_O, distance)


def _worth_checking(probes: LinkProbes, chain: Chain, Q: np.ndarray, ok: np.ndarray, b: np.ndarray,
                    X_OG: np.ndarray, distance: DistanceGrid | None) -> np.ndarray:
    """The rows of the IK solutions ``Q`` (c, d) of one finger whose exact collision check
    is worth making, in row order: converged (``ok`` (c,)) and, with the object's
    ``distance`` grid, not burying a link sphere (``probes``, posed by the solution in the
    frame ``b`` (c,) of each row) deeper than :data:`SKIP_DEPTH` in it (on a YCB can, 99 %
    of the exact checks of such solutions collided)."""
    rows = np.flatnonzero(ok)
    if distance is None or not len(rows) or not len(probes.radii):
        return rows
    return rows[_link_depth(probes, chain.forward(Q[rows])[0], X_OG[b[rows]], distance) <= SKIP_DEPTH]


def _with_hints(hints: Hints, opposing: bool, finger: int, live: np.ndarray, X_OG: np.ndarray, ws: FingerWorkspace,
                r_tip: float, fl: np.ndarray, slot: np.ndarray, near: np.ndarray, cand_p: np.ndarray,
                cand_n: np.ndarray) -> tuple[np.ndarray, ...]:
    """The candidate rows (frame in ``live``, seed, point, normal in O) with each hinted
    contact of this finger first in its frame, seeded from the hint's workspace sample (the
    sample nearest to the target may sit on a joint limit, with the target beyond it)."""
    hinted = np.flatnonzero(opposing | (hints.finger[live] == finger))
    hp = (hints.p1 if opposing else hints.p2)[live[hinted]]
    hn = (hints.n1 if opposing else hints.n2)[live[hinted]]
    seed = (hints.thumb_sample if opposing else hints.finger_sample)[live[hinted]]
    unknown = seed < 0
    if unknown.any():  # a hint without its sample: the one nearest to the tip's target
        X = X_OG[live[hinted[unknown]]]
        tip_G = np.einsum("bji,bj->bi", X[:, :3, :3], hp[unknown] + r_tip * hn[unknown] - X[:, :3, 3])
        seed[unknown] = ws.tree.query(tip_G)[1]
    fl, slot = np.concatenate([hinted, fl]), np.concatenate([np.full(len(hinted), -1), slot])
    near = np.concatenate([seed, near])
    order = np.lexsort((slot, fl))
    return fl[order], near[order], np.concatenate([hp, cand_p])[order], np.concatenate([hn, cand_n])[order]


def grasp_for_frame(hm: HandModel, workspaces: tuple[FingerWorkspace, ...], surface: Surface, X_OG: np.ndarray,
                    frame_index: int, friction: float, rho: float, options: GraspOptions,
                    distance: DistanceGrid | None = None) -> tuple[Grasp | None, dict]:
    """The grasp of one grasp frame X_OG (4, 4), or None; plus counters for the summary."""
    grasps, stats = grasps_for_frames(hm, workspaces, surface, X_OG[None], np.array([frame_index]), friction, rho,
                                      options, distance=distance)
    return (grasps[0] if grasps else None), stats


def grasps_for_frames(hm: HandModel, workspaces: tuple[FingerWorkspace, ...], surface: Surface, X_OG: np.ndarray,
                      frame_index: np.ndarray, friction: float, rho: float, options: GraspOptions,
                      hints: Hints | None = None, distance: DistanceGrid | None = None) -> tuple[list[Grasp], dict]:
    """The grasps of frames ``X_OG`` (F, 4, 4) (indices ``frame_index`` (F,)), and counters
    for the summary, summed over the frames: contact candidates, IK successes, candidates
    colliding, frames with the palm in the object, with too few contacts, with the closed
    hand colliding, not force closure.  With ``hints``, their contacts are tried first; with
    the object's ``distance`` grid, frames that bury the palm and IK solutions that bury a
    phalanx are not checked (:func:`_buried`, :func:`_worth_checking`)."""
    h = hm.hand
    chains = hm.chains()
    F = len(X_OG)
    stats = {"contacts": 0, "ik": 0, "collisions": 0, "palm": 0, "few_contacts": 0, "hand_collision": 0,
             "not_force_closure": 0}
    live = []
    buried = _buried(hm, X_OG, distance)
    stats["buried"] = int(buried.sum())
    X_JO = hm.object_in_joint(X_OG)
    for b in np.flatnonzero(~buried):  # the palm inside the object: no grasp from this frame
        hm.set_object(X_OG[b], X_JO[b])
        if hm.collides(hm.q, set(), -1):
            stats["palm"] += 1
        else:
            live.append(b)
    live = np.array(live, dtype=np.intp)
    n_f = len(h.finger_idx)
    q = np.tile(hm.q, (F, 1))
    in_contact = np.zeros((F, n_f), dtype=bool)
    points, normals = np.full((F, n_f, 3), np.nan), np.full((F, n_f, 3), np.nan)
    axes = np.zeros((F, n_f, 3))
    placed: list[set[int]] = [set() for _ in range(F)]
    R_GO = X_OG[:, :3, :3].transpose(0, 2, 1)
    t_GO = -np.einsum("bij,bj->bi", R_GO, X_OG[:, :3, 3])
    # which fingers' workspaces hold each surface sample, in every live frame: (F_live, S)
    voxels = hm.hand_voxels(workspaces)
    probes = hm.probes()
    points_G = surface.points @ X_OG[live, :3, :3] + t_GO[live, None]  # (F_live, S, 3)
    normals_G = surface.normals @ X_OG[live, :3, :3]
    bits = voxels.lookup(points_G.reshape(-1, 3)).reshape(len(live), len(surface.points))
    row = np.full(F, -1)
    row[live] = np.arange(len(live))
    thumb = h.opposing
    for f in [thumb] + [f for f in range(n_f) if f != thumb]:
        if not len(live):
            break
        ws, idx, r_tip = workspaces[f], h.finger_idx[f], h.spec.fingers[f].tip_radius
        anchor = None if f == thumb else (points[live, thumb], normals[live, thumb])
        inside = np.nonzero(bits[row[live]] & np.uint32(1 << f))
        fl, si, near, slot = _candidates(voxels, f, ws, inside, surface, (points_G, normals_G, row[live]), r_tip,
                                         anchor, options.candidates_per_finger)
        cand_p, cand_n = surface.points[si], surface.normals[si]
        if hints is not None:
            fl, near, cand_p, cand_n = _with_hints(hints, f == thumb, f, live, X_OG, ws, r_tip, fl, slot, near,
                                                   cand_p, cand_n)
        stats["contacts"] += len(fl)
        rank = np.arange(len(fl)) - np.searchsorted(fl, fl)  # a row's place in its frame's order
        held, J_held = [], []  # the frames this finger touches in, and its Jacobians there
        for lo, hi in IK_ROUNDS:  # the first rows of every frame, then the next of those left open
            rows = np.flatnonzero((rank >= lo) & (rank < hi))
            rows = rows[~in_contact[live[fl[rows]], f]]
            if not len(rows):
                continue
            b = live[fl[rows]]
            p, n = cand_p[rows], cand_n[rows]
            target_G = np.einsum("bij,bj->bi", R_GO[b], p + r_tip * n) + t_GO[b]
            Q, ok, J = batch_ik(chains[f], hm.robot.lower[idx], hm.robot.upper[idx], ws.sample_q[near[rows]], target_G,
                                options.ik_iterations, options.ik_tolerance)
            stats["ik"] += int(ok.sum())
            for k in _worth_checking(probes[f], chains[f], Q, ok, b, X_OG, distance):
                frame = b[k]
                if f in placed[frame]:
                    continue
                qf = q[frame].copy()
                qf[idx] = Q[k]
                hm.set_object(X_OG[frame], X_JO[frame])
                if hm.collides(qf, placed[frame], f):
                    stats["collisions"] += 1
                    continue
                q[frame] = qf
                placed[frame].add(f)
                in_contact[frame, f] = True
                points[frame, f], normals[frame, f] = p[k], n[k]
                held.append(frame)
                J_held.append(J[k])
        if held:  # the force ellipsoids' axes, in O
            axes[held, f] = np.einsum("bij,bj->bi", X_OG[held, :3, :3], force_ellipsoid_axis(np.array(J_held)))
        if f == thumb:  # no stable grasp without the thumb (§IV-A-2)
            stats["few_contacts"] += int((~in_contact[live, thumb]).sum())
            live = live[in_contact[live, thumb]]
    need = 2 if h.spec.contact == "soft" else 3
    grasps = []
    for frame in live:
        if in_contact[frame].sum() < need:
            stats["few_contacts"] += 1
            continue
        hm.set_object(X_OG[frame], X_JO[frame])
        if hm.collides(q[frame], set(range(n_f)), None):
            stats["hand_collision"] += 1
            continue
        one: dict = {"not_force_closure": 0}
        g, _ = scored_grasp(hm, surface, X_OG[frame], int(frame_index[frame]), q[frame], in_contact[frame],
                            points[frame], normals[frame], axes[frame], friction, rho, options, one)
        stats["not_force_closure"] += one["not_force_closure"]
        if g is not None:
            grasps.append(g)
    return grasps, stats
