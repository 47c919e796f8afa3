"""Collision world: robot self-collision, static obstacles and the manipulated object.

A :class:`CollisionModel` is the immutable description of which geometry pairs are
checked and with which tolerance; a :class:`CollisionWorld` made from it is the scratch of
one worker or query (pinocchio data, coal geometry data and broadphase manager, where the
object is), like pinocchio's Model/Data split.  Checks go through pinocchio + coal's broadphase manager (a dynamic AABB
tree) with early exit at the first collision: on the default robot this is the fastest of
the back-ends we measured (``scripts/bench_collision.py``, docs/BENCHMARKS.md).

Pairs checked:

* robot-robot: every pair of robot geometries except the disabled link pairs
  (:mod:`regrasp_cli.model.selfcollision`: adjacent, never or always colliding, and those
  listed in robot.yaml);
* robot-obstacle: every moving robot geometry against every obstacle (geometries fixed to
  the robot's root never move, so touching a support is the user's design, not a collision);
  the fingertips of the hands in ``touching`` may touch an obstacle as they touch the
  object, up to ``contact_tolerance``: a hand pinching a flat object on a desk rests its
  fingertips on the desk (docs/DESIGN-NOTES.md, "Fingertips on the support");
* object-robot: every robot geometry; the fingertips of the hands in ``touching`` may
  penetrate the object by up to ``contact_tolerance`` (a precision grasp touches it);
* object-obstacle: only when the object moves with a hand; it may rest on a support with
  up to ``support_tolerance`` of penetration (the pick and place configurations).

A tolerance is applied by checking an *eroded* copy of the primitive (sphere, capsule,
box, cylinder) shrunk by the tolerance on every side against the object: coal refuses
negative security margins for meshes (``BVHModel``), and the object is a mesh.  A
geometry that cannot be eroded (a mesh) is checked with no tolerance.
"""

from __future__ import annotations

import warnings
from collections import deque
from dataclasses import dataclass
from functools import lru_cache
from typing import Callable, Iterable, Sequence

import coal
import numpy as np
import pinocchio as pin
import trimesh

from regrasp_cli.config import ObstacleSpec
from regrasp_cli.model.robot import Robot
from regrasp_cli.spatial import inverse


@dataclass(frozen=True)
class CollisionOptions:
    contact_tolerance: float = 0.002  # m, fingertip-object penetration allowed when touching
    support_tolerance: float = 0.002  # m, object-obstacle penetration allowed (resting)


@dataclass(frozen=True)
class ObjectPlacement:
    """Where the manipulated object is.

    ``X_PO`` is the object pose in its parent: the world W when ``attached_to`` is None,
    otherwise the grasp frame G of that hand.  ``touching`` lists the hands whose
    fingertips are in contact with it (the holding hand is always included).
    """

    mesh: trimesh.Trimesh
    X_PO: np.ndarray
    attached_to: str | None = None
    touching: tuple[str, ...] = ()
    geometry: coal.CollisionGeometry | None = None  # the mesh's BVH (:func:`mesh_geometry`) when the caller has it


def mesh_geometry(mesh: trimesh.Trimesh) -> coal.BVHModelOBBRSS:
    """A coal BVH of a triangle mesh (works for non-convex, non-watertight meshes)."""
    bvh = coal.BVHModelOBBRSS()
    bvh.beginModel(len(mesh.faces), len(mesh.vertices))
    bvh.addVertices(np.asarray(mesh.vertices, dtype=float))
    bvh.addTriangles(np.asarray(mesh.faces, dtype=np.int64))
    bvh.endModel()
    return bvh


def obstacle_geometry(ob: ObstacleSpec) -> coal.CollisionGeometry:
    if ob.shape == "box":
        return coal.Box(*ob.size)
    if ob.shape == "cylinder":
        return coal.Cylinder(*ob.size)
    if ob.shape == "sphere":
        return coal.Sphere(ob.size[0])
    from regrasp_cli.model.objects import load_object_mesh

    mesh = load_object_mesh(str(ob.mesh), base_dir=ob.mesh.parent, scale=ob.size[0], field=f"obstacles.{ob.name}")
    return mesh_geometry(mesh.mesh)


def cold_start(geometry_data: pin.GeometryData, distances: bool = True) -> None:
    """Make coal's answers exact and independent of earlier queries (and its distances'
    too, unless ``distances`` is False: for data that only checks collisions).

    No GJK warm start from the previous query: with pinocchio's cached guesses coal misses
    about 1% of collisions (e.g. two deeply overlapping palm boxes).  Contacts enabled:
    without them coal 3.0.3's early GJK exit missed 2 in 17,548 colliding configurations
    (a palm box against a thumb cylinder, 10 mm deep); with them, none
    (scripts/bench_collision.py, docs/BENCHMARKS.md)."""
    requests = list(geometry_data.collisionRequests) + (list(geometry_data.distanceRequests) if distances else [])
    with warnings.catch_warnings():  # deprecated in coal, but pinocchio still sets it
        warnings.simplefilter("ignore", DeprecationWarning)
        for req in requests:
            req.gjk_initial_guess = coal.GJKInitialGuess.DefaultGuess
            req.enable_cached_gjk_guess = False
    for req in geometry_data.collisionRequests:
        req.enable_contact = True


def eroded_geometry(geom: coal.CollisionGeometry, tol: float) -> coal.CollisionGeometry | None:
    """The primitive or convex hull ``geom`` shrunk by ``tol`` (m) on every side, or None
    for other shapes (a mesh)."""
    tiny = 1e-6
    if isinstance(geom, coal.ConvexBase):
        return _eroded_hull(np.asarray(geom.points()), tol)
    if isinstance(geom, coal.Sphere):
        return coal.Sphere(max(geom.radius - tol, tiny))
    if isinstance(geom, coal.Capsule):
        return coal.Capsule(max(geom.radius - tol, tiny), 2.0 * geom.halfLength)
    if isinstance(geom, coal.Box):
        return coal.Box(*np.maximum(2.0 * (geom.halfSide - tol), tiny))
    if isinstance(geom, coal.Cylinder):
        return coal.Cylinder(max(geom.radius - tol, tiny), max(2.0 * (geom.halfLength - tol), tiny))
    return None


@dataclass(frozen=True, eq=False)
class CollisionModel:
    """Which geometry pairs are checked, with which tolerances and clearances: the model
    side of pinocchio's Model/Data split, immutable and shared by every query.  Build with
    :func:`collision_model`; check configurations with a :class:`CollisionWorld` made
    from it (the per-query data side)."""

    robot: Robot
    obstacles: tuple[ObstacleSpec, ...]
    object: ObjectPlacement | None
    options: CollisionOptions
    geometry_model: pin.GeometryModel  # robot, obstacles, eroded copies, the object at object.X_PO
    margins: np.ndarray  # (n_pairs,) m: coal security margin (clearance) of each collision pair
    n_robot: int  # the robot geometries come first in geometry_model
    obstacle_geoms: tuple[int, ...]
    object_geom: int | None
    alias: dict  # eroded copy -> original geometry index
    X_JP: np.ndarray | None  # (4, 4) the object's parent frame P (W or G) in its joint frame

    @property
    def robot_geoms(self) -> np.ndarray:
        return np.arange(self.n_robot)

    @property
    def n_pairs(self) -> int:
        return len(self.geometry_model.collisionPairs)

    def geometry_name(self, gid: int) -> str:
        """A link name, ``obstacle:NAME`` or ``object`` (eroded copies by their original)."""
        gid = self.alias.get(gid, gid)
        go = self.geometry_model.geometryObjects[gid]
        if gid < self.n_robot:
            return self.robot.model.frames[go.parentFrame].name
        return go.name


def _eroded_hull(points: np.ndarray, tol: float) -> coal.ConvexBase:
    """The convex hull of ``points`` (k, 3) shrunk by ``tol`` (m): its facets' half-spaces
    moved inward by tol and intersected (scipy's Qhull).  A hull thinner than 2 tol leaves
    a point: a tetrahedron of 1 micrometre at the mean of its points."""
    from scipy.optimize import linprog
    from scipy.spatial import ConvexHull, HalfspaceIntersection

    eq = ConvexHull(points).equations  # (f, 4): n.x + d <= 0 inside, n unit
    # the Chebyshev centre: max r subject to n.x + d + r <= 0
    lp = linprog(np.r_[0.0, 0.0, 0.0, -1.0], A_ub=np.c_[eq[:, :3], np.ones(len(eq))], b_ub=-eq[:, 3],
                 bounds=[(None, None)] * 3 + [(0.0, None)], method="highs")
    centre, depth = lp.x[:3], lp.x[3]
    if depth <= tol + 1e-6:
        corners = points.mean(axis=0) + 1e-6 * np.array([[1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0], [-1.0, -1.0, -1.0]])
        return coal.Convex.convexHull(list(corners), False, None)
    shrunk = eq.copy()
    shrunk[:, 3] += tol
    return coal.Convex.convexHull(list(HalfspaceIntersection(shrunk, centre).intersections), False, None)


def _eroded(gm: pin.GeometryModel, alias: dict, gid: int, tol: float) -> int:
    """Index of a copy of geometry ``gid`` shrunk by ``tol`` (added to ``gm``, recorded in
    ``alias``), or ``gid`` itself when its shape cannot be eroded (no tolerance applies)."""
    go = gm.geometryObjects[gid]
    geom = eroded_geometry(go.geometry, tol) if tol > 0 else None
    if geom is None:
        return gid
    copy = gm.addGeometryObject(pin.GeometryObject(f"{go.name}:eroded", go.parentJoint, go.parentFrame,
                                                   go.placement, geom))
    alias[copy] = gid
    return copy


def _robot_geometries(robot: Robot, links: Callable[[str], bool] | None) -> pin.GeometryModel:
    if links is None:
        return robot.collision_model.copy()
    gm = pin.GeometryModel()  # only the robot geometries of the given links: a smaller broadphase
    for g, go in enumerate(robot.collision_model.geometryObjects):
        if links(robot.link_of_geometry(g)):
            gm.addGeometryObject(go.copy())
    return gm


def _add_object(robot: Robot, gm: pin.GeometryModel, obj: ObjectPlacement) -> tuple[int, np.ndarray]:
    """Add the object on its parent's joint; returns its geometry index and X_JP."""
    if obj.attached_to is None:
        joint, frame, X_JO = 0, 0, obj.X_PO
    else:
        fid = robot.hands[obj.attached_to].grasp_frame
        f = robot.model.frames[fid]
        joint, frame = f.parentJoint, fid
        X_JO = f.placement.homogeneous @ obj.X_PO
    go = pin.GeometryObject("object", joint, frame, pin.SE3(X_JO[:3, :3].copy(), X_JO[:3, 3].copy()),
                            obj.geometry if obj.geometry is not None else mesh_geometry(obj.mesh))
    return gm.addGeometryObject(go), X_JO @ inverse(obj.X_PO)


def collision_model(robot: Robot, obstacles: Sequence[ObstacleSpec] = (),
                    disabled_links: Iterable[tuple[str, str]] = (), obj: ObjectPlacement | None = None,
                    options: CollisionOptions = CollisionOptions(),
                    pair_filter: Callable[[str, str], bool] | None = None,
                    margin: Callable[[str, str], float] | None = None,
                    links: Callable[[str], bool] | None = None) -> CollisionModel:
    """The pairs of the module docstring.  ``pair_filter(a, b)``, when given, keeps only
    the pairs it accepts; ``a`` and ``b`` are link names, ``"obstacle:NAME"`` or
    ``"object"`` (used by the roadmap to check only what an elementary roadmap did not
    already check).  ``margin(a, b)`` (m, >= 0) is a clearance the pair must keep (coal
    security margin), used by certified segment checks.  ``links(name)``, when given,
    leaves out the robot links it rejects altogether."""
    obstacles = tuple(obstacles)
    gm = _robot_geometries(robot, links)
    n_robot = gm.ngeoms
    obstacle_geoms = []
    for ob in obstacles:
        X = ob.X_WO
        go = pin.GeometryObject(f"obstacle:{ob.name}", 0, 0, pin.SE3(X[:3, :3].copy(), X[:3, 3].copy()),
                                obstacle_geometry(ob))
        obstacle_geoms.append(gm.addGeometryObject(go))
    object_geom, X_JP, alias = None, None, {}
    if obj is not None:
        object_geom, X_JP = _add_object(robot, gm, obj)

    disabled = {frozenset(p) for p in disabled_links}
    link = [robot.model.frames[gm.geometryObjects[g].parentFrame].name for g in range(n_robot)]
    keep = pair_filter or (lambda a, b: True)
    obstacle_name = {o: gm.geometryObjects[o].name for o in obstacle_geoms}

    def add(a: int, b: int, name_a: str, name_b: str) -> None:
        if keep(name_a, name_b):
            gm.addCollisionPair(pin.CollisionPair(a, b))

    for a in range(n_robot):
        for b in range(a + 1, n_robot):
            if frozenset((link[a], link[b])) not in disabled and link[a] != link[b]:
                add(a, b, link[a], link[b])
    touch = {}  # geometry -> its eroded copy, for the fingertips of the hands touching the object
    if obj is not None:
        touching = set(obj.touching) | ({obj.attached_to} if obj.attached_to else set())
        tips = {robot.model.frames[f].name for h in touching for f in robot.hands[h].tip_frames}
        touch = {a: _eroded(gm, alias, a, options.contact_tolerance) for a in range(n_robot) if link[a] in tips}
    for a in range(n_robot):
        if gm.geometryObjects[a].parentJoint == 0:
            continue  # fixed to the root: never moves
        for o in obstacle_geoms:
            if keep(link[a], obstacle_name[o]):
                gm.addCollisionPair(pin.CollisionPair(touch.get(a, a), o))
    if obj is not None:
        for a in range(n_robot):
            if keep(link[a], "object"):
                gm.addCollisionPair(pin.CollisionPair(touch.get(a, a), object_geom))
        if obj.attached_to is not None:
            for o in obstacle_geoms:
                if keep("object", obstacle_name[o]):
                    gm.addCollisionPair(pin.CollisionPair(object_geom,
                                                          _eroded(gm, alias, o, options.support_tolerance)))
    model = CollisionModel(robot, obstacles, obj, options, gm, np.zeros(len(gm.collisionPairs)), n_robot,
                           tuple(obstacle_geoms), object_geom, alias, X_JP)
    if margin is not None:
        names = [model.geometry_name(g) for g in range(gm.ngeoms)]
        for k, cp in enumerate(gm.collisionPairs):
            model.margins[k] = margin(names[cp.first], names[cp.second])
    model.margins.flags.writeable = False
    return model


class CollisionWorld:
    """Checks full-robot configurations against the robot itself, obstacles and the object
    of a shared :class:`CollisionModel`: the per-query data side (pinocchio Data, coal
    geometry data and broadphase manager, the object's current pose, a check counter).
    One per worker or query; never shared between threads."""

    def __init__(self, model: CollisionModel):
        self.model = model
        # the object's pose lives in the geometry model (pinocchio reads placements there):
        # a world that moves the object moves it in its own copy, never in the shared model
        self.geometry_model = model.geometry_model.copy() if model.object_geom is not None else model.geometry_model
        self.data = model.robot.model.createData()
        self.geometry_data, self.manager = self._checker(1.0)
        self._scaled = {1.0: (self.geometry_data, self.manager)}  # margin scale -> its checker
        self.X_PO = None if model.object is None else model.object.X_PO
        self.n_checks = 0
        self.certified = bool(model.margins.any())  # some pair keeps a clearance at the checked configurations

    def _checker(self, scale: float) -> tuple[pin.GeometryData, pin.BroadPhaseManager_DynamicAABBTreeCollisionManager]:
        """Geometry data keeping ``scale`` times the model's margins, and its broadphase."""
        gd = self.geometry_model.createData()
        cold_start(gd, distances=False)  # a world checks collisions, never distances
        for k in np.flatnonzero(self.model.margins):
            gd.collisionRequests[int(k)].security_margin = scale * float(self.model.margins[k])
        return gd, pin.BroadPhaseManager_DynamicAABBTreeCollisionManager(self.model.robot.model,
                                                                          self.geometry_model, gd)

    # the model's description, for callers that hold only a world
    robot = property(lambda self: self.model.robot)
    obstacles = property(lambda self: self.model.obstacles)
    object = property(lambda self: self.model.object)
    options = property(lambda self: self.model.options)
    robot_geoms = property(lambda self: self.model.robot_geoms)
    obstacle_geoms = property(lambda self: self.model.obstacle_geoms)
    object_geom = property(lambda self: self.model.object_geom)
    n_pairs = property(lambda self: self.model.n_pairs)

    def geometry_name(self, gid: int) -> str:
        return self.model.geometry_name(gid)

    def set_object_pose(self, X_PO: np.ndarray) -> None:
        """Move the object within its parent (W, or the holding hand's grasp frame): the
        pairs and tolerances stay, so one world serves every placement of an attachment.
        ``X_PO`` (4, 4) is kept, not copied: poses are never changed in place."""
        X_JO = self.model.X_JP @ X_PO
        self.geometry_model.geometryObjects[self.model.object_geom].placement = pin.SE3(X_JO[:3, :3].copy(),
                                                                                      X_JO[:3, 3].copy())
        self.X_PO = X_PO

    # ------------------------------------------------------------------ checks

    def is_free(self, q: np.ndarray, scale: float = 1.0) -> bool:
        """True when the configuration (nq,) is collision-free (early exit), every pair
        keeping ``scale`` times its margin (a larger clearance certifies a longer step)."""
        self.n_checks += 1
        checker = self._scaled.get(scale)
        if checker is None:  # the data is kept with its manager: the manager points into it
            checker = self._scaled[scale] = self._checker(scale)
        return not pin.computeCollisions(self.robot.model, self.data, checker[1], self.robot.to_pin(q), True)

    def colliding_pairs(self, q: np.ndarray) -> list[tuple[str, str]]:
        """All colliding pairs (link or obstacle names) at q: for reports, not the hot path."""
        pin.computeCollisions(self.robot.model, self.data, self.geometry_model, self.geometry_data,
                              self.robot.to_pin(q), False)
        out = []
        for k, cp in enumerate(self.geometry_model.collisionPairs):
            if self.geometry_data.collisionResults[k].isCollision():
                out.append((self.geometry_name(cp.first), self.geometry_name(cp.second)))
        return out

    def segment_free(self, q0: np.ndarray, q1: np.ndarray, resolution: float, min_steps: int = 1,
                     limit: int | None = None) -> bool:
        """Straight segment q0 -> q1 in joint space, checked so that no joint moves more than
        ``resolution`` (rad or m) between two checked configurations.  The end points are
        checked too.  Samples are visited in bisection order (coarse to fine), so a
        colliding segment is usually rejected after few checks.  With ``limit``, only the
        first ``limit`` samples of that order are checked: False is then a proof of
        collision, True only says none was found."""
        for t in segment_samples(q0, q1, resolution, min_steps)[:limit]:
            if not self.is_free(q0 + t * (q1 - q0)):
                return False
        return True


def collision_world(robot: Robot, obstacles: Sequence[ObstacleSpec] = (),
                    disabled_links: Iterable[tuple[str, str]] = (), obj: ObjectPlacement | None = None,
                    options: CollisionOptions = CollisionOptions(), **kwargs) -> CollisionWorld:
    """A fresh model and one world on it (arguments of :func:`collision_model`)."""
    return CollisionWorld(collision_model(robot, obstacles, disabled_links, obj, options, **kwargs))


def segment_samples(q0: np.ndarray, q1: np.ndarray, resolution: float, min_steps: int = 1) -> np.ndarray:
    """Interpolation parameters in [0, 1] (ends included) spaced so that no joint moves more
    than ``resolution`` between neighbours, ordered coarse to fine (ends, then midpoints
    breadth-first)."""
    return bisection_order(max(1, min_steps, int(np.ceil(np.max(np.abs(q1 - q0)) / resolution))))


@lru_cache(maxsize=4096)
def bisection_order(n: int) -> np.ndarray:
    """The parameters k / n, k = 0 .. n, ends first, then midpoints breadth-first (n + 1,),
    read-only: it depends on n alone, and Vis-PRM asks for the first samples of thousands
    of segments."""
    order, queue = [0, n], deque([(0, n)])
    while queue:
        a, b = queue.popleft()
        if b - a >= 2:
            m = (a + b) // 2
            order.append(m)
            queue.extend(((a, m), (m, b)))
    out = np.asarray(order, dtype=float) / n
    out.flags.writeable = False
    return out
