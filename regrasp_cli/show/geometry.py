"""Solids to draw: the robot's links, the obstacles and the object, as shapes in a parent
frame, their poses at a configuration, and their triangles.

Viewing only (not a paper section): the 3D page (:mod:`.html`) and the pictures
(:mod:`.png`) draw the same shapes.  A :class:`Shape` is a primitive (box, sphere,
cylinder, capsule; cylinders and capsules along their z axis, centred, as coal and URDF
have them) or a triangle mesh, posed in its parent frame P by ``X_PS``.  A robot link L
carries the shapes of its URDF ``visual`` (or ``collision``) elements, posed by ``X_LS``;
:func:`link_poses` gives X_WL, the link frames in the robot base frame W, by pinocchio's
forward kinematics.  Lengths are metres; colours RGBA in [0, 1].

The heavy part is pure array functions: :func:`shape_triangles` (a shape's triangles
``(n, 3, 3)`` in its own frame) and :func:`transform_triangles`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Iterable, Sequence

import coal
import numpy as np
import trimesh

from regrasp_cli.config import ObstacleSpec
from regrasp_cli.model.robot import Kinematics, Robot
from regrasp_cli.spatial import inverse

KINDS = ("box", "sphere", "cylinder", "capsule", "mesh")
OBSTACLE_RGBA = (0.72, 0.58, 0.42, 1.0)  # furniture: light wood
OBJECT_RGBA = (0.95, 0.45, 0.08, 1.0)  # the manipulated object stands out in orange
ROBOT_RGBA = (0.75, 0.75, 0.78, 1.0)  # links without a colour of their own
# The common viewpoint of the page's initial camera and of the pictures: from the front
# right, above the desk (x forward from the robot, y to its left, z up), unit vector in W.
VIEW_DIRECTION = np.array([1.6, -1.4, 1.0]) / np.linalg.norm([1.6, -1.4, 1.0])


@dataclass(frozen=True, eq=False)
class Shape:
    """A solid S posed in its parent frame P.

    ``size``: box (x, y, z) side lengths; sphere (radius,); cylinder and capsule
    (radius, length) along z (a capsule's length is between its two sphere centres);
    mesh: ``()`` with ``vertices`` (v, 3) and ``faces`` (f, 3) in frame S.
    """

    name: str
    kind: str
    size: tuple[float, ...]
    X_PS: np.ndarray  # (4, 4)
    rgba: tuple[float, float, float, float]
    vertices: np.ndarray | None = None
    faces: np.ndarray | None = None

    def __post_init__(self):
        if self.kind not in KINDS:
            raise ValueError(f"shape {self.name}: kind must be one of {KINDS}, got {self.kind!r}")
        if self.kind == "mesh" and (self.vertices is None or self.faces is None):
            raise ValueError(f"shape {self.name}: a mesh needs vertices (v, 3) and faces (f, 3)")


@dataclass(frozen=True, eq=False)
class LinkShapes:
    """The shapes of one robot link L (``X_PS`` is X_LS) and its pinocchio frame id."""

    link: str
    frame_id: int
    shapes: tuple[Shape, ...]


# ------------------------------------------------------------------ shapes of the scene


def _rgba(c: Sequence[float], default: tuple[float, float, float, float]) -> tuple[float, float, float, float]:
    c = np.asarray(c, dtype=float).ravel()
    if c.shape != (4,) or not np.all(np.isfinite(c)):
        return default
    return tuple(float(v) for v in np.clip(c, 0.0, 1.0))  # type: ignore[return-value]


def _bvh_arrays(geom: coal.BVHModelBase) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (v, 3) and faces (f, 3) of a coal BVH (pinocchio loaded and scaled the mesh)."""
    v = np.asarray(geom.vertices(), dtype=float).reshape(-1, 3)
    f = np.array([[t[0], t[1], t[2]] for t in (geom.tri_indices(i) for i in range(geom.num_tris))],
                 dtype=np.int64).reshape(-1, 3)
    return v, f


def decimate(vertices: np.ndarray, faces: np.ndarray, max_faces: int) -> tuple[np.ndarray, np.ndarray]:
    """A coarser mesh by vertex clustering: vertices (v, 3) snapped to a cubic grid and
    merged (each cluster at its mean), faces whose corners merged dropped; the grid cell
    doubles from 1/256 of the largest extent until at most ``max_faces`` remain.  Good
    enough to look at (detail below the cell size is lost), not for collision checking.
    Returns (vertices (v', 3), faces (f', 3)); the mesh itself when already small enough."""
    v, f = np.asarray(vertices, dtype=float), np.asarray(faces, dtype=np.int64)
    if len(f) <= max_faces:
        return v, f
    lo = v.min(axis=0)
    cell = max(float((v.max(axis=0) - lo).max()) / 256, 1e-9)
    while True:
        keys = np.floor((v - lo) / cell).astype(np.int64)
        _, cluster, counts = np.unique(keys, axis=0, return_inverse=True, return_counts=True)
        cluster = cluster.ravel()
        g = cluster[f]
        keep = (g[:, 0] != g[:, 1]) & (g[:, 1] != g[:, 2]) & (g[:, 2] != g[:, 0])
        if keep.sum() <= max_faces:
            centres = np.zeros((len(counts), 3))
            np.add.at(centres, cluster, v)
            return centres / counts[:, None], g[keep]
        cell *= 2


def geometry_shape(name: str, geom: coal.CollisionGeometry, X_PS: np.ndarray,
                   rgba: tuple[float, float, float, float], scale: Sequence[float] = (1.0, 1.0, 1.0),
                   max_faces: int | None = None) -> Shape | None:
    """A :class:`Shape` of a coal geometry (as in pinocchio's geometry models), or None for
    kinds that are not drawn (planes, half-spaces, octrees); meshes of more than
    ``max_faces`` triangles are :func:`decimate` d."""
    if isinstance(geom, coal.Box):
        return Shape(name, "box", tuple(2.0 * np.asarray(geom.halfSide, dtype=float)), X_PS, rgba)
    if isinstance(geom, coal.Sphere):
        return Shape(name, "sphere", (float(geom.radius),), X_PS, rgba)
    if isinstance(geom, coal.Capsule):
        return Shape(name, "capsule", (float(geom.radius), 2.0 * float(geom.halfLength)), X_PS, rgba)
    if isinstance(geom, coal.Cylinder):
        return Shape(name, "cylinder", (float(geom.radius), 2.0 * float(geom.halfLength)), X_PS, rgba)
    if isinstance(geom, coal.Ellipsoid):
        m = trimesh.creation.icosphere(subdivisions=2, radius=1.0)
        return Shape(name, "mesh", (), X_PS, rgba, m.vertices * np.asarray(geom.radii, dtype=float), m.faces)
    if isinstance(geom, coal.BVHModelBase):
        v, f = _bvh_arrays(geom)
        if max_faces is not None:
            v, f = decimate(v, f, max_faces)
        return Shape(name, "mesh", (), X_PS, rgba, v, f) if len(f) else None
    if isinstance(geom, coal.ConvexBase):
        points = np.asarray(geom.points(), dtype=float).reshape(-1, 3) * np.asarray(scale, dtype=float)
        hull = trimesh.convex.convex_hull(points)
        return Shape(name, "mesh", (), X_PS, rgba, hull.vertices, hull.faces)
    return None


def robot_links(robot: Robot, source: str = "visual", max_faces: int | None = None) -> tuple[LinkShapes, ...]:
    """The robot's links that carry geometry, with their shapes posed in the link frame.

    Args:
        robot: the loaded robot.
        source: ``"visual"`` (the URDF's visual elements; the collision ones when a URDF
            has no visual element at all) or ``"collision"`` (what the planner checks).
        max_faces: meshes with more triangles are decimated to at most this many.

    Returns:
        One :class:`LinkShapes` per link, in the order of pinocchio's frames.  A shape's
        ``X_PS`` is X_LS: pinocchio places a geometry in its parent *joint* frame J, so
        ``X_LS = inv(X_JL) @ X_JS`` with X_JL the link frame's placement in J.
    """
    if source not in ("visual", "collision"):
        raise ValueError(f"source must be 'visual' or 'collision', got {source!r}")
    gmodel = robot.visual_model if source == "visual" else robot.collision_model
    if source == "visual" and not len(gmodel.geometryObjects):
        gmodel = robot.collision_model
    by_frame: dict[int, list[Shape]] = {}
    for go in gmodel.geometryObjects:
        X_JL = robot.model.frames[go.parentFrame].placement.homogeneous
        shape = geometry_shape(go.name, go.geometry, inverse(X_JL) @ go.placement.homogeneous,
                               _rgba(go.meshColor, ROBOT_RGBA), go.meshScale, max_faces)
        if shape is not None:
            by_frame.setdefault(int(go.parentFrame), []).append(shape)
    return tuple(LinkShapes(robot.model.frames[f].name, f, tuple(s)) for f, s in sorted(by_frame.items()))


def link_poses(kin: Kinematics, links: Sequence[LinkShapes], q: np.ndarray) -> np.ndarray:
    """X_WL (L, 4, 4) of ``links`` at configuration q (nq,) (the robot's joint order)."""
    return np.array(kin.fk_many(np.asarray(q, dtype=float), [ls.frame_id for ls in links])).reshape(-1, 4, 4)


def obstacle_shapes(obstacles: Iterable[ObstacleSpec]) -> tuple[Shape, ...]:
    """The static obstacles, posed in the world W (``X_PS`` is the obstacle's X_WO)."""
    from regrasp_cli.model.objects import load_object_mesh

    out = []
    for ob in obstacles:
        if ob.shape == "mesh":
            m = load_object_mesh(str(ob.mesh), base_dir=ob.mesh.parent, scale=ob.size[0],
                                 field=f"obstacles.{ob.name}").mesh
            out.append(Shape(ob.name, "mesh", (), ob.X_WO, OBSTACLE_RGBA, np.asarray(m.vertices), np.asarray(m.faces)))
        else:
            out.append(Shape(ob.name, ob.shape, tuple(float(s) for s in ob.size), ob.X_WO, OBSTACLE_RGBA))
    return tuple(out)


def mesh_shape(name: str, mesh: trimesh.Trimesh, X_PS: np.ndarray | None = None,
               rgba: tuple[float, float, float, float] = OBJECT_RGBA) -> Shape:
    """A triangle mesh (e.g. the object, in its frame O) as a :class:`Shape`."""
    return Shape(name, "mesh", (), np.eye(4) if X_PS is None else X_PS, rgba,
                 np.asarray(mesh.vertices, dtype=float), np.asarray(mesh.faces, dtype=np.int64))


# ------------------------------------------------------------------ triangles


def shape_triangles(shape: Shape, sections: int = 20) -> np.ndarray:
    """Triangles (n, 3, 3) of ``shape`` in its own frame S (not posed by X_PS), m.

    ``sections`` sets the angular resolution of round primitives.
    """
    if shape.kind == "mesh":
        return np.asarray(shape.vertices, dtype=float)[np.asarray(shape.faces)]
    if shape.kind == "box":
        m = trimesh.creation.box(extents=shape.size)
    elif shape.kind == "sphere":
        m = trimesh.creation.icosphere(subdivisions=2, radius=shape.size[0])
    elif shape.kind == "cylinder":
        m = trimesh.creation.cylinder(radius=shape.size[0], height=shape.size[1], sections=sections)
    else:  # capsule
        m = trimesh.creation.capsule(height=shape.size[1], radius=shape.size[0], count=[sections, sections // 2])
    return np.asarray(m.triangles, dtype=float)


def transform_triangles(X_AB: np.ndarray, tri_B: np.ndarray) -> np.ndarray:
    """Triangles (n, 3, 3) in frame B -> frame A."""
    return tri_B @ X_AB[:3, :3].T + X_AB[:3, 3]


def subdivide(tri: np.ndarray, max_edge: float) -> np.ndarray:
    """Triangles (n, 3, 3) split at their edge midpoints (one into four) until no edge is
    longer than ``max_edge`` (m); the surface is unchanged.  Painter's-algorithm renderers
    sort whole triangles, so big ones (a desk top) must be cut to sort right against the
    small ones on them."""
    if not max_edge > 0:
        raise ValueError(f"max_edge must be > 0, got {max_edge}")
    done, todo = [], np.asarray(tri, dtype=float)
    while len(todo):
        edge = np.linalg.norm(todo - np.roll(todo, -1, axis=1), axis=2).max(axis=1)
        big = edge > max_edge
        done.append(todo[~big])
        a, b, c = todo[big, 0], todo[big, 1], todo[big, 2]
        ab, bc, ca = (a + b) / 2, (b + c) / 2, (c + a) / 2
        todo = np.concatenate([np.stack(t, axis=1) for t in ((a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca))])
    return np.concatenate(done) if done else np.zeros((0, 3, 3))


@dataclass(frozen=True, eq=False)
class Soup:
    """Triangles ``(n, 3, 3)`` in one frame with a colour each ``(n, 4)``."""

    triangles: np.ndarray
    rgba: np.ndarray

    @staticmethod
    def join(parts: Iterable["Soup"]) -> "Soup":
        parts = list(parts)
        if not parts:
            return Soup(np.zeros((0, 3, 3)), np.zeros((0, 4)))
        return Soup(np.concatenate([p.triangles for p in parts]), np.concatenate([p.rgba for p in parts]))

    def subdivided(self, max_edge: float) -> "Soup":
        """The same surface cut into triangles no longer than ``max_edge`` (m)."""
        parts = []
        for rgba in np.unique(self.rgba, axis=0):
            tri = subdivide(self.triangles[np.all(self.rgba == rgba, axis=1)], max_edge)
            parts.append(Soup(tri, np.tile(rgba, (len(tri), 1))))
        return Soup.join(parts)

    def moved(self, X_AB: np.ndarray) -> "Soup":
        """The same soup, from frame B to frame A."""
        return Soup(transform_triangles(X_AB, self.triangles), self.rgba)


def shapes_soup(shapes: Iterable[Shape], sections: int = 20) -> Soup:
    """The shapes' triangles posed in their parent frame P, with their colours."""
    parts = []
    for s in shapes:
        tri = transform_triangles(s.X_PS, shape_triangles(s, sections))
        parts.append(Soup(tri, np.tile(np.asarray(s.rgba, dtype=float), (len(tri), 1))))
    return Soup.join(parts)


def robot_soup(links: Sequence[LinkShapes], X_WL: np.ndarray, link_soups: Sequence[Soup] | None = None) -> Soup:
    """The robot's triangles in W, links posed by X_WL (L, 4, 4).  ``link_soups`` (one per
    link, in the link frame, from :func:`shapes_soup`) saves re-triangulating."""
    soups = link_soups if link_soups is not None else [shapes_soup(ls.shapes) for ls in links]
    return Soup.join(s.moved(X) for s, X in zip(soups, X_WL))


def hand_links(robot: Robot, links: Sequence[LinkShapes], hand: str) -> tuple[LinkShapes, ...]:
    """The links that move with a hand's grasp frame: the palm's joint and every joint
    below it (fingers)."""
    joint = robot.model.frames[robot.hands[hand].grasp_frame].parentJoint
    below = set(robot.model.subtrees[joint])
    return tuple(ls for ls in links if robot.model.frames[ls.frame_id].parentJoint in below)


def bounds(soup: Soup) -> np.ndarray:
    """Axis-aligned bounds (2, 3): min and max corner of the triangles."""
    if not len(soup.triangles):
        return np.zeros((2, 3))
    p = soup.triangles.reshape(-1, 3)
    return np.array([p.min(axis=0), p.max(axis=0)])

