"""Grasps of hands whose fingers have one or two joints: approach, close until contact (issue 15).

Seed 000's fingertip IK (:mod:`.single`) puts a fingertip point on a chosen surface point;
a finger of one or two joints sweeps a curve or a surface, so it almost never can.  Such a
finger touches the object somewhere on its pad (any link of the finger), wherever it meets
it as it closes.  A grasp is therefore found as a hand is used (GraspIt's "auto-grasp"):

1. **Approach frames** (:func:`pad_frames`).  A surface sample p (outward normal n) gives
   an approach direction a = -n tilted by up to 20 degrees; the hand's grasp centre (the
   fingertips half closed, :class:`PadHand`) is put on the chord from p along a, at a
   random depth up to half the chord, the hand turned about a by a random angle.
2. **Closing until contact** (:func:`close_fingers`).  Each finger moves along the straight
   line in joint space from open to closed (robot.yaml's ``closed``, by default each
   joint at the limit farther from open), by conservative advancement: no point of the
   finger moves faster than ``reach`` metres per unit of the line's parameter (the sum
   over its joints of the joint's travel times the farthest finger point from the joint),
   so the distance to the object divided by ``reach`` is a step that cannot pass through
   it.  The distances are those of the finger links' convex hulls (a lower bound, far
   cheaper for scanned links) until a hull is within 0.1 mm; the finger touches if its
   links themselves are within 1 mm, else it goes on with their true distance.  One
   that closes fully without touching goes back to open.  An open hand that starts inside the object is first
   backed off along the approach, 1 cm at a time (up to 3 cm).
3. **Force closure and quality** (:mod:`.quality`) at the contacts found: the middle of
   the patch of surface under each finger's touching link (:func:`.jaw.contact_patch`),
   or the nearest surface point when that middle is off the link (a patch in pieces),
   with the hand's contact model (point or soft), at least 3 point or 2 soft contacts.
"""

from __future__ import annotations

from dataclasses import dataclass

import coal
import numpy as np
import pinocchio as pin
import trimesh

from regrasp_cli.grasp.jaw import ADVANCE_ITERATIONS, CONTACT_GAP, finger_pairs, contact_patch, outside_distance
from regrasp_cli.grasp.single import Grasp, GraspOptions, HandModel, scored_grasp
from regrasp_cli.grasp.surface import Surface
from regrasp_cli.model.robot import Kinematics, carries
from regrasp_cli.spatial import inverse

APPROACH_TILT = np.radians(20.0)  # rad: approach directions within this cone about -n
REACH_MARGIN = 1.1  # the reach bound is sampled along the closing line: a margin between samples
PAD_CONTACT = 1e-3  # m: a finger whose hull touches touches the object if its surface is this close


@dataclass(frozen=True, eq=False)
class PadHand:
    """What the approach-and-close search needs of a hand (frame G, metres, radians)."""

    closed: np.ndarray  # (n_hand_joints,) the hand closed, in the order of Hand.idx
    reach: np.ndarray  # (n_fingers,) m per unit of the closing parameter: the fastest finger point
    centre_G: np.ndarray  # (3,) the grasp centre: mean of the fingertips half closed
    approach_G: np.ndarray  # (3,) unit: from the palm towards the fingertips closed
    hulls: dict  # finger geometry index in the hand model -> its convex hull (a primitive: itself)


def _hull(geometry):
    """The convex hull of a coal mesh (a primitive is returned as it is): its distance to
    the object is a lower bound of the mesh's, 10-50x cheaper for a finger's scan."""
    if not isinstance(geometry, coal.BVHModelBase):
        return geometry
    hull = trimesh.convex.convex_hull(np.asarray(geometry.vertices()))
    return coal.Convex.convexHull(list(hull.vertices), False, None)


def closed_configuration(robot, hand) -> np.ndarray:
    """The hand's joints closed (n_hand_joints,): robot.yaml's ``closed`` per finger, or
    each joint at the limit farther from its open value."""
    out = []
    for f, idx in zip(hand.spec.fingers, hand.finger_idx):
        if f.closed is not None:
            out.extend(f.closed)
            continue
        lo, hi = robot.lower[idx], robot.upper[idx]
        o = np.array(f.open)
        out.extend(np.where(hi - o >= o - lo, hi, lo))
    return np.array(out, dtype=float)


def _at(hm: HandModel, s: np.ndarray, closed: np.ndarray) -> np.ndarray:
    """The hand model's q with finger f at the fraction s[f] (n_fingers,) of its closing line."""
    h = hm.hand
    q = hm.q.copy()
    start = 0
    for f, idx in enumerate(h.finger_idx):
        sl = slice(start, start + len(idx))
        q[idx] = h.open[sl] + s[f] * (closed[sl] - h.open[sl])
        start += len(idx)
    return hm.robot.coupled(q)


def _corners(geometry) -> np.ndarray:
    """The 8 corners (8, 3) of a coal geometry's local bounding box: its convex hull holds it."""
    geometry.computeLocalAABB()
    lo, hi = geometry.aabb_local.min_, geometry.aabb_local.max_
    return np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])


def pad_geometry(hm: HandModel, samples: int = 11) -> PadHand:
    """:class:`PadHand` of the hand model's hand."""
    robot, h = hm.robot, hm.hand
    model, data = robot.model, hm.data
    closed = closed_configuration(robot, h)
    n_f = len(h.finger_idx)
    travel = np.abs(closed - h.open)
    joint_ids = [[model.getJointId(robot.joint_names[i]) for i in idx] for idx in h.finger_idx]
    corners = {a: _corners(hm.gm.geometryObjects[a].geometry) for a, o in enumerate(hm.owner) if o >= 0}
    reach = np.zeros(n_f)
    for s in np.linspace(0.0, 1.0, samples):
        q = _at(hm, np.full(n_f, s), closed)
        pin.forwardKinematics(model, data, robot.to_pin(q))
        pin.updateGeometryPlacements(model, data, hm.gm, hm.gd)
        start = 0
        for f in range(n_f):
            speed = 0.0
            for k, (i, j) in enumerate(zip(h.finger_idx[f], joint_ids[f])):
                if robot.prismatic[i]:
                    arm = 1.0
                else:  # every finger point carried by joint j: farthest from its origin
                    carried = [a for a in corners if carries(model, j, hm.gm.geometryObjects[a].parentJoint)]
                    o = data.oMi[j].translation
                    arm = max((np.linalg.norm(corners[a] @ hm.gd.oMg[a].rotation.T + hm.gd.oMg[a].translation - o,
                                              axis=1).max() for a in carried), default=0.0)
                speed += travel[start + k] * arm
            reach[f] = max(reach[f], speed)
            start += len(h.finger_idx[f])
    X_GW = inverse(hm.X_WG)
    kin = Kinematics(robot)

    def tips_G(s: float) -> np.ndarray:
        tips = np.array([X[:3, 3] for X in kin.fk_many(_at(hm, np.full(n_f, s), closed), h.tip_frames)])
        return tips.mean(axis=0) @ X_GW[:3, :3].T + X_GW[:3, 3]

    pin.updateGeometryPlacements(model, data, hm.gm, hm.gd, robot.to_pin(hm.q))
    palm = [a for a, o in enumerate(hm.owner) if o == -1]
    palm_W = (np.mean([corners_W(hm, a).mean(axis=0) for a in palm], axis=0) if palm
              else hm.X_WG[:3, 3])
    # closed fingertips curl in front of the palm: the side the hand grasps with
    a = tips_G(1.0) - (X_GW[:3, :3] @ palm_W + X_GW[:3, 3])
    if np.linalg.norm(a) < 1e-9:
        a = np.array([0.0, 0.0, 1.0])
    hulls = {k: _hull(hm.gm.geometryObjects[k].geometry) for k in corners}
    return PadHand(closed, REACH_MARGIN * reach, tips_G(0.5), a / np.linalg.norm(a), hulls)


def corners_W(hm: HandModel, a: int) -> np.ndarray:
    """Bounding-box corners (8, 3) of geometry a of the hand model, in W (placements current)."""
    X = hm.gd.oMg[a]
    return _corners(hm.gm.geometryObjects[a].geometry) @ X.rotation.T + X.translation


def pad_frames(pads: PadHand, mesh: trimesh.Trimesh, surface: Surface, n: int,
               rng: np.random.Generator) -> np.ndarray:
    """Approach frames X_OG (n, 4, 4), see the module docstring."""
    i = rng.choice(len(surface.points), size=n, replace=n > len(surface.points))
    p, nrm = surface.points[i], surface.normals[i]
    a = -nrm + np.tan(rng.uniform(0, APPROACH_TILT, n))[:, None] * _perpendicular(nrm, rng)
    a /= np.linalg.norm(a, axis=1, keepdims=True)
    loc, ray, _ = mesh.ray.intersects_location(p + 1e-5 * a, a, multiple_hits=False)
    chord = np.full(n, 0.02)  # an open scan may have no far side: a shallow grasp
    chord[ray] = np.linalg.norm(loc - p[ray], axis=1)
    centre = p + (rng.uniform(0, 0.5, n) * chord)[:, None] * a
    # rotation taking approach_G onto a, then a random turn about a
    R = np.array([_align(pads.approach_G, ak) for ak in a])
    th = rng.uniform(0, 2 * np.pi, n)
    R = np.array([_about(ak, t) @ Rk for ak, t, Rk in zip(a, th, R)])
    X = np.tile(np.eye(4), (n, 1, 1))
    X[:, :3, :3] = R
    X[:, :3, 3] = centre - R @ pads.centre_G
    return X


def _perpendicular(n: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Random unit vectors (k, 3) perpendicular to the rows of n (k, 3)."""
    v = rng.normal(size=n.shape)
    v -= np.einsum("ij,ij->i", v, n)[:, None] * n
    return v / np.maximum(np.linalg.norm(v, axis=1, keepdims=True), 1e-12)


def _align(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """A rotation (3, 3) taking the unit vector u onto the unit vector v."""
    w, c = np.cross(u, v), float(u @ v)
    if c < -1 + 1e-9:  # opposite: a half turn about any perpendicular axis
        p = np.cross(u, [1.0, 0, 0]) if abs(u[0]) < 0.9 else np.cross(u, [0, 1.0, 0])
        return _about(p / np.linalg.norm(p), np.pi)
    K = np.array([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]])
    return np.eye(3) + K + K @ K / (1 + c)


def _about(axis: np.ndarray, angle: float) -> np.ndarray:
    return pin.AngleAxis(angle, axis).matrix()


def _finger_gap(hm: HandModel, f: int) -> tuple[float, int]:
    """Distance (m) from finger f's true surface to the object at the current placements,
    and the collision pair that gives it."""
    best, k_best = np.inf, -1
    for k in finger_pairs(hm, f):
        d = pin.computeDistance(hm.gm, hm.gd, k).min_distance - hm.erosion[hm.gm.collisionPairs[k].first]
        if d < best:
            best, k_best = d, k
    return best, k_best


def _hull_gap(hm: HandModel, pads: PadHand, f: int) -> float:
    """A lower bound (m) of finger f's distance to the object: its hulls' distance."""
    X_obj = hm.gd.oMg[hm.obj]
    best = np.inf
    for a, o in enumerate(hm.owner):
        if o == f:
            best = min(best, _distance_to(pads.hulls[a], hm.gd.oMg[a], hm.gm.geometryObjects[hm.obj].geometry, X_obj)
                       - hm.erosion[a])
    return best


def _distance_to(ga, Xa: pin.SE3, gb, Xb: pin.SE3) -> float:
    return float(coal.distance(ga, coal.Transform3s(Xa.rotation, Xa.translation), gb,
                               coal.Transform3s(Xb.rotation, Xb.translation), coal.DistanceRequest(),
                               coal.DistanceResult()))


def _retreat(hm: HandModel, X_OG: np.ndarray, back_O: np.ndarray) -> np.ndarray | None:
    """X_OG moved back along ``back_O`` (3,) by 1 cm steps, up to 3, until the open hand
    is clear of the object; None if it never is."""
    n_f = len(hm.hand.finger_idx)
    for step in range(4):
        X = X_OG.copy()
        X[:3, 3] += 0.01 * step * back_O
        hm.set_object(X)
        if not hm.collides(hm.q, set(range(n_f)), None):
            return X
    return None


def close_fingers(hm: HandModel, pads: PadHand, X_OG: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """The open hand backed off the object along its approach until clear, then each
    finger closed until it touches the object: the grasp frame, the hand's q (nq,) and
    which fingers touch (n_fingers,) bool; None when the open hand stays in collision."""
    robot, h = hm.robot, hm.hand
    n_f = len(h.finger_idx)
    X_OG = _retreat(hm, X_OG, -(X_OG[:3, :3] @ pads.approach_G))
    if X_OG is None:
        return None
    s, touching = np.zeros(n_f), np.zeros(n_f, dtype=bool)
    for f in range(n_f):
        exact = False  # the hulls' distance until they touch, then the true surfaces'
        for _ in range(ADVANCE_ITERATIONS):
            q = _at(hm, s, pads.closed)
            pin.updateGeometryPlacements(robot.model, hm.data, hm.gm, hm.gd, robot.to_pin(q))
            gap = _finger_gap(hm, f)[0] if exact else _hull_gap(hm, pads, f)
            if gap < CONTACT_GAP and not exact:  # the hull touches: does the finger?
                exact = True
                gap = _finger_gap(hm, f)[0]
            if gap < (PAD_CONTACT if exact else CONTACT_GAP):
                touching[f] = True
                break
            s[f] += gap / max(pads.reach[f], 1e-9)
            if s[f] > 1.0:
                break
        if not touching[f]:
            s[f] = 0.0  # missed: back to open
    return X_OG, _at(hm, s, pads.closed), touching


def pad_grasp(hm: HandModel, pads: PadHand, surface: Surface, X_OG: np.ndarray, frame_index: int,
              friction: float, rho: float, options: GraspOptions) -> tuple[Grasp | None, dict]:
    """The grasp of one approach frame, or None; plus counters for the summary."""
    robot, h = hm.robot, hm.hand
    stats = {"palm": 0, "few_contacts": 0, "hand_collision": 0, "not_force_closure": 0}
    closed = close_fingers(hm, pads, X_OG)
    if closed is None:
        stats["palm"] = 1
        return None, stats
    X_OG, q, touching = closed
    need = 2 if h.spec.contact == "soft" else 3
    if touching.sum() < need:
        stats["few_contacts"] = 1
        return None, stats
    n_f = len(h.finger_idx)
    if hm.collides(q, set(range(n_f)), None):  # fingers against each other or the palm
        stats["hand_collision"] = 1
        return None, stats
    X_OW = X_OG @ inverse(hm.X_WG)
    pin.updateGeometryPlacements(robot.model, hm.data, hm.gm, hm.gd, robot.to_pin(q))
    points, normals = np.full((n_f, 3), np.nan), np.full((n_f, 3), np.nan)
    axes = np.zeros((n_f, 3))
    for f in np.flatnonzero(touching):
        k = _finger_gap(hm, f)[1]
        w = X_OW[:3, :3] @ pin.computeDistance(hm.gm, hm.gd, k).getNearestPoint2() + X_OW[:3, 3]
        near = surface.under(w)
        # the patch under the touching link alone (two links of a finger may touch apart)
        a = hm.gm.collisionPairs[k].first
        pad = [(X_OW @ hm.gd.oMg[a].homogeneous, hm.gm.geometryObjects[a].geometry, hm.erosion[a])]
        p, n = contact_patch(surface, w, -surface.normals[near], pad)
        X, geometry, grow = pad[0]
        if outside_distance(geometry, grow, ((p - X[:3, 3]) @ X[:3, :3])[None])[0] > PAD_CONTACT:
            p, n = w, surface.normals[near]  # a patch in pieces (a link around an edge): its middle is off the link
        points[f], normals[f], axes[f] = p, n, -n
    return scored_grasp(hm, surface, X_OG, frame_index, q, touching, points, normals, axes, friction, rho, options,
                        stats)
