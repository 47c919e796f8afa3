"""Finger workspaces approximated by spheres: Algorithm 1 of Saut et al. 2010, §IV-A-2.

For each finger, the fingertip-sphere centre positions (in the hand's grasp frame G) are
sampled on an *interior* grid W (every joint over its range) and an *envelope* grid E
(one joint held at its lower, then upper limit, the others sampled, the grid refined until
neighbouring envelope points are at most ``envelope_spacing`` apart).  Spheres are then
grown greedily: the interior point farthest from E and from the spheres found so far is
the centre of the next sphere, whose radius is that distance; interior points inside it
are removed; stop after ``k_max`` spheres or when the radius falls below ``r_min``.  The
spheres come out biggest first, i.e. farthest from the joint limits first, which is the
order in which contacts are searched.

The interior samples are kept with their joint values: the nearest one seeds finger IK.
Computed once per hand and cached (HDF5, keyed by the hand's own inputs,
:func:`~regrasp_cli.model.handshape.hand_inputs`, and the options).
"""

from __future__ import annotations

import itertools
from dataclasses import asdict, dataclass, replace
from functools import cached_property
from pathlib import Path

import numpy as np
import pinocchio as pin
from scipy.spatial import cKDTree

from regrasp_cli.model.collision import cold_start
from regrasp_cli.model.robot import Kinematics, Robot
from regrasp_cli.spatial import inverse
from regrasp_cli.model.handshape import hand_inputs
from regrasp_cli.store import Provenance, is_fresh, read_artefact, robot_label, sha256_params, write_artefact

FORMAT, FORMAT_VERSION = "regrasp.workspace", 6  # 6: with each finger's voxel map
VOXEL_RESOLUTION = 0.002  # m: the side of a voxel of the fingers' maps
_STORED = ("centres", "radii", "samples", "sample_q", "sample_closing", "root")


@dataclass(frozen=True)
class WorkspaceOptions:
    interior_samples: int = 4096  # about this many W points per finger
    envelope_samples: int = 4096  # about this many E points per finger before refinement
    # m: each envelope face grid is refined until neighbouring E points are at most this far
    # apart, so that a sphere cannot reach out of the workspace between two E points by more
    # than r - sqrt(r^2 - spacing^2 / 2) (a few tenths of a mm at r = r_min)
    envelope_spacing: float = 0.002
    k_max: int = 30  # at most this many spheres per finger
    r_min: float = 0.004  # m, smallest sphere kept


@dataclass(frozen=True)
class FingerWorkspace:
    """Spheres (centres (k, 3) and radii (k,), metres, frame G) biggest first, plus the
    interior samples: positions (m, 3) in G, joint values (m, n_joints) and the unit
    direction (m, 3) in G in which the fingertip moves when the finger closes."""

    centres: np.ndarray
    radii: np.ndarray
    samples: np.ndarray
    sample_q: np.ndarray
    sample_closing: np.ndarray
    root: np.ndarray  # (3,) position in G of the finger's first joint
    voxels: "SphereVoxels | None" = None  # the spheres grown by the fingertip's radius (:func:`hand_workspace`)

    @cached_property
    def tree(self) -> cKDTree:
        return cKDTree(self.samples)

    def nearest(self, p_G: np.ndarray) -> int:
        """Index of the interior sample nearest to ``p_G`` (3,)."""
        return int(self.tree.query(p_G)[1])


@dataclass(frozen=True)
class SphereVoxels:
    """A voxel map of a finger's spheres, each inflated by a radius: which sphere (index,
    biggest first) holds a point, in constant time.  Exact up to half a voxel diagonal."""

    origin: np.ndarray  # (3,) centre of voxel (0, 0, 0), frame G
    resolution: float  # m
    index: np.ndarray  # (nx, ny, nz) int16, -1 where no sphere
    inflate: float = 0.0  # m the spheres are grown by
    nearest: np.ndarray | None = None  # (nx, ny, nz) int32: the interior sample nearest to each voxel's centre, -1 off the map

    def lookup(self, p_G: np.ndarray) -> np.ndarray:
        """Index of the biggest sphere holding each point (n, 3) in G, or -1 (n,)."""
        ijk = np.rint((p_G - self.origin) / self.resolution).astype(np.intp)
        shape = np.array(self.index.shape)
        inside = np.all((ijk >= 0) & (ijk < shape), axis=1)
        out = np.full(len(p_G), -1, dtype=np.intp)
        i = ijk[inside]
        out[inside] = self.index[i[:, 0], i[:, 1], i[:, 2]]
        return out


@dataclass(frozen=True)
class HandVoxels:
    """The voxel maps of all fingers of a hand on one lattice: per voxel, bit f set when
    finger f's map holds it (exactly as the fingers' own maps: :func:`sphere_voxels` puts
    them on the same lattice) and the closing direction of finger f's interior sample
    nearest to the voxel's centre (zero off its map).  One lookup answers for every finger."""

    origin: np.ndarray  # (3,) centre of voxel (0, 0, 0), frame G
    resolution: float  # m
    bits: np.ndarray  # (nx, ny, nz) uint32
    nearest: np.ndarray  # (n_fingers, nx * ny * nz) int32: finger f's sample nearest to the voxel, -1 off its map
    directions: tuple[np.ndarray, ...]  # per finger, its samples' closing directions (m + 1, 3) float32, frame G, last zero

    def closing(self, finger: int, cells: np.ndarray) -> np.ndarray:
        """The closing direction (c, 3) of ``finger`` at the voxels ``cells`` (c,) (:meth:`cells`):
        that of its interior sample nearest to the voxel, zero off its map."""
        return np.take(self.directions[finger], np.take(self.nearest[finger], cells), axis=0)

    def cells(self, p_G: np.ndarray) -> np.ndarray:
        """Flat index into the maps' one-voxel border of each point (n, 3) in G: points
        off the map land on the border, which holds no finger."""
        shape = np.array(self.bits.shape)
        x = np.subtract(p_G, self.origin)
        np.divide(x, self.resolution, out=x)
        ijk = np.rint(x, out=x).astype(np.intp)  # in place: a search looks up millions of points
        np.maximum(ijk, 0, out=ijk)
        np.minimum(ijk, shape - 1, out=ijk)
        ijk[:, 0] *= shape[1]
        ijk[:, 0] += ijk[:, 1]
        ijk[:, 0] *= shape[2]
        ijk[:, 0] += ijk[:, 2]
        return ijk[:, 0]

    def lookup(self, p_G: np.ndarray) -> np.ndarray:
        """The finger bits of the voxel of each point (n, 3) in G, 0 off the map (n,)."""
        return np.take(self.bits.ravel(), self.cells(p_G))


def hand_voxels(fingers: tuple[SphereVoxels, ...], workspaces: tuple[FingerWorkspace, ...]) -> HandVoxels:
    """The fingers' maps (on one lattice, of one resolution, with their nearest samples:
    :func:`sphere_voxels`) as one map of finger bits, with the closing direction of each
    finger's interior sample nearest to each voxel of its map, and a border of one empty
    voxel all round."""
    res = fingers[0].resolution
    lo = np.rint(np.min([v.origin for v in fingers], axis=0) / res).astype(int) - 1
    hi = np.rint(np.max([v.origin / res + v.index.shape for v in fingers], axis=0)).astype(int) + 1
    bits = np.zeros(tuple(hi - lo), dtype=np.uint32)
    nearest = np.full((len(fingers), *bits.shape), -1, dtype=np.int32)
    for f, v in enumerate(fingers):
        a = np.rint(v.origin / res).astype(int) - lo
        b = a + v.index.shape
        bits[a[0]:b[0], a[1]:b[1], a[2]:b[2]] |= (v.index >= 0).astype(np.uint32) << f
        if v.nearest is not None:
            nearest[f, a[0]:b[0], a[1]:b[1], a[2]:b[2]] = v.nearest
    directions = tuple(np.vstack([ws.sample_closing, np.zeros((1, 3))]).astype(np.float32) for ws in workspaces)
    return HandVoxels(lo * res, res, bits, nearest.reshape(len(fingers), -1), directions)


def sphere_voxels(ws: "FingerWorkspace", inflate: float, resolution: float = VOXEL_RESOLUTION) -> SphereVoxels:
    """The voxel map of ``ws``'s spheres grown by ``inflate`` (m), with the interior
    sample nearest to each of its voxels (when ``ws`` has samples)."""
    if len(ws.radii) == 0:
        return SphereVoxels(np.zeros(3), resolution, -np.ones((1, 1, 1), dtype=np.int16), inflate,
                            -np.ones((1, 1, 1), dtype=np.int32))
    r = ws.radii + inflate
    lo, hi = (ws.centres - r[:, None]).min(axis=0), (ws.centres + r[:, None]).max(axis=0)
    lo = np.floor(lo / resolution) * resolution  # on one lattice for every finger (HandVoxels)
    shape = np.ceil((hi - lo) / resolution).astype(int) + 1
    axes = [lo[d] + resolution * np.arange(shape[d]) for d in range(3)]
    index = np.full(tuple(shape), -1, dtype=np.int16)
    for k in range(len(r) - 1, -1, -1):  # smallest first: the biggest sphere writes last
        # only the voxels of the sphere's bounding box (a whole-grid pass per sphere was
        # most of an in-hand run's setup); the same distances, so the same map
        a = np.maximum(np.floor((ws.centres[k] - r[k] - lo) / resolution).astype(int) - 1, 0)
        b = np.minimum(np.ceil((ws.centres[k] + r[k] - lo) / resolution).astype(int) + 2, shape)
        X = np.stack(np.meshgrid(*(axes[d][a[d]:b[d]] for d in range(3)), indexing="ij"), axis=-1)
        box = index[a[0]:b[0], a[1]:b[1], a[2]:b[2]]
        box[np.linalg.norm(X - ws.centres[k], axis=-1) <= r[k]] = k
    nearest = np.full(tuple(shape), -1, dtype=np.int32)
    ijk = np.argwhere(index >= 0)
    if len(ijk) and len(getattr(ws, "samples", ())):
        nearest[ijk[:, 0], ijk[:, 1], ijk[:, 2]] = ws.tree.query(lo + resolution * ijk)[1]
    return SphereVoxels(lo, resolution, index, inflate, nearest)


def _grid(lo: np.ndarray, hi: np.ndarray, total: int) -> np.ndarray:
    """Regular grid (m, d) over the box [lo, hi] with about ``total`` points."""
    d = len(lo)
    n = max(2, int(round(total ** (1.0 / d))))
    axes = [np.linspace(a, b, n) for a, b in zip(lo, hi)]
    return np.array(list(itertools.product(*axes)), dtype=float)


def _grid_counts(lo: np.ndarray, hi: np.ndarray, counts) -> np.ndarray:
    """Regular grid (prod(counts), d) over the box [lo, hi], ``counts[k]`` values on axis k."""
    axes = [np.linspace(a, b, n) for a, b, n in zip(lo, hi, counts)]
    return np.array(list(itertools.product(*axes)), dtype=float).reshape(-1, len(lo))


def _envelope_positions(robot: Robot, hand: str, finger: int, base: np.ndarray, lo: np.ndarray,
                        hi: np.ndarray, total: int, spacing: float, order: np.ndarray,
                        max_per_axis: int = 1000) -> np.ndarray:
    """Fingertip positions (e, 3) in G on the envelope: one free joint at a limit, the
    others on a grid of about ``total`` points in all, refined per axis until neighbouring
    positions are at most ``spacing`` apart.  Joint values are (fixed ``base``, free) in
    the finger's joints permuted by ``order`` (:func:`_fixed_first`).

    A joint-space grid alone leaves Cartesian gaps where a joint has a long lever (an
    extended finger's proximal joint): Algorithm 1's radius, the distance to the nearest E
    point, then overestimates the distance to the workspace boundary by up to half a gap,
    and a sphere reaches out of the workspace (by 4 mm with the default robot's thumb)."""
    d = len(lo)
    back = np.argsort(order)
    if d == 1:
        q = np.column_stack([np.tile(base, (2, 1)), [lo[0], hi[0]]])
        return tip_positions(robot, hand, finger, q[:, back])
    per_face = max(4, total // (2 * d))
    n0 = max(2, int(round(per_face ** (1.0 / (d - 1)))))
    out = []
    for j in range(d):
        others = [i for i in range(d) if i != j]
        for limit in (lo[j], hi[j]):
            counts = [n0] * (d - 1)
            for _ in range(4):  # the steps of a refined grid are measured again
                g = _grid_counts(lo[others], hi[others], counts)
                q = np.empty((len(g), d))
                q[:, others] = g
                q[:, j] = limit
                P = tip_positions(robot, hand, finger, np.hstack([np.tile(base, (len(q), 1)), q])[:, back])
                P3 = P.reshape(*counts, 3)
                need = list(counts)
                for a in range(d - 1):
                    if counts[a] > 1 and hi[others[a]] > lo[others[a]]:
                        step = float(np.linalg.norm(np.diff(P3, axis=a), axis=-1).max())
                        need[a] = min(max_per_axis, max(counts[a], int(np.ceil((counts[a] - 1) * step / spacing)) + 1))
                if need == counts:
                    break
                counts = need
            out.append(P)
    return np.concatenate(out)


def _palm_pairs(robot: Robot, hand: str, finger: int) -> pin.GeometryModel:
    """Geometry model of the palm and one finger, with the finger-palm pairs that are not
    adjacent (the finger's first link with geometry touches the palm by design)."""
    h = robot.hands[hand]
    model, src = robot.model, robot.collision_model
    palm_joint = model.frames[h.grasp_frame].parentJoint
    finger_joints = {j for j, f in robot.hand_joints(hand).items() if f == finger}
    with_geometry = {go.parentJoint for go in src.geometryObjects}
    gm, palm, links = pin.GeometryModel(), [], []
    for go in src.geometryObjects:
        if go.parentJoint == palm_joint:
            palm.append(gm.addGeometryObject(go.copy()))
        elif go.parentJoint in finger_joints:
            j = model.parents[go.parentJoint]
            while j not in with_geometry and j != 0:
                j = model.parents[j]
            if j != palm_joint:  # not the phalanx mounted on the palm
                links.append(gm.addGeometryObject(go.copy()))
    for a in links:
        for b in palm:
            gm.addCollisionPair(pin.CollisionPair(a, b))
    return gm


def tip_positions(robot: Robot, hand: str, finger: int, Q: np.ndarray,
                  with_collisions: bool = False) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    """Fingertip-sphere centres (m, 3) in the grasp frame G for finger joint values Q (m, n);
    with ``with_collisions``, also whether the finger then collides with the palm (m,)."""
    h = robot.hands[hand]
    q = robot.q_rest.copy()
    q[h.idx] = h.open
    idx, tip = h.finger_idx[finger], h.tip_frames[finger]
    kin = Kinematics(robot)
    model, data = robot.model, kin.data
    gm = _palm_pairs(robot, hand, finger) if with_collisions else None
    gd = gm.createData() if with_collisions else None
    if gd is not None:
        cold_start(gd)
    X_GW = inverse(kin.fk(q, h.grasp_frame))
    out, hit = np.empty((len(Q), 3)), np.zeros(len(Q), dtype=bool)
    for k, qf in enumerate(Q):
        q[idx] = qf
        if with_collisions:
            hit[k] = pin.computeCollisions(model, data, gm, gd, robot.to_pin(q), True)
        else:
            pin.forwardKinematics(model, data, robot.to_pin(q))
        out[k] = pin.updateFramePlacement(model, data, tip).translation
    out = out @ X_GW[:3, :3].T + X_GW[:3, 3]
    return (out, hit) if with_collisions else out


def fit_spheres(W: np.ndarray, E: np.ndarray, k_max: int, r_min: float) -> tuple[np.ndarray, np.ndarray]:
    """Algorithm 1: spheres inside the region of interior points W (m, 3) bounded by the
    envelope points E (e, 3).  Returns centres (k, 3) and radii (k,), biggest first."""
    d = cKDTree(E).query(W)[0]  # distance to the envelope
    alive = np.ones(len(W), dtype=bool)
    centres, radii = [], []
    while len(centres) < k_max and alive.any():
        i = int(np.argmax(np.where(alive, d, -np.inf)))
        r = float(d[i])
        if r < r_min:
            break
        c = W[i]
        centres.append(c)
        radii.append(r)
        dist_c = np.linalg.norm(W - c, axis=1)
        alive &= dist_c > r
        np.minimum(d, dist_c - r, out=d)  # distance to the new sphere's surface
    return np.array(centres).reshape(-1, 3), np.array(radii)


def _fixed_first(robot: Robot, hand: str, finger: int, n_fixed: int) -> np.ndarray:
    """The finger's joints (positions in its chain) ordered with the ``n_fixed`` to fix
    first: the leading ones (a thumb's base), unless the others then move the tip in a
    plane only (an Allegro finger's three flexions after its abduction): then the
    trailing ones.  Judged by the rank of the free joints' tip Jacobian at mid-range."""
    n = len(robot.hands[hand].finger_idx[finger])
    leading = np.arange(n)
    if n_fixed == 0:
        return leading
    idx = robot.hands[hand].finger_idx[finger]
    mid = (robot.lower[idx] + robot.upper[idx]) / 2
    h = 1e-4
    Q = np.vstack([mid, mid + h * np.eye(n)])
    P = tip_positions(robot, hand, finger, Q)
    J = (P[1:] - P[0]).T / h  # (3, n)
    free = J[:, n_fixed:]
    sv = np.linalg.svd(free, compute_uv=False)
    if sv[-1] > 1e-3 * sv[0]:
        return leading
    return np.concatenate([np.arange(n - n_fixed, n), np.arange(n - n_fixed)])


def finger_workspace(robot: Robot, hand: str, finger: int, options: WorkspaceOptions) -> FingerWorkspace:
    """Algorithm 1 for one finger.  A finger with more than three joints (a thumb with a
    base joint, an Allegro finger) has a redundant chain whose "envelope" grid also covers
    its interior, so some joints are fixed at a few values (limits and middle;
    :func:`_fixed_first`) and the spheres of each fixed value are pooled, biggest first."""
    h = robot.hands[hand]
    idx = h.finger_idx[finger]
    n_base = max(0, len(idx) - 3)
    order = _fixed_first(robot, hand, finger, n_base)
    back = np.argsort(order)
    lo, hi = robot.lower[idx], robot.upper[idx]
    lo_p, hi_p = lo[order], hi[order]  # fixed joints first
    bases = _grid(lo_p[:n_base], hi_p[:n_base], 3 ** n_base) if n_base else np.empty((1, 0))
    centres, radii, W_all, Q_all, D_all = [], [], [], [], []
    # closing: every joint moves away from its open value towards its far limit
    # (flexions curl, a gripper jaw moves towards the other; abduction stays put)
    open_ = robot.hands[hand].open[sum(len(i) for i in h.finger_idx[:finger]):][: len(idx)]
    closing = np.sign((lo + hi) / 2 - open_) * (hi - lo > 0)
    for b in bases:
        Qw = _grid(lo_p[n_base:], hi_p[n_base:], options.interior_samples // len(bases))
        Qw = np.hstack([np.tile(b, (len(Qw), 1)), Qw])[:, back]
        W, hit = tip_positions(robot, hand, finger, Qw, with_collisions=True)
        # configurations where the finger runs into the palm are outside the usable
        # workspace: they join the envelope, so no sphere contains them
        blocked = W[hit]
        W, Qw = W[~hit], Qw[~hit]
        step = 1e-4 * (hi - lo)
        D = tip_positions(robot, hand, finger, np.clip(Qw + closing * step, lo, hi)) - W
        D /= np.maximum(np.linalg.norm(D, axis=1, keepdims=True), 1e-12)
        if len(idx) == 1:
            # a 1-joint finger's workspace is a curve: no sphere fits inside it, so samples
            # near the middle of its range, with radius r_min, stand for it
            order = np.argsort(np.abs(Qw[:, 0] - (lo[0] + hi[0]) / 2))[: options.k_max]
            c, r = W[order], np.full(len(order), options.r_min)
        else:
            E = np.concatenate([_envelope_positions(robot, hand, finger, b, lo_p[n_base:], hi_p[n_base:],
                                                    options.envelope_samples // len(bases),
                                                    options.envelope_spacing, order), blocked])
            c, r = fit_spheres(W, E, options.k_max, options.r_min)
        centres.append(c)
        radii.append(r)
        W_all.append(W)
        Q_all.append(Qw)
        D_all.append(D)
    centres, radii = np.concatenate(centres), np.concatenate(radii)
    order = np.argsort(-radii, kind="stable")[: options.k_max]
    q = robot.q_rest.copy()
    q[h.idx] = h.open
    root_frame = robot.model.getFrameId(robot.joint_names[idx[0]], pin.FrameType.JOINT)
    kin = Kinematics(robot)
    X_GW = inverse(kin.fk(q, h.grasp_frame))
    p_root = X_GW[:3, :3] @ kin.fk(q, root_frame)[:3, 3] + X_GW[:3, 3]
    return FingerWorkspace(centres[order], radii[order], np.concatenate(W_all), np.concatenate(Q_all),
                           np.concatenate(D_all), p_root)


def hand_workspace(robot: Robot, hand: str, options: WorkspaceOptions = WorkspaceOptions(),
                   cache_dir: Path | None = None) -> tuple[FingerWorkspace, ...]:
    """Workspaces of every finger of a hand, cached under ``cache_dir/workspace/``."""
    inputs = {"hand": sha256_params(hand_inputs(robot, hand, set())),  # the hand alone, not the rest posture
              "params": sha256_params({"hand": hand, **asdict(options)})}
    expected = Provenance(FORMAT, FORMAT_VERSION, inputs)
    # the hand's digest in the name: two robots' right hands in one cache would otherwise
    # overwrite each other's file (the provenance refusing the other's)
    name = f"{robot_label(robot)}-{hand}-{sha256_params(inputs)[:12]}.h5"
    path = None if cache_dir is None else Path(cache_dir) / "workspace" / name
    tips = [f.tip_radius for f in robot.hands[hand].spec.fingers]
    if path is not None and path.is_file() and is_fresh(path, expected):
        a = read_artefact(path, expected)
        return tuple(FingerWorkspace(*(a[f"finger{i}/{k}"] for k in _STORED),
                                     SphereVoxels(a[f"finger{i}/voxel_origin"], VOXEL_RESOLUTION,
                                                  a[f"finger{i}/voxel_index"], r, a[f"finger{i}/voxel_nearest"]))
                     for i, r in enumerate(tips))
    fingers = tuple(finger_workspace(robot, hand, i, options) for i in range(len(tips)))
    # the voxel maps too (a fifth of a second a hand): they depend on the spheres and the tip radii alone
    fingers = tuple(replace(f, voxels=sphere_voxels(f, r)) for f, r in zip(fingers, tips))
    if path is not None:
        groups = {f"finger{i}": {**{k: getattr(f, k) for k in _STORED}, "voxel_origin": f.voxels.origin,
                                 "voxel_index": f.voxels.index, "voxel_nearest": f.voxels.nearest}
                  for i, f in enumerate(fingers)}
        write_artefact(path, expected, {}, groups=groups)
    return fingers
