"""Single grasps of one hand for one grasp frame: Saut et al. 2010, §IV-A-2 and §IV-A-3.

For a grasp frame X_OG (hand grasp frame G in the object frame O) the grasp is built
finger by finger, the opposing finger (robot.yaml's ``opposing``, the thumb) first: no
stable grasp exists without it; then the others in robot.yaml order.  For finger i, its workspace spheres (biggest first, :mod:`.workspace`) are
intersected with the object's surface kd-tree; each surface point found is a contact
candidate if its outward normal faces the finger (towards the finger's first joint),
finger IK puts the fingertip-sphere centre at ``p + r_tip n`` (seeded from the nearest
workspace sample), and the finger is checked against the object (the fingertip may touch
it within ``contact_tolerance``), the palm and the fingers 1..i-1.  A finger without a
contact stays open.  With enough contacts (3 point contacts, 2 soft ones), the whole hand
is checked against the object and the grasp goes to the force-closure test and quality
score (:mod:`.quality`).

The hand is checked in isolation (no arm, no environment): collisions with the
environment and the rest of the robot are the business of the online stage (§IV-B).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from regrasp_cli.grasp.quality import GraspScores, QualityWeights, force_ellipsoid_axis, grasp_quality
from regrasp_cli.grasp.surface import Surface
from regrasp_cli.grasp.workspace import FingerWorkspace, SphereVoxels, sphere_voxels
from regrasp_cli.model.collision import cold_start, eroded_geometry, mesh_geometry
from regrasp_cli.model.robot import Kinematics, Robot
from regrasp_cli.spatial import inverse


@dataclass(frozen=True)
class GraspOptions:
    """Options of the single-grasp search (metres, radians)."""

    n_positions: int = 4  # grasp-frame positions in the object's bounding box
    n_orientations: int = 4096  # grasp-frame orientations (incremental SO(3) grid)
    target: int = 120  # stop once this many distinct grasps are found (0: try every frame)
    candidates_per_finger: int = 6  # contact candidates tried per finger before leaving it open
    contact_tolerance: float = 0.002  # fingertip-object penetration allowed, m
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


class HandModel:
    """The hand alone, with the object attached to its grasp frame: the scratch for the
    per-frame grasp search (one per process)."""

    def __init__(self, robot: Robot, hand: str, mesh, disabled_links: set[tuple[str, str]], tolerance: float):
        self.robot, self.hand = robot, robot.hands[hand]
        self.disabled_links = frozenset(disabled_links)  # link pairs never checked
        h = self.hand
        model = robot.model
        self.q = robot.q_rest.copy()
        self.q[h.idx] = h.open
        # geometries of the palm and fingers: those whose joint is in the hand's subtree
        hand_joints = {model.getJointId(robot.joint_names[i]) for i in h.idx}
        palm_joint = model.frames[h.grasp_frame].parentJoint
        self.finger_of_joint = {}
        for f, idx in enumerate(h.finger_idx):
            for i in idx:
                self.finger_of_joint[model.getJointId(robot.joint_names[i])] = f
        src = robot.collision_model
        gm = pin.GeometryModel()
        self.owner: list[int] = []  # finger index of each geometry, -1 for the palm
        self.erosion: list[float] = []  # m the fingertips are shrunk by (the contact tolerance)
        tips = {model.frames[t].name for t in h.tip_frames}
        links = []
        for go in src.geometryObjects:
            j = go.parentJoint
            if j == palm_joint or j in hand_joints:
                name = model.frames[go.parentFrame].name
                geom = eroded_geometry(go.geometry, tolerance) if name in tips else None
                self.erosion.append(tolerance if geom is not None else 0.0)
                gm.addGeometryObject(pin.GeometryObject(go.name, j, go.parentFrame, go.placement,
                                                        geom or go.geometry))
                self.owner.append(self.finger_of_joint.get(j, -1))
                links.append(name)
        # object attached to the grasp frame's joint: placement set per grasp frame
        f = model.frames[h.grasp_frame]
        self.X_JG = f.placement.homogeneous
        self.obj = gm.addGeometryObject(pin.GeometryObject("object", f.parentJoint, h.grasp_frame, pin.SE3.Identity(),
                                                           mesh_geometry(mesh)))
        n = len(self.owner)
        pairs_of = {f: [] for f in range(-1, len(h.finger_idx))}
        self.pair_fingers = []
        for a in range(n):
            gm.addCollisionPair(pin.CollisionPair(a, self.obj))
            self.pair_fingers.append((self.owner[a], None))
        for a in range(n):
            for b in range(a + 1, n):
                fa, fb = self.owner[a], self.owner[b]
                if fa == fb or tuple(sorted((links[a], links[b]))) in disabled_links:
                    continue
                gm.addCollisionPair(pin.CollisionPair(a, b))
                self.pair_fingers.append((fa, fb))
        self.gm, self.gd = gm, gm.createData()
        cold_start(self.gd)
        for k, (fa, fb) in enumerate(self.pair_fingers):
            for f_ in {fa, fb} - {None}:
                pairs_of[f_].append(k)
        self.pairs_of = pairs_of
        kin = Kinematics(robot)
        self.data = kin.data
        self.X_WG = kin.fk(self.q, h.grasp_frame)
        self._voxels: tuple[int, tuple[SphereVoxels, ...]] | None = None

    def voxels(self, workspaces: tuple[FingerWorkspace, ...]) -> tuple[SphereVoxels, ...]:
        """Voxel maps of the fingers' spheres grown by the tip radii (built on first use)."""
        if self._voxels is None or self._voxels[0] != id(workspaces):
            tips = [f.tip_radius for f in self.hand.spec.fingers]
            self._voxels = (id(workspaces), tuple(sphere_voxels(ws, r) for ws, r in zip(workspaces, tips)))
        return self._voxels[1]

    def set_object(self, X_OG: np.ndarray) -> None:
        """Place the object so that the grasp frame is at X_OG in the object frame."""
        X_JO = self.X_JG @ inverse(X_OG)
        self.gm.geometryObjects[self.obj].placement = pin.SE3(X_JO[:3, :3].copy(), X_JO[:3, 3].copy())

    def collides(self, q: np.ndarray, fingers_placed: set[int], finger: int | None) -> bool:
        """Collision of finger ``finger`` (or of the whole hand when None) with the object,
        the palm and the ``fingers_placed``."""
        pin.updateGeometryPlacements(self.robot.model, self.data, self.gm, self.gd, self.robot.to_pin(q))
        if finger is None:
            ks = range(len(self.pair_fingers))
        else:
            allowed = fingers_placed | {-1, finger, None}  # None: the object
            ks = [k for k in self.pairs_of[finger] if set(self.pair_fingers[k]) <= allowed]
        for k in ks:
            if pin.computeCollision(self.gm, self.gd, k):
                return True
        return False


def _finger_ik(robot: Robot, data, q: np.ndarray, idx: np.ndarray, tip: int, p_W: np.ndarray,
               iters: int, tol: float) -> bool:
    """Damped least squares on the fingertip position; edits q[idx] in place."""
    model = robot.model
    lo, hi = robot.lower[idx], robot.upper[idx]
    cols = robot._idx_q[idx]
    last = np.inf
    for _ in range(iters):
        qp = robot.to_pin(q)
        pin.forwardKinematics(model, data, qp)
        e = p_W - pin.updateFramePlacement(model, data, tip).translation
        err = e @ e
        if err < tol * tol:
            return True
        if err > 0.8 * last:  # stalled (typically against a joint limit): give up
            return False
        last = err
        J = pin.computeFrameJacobian(model, data, qp, tip, pin.LOCAL_WORLD_ALIGNED)[:3, cols]
        JJt = J @ J.T
        JJt[np.diag_indices(3)] += 1e-6
        q[idx] = np.clip(q[idx] + J.T @ np.linalg.solve(JJt, e), lo, hi)
    return False


def _candidates(ws: FingerWorkspace, vox: SphereVoxels, surface: Surface, p_G: np.ndarray, X_OG: np.ndarray,
                r_tip: float, anchor: tuple[np.ndarray, np.ndarray] | None,
                limit: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Contact candidates of one finger, best first: surface points (c, 3) and normals
    (c, 3) in O, and the index of the nearest workspace sample of each (c,).  ``p_G``
    (n, 3) holds every surface sample in the grasp frame.

    The candidates are the surface points inside the finger's workspace spheres (grown by
    the fingertip radius) whose outward normal faces the closing fingertip (cosine above
    0.2).  They are ranked by how squarely the fingertip pushes (its closing direction
    against the normal) and, for the fingers after the first (the thumb), by how well the
    contact lines up with the thumb's: Nguyen's condition for two contacts, the line
    joining them inside both friction cones.  The paper tries the spheres biggest first;
    ranking every point in the spheres instead gave 1.6x (statuette) and 1.4x (horse)
    more force-closure grasps per frame (docs/DESIGN-NOTES.md).
    """
    R, t = X_OG[:3, :3], X_OG[:3, 3]
    sphere = vox.lookup(p_G)
    cand = np.nonzero(sphere >= 0)[0]
    if cand.size == 0:
        return np.empty((0, 3)), np.empty((0, 3)), np.empty(0, np.intp)
    p, n = surface.points[cand], surface.normals[cand]
    near = ws.tree.query((p + r_tip * n - t) @ R)[1]  # tip centres in G
    facing = -np.einsum("ij,ij->i", n, ws.sample_closing[near] @ R.T)
    rank = facing
    if anchor is not None:
        # Nguyen's condition for two contacts: the line joining them lies inside both
        # friction cones, i.e. along both inward normals
        a_p, a_n = anchor
        u = a_p - p
        u /= np.maximum(np.linalg.norm(u, axis=1, keepdims=True), 1e-12)
        rank = facing + 4.0 * (-np.einsum("ij,ij->i", n, u) + u @ a_n)
    keep = facing > 0.2
    order = np.argsort(-rank[keep], kind="stable")[:limit]
    return p[keep][order], n[keep][order], near[keep][order]


@dataclass(frozen=True)
class ContactHint:
    """Contacts to try first (frame O): ``p1, n1`` for the opposing finger, ``p2, n2`` for
    finger ``finger`` (a pinch frame's antipodal pair, :mod:`.pinch`)."""

    finger: int
    p1: np.ndarray
    n1: np.ndarray
    p2: np.ndarray
    n2: np.ndarray


def _with_hint(p: np.ndarray, n: np.ndarray, near: np.ndarray, ws: FingerWorkspace, X_OG: np.ndarray,
               r_tip: float, hp: np.ndarray, hn: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The candidates with the hinted contact (hp, hn) first."""
    tip_G = (hp + r_tip * hn - X_OG[:3, 3]) @ X_OG[:3, :3]
    return np.vstack([hp, p]), np.vstack([hn, n]), np.concatenate([[ws.tree.query(tip_G)[1]], near])


def grasp_for_frame(hm: HandModel, workspaces: tuple[FingerWorkspace, ...], surface: Surface, X_OG: np.ndarray,
                    frame_index: int, friction: float, rho: float, options: GraspOptions,
                    hint: ContactHint | None = None) -> tuple[Grasp | None, dict]:
    """The grasp of one grasp frame, or None; plus counters for the summary.  With a
    ``hint``, its contacts are tried first for its two fingers."""
    robot, h = hm.robot, hm.hand
    stats = {"contacts": 0, "ik": 0, "collisions": 0, "palm": 0, "few_contacts": 0, "hand_collision": 0,
             "not_force_closure": 0}
    hm.set_object(X_OG)
    q = hm.q.copy()
    if hm.collides(q, set(), -1):  # the palm inside the object: no grasp from this frame
        stats["palm"] = 1
        return None, stats
    X_WG = hm.X_WG  # hand pose with the arm at rest (only the relative pose matters)
    X_WO = X_WG @ inverse(X_OG)
    X_GO = inverse(X_OG)
    p_G = surface.points @ X_GO[:3, :3].T + X_GO[:3, 3]
    voxels = hm.voxels(workspaces)
    n_f = len(h.finger_idx)
    in_contact = np.zeros(n_f, dtype=bool)
    points, normals = np.full((n_f, 3), np.nan), np.full((n_f, 3), np.nan)
    axes = np.zeros((n_f, 3))
    placed: set[int] = set()
    thumb = h.opposing
    for f in [thumb] + [f for f in range(n_f) if f != thumb]:
        ws, idx, tip = workspaces[f], h.finger_idx[f], h.tip_frames[f]
        r_tip = h.spec.fingers[f].tip_radius
        anchor = (points[thumb], normals[thumb]) if placed else None  # the thumb's contact
        p, n, near = _candidates(ws, voxels[f], surface, p_G, X_OG, r_tip, anchor,
                                 options.candidates_per_finger)
        if hint is not None and f in (thumb, hint.finger):
            hp, hn = (hint.p1, hint.n1) if f == thumb else (hint.p2, hint.n2)
            p, n, near = _with_hint(p, n, near, ws, X_OG, r_tip, hp, hn)
        stats["contacts"] += len(p)
        for k in range(len(p)):
            target_O = p[k] + r_tip * n[k]
            qf = q.copy()
            qf[idx] = ws.sample_q[near[k]]
            p_W = X_WO[:3, :3] @ target_O + X_WO[:3, 3]
            if not _finger_ik(robot, hm.data, qf, idx, tip, p_W, options.ik_iterations, options.ik_tolerance):
                continue
            stats["ik"] += 1
            if hm.collides(qf, placed, f):
                stats["collisions"] += 1
                continue
            q = qf
            placed.add(f)
            in_contact[f] = True
            points[f], normals[f] = p[k], n[k]
            pin.computeJointJacobians(robot.model, hm.data, robot.to_pin(q))
            J = pin.getFrameJacobian(robot.model, hm.data, tip, pin.LOCAL_WORLD_ALIGNED)[:3, robot._idx_q[idx]]
            axes[f] = X_OG[:3, :3] @ (X_WG[:3, :3].T @ force_ellipsoid_axis(J))
            break
        if f == thumb and not in_contact[thumb]:  # no stable grasp without the thumb (§IV-A-2)
            stats["few_contacts"] = 1
            return None, stats
    need = 2 if h.spec.contact == "soft" else 3
    if in_contact.sum() < need:
        stats["few_contacts"] = 1
        return None, stats
    if hm.collides(q, set(range(n_f)), None):
        stats["hand_collision"] = 1
        return None, stats
    return scored_grasp(hm, surface, X_OG, frame_index, q, in_contact, points, normals, axes, friction, rho,
                        options, stats)


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
