"""Grasps of parallel-jaw grippers: antipodal pairs, closing until contact (issue 15).

Fingertip IK on a surface point (seed 000's method, :mod:`.single`) cannot serve a jaw:
a finger that slides on one prismatic joint moves along a line, so its pad almost never
passes through a given point.  A jaw grasp is found the other way round:

1. **Antipodal pairs** (:func:`antipodal_pairs`).  A surface sample p1 (outward normal n1)
   casts a ray into the object along -n1 tilted by up to half the friction angle; the
   ray leaves the object at p2 (normal n2).  The pair is kept when the line p1-p2 lies
   inside both friction cones (Nguyen's condition for two contacts) and its length fits
   between the pads, open and closed.
2. **Grasp frames** (:func:`jaw_frames`).  The jaw's closing axis is laid along p1-p2, the
   pads' midpoint on the pair's midpoint (shifted by a random depth along the pads), the
   hand turned about the axis by a random angle: every side the hand may come from.
3. **Closing until contact** (:func:`close_jaw`).  Each pad slides along its axis by
   conservative advancement: the coal distance to the object is a step it can take
   without touching it, repeated until the gap is below 0.1 mm.  Fingers coupled by a URDF
   mimic joint close together, so the hand is first shifted along the axis until both
   gaps are equal (the gripper centres the object); independent fingers close each on
   its own.  A pad that reaches its joint limit without contact, or a hand that collides
   once closed (the fingertips may touch the object within the contact tolerance),
   gives no grasp.
4. **Soft-finger force closure and quality** (:mod:`.quality`, ``contact="soft"``) at the
   contacts found: each a patch of the object's surface under the closed pad
   (:func:`contact_patch`).
"""

from __future__ import annotations

from dataclasses import dataclass

import coal
import numpy as np
import pinocchio as pin
import trimesh

from regrasp_cli.grasp.quality import grasp_quality
from regrasp_cli.grasp.single import Grasp, GraspOptions, HandModel
from regrasp_cli.grasp.surface import Surface
from regrasp_cli.model.robot import Kinematics
from regrasp_cli.spatial import inverse

CONTACT_GAP = 1e-4  # m: a pad this close to the object touches it
ADVANCE_ITERATIONS = 60
NEAR_BOX = 0.005  # m: points this close to a mesh's bounding box get their exact distance


@dataclass(frozen=True)
class Jaw:
    """Geometry of a two-finger jaw in its grasp frame G, open (metres)."""

    axis_G: np.ndarray  # (3,) unit: the closing direction of finger 0 (towards finger 1)
    centre_G: np.ndarray  # (3,) midpoint of the two pads
    depth_G: np.ndarray  # (3,) unit, perpendicular to the axis: along the pads, palm to tips
    depth: float  # m: half the pads' length along depth_G (the range of depth offsets)
    width_open: float  # m: gap between the pads, open
    width_closed: float  # m: gap between the pads, closed (0 when they meet)
    sign: np.ndarray  # (2,) +1 or -1: the sign of each finger's joint motion when closing
    closing_G: np.ndarray  # (2, 3) unit: the direction each pad moves when closing
    travel: np.ndarray  # (2,) m or rad: each finger's driving joint range from open to closed
    coupled: bool  # both fingers close by one joint (the other follows it through URDF mimics)
    drivers: tuple[int, int] = (-1, -1)  # index in q of the joint that closes each finger
    speed: np.ndarray | None = None  # (2,) m per unit of the driver: a bound of each pad's speed
    revolute: bool = False  # a driver turns: pads move on arcs (:func:`close_revolute`)


def finger_pairs(hm: HandModel, f: int) -> list[int]:
    """Collision pairs (finger f's geometries, object) of a :class:`HandModel`."""
    return [k for k, (fa, fb) in enumerate(hm.pair_fingers) if fa == f and fb is None]


def drivers(robot, hand) -> np.ndarray:
    """Index in q (2,) of the joint that closes each finger of a two-finger hand: the
    finger's first joint, or the joint it follows through URDF mimics (the same for both
    fingers of a coupled jaw)."""
    return np.array([robot.driver(int(i[0])) for i in hand.finger_idx])


def _closed(robot, hand, q_open: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The hand closed (each finger's driver at the limit farther from open): q, signs, ranges."""
    idx = drivers(robot, hand)
    lo, hi = robot.lower[idx], robot.upper[idx]
    o = q_open[idx]
    sign = np.where(hi - o >= o - lo, 1.0, -1.0)
    q = q_open.copy()
    q[idx] = np.where(sign > 0, hi, lo)
    return robot.coupled(q), sign, np.abs(q[idx] - o)


def _pad_gap(hm: HandModel, q: np.ndarray, tips_only: bool = False) -> float:
    """Distance (m) between finger 0 and finger 1 at q, over the pairs the hand model
    checks (not those disabled, such as sliding blocks that always touch); with
    ``tips_only``, between their fingertip geometries (a turning finger's proximal links
    pass near each other at the palm whatever the opening)."""
    robot, tips = hm.robot, set(hm.hand.tip_frames)
    pin.updateGeometryPlacements(robot.model, hm.data, hm.gm, hm.gd, robot.to_pin(q))
    tip = [go.parentFrame in tips for go in hm.gm.geometryObjects]
    gaps = [pin.computeDistance(hm.gm, hm.gd, k).min_distance - hm.erosion[cp.first] - hm.erosion[cp.second]
            for k, cp in enumerate(hm.gm.collisionPairs) if set(hm.pair_fingers[k]) == {0, 1}
            and (not tips_only or (tip[cp.first] and tip[cp.second]))]
    return max(min(gaps, default=np.inf), 0.0)


def _distance(hm: HandModel, a: int, Xa: pin.SE3, b: int, Xb: pin.SE3) -> float:
    """coal distance (m) between geometries a and b of the hand model at Xa, Xb (in W)."""
    req, res = coal.DistanceRequest(), coal.DistanceResult()
    ga, gb = hm.gm.geometryObjects[a].geometry, hm.gm.geometryObjects[b].geometry
    return float(coal.distance(ga, coal.Transform3s(Xa.rotation, Xa.translation),
                               gb, coal.Transform3s(Xb.rotation, Xb.translation), req, res))


def jaw_geometry(hm: HandModel) -> Jaw:
    """:class:`Jaw` of the hand model's hand (two fingers each closed by one joint)."""
    robot, hand = hm.robot, hm.hand
    model = robot.model
    q_open = hm.q
    q_closed, sign, travel = _closed(robot, hand, q_open)
    X_GW = inverse(hm.X_WG)
    idx = [int(i[0]) for i in hand.finger_idx]
    # finger 0's tip moves along its axis when it closes
    kin = Kinematics(robot)
    tips = [[X[:3, 3] for X in kin.fk_many(q, hand.tip_frames)] for q in (q_open, q_closed)]
    closing_G = np.array([X_GW[:3, :3] @ (tips[1][f] - tips[0][f]) for f in (0, 1)])
    closing_G /= np.maximum(np.linalg.norm(closing_G, axis=1, keepdims=True), 1e-12)
    axis_G = closing_G[0]
    # the pads, open: their centres and extents in G
    pin.updateGeometryPlacements(model, hm.data, hm.gm, hm.gd, robot.to_pin(q_open))
    corners, centres = [], []
    for f in (0, 1):
        pts = []
        mine = [a for a, o in enumerate(hm.owner) if o == f]
        # the pads: the tip links' geometries (every geometry of the finger if none)
        pads = [a for a in mine if hm.gm.geometryObjects[a].parentFrame in hand.tip_frames] or mine
        for a in pads:
            g = hm.gm.geometryObjects[a].geometry
            g.computeLocalAABB()
            lo, hi = g.aabb_local.min_, g.aabb_local.max_
            box = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
            X = hm.gd.oMg[a]
            pts.append((box @ X.rotation.T + X.translation) @ X_GW[:3, :3].T + X_GW[:3, 3])
        pts = np.concatenate(pts)
        corners.append(pts)
        centres.append(pts.mean(axis=0))
    centre_G = (centres[0] + centres[1]) / 2
    drive = drivers(robot, hand)
    revolute = not robot.prismatic[drive].all()
    if revolute:  # the pads move on arcs: the axis is the line between them, open
        axis_G = (centres[1] - centres[0]) / max(float(np.linalg.norm(centres[1] - centres[0])), 1e-12)
    palm = [a for a, o in enumerate(hm.owner) if o == -1]
    palm_G = (np.mean([hm.gd.oMg[a].translation for a in palm], axis=0) @ X_GW[:3, :3].T + X_GW[:3, 3]
              if palm else np.zeros(3))
    d = centre_G - palm_G
    d -= (d @ axis_G) * axis_G
    if np.linalg.norm(d) < 1e-9:  # no palm, or the pads around it: any perpendicular
        d = np.cross(axis_G, [1.0, 0, 0]) if abs(axis_G[0]) < 0.9 else np.cross(axis_G, [0, 1.0, 0])
    depth_G = d / np.linalg.norm(d)
    ext = [np.ptp(c @ depth_G) for c in corners]
    # a turning finger's proximal links curl in behind its pad: contacts reach out to the tip
    return Jaw(axis_G, centre_G, depth_G, (0.5 if revolute else 0.25) * min(ext), _pad_gap(hm, q_open, revolute),
               _pad_gap(hm, q_closed, revolute), sign, closing_G, travel, bool(drive[0] == drive[1]),
               (int(drive[0]), int(drive[1])),
               np.array([_pad_speed(hm, f, int(drive[f])) for f in (0, 1)]), bool(revolute))


def _pad_speed(hm: HandModel, f: int, driver: int) -> float:
    """A bound (m per unit of the driver) of how fast any point of finger f's geometries
    moves when the driver moves: over the joints between the palm and each geometry, the
    driver's and its followers' rates (1, or the mimic multiplier) times the joint's reach
    (:func:`motion.local.joint_reach`; 1 for a prismatic joint)."""
    from regrasp_cli.motion.local import joint_reach

    robot, model = hm.robot, hm.robot.model
    reach = joint_reach(robot)
    rate = {driver: 1.0} | {k: abs(m) for k, (lead, m, _) in robot.mimic.items() if lead == driver}
    best = 0.0
    for a, o in enumerate(hm.owner):
        if o != f:
            continue
        v, j = 0.0, hm.gm.geometryObjects[a].parentJoint
        while j > 0:
            i = j - 1  # the joint's index in q (every joint has one degree of freedom)
            v += rate.get(i, 0.0) * reach[i]
            j = model.parents[j]
        best = max(best, v)
    return best


def antipodal_pairs(mesh: trimesh.Trimesh, surface: Surface, friction: float, width: tuple[float, float],
                    n: int, rng: np.random.Generator,
                    among: np.ndarray | None = None,
                    level: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Up to ``n`` samples' antipodal pairs: points p1, p2 (k, 3) and outward normals n1,
    n2 (k, 3) in O with p2 - p1 inside both friction cones and |p2 - p1| in ``width``;
    p1 drawn among the surface samples of index ``among`` (default: all).  The ray from
    p1 goes along -n1, or with ``level`` (a unit vector in O, the support's normal) along
    -n1 levelled (its component along ``level`` removed: the pinch across a flat object
    lying on its support), tilted at random by up to half the friction angle."""
    among = np.arange(len(surface.points)) if among is None else among
    if not len(among):
        return (np.empty((0, 3)),) * 4
    i = among[rng.choice(len(among), size=n, replace=n > len(among))]  # tilts differ
    p1, n1 = surface.points[i], surface.normals[i]
    a = n1 if level is None else n1 - np.outer(n1 @ level, level)
    ok = np.linalg.norm(a, axis=1) > 0.1  # a level ray from a face parallel to the support: none
    i, p1, n1, a = i[ok], p1[ok], n1[ok], a[ok] / np.linalg.norm(a[ok], axis=1, keepdims=True)
    # directions into the object: -a tilted by up to half the friction angle
    half = 0.5 * np.arctan(friction)
    e1 = np.cross(a, [1.0, 0.0, 0.0])
    e1[np.linalg.norm(e1, axis=1) < 1e-6] = np.cross(a[np.linalg.norm(e1, axis=1) < 1e-6], [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    e2 = np.cross(a, e1)
    phi, tilt = rng.uniform(0, 2 * np.pi, len(i)), np.tan(rng.uniform(0, half, len(i)))
    d = -a + tilt[:, None] * (np.cos(phi)[:, None] * e1 + np.sin(phi)[:, None] * e2)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    loc, ray, tri = mesh.ray.intersects_location(p1 + 1e-5 * d, d, multiple_hits=False)
    p2 = np.full_like(p1, np.nan)
    t2 = np.full(len(p1), -1)
    p2[ray], t2[ray] = loc, tri
    hit = t2 >= 0
    p1, n1, p2, t2 = p1[hit], n1[hit], p2[hit], t2[hit]
    n2 = mesh.face_normals[t2]
    # a non-watertight scan may be inside out: orient n2 like the nearest sample's normal
    near = surface.tree.query(p2)[1]
    n2 = np.where((np.einsum("ij,ij->i", n2, surface.normals[near]) < 0)[:, None], -n2, n2)
    u = p2 - p1
    w = np.linalg.norm(u, axis=1)
    u = u / np.maximum(w, 1e-12)[:, None]
    cos = np.cos(np.arctan(friction))
    ok = (-np.einsum("ij,ij->i", u, n1) >= cos) & (np.einsum("ij,ij->i", u, n2) >= cos)
    ok &= (w > width[0]) & (w < width[1])
    return p1[ok], n1[ok], p2[ok], n2[ok]


def jaw_frames(jaw: Jaw, p1: np.ndarray, p2: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Grasp frames X_OG (k, 4, 4): the jaw's axis along p1 -> p2 (or reversed, at
    random), its pads' midpoint on the pair's midpoint shifted by a random depth, the hand
    turned about the axis by a random angle."""
    k = len(p1)
    u = p2 - p1
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    u *= rng.choice([-1.0, 1.0], size=k)[:, None]
    ref = np.where((np.abs(u[:, 0]) < 0.9)[:, None], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    e1 = np.cross(u, ref)
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    e2 = np.cross(u, e1)
    th = rng.uniform(0, 2 * np.pi, k)
    v = np.cos(th)[:, None] * e1 + np.sin(th)[:, None] * e2  # depth direction in O
    a, b = jaw.axis_G, jaw.depth_G
    B_G = np.stack([a, b, np.cross(a, b)], axis=1)  # (3, 3) columns
    B_O = np.stack([u, v, np.cross(u, v)], axis=2)  # (k, 3, 3)
    X = np.tile(np.eye(4), (k, 1, 1))
    X[:, :3, :3] = B_O @ B_G.T
    offset = jaw.centre_G + rng.uniform(-jaw.depth, jaw.depth, k)[:, None] * b
    X[:, :3, 3] = (p1 + p2) / 2 - np.einsum("kij,kj->ki", X[:, :3, :3], offset)
    return X


def _slide(hm: HandModel, f: int, direction_W: np.ndarray, travel: float) -> float | None:
    """Distance (m) finger f's pad slides along ``direction_W`` (3,) from where it is (the
    hand model's current placements) before it touches the object, or None when that
    is more than ``travel``: conservative advancement (the gap is a safe step)."""
    pads = [a for a, o in enumerate(hm.owner) if o == f]
    X_obj = hm.gd.oMg[hm.obj]
    t = 0.0
    for _ in range(ADVANCE_ITERATIONS):
        gap = min(_distance(hm, a, pin.SE3(hm.gd.oMg[a].rotation, hm.gd.oMg[a].translation + t * direction_W),
                            hm.obj, X_obj) - hm.erosion[a] for a in pads)  # the true pad, not its eroded copy
        if gap < CONTACT_GAP:
            return t
        t += gap
        if t > travel:
            return None
    return None


def close_jaw(hm: HandModel, jaw: Jaw, X_OG: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """The grasp frame (shifted to centre a coupled jaw) and the closed hand q (nq,), or
    None when the open hand collides or a pad misses the object within its travel."""
    robot, hand = hm.robot, hm.hand
    idx = [int(i[0]) for i in hand.finger_idx]
    hm.set_object(X_OG)
    q = hm.q.copy()
    if hm.collides(q, {0, 1}, None):  # open hand (palm, pads) inside the object
        return None
    if jaw.revolute:
        return close_revolute(hm, jaw, X_OG, q)
    R_WG = hm.X_WG[:3, :3]
    gaps = []
    for f in (0, 1):  # each pad alone: a prismatic finger translates its pad
        room = float(jaw.travel.sum()) if jaw.coupled else float(jaw.travel[f])  # coupled: centred below
        g = _slide(hm, f, R_WG @ jaw.closing_G[f], room)
        if g is None:
            return None
        gaps.append(g)
    if jaw.coupled:  # one motion closes both: centre the hand between the two gaps
        shift = (gaps[0] - gaps[1]) / 2  # along finger 0's closing direction
        X_OG = X_OG.copy()
        X_OG[:3, 3] += X_OG[:3, :3] @ (shift * jaw.closing_G[0])
        gaps = [(gaps[0] + gaps[1]) / 2] * 2
    if any(g > t for g, t in zip(gaps, jaw.travel)):
        return None
    for f in (0, 1):
        q[idx[f]] += jaw.sign[f] * gaps[f]
    return X_OG, robot.coupled(q)


def _gaps(hm: HandModel, q: np.ndarray) -> list[float]:
    """Distance (m) from each finger's true pads (not their eroded copies) to the object,
    the hand at q (one placement update for both) and the object where
    :meth:`HandModel.set_object` put it."""
    robot = hm.robot
    pin.updateGeometryPlacements(robot.model, hm.data, hm.gm, hm.gd, robot.to_pin(q))
    X_obj = hm.gd.oMg[hm.obj]
    return [min(_distance(hm, a, hm.gd.oMg[a], hm.obj, X_obj) - hm.erosion[a]
                for a, o in enumerate(hm.owner) if o == f) for f in (0, 1)]


def _gap(hm: HandModel, f: int, q: np.ndarray) -> float:
    """:func:`_gaps` of finger f."""
    return _gaps(hm, q)[f]


def _pad_centre_G(hm: HandModel, f: int) -> np.ndarray:
    """Mean position (3,) in G of finger f's geometries, at the placements last computed."""
    X_GW = inverse(hm.X_WG)
    c = np.mean([hm.gd.oMg[a].translation for a, o in enumerate(hm.owner) if o == f], axis=0)
    return X_GW[:3, :3] @ c + X_GW[:3, 3]


def close_revolute(hm: HandModel, jaw: Jaw, X_OG: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """:func:`close_jaw` for fingers that turn (or follow a joint that does): each driver
    advances by conservative steps, the pad's gap over its speed bound (a step that cannot
    make it touch), until the pad is within ``CONTACT_GAP``.  A coupled jaw closes by one
    driver: before each step the hand is shifted along the line between its pads by half
    the difference of their gaps, so that both touch together (a gripper centres what it
    holds).  None when a driver reaches its limit without contact."""
    robot, X_OG = hm.robot, X_OG.copy()
    far = [q[d] + jaw.sign[f] * jaw.travel[f] for f, d in enumerate(jaw.drivers)]
    active = [0] if jaw.coupled else [0, 1]
    done = set()
    for _ in range(ADVANCE_ITERATIONS):
        gaps = _gaps(hm, q)
        if jaw.coupled:
            if max(gaps) < CONTACT_GAP:
                return X_OG, robot.coupled(q)
            c0, c1 = _pad_centre_G(hm, 0), _pad_centre_G(hm, 1)
            u = (c1 - c0) / max(float(np.linalg.norm(c1 - c0)), 1e-12)
            X_OG[:3, 3] += X_OG[:3, :3] @ (u * (gaps[0] - gaps[1]) / 2)  # the farther pad comes as near as the other
            hm.set_object(X_OG)
            gaps = _gaps(hm, q)
            step = min(gaps) / max(float(jaw.speed.max()), 1e-9)
        for f in active:
            if f in done:
                continue
            d = jaw.drivers[f]
            if not jaw.coupled:
                if gaps[f] < CONTACT_GAP:
                    done.add(f)
                    continue
                step = gaps[f] / max(float(jaw.speed[f]), 1e-9)
            q[d] += jaw.sign[f] * step
            if jaw.sign[f] * (q[d] - far[f]) > 1e-12:
                return None
            q = robot.coupled(q)
        if not jaw.coupled and len(done) == 2:
            return X_OG, robot.coupled(q)
    return None


def outside_distance(geometry, grow: float, local: np.ndarray) -> np.ndarray:
    """Distance (k,) from points ``local`` (k, 3), in a geometry's own frame, to the
    geometry grown by ``grow`` (0 inside): exact for boxes, cylinders, spheres and
    capsules; for any other shape the distance to its surface (by coal) where the local
    bounding box is within ``NEAR_BOX``, the bounding box's beyond."""
    if isinstance(geometry, coal.Sphere):
        return np.maximum(np.linalg.norm(local, axis=1) - geometry.radius - grow, 0.0)
    if isinstance(geometry, coal.Cylinder):
        radial = np.maximum(np.hypot(local[:, 0], local[:, 1]) - geometry.radius - grow, 0.0)
        return np.hypot(radial, np.maximum(np.abs(local[:, 2]) - geometry.halfLength - grow, 0.0))
    if isinstance(geometry, coal.Capsule):
        z = np.clip(local[:, 2], -geometry.halfLength, geometry.halfLength)
        return np.maximum(np.linalg.norm(local - np.c_[0 * z, 0 * z, z], axis=1) - geometry.radius - grow, 0.0)
    if isinstance(geometry, coal.Box):
        half = np.asarray(geometry.halfSide) + grow
        return np.linalg.norm(np.maximum(np.abs(local) - half, 0.0), axis=1)
    geometry.computeLocalAABB()
    lo, hi = np.asarray(geometry.aabb_local.min_) - grow, np.asarray(geometry.aabb_local.max_) + grow
    d = np.linalg.norm(np.maximum(np.abs(local - (lo + hi) / 2) - (hi - lo) / 2, 0.0), axis=1)
    # a mesh: coal's distance to its surface, for the points its bounding box cannot rule out
    point, I = coal.Sphere(1e-9), coal.Transform3s()
    for k in np.flatnonzero(d < NEAR_BOX):
        r = coal.DistanceResult()
        coal.distance(geometry, I, point, coal.Transform3s(np.eye(3), local[k]), coal.DistanceRequest(), r)
        d[k] = max(r.min_distance - grow, 0.0)
    return d


def contact_patch(surface: Surface, w: np.ndarray, closing: np.ndarray, pads: list[tuple[np.ndarray, object, float]],
                  thickness: float = 1e-3) -> tuple[np.ndarray, np.ndarray]:
    """Where a closed pad touches the object, in O: the mean point and mean outward normal
    of the surface samples within ``thickness`` of one of its geometries (``pads``: pose
    X_OP (4, 4), coal geometry and how much to grow it, per geometry) whose normals face
    the pad's motion ``closing`` (3,).  A flat face under a flat pad gives its normal and
    the middle of the overlap, not the edge coal's witness point ``w`` (3,) may sit on;
    with no such sample, the sample nearest to w."""
    near = np.asarray(surface.tree.query_ball_point(w, 0.05), dtype=int)
    inside = np.zeros(near.size, dtype=bool)
    if near.size:
        P = surface.points[near]
        for X, geometry, grow in pads:
            inside |= outside_distance(geometry, grow, (P - X[:3, 3]) @ X[:3, :3]) <= thickness
        inside &= surface.normals[near] @ closing < -0.5  # outward normals against the pad's motion
    near = near[inside]
    if near.size == 0:
        i = surface.under(w)
        return surface.points[i], surface.normals[i]
    n = surface.normals[near].sum(axis=0)
    return surface.points[near].mean(axis=0), n / max(float(np.linalg.norm(n)), 1e-12)


def _pads(hm: HandModel, f: int, X_OW: np.ndarray) -> list[tuple[np.ndarray, object, float]]:
    """Finger f's geometries (placements current) for :func:`contact_patch`: pose in O,
    geometry, and the erosion that grows an eroded fingertip back to the true pad."""
    return [(X_OW @ hm.gd.oMg[a].homogeneous, hm.gm.geometryObjects[a].geometry, hm.erosion[a])
            for a, o in enumerate(hm.owner) if o == f]


def jaw_grasp(hm: HandModel, jaw: Jaw, surface: Surface, X_OG: np.ndarray, frame_index: int, friction: float,
              rho: float, options: GraspOptions) -> tuple[Grasp | None, dict]:
    """The grasp of one candidate frame, or None; plus counters for the summary."""
    robot, hand = hm.robot, hm.hand
    stats = {"palm": 0, "few_contacts": 0, "hand_collision": 0, "not_force_closure": 0}
    closed = close_jaw(hm, jaw, X_OG)
    if closed is None:
        stats["few_contacts"] = 1
        return None, stats
    X_OG, q = closed
    hm.set_object(X_OG)
    if hm.collides(q, {0, 1}, None):
        stats["hand_collision"] = 1
        return None, stats
    # contacts: where each closed pad touches the object (its patch, not coal's witness point)
    X_OW = X_OG @ inverse(hm.X_WG)
    pin.updateGeometryPlacements(robot.model, hm.data, hm.gm, hm.gd, robot.to_pin(q))
    points, normals, axes = np.zeros((2, 3)), np.zeros((2, 3)), np.zeros((2, 3))
    for f in (0, 1):
        # the witness of the geometry truly nearest (an eroded pad touching reads +erosion)
        found = [(pin.computeDistance(hm.gm, hm.gd, k), k) for k in finger_pairs(hm, f)]
        best = min(found, key=lambda rk: rk[0].min_distance - hm.erosion[hm.gm.collisionPairs[rk[1]].first])[0]
        axes[f] = X_OG[:3, :3] @ jaw.closing_G[f]
        points[f], normals[f] = contact_patch(surface, X_OW[:3, :3] @ best.getNearestPoint2() + X_OW[:3, 3], axes[f],
                                              _pads(hm, f, X_OW))
    kappa = surface.curvature[surface.tree.query(points)[1]]
    scores = grasp_quality(points, normals, friction, surface.mass_centre, axes, kappa, rho, options.weights,
                           contact="soft", n_edges=options.cone_edges)
    if not scores.is_force_closure:
        stats["not_force_closure"] = 1
        return None, stats
    return Grasp(frame_index, X_OG.copy(), q[hand.idx].copy(), np.ones(2, dtype=bool), points, normals, scores), stats
