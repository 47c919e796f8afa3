"""A hand's collision geometry in its grasp frame G, for tests that do not need the arm.

The double-grasp filters of Saut et al. 2010 §IV-B test a hand placed at a grasp against
the environment (at the object's start or goal pose) and against the other hand (both
holding the object): only the palm and fingers matter there, and placing them directly
(object pose x grasp) is far cheaper than solving the arm's IK first.  Geometries are
checked with coal after a vectorised bounding-sphere test, which rejects almost every
pair at these distances.

A hand holding the object may rest its fingertips on an obstacle as on the object, up to
the contact tolerance (:mod:`model.collision`): ``hand_hits_static(..., touching=True)``
checks the fingertips eroded by the tolerance the shapes were made with.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import coal
import numpy as np
import pinocchio as pin

from regrasp_cli.config import ObstacleSpec
from regrasp_cli.model.collision import eroded_geometry, obstacle_geometry
from regrasp_cli.model.robot import Robot
from regrasp_cli.spatial import inverse


@dataclass(frozen=True)
class HandShape:
    """The palm and finger geometries of a hand with its fingers at given values."""

    geometries: tuple[coal.CollisionGeometry, ...]
    X_GL: np.ndarray  # (n, 4, 4) geometry poses in the grasp frame G
    centres: np.ndarray  # (n, 3) bounding-sphere centres in G, m
    radii: np.ndarray  # (n,) bounding-sphere radii, m
    touch_geometries: tuple[coal.CollisionGeometry, ...]  # the fingertips eroded by the contact tolerance


def single_shape(geometry: coal.CollisionGeometry) -> HandShape:
    """One geometry at the origin of G as a shape (an object, a lone fingertip), for the
    same checks as a hand's."""
    geometry.computeLocalAABB()
    return HandShape((geometry,), np.eye(4)[None], np.array([geometry.aabb_local.center()]),
                     np.array([float(geometry.aabb_radius)]), (geometry,))


def palm_and_finger_links(robot: Robot, hand: str) -> set[str]:
    """Names of the links of the palm and fingers of a hand (every link that moves with
    the fingers, :meth:`Robot.hand_joints`)."""
    h, model = robot.hands[hand], robot.model
    joints = set(robot.hand_joints(hand)) | {model.frames[h.grasp_frame].parentJoint}
    return {model.frames[go.parentFrame].name for go in robot.collision_model.geometryObjects
            if go.parentJoint in joints}


def hand_inputs(robot: Robot, hand: str, disabled_links: set[tuple[str, str]]) -> dict:
    """Everything of the robot that a hand's grasps depend on, as JSON-able values to hash:
    its robot.yaml section, the joints of its palm and fingers (placements, axes, limits,
    mimic couplings), its grasp and tip frames, the collision geometry of its links (shape
    parameters, or the mesh file's digest and scale) and the link pairs never checked among
    them.  Not the rest of the robot (arms, rest posture, other hand), so that an edit
    there keeps the hand's grasp lists and finger workspaces."""
    import hashlib

    h, model = robot.hands[hand], robot.model
    palm = model.frames[h.grasp_frame].parentJoint
    joints = sorted(robot.hand_joints(hand))
    rnd = lambda X: np.round(np.asarray(X, dtype=float), 12).tolist()  # noqa: E731

    def joint(j: int) -> dict:
        jm, i = model.joints[j], j - 1
        jd = jm.createData()
        jm.calc(jd, np.array([1.0, 0.0]) if jm.nq == 2 else np.zeros(1))
        return {"name": model.names[j], "parent": model.names[model.parents[j]], "type": jm.shortname(),
                "placement": rnd(model.jointPlacements[j].homogeneous), "axis": rnd(np.asarray(jd.S).ravel()),
                "limits": rnd([robot.lower[i], robot.upper[i]]), "mimic": list(robot.mimic.get(i, ()))}

    def frame(f: int) -> dict:
        fr = model.frames[f]
        return {"name": fr.name, "joint": model.names[fr.parentJoint], "placement": rnd(fr.placement.homogeneous)}

    def geometry(go) -> dict:
        g = go.geometry
        key = {"name": go.name, "frame": model.frames[go.parentFrame].name, "joint": model.names[go.parentJoint],
               "placement": rnd(go.placement.homogeneous), "type": type(g).__name__}
        for attr in ("halfSide", "radius", "halfLength"):
            if hasattr(g, attr):
                key[attr] = rnd(getattr(g, attr))
        if go.meshPath:
            try:
                key["mesh"] = hashlib.sha256(open(go.meshPath, "rb").read()).hexdigest()
            except OSError:
                key["mesh"] = go.meshPath
            key["scale"] = rnd(go.meshScale)
        return key

    links = palm_and_finger_links(robot, hand)
    return {"spec": repr(robot.spec.hands[hand]), "palm": model.names[palm], "joints": [joint(j) for j in joints],
            "frames": [frame(h.grasp_frame), *map(frame, h.tip_frames)],
            "geometry": [geometry(go) for go in robot.collision_model.geometryObjects
                         if go.parentJoint == palm or go.parentJoint in joints],
            "convex_hulls": robot.spec.convex_hulls,
            "disabled": sorted(sorted(p) for p in disabled_links if set(p) <= links)}


def hand_shapes(robot: Robot, hand: str, finger_values: np.ndarray, contact_tolerance: float = 0.0) -> list[HandShape]:
    """The hand's geometries posed in G, for each row of finger values (k, n_hand_joints);
    their fingertips shrunk by ``contact_tolerance`` (m) for checks of a hand that touches."""
    h, model = robot.hands[hand], robot.model
    data, gm = model.createData(), robot.collision_model
    gd = gm.createData()
    joints = {model.getJointId(robot.joint_names[i]) for i in h.idx} | {model.frames[h.grasp_frame].parentJoint}
    ids = [g for g, go in enumerate(gm.geometryObjects) if go.parentJoint in joints]
    geoms = tuple(gm.geometryObjects[g].geometry for g in ids)
    tips = {model.frames[t].name for t in h.tip_frames}
    touch = tuple((eroded_geometry(g, contact_tolerance) if contact_tolerance > 0 else None) or g
                  if model.frames[gm.geometryObjects[i].parentFrame].name in tips else g for i, g in zip(ids, geoms))
    for g in geoms:
        g.computeLocalAABB()
    c_L = np.array([g.aabb_local.center() for g in geoms])
    radii = np.array([float(g.aabb_radius) for g in geoms])
    q = robot.q_rest.copy()
    out = []
    for values in np.atleast_2d(finger_values):
        q[h.idx] = values
        pin.framesForwardKinematics(model, data, robot.to_pin(q))
        pin.updateGeometryPlacements(model, data, gm, gd)
        X_GW = inverse(data.oMf[h.grasp_frame].homogeneous)
        X = np.array([X_GW @ gd.oMg[g].homogeneous for g in ids])
        centres = np.einsum("nij,nj->ni", X[:, :3, :3], c_L) + X[:, :3, 3]
        out.append(HandShape(geoms, X, centres, radii, touch))
    return out


def _tf(X: np.ndarray) -> coal.Transform3s:
    return coal.Transform3s(X[:3, :3].copy(), X[:3, 3].copy())


def _collide(g1, X1: np.ndarray, g2, X2: np.ndarray) -> bool:
    req, res = coal.CollisionRequest(), coal.CollisionResult()
    req.enable_contact = True
    return coal.collide(g1, _tf(X1), g2, _tf(X2), req, res) > 0


@dataclass(frozen=True)
class StaticGeometry:
    """Obstacles as coal geometries with world poses and bounding boxes (each geometry's
    local axis-aligned box, posed with it)."""

    geometries: tuple[coal.CollisionGeometry, ...]
    X_W: np.ndarray  # (m, 4, 4)
    centres: np.ndarray  # (m, 3) the boxes' centres, frame W
    half: np.ndarray  # (m, 3) their half sizes, each in its geometry's frame

    def reaching_above(self, z: float) -> StaticGeometry:
        """The geometries whose bounding boxes reach above the height ``z`` (m, frame W):
        nothing lying wholly above ``z`` can touch the others."""
        top = self.centres[:, 2] + np.einsum("mj,mj->m", np.abs(self.X_W[:, 2, :3]), self.half)
        keep = top > z
        return StaticGeometry(tuple(g for g, k in zip(self.geometries, keep) if k), self.X_W[keep],
                              self.centres[keep], self.half[keep])


def static_geometry_of(geometries: Sequence[coal.CollisionGeometry], X_W: Sequence[np.ndarray]) -> StaticGeometry:
    """The geometries at the world poses ``X_W`` (4, 4) each, with their bounding boxes."""
    X_W = np.array(X_W, dtype=float).reshape(-1, 4, 4)
    lo, hi = np.zeros((len(X_W), 3)), np.zeros((len(X_W), 3))
    for k, g in enumerate(geometries):
        g.computeLocalAABB()
        lo[k], hi[k] = np.asarray(g.aabb_local.min_), np.asarray(g.aabb_local.max_)
    centres = np.einsum("mij,mj->mi", X_W[:, :3, :3], (lo + hi) / 2) + X_W[:, :3, 3]
    return StaticGeometry(tuple(geometries), X_W, centres, (hi - lo) / 2)


def static_geometry(obstacles: tuple[ObstacleSpec, ...]) -> StaticGeometry:
    return static_geometry_of([obstacle_geometry(ob) for ob in obstacles], [ob.X_WO for ob in obstacles])


def hand_hits_static(shape: HandShape, X_WG: np.ndarray, env: StaticGeometry, clearance: float = 0.0,
                     touching: bool = False) -> bool:
    """Does the hand at X_WG (4, 4) touch an obstacle (or come within ``clearance``)?
    With ``touching`` (the hand holds the object), its fingertips may touch, up to the
    tolerance of :func:`hand_shapes`."""
    if not len(env.geometries):
        return False
    geometries = shape.touch_geometries if touching else shape.geometries
    c = shape.centres @ X_WG[:3, :3].T + X_WG[:3, 3]
    near = np.argwhere(_box_gaps(c, env) <= shape.radii[:, None] + clearance)
    for a, b in near:
        X = X_WG @ shape.X_GL[a]
        if clearance > 0:
            req, res = coal.DistanceRequest(), coal.DistanceResult()
            if coal.distance(geometries[a], _tf(X), env.geometries[b], _tf(env.X_W[b]), req, res) < clearance:
                return True
        elif _collide(geometries[a], X, env.geometries[b], env.X_W[b]):
            return True
    return False


def may_hit_static(shape: HandShape, X_WG: np.ndarray, env: StaticGeometry) -> np.ndarray:
    """For many poses ``X_WG`` (k, 4, 4): (k,) bool, False where no bounding sphere of the
    shape comes near an obstacle's bounding box (then :func:`hand_hits_static` without
    clearance is False too, without asking coal)."""
    if not len(env.geometries):
        return np.zeros(len(X_WG), dtype=bool)
    c = np.einsum("kij,nj->kni", X_WG[:, :3, :3], shape.centres) + X_WG[:, None, :3, 3]  # (k, n, 3)
    return (_box_gaps(c, env) <= shape.radii[:, None]).any(axis=(1, 2))


def _box_gaps(c: np.ndarray, env: StaticGeometry) -> np.ndarray:
    """Distances (..., m) from points ``c`` (..., 3) in W to each obstacle's bounding box:
    a hand geometry's bounding sphere against the box (a table's bounding sphere holds most
    of the hand's reach, its box does not)."""
    q = np.einsum("mji,...mj->...mi", env.X_W[:, :3, :3], c[..., None, :] - env.centres)  # in the boxes
    return np.linalg.norm(np.maximum(np.abs(q) - env.half, 0.0), axis=-1)


def hands_collide(a: HandShape, X_OGa: np.ndarray, b: HandShape, X_OGb: np.ndarray) -> bool:
    """Do two hands holding the same object (grasps X_OG of each, (4, 4)) collide?"""
    X_GaGb = inverse(X_OGa) @ X_OGb
    cb = b.centres @ X_GaGb[:3, :3].T + X_GaGb[:3, 3]
    d = np.linalg.norm(a.centres[:, None] - cb[None], axis=2)
    for i, j in np.argwhere(d <= a.radii[:, None] + b.radii[None]):
        if _collide(a.geometries[i], a.X_GL[i], b.geometries[j], X_GaGb @ b.X_GL[j]):
            return True
    return False
