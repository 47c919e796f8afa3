"""What a fingertip grasp is and the hand it is searched with (Saut et al. 2010, §IV-A).

:class:`GraspOptions` (the search's options), :class:`Grasp` (a force-closure grasp: the
grasp frame in the object, finger joint values, contacts), :class:`HandModel` (the hand
alone with the object attached to its grasp frame: collision pairs, finger chains, voxel
maps of the finger workspaces; one per process) and :func:`scored_grasp` (the stability
filter and quality score of §IV-A-3, :mod:`.quality`).  The search itself, for one frame
or many, is :mod:`.fingertips`; jaws and pads are :mod:`.jaw` and :mod:`.pads`.

The hand is checked in isolation (no arm, no environment): collisions with the
environment and the rest of the robot are the business of the online stage (§IV-B).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from regrasp_cli.grasp.quality import GraspScores, QualityWeights, grasp_quality
from regrasp_cli.grasp.surface import DistanceGrid, Surface
from regrasp_cli.grasp.workspace import FingerWorkspace, HandVoxels, SphereVoxels, hand_voxels, sphere_voxels
from regrasp_cli.model.collision import cold_start, eroded_geometry, mesh_geometry
from regrasp_cli.model.chain import Chain, read_chain
from regrasp_cli.model.robot import Kinematics, Robot
from regrasp_cli.spatial import inverse


@dataclass(frozen=True)
class GraspOptions:
    """Options of the single-grasp search (metres, radians)."""

    n_positions: int = 4  # grasp-frame positions in the object's bounding box
    n_orientations: int = 4096  # grasp-frame orientations (incremental SO(3) grid)
    target: int = 120  # stop once this many distinct grasps are found (0: try every frame) ...
    support_share: float = 1.0  # ... and this share of it clear each support of the object's stable placements
    candidates_per_finger: int = 24  # contact candidates tried per finger before leaving it open
    contact_tolerance: float = 0.002  # fingertip-object penetration allowed, m
    link_clearance: float = 0.0003  # m every other hand geometry keeps from the object: a phalanx grazing
    # it (0.04 mm off, YCB drill) was free in the planner's world and colliding in the validator's
    ik_tolerance: float = 2e-4  # fingertip placement error accepted, m
    ik_iterations: int = 30
    cone_edges: int = 8  # linearised friction cone
    antipodal_samples: int = 4096  # jaws: surface samples that cast a ray for an antipodal pair (grasp.jaw)
    pinch_frames: int = 4096  # fingertip hands: such samples for the pinch frames after the grid (grasp.pinch)
    duplicate_distance: float = 0.01  # m: grasps closer than this (hand position) ...
    duplicate_angle: float = 0.2  # rad: ... and this (hand orientation) are duplicates
    weights: QualityWeights = QualityWeights()


@dataclass(frozen=True)
class Grasp:
    """A force-closure grasp.  Arrays per finger (n_fingers, ...); fingers without contact
    have ``in_contact`` False and NaN points/normals."""

    frame_index: int
    X_OG: np.ndarray  # (4, 4) grasp frame in the object frame ("hand in object")
    finger_q: np.ndarray  # (n_hand_joints,) finger joint values, robot.yaml order
    in_contact: np.ndarray  # (n_fingers,) bool
    points: np.ndarray  # (n_fingers, 3) contact points on the surface, frame O
    normals: np.ndarray  # (n_fingers, 3) outward surface normals, frame O
    scores: GraspScores


@dataclass(frozen=True)
class LinkProbes:
    """Spheres inside the link geometries of a finger but its fingertip (:func:`link_probes`),
    each hanging from a joint of the finger's chain (:mod:`model.chain`).  Where they lie in
    the object tells which finger postures bury a phalanx in it, far more cheaply than the
    exact check, which alone decides (:mod:`.fingertips` skips the hopeless checks by it)."""

    joint: np.ndarray  # (P,) index in the chain of the joint each sphere hangs from
    p_J: np.ndarray  # (P, 3) centres in that joint's frame, m
    radii: np.ndarray  # (P,) m

    def centres(self, frames: np.ndarray) -> np.ndarray:
        """Centres (B, P, 3) in the chain's frame for its joint frames ``frames`` (B, n, 4, 4)."""
        X = frames[:, self.joint]
        return np.einsum("bpij,pj->bpi", X[..., :3, :3], self.p_J) + X[..., :3, 3]

    def depth(self, centres_O: np.ndarray, distance: DistanceGrid) -> np.ndarray:
        """How deep (m) the deepest sphere of each row of centres (B, P, 3) in O lies in the
        object, by the ``distance`` grid (negative: clear of it by that much; -inf: no sphere)."""
        if not len(self.radii):
            return np.full(len(centres_O), -np.inf)
        return np.max(self.radii - distance(centres_O), axis=1)


class HandModel:
    """The hand alone, with the object attached to its grasp frame: the scratch for the
    per-frame grasp search (one per process).  The fingertips may sink ``tolerance`` (m)
    into the object; every other geometry keeps ``clearance`` (m) from it."""

    def __init__(self, robot: Robot, hand: str, mesh, disabled_links: set[tuple[str, str]], tolerance: float,
                 clearance: float = 0.0):
        self.robot, self.hand = robot, robot.hands[hand]
        self.disabled_links = frozenset(disabled_links)  # link pairs never checked
        h = self.hand
        model = robot.model
        self.q = robot.q_rest.copy()
        self.q[h.idx] = h.open
        # geometries of the palm and of every link that moves with the fingers
        self.finger_of_joint = robot.hand_joints(hand)
        hand_joints = set(self.finger_of_joint)
        palm_joint = model.frames[h.grasp_frame].parentJoint
        src = robot.collision_model
        gm = pin.GeometryModel()
        self.owner: list[int] = []  # finger index of each geometry, -1 for the palm
        self.erosion: list[float] = []  # per geometry, m it is shrunk by (a fingertip against the object)
        self.is_tip: list[bool] = []  # a fingertip's geometry
        tips = {model.frames[t].name for t in h.tip_frames}
        links, sources = [], []
        for go in src.geometryObjects:
            j = go.parentJoint
            if j == palm_joint or j in hand_joints:
                name = model.frames[go.parentFrame].name
                geom = eroded_geometry(go.geometry, tolerance) if name in tips else None
                self.erosion.append(tolerance if geom is not None else 0.0)
                self.is_tip.append(name in tips)
                gm.addGeometryObject(pin.GeometryObject(go.name, j, go.parentFrame, go.placement,
                                                        geom or go.geometry))
                self.owner.append(self.finger_of_joint.get(j, -1))
                links.append(name)
                sources.append(go)
        # object attached to the grasp frame's joint: placement set per grasp frame
        f = model.frames[h.grasp_frame]
        self.X_JG = f.placement.homogeneous
        self.obj = gm.addGeometryObject(pin.GeometryObject("object", f.parentJoint, h.grasp_frame, pin.SE3.Identity(),
                                                           mesh_geometry(mesh)))
        n = len(self.owner)
        # a fingertip touches the object within the tolerance, never another finger or the
        # palm: those pairs check its true geometry, a copy after the object's (checked
        # eroded, index and middle tips 4 mm apart passed, and 1 grasp in 7 of the
        # statuette's lists had the hand colliding with itself in the planner's world)
        self.erosion.append(0.0)  # the object's
        true = list(range(n))
        for a in np.flatnonzero(self.erosion[:n]):
            go = sources[a]
            true[a] = gm.addGeometryObject(pin.GeometryObject(go.name + "/true", go.parentJoint, go.parentFrame,
                                                              go.placement, go.geometry))
            self.erosion.append(0.0)
        pairs_of = {f: [] for f in range(-1, len(h.finger_idx))}
        self.pair_fingers = []
        # the hand's own pairs first: checked in this order, and most collisions of a search
        # are a finger's proximal phalanx against its neighbour's, cheap shapes
        for a in range(n):
            for b in range(a + 1, n):
                fa, fb = self.owner[a], self.owner[b]
                if fa == fb or tuple(sorted((links[a], links[b]))) in disabled_links:
                    continue
                gm.addCollisionPair(pin.CollisionPair(true[a], true[b]))
                self.pair_fingers.append((fa, fb))
        for a in range(n):
            gm.addCollisionPair(pin.CollisionPair(a, self.obj))
            self.pair_fingers.append((self.owner[a], None))
        self.gm, self.gd = gm, gm.createData()
        cold_start(self.gd)
        for k, (a, b) in enumerate((p.first, p.second) for p in gm.collisionPairs):
            if b == self.obj and a < n and not self.is_tip[a]:  # not a fingertip: keep ``clearance`` from the object
                # (a fingertip touches it, eroded or, a mesh, not)
                self.gd.collisionRequests[k].security_margin = clearance
        for k, (fa, fb) in enumerate(self.pair_fingers):
            for f_ in {fa, fb} - {None}:
                pairs_of[f_].append(k)
        self.pairs_of = pairs_of
        kin = Kinematics(robot)
        self.data = kin.data
        self.X_WG = kin.fk(self.q, h.grasp_frame)
        self._voxels: tuple[int, tuple[SphereVoxels, ...], HandVoxels] | None = None
        self._chains: tuple[Chain, ...] | None = None
        self._probes: tuple[LinkProbes, ...] | None = None
        self._palm_probes: tuple[np.ndarray, np.ndarray] | None = None
        self._object_at: bytes | None = None
        self._pair_memo: dict[tuple[frozenset[int], int | None], list[int]] = {}

    def voxels(self, workspaces: tuple[FingerWorkspace, ...]) -> tuple[SphereVoxels, ...]:
        """Voxel maps of the fingers' spheres grown by the tip radii (built on first use)."""
        if self._voxels is None or self._voxels[0] != id(workspaces):
            tips = [f.tip_radius for f in self.hand.spec.fingers]
            fingers = tuple(ws.voxels if ws.voxels is not None and ws.voxels.inflate == r else sphere_voxels(ws, r)
                            for ws, r in zip(workspaces, tips))  # cached with the workspaces
            self._voxels = (id(workspaces), fingers, hand_voxels(fingers, workspaces))
        return self._voxels[1]

    def chains(self) -> tuple[Chain, ...]:
        """Each finger's chain from the grasp frame G to its tip, driven by its joints
        (read on first use)."""
        if self._chains is None:
            h = self.hand
            self._chains = tuple(read_chain(self.robot, h.grasp_frame, h.tip_frames[f], idx, self.q)
                                 for f, idx in enumerate(h.finger_idx))
        return self._chains

    def probes(self) -> tuple["LinkProbes", ...]:
        """Per finger, spheres inside the geometries of its links but the fingertip
        (:class:`LinkProbes`, built on first use)."""
        if self._probes is None:
            gos = self.gm.geometryObjects
            out = []
            for f, chain in enumerate(self.chains()):
                joint, centres, radii = [np.zeros(0, int)], [np.zeros((0, 3))], [np.zeros(0)]
                for g, go in enumerate(gos[:len(self.owner)]):
                    if self.owner[g] != f or self.is_tip[g] or go.parentJoint not in chain.joints:
                        continue
                    p_L, r = link_probes(go.geometry)
                    centres.append(p_L @ go.placement.rotation.T + go.placement.translation)
                    joint.append(np.full(len(r), chain.joints.index(go.parentJoint)))
                    radii.append(r)
                out.append(LinkProbes(np.concatenate(joint), np.concatenate(centres), np.concatenate(radii)))
            self._probes = tuple(out)
        return self._probes

    def palm_probes(self) -> tuple[np.ndarray, np.ndarray]:
        """Spheres inside the palm's geometries (:func:`link_probes`): centres (P, 3) in G, radii (P,)."""
        if self._palm_probes is not None:
            return self._palm_probes
        X_GJ = inverse(self.X_JG)
        centres, radii = [np.zeros((0, 3))], [np.zeros(0)]
        for g, go in enumerate(self.gm.geometryObjects[:len(self.owner)]):
            if self.owner[g] == -1:
                p_L, r = link_probes(go.geometry)
                p_J = p_L @ go.placement.rotation.T + go.placement.translation
                centres.append(p_J @ X_GJ[:3, :3].T + X_GJ[:3, 3])
                radii.append(r)
        self._palm_probes = (np.concatenate(centres), np.concatenate(radii))
        return self._palm_probes

    def hand_voxels(self, workspaces: tuple[FingerWorkspace, ...]) -> HandVoxels:
        """The fingers' voxel maps as one map of finger bits (:class:`.workspace.HandVoxels`)."""
        self.voxels(workspaces)
        return self._voxels[2]

    def set_object(self, X_OG: np.ndarray, X_JO: np.ndarray | None = None) -> None:
        """Place the object so that the grasp frame is at X_OG in the object frame; ``X_JO``,
        the object in the grasp frame's joint, when the caller has it (:meth:`object_in_joint`)."""
        key = X_OG.tobytes()
        if key != self._object_at:  # a search checks several candidates of one frame in a row
            if X_JO is None:
                X_JO = self.X_JG @ inverse(X_OG)
            self.gm.geometryObjects[self.obj].placement = pin.SE3(X_JO[:3, :3].copy(), X_JO[:3, 3].copy())
            self._object_at = key

    def object_in_joint(self, X_OG: np.ndarray) -> np.ndarray:
        """The object's placements X_JO (F, 4, 4) in the grasp frame's joint for the grasp
        frames X_OG (F, 4, 4), in one array operation."""
        return self.X_JG @ inverse(X_OG)

    def _pairs(self, fingers_placed: frozenset[int], finger: int | None) -> list[int]:
        """The collision pairs :meth:`collides` checks (memoised)."""
        key = (fingers_placed, finger)
        if key not in self._pair_memo:
            if finger is None:
                self._pair_memo[key] = list(range(len(self.pair_fingers)))
            else:
                allowed = fingers_placed | {-1, finger, None}  # None: the object
                self._pair_memo[key] = [k for k in self.pairs_of[finger] if set(self.pair_fingers[k]) <= allowed]
        return self._pair_memo[key]

    def collides(self, q: np.ndarray, fingers_placed: set[int], finger: int | None) -> bool:
        """Collision of finger ``finger`` (or of the whole hand when None) with the object,
        the palm and the ``fingers_placed``."""
        pin.updateGeometryPlacements(self.robot.model, self.data, self.gm, self.gd, self.robot.to_pin(q))
        for k in self._pairs(frozenset(fingers_placed), finger):
            if pin.computeCollision(self.gm, self.gd, k):
                return True
        return False


def link_probes(geometry) -> tuple[np.ndarray, np.ndarray]:
    """Spheres inside a link geometry's local bounding box, centres (P, 3) in the
    geometry's frame and radii (P,): as wide as the box's thinnest side, a radius apart
    over its two longer sides (a cylinder's or capsule's core; a box's or mesh's, roughly)."""
    geometry.computeLocalAABB()
    lo, hi = np.asarray(geometry.aabb_local.min_), np.asarray(geometry.aabb_local.max_)
    half, centre = (hi - lo) / 2, (hi + lo) / 2
    thin = int(np.argmin(half))
    r = max(float(half[thin]), 1e-4)
    axes = [centre[d] + (np.zeros(1) if d == thin else
                         np.linspace(-max(half[d] - r, 0.0), max(half[d] - r, 0.0),
                                     int(np.ceil(2 * max(half[d] - r, 0.0) / r)) + 1)) for d in range(3)]
    p = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    return p, np.full(len(p), r)


def scored_grasp(hm: HandModel, surface: Surface, X_OG: np.ndarray, frame_index: int, q: np.ndarray,
                 in_contact: np.ndarray, points: np.ndarray, normals: np.ndarray, axes: np.ndarray, friction: float,
                 rho: float, options: GraspOptions, stats: dict) -> tuple[Grasp | None, dict]:
    """The grasp with these contacts (per finger, rows of ``in_contact`` used), scored
    (:mod:`.quality`), or None when it is not force closure (counted in ``stats``)."""
    c = in_contact
    kappa = surface.curvature[surface.tree.query(points[c])[1]]
    scores = grasp_quality(points[c], normals[c], friction, surface.mass_centre, axes[c], kappa, rho,
                           options.weights, contact=hm.hand.spec.contact, n_edges=options.cone_edges)
    if not scores.is_force_closure:
        stats["not_force_closure"] = 1
        return None, stats
    return Grasp(frame_index, X_OG.copy(), q[hm.hand.idx].copy(), in_contact, points, normals, scores), stats
