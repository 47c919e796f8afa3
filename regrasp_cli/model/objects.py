"""Object meshes: procedural built-in objects and loading of user mesh files.

An object is given either as ``builtin:NAME`` (see :func:`builtin_names`) or as the path
of a mesh file that trimesh reads (STL, OBJ, PLY, OFF, GLB/glTF, ...), relative to the
directory of the file that names it.  :func:`load_object_mesh` returns an
:class:`ObjectMesh`: the triangle mesh in the *object frame*, in metres, multiplied by
``scale``.  For built-ins the object frame is at the centre of the base footprint with
+z up, so the object rests on a support plane at z = 0; user meshes keep their own frame.
Bad input raises :class:`~regrasp_cli.errors.InputError`; a mesh that is not watertight
loads with a :class:`UserWarning` (contacts and stable poses are still computed, but
volumes and inside/outside tests are approximate).

:func:`mesh_sha256` hashes the geometry so cached artefacts can record which mesh they
were computed for.
"""

from __future__ import annotations

import hashlib
import math
import struct
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import trimesh
from trimesh import creation

from regrasp_cli.errors import InputError, shown

BUILTIN_PREFIX = "builtin:"
MIN_EXTENT, MAX_EXTENT = 1e-3, 100.0  # m: the largest side of a mesh's bounding box, scaled


# --------------------------------------------------------------------------- built-ins


def _combine(parts: Sequence[trimesh.Trimesh]) -> trimesh.Trimesh:
    """Union of closed parts with trimesh's manifold engine when it is installed
    (result: one watertight shell), else their concatenation (one closed shell per part,
    interpenetrating where parts overlap, like a multi-shell scan)."""
    for part in parts:
        trimesh.repair.fix_normals(part)
    if "manifold" in trimesh.boolean.engines_available:
        mesh = trimesh.boolean.union(list(parts), engine="manifold")
    else:
        mesh = trimesh.util.concatenate(list(parts))
    mesh.merge_vertices()
    trimesh.repair.fix_normals(mesh, multibody=True)
    # Rest on z = 0 (the parts are built with their base at z = 0 already; this removes
    # tessellation round-off).
    mesh.apply_translation([0.0, 0.0, -float(mesh.bounds[0, 2])])
    return mesh


def _frame(origin: Sequence[float], z_axis: Sequence[float]) -> np.ndarray:
    """4x4 transform whose local +z maps to ``z_axis`` and local origin to ``origin``."""
    t = trimesh.geometry.align_vectors([0.0, 0.0, 1.0], np.asarray(z_axis, float))
    t[:3, 3] = origin
    return t


def _capsule(p0: Sequence[float], p1: Sequence[float], radius: float) -> trimesh.Trimesh:
    """Capsule of ``radius`` (m) whose axis segment runs from ``p0`` to ``p1`` (m)."""
    a, b = np.asarray(p0, float), np.asarray(p1, float)
    return creation.capsule(
        height=float(np.linalg.norm(b - a)),
        radius=radius,
        count=[12, 8],
        transform=_frame((a + b) / 2.0, b - a),
    )


def _ellipsoid(centre: Sequence[float], semi_axes: Sequence[float], pitch: float = 0.0) -> trimesh.Trimesh:
    """Ellipsoid with ``semi_axes`` (m, along x, y, z), rotated by ``pitch`` (rad) about
    +y, centred at ``centre`` (m)."""
    m = creation.uv_sphere(radius=1.0, count=[16, 12])
    m.apply_scale(np.asarray(semi_axes, float))
    m.apply_transform(trimesh.transformations.rotation_matrix(pitch, [0.0, 1.0, 0.0]))
    m.apply_translation(centre)
    return m


def _statuette() -> trimesh.Trimesh:
    """Stylised horse on a plinth (x: towards the head, y: left, z: up)."""
    plinth = creation.box(extents=[0.15, 0.065, 0.02])
    plinth.apply_translation([0.0, 0.0, 0.01])
    dx = -0.012  # shift the animal back so the overhanging head balances the tail
    legs = [
        _capsule([dx + sx, sy, 0.022], [dx + sx * 0.9, sy, 0.118], radius=0.01)
        for sx in (-0.045, 0.045)
        for sy in (-0.017, 0.017)
    ]
    body = _ellipsoid([dx, 0.0, 0.128], [0.066, 0.026, 0.03])
    neck = _capsule([dx + 0.045, 0.0, 0.138], [dx + 0.075, 0.0, 0.19], radius=0.013)
    head = _ellipsoid([dx + 0.09, 0.0, 0.197], [0.033, 0.014, 0.016], pitch=math.radians(35))
    tail = _capsule([dx - 0.062, 0.0, 0.14], [dx - 0.082, 0.0, 0.092], radius=0.006)
    return _combine([plinth, *legs, body, neck, head, tail])


def _mug() -> trimesh.Trimesh:
    """Tall mug (tankard): a hollow revolved body with a partial-torus handle whose ends
    are embedded in the wall (so even without a union the handle never pokes into the
    cavity)."""
    r_out, r_in, height, bottom = 0.038, 0.033, 0.20, 0.01
    body = creation.revolve(
        [[0.0, 0.0], [r_out, 0.0], [r_out, height], [r_in, height], [r_in, bottom], [0.0, bottom]],
        sections=64,
    )
    # Handle: an elliptical tube section (1 cm radially x 1.8 cm laterally) swept along a
    # 200-degree arc of radius 4 cm in the xz plane, ending mid-wall at x = 0.0355.
    major, half_arc = 0.04, math.radians(100)
    s = np.linspace(0.0, 2.0 * math.pi, 12, endpoint=False)
    section = np.column_stack([major + 0.005 * np.cos(s), 0.009 * np.sin(s)])
    section = np.vstack([section, section[:1]])  # exactly closed, so the tube is closed
    handle = creation.revolve(section, angle=2.0 * half_arc, cap=True, sections=32)
    handle.apply_transform(trimesh.transformations.rotation_matrix(-half_arc, [0.0, 0.0, 1.0]))
    handle.apply_transform(trimesh.transformations.rotation_matrix(math.pi / 2, [1.0, 0.0, 0.0]))
    handle.apply_translation([0.0355 - major * math.cos(half_arc), 0.0, 0.115])
    return _combine([body, handle])


def _block() -> trimesh.Trimesh:
    """Wooden block, 4 x 4 x 12 cm: narrow enough for Baxter's shipped jaw (4.8 cm open)."""
    return _upright(creation.box(extents=(0.04, 0.04, 0.12)))


def _can() -> trimesh.Trimesh:
    """Can of 2 cm radius, 11 cm tall."""
    return _upright(creation.cylinder(radius=0.02, height=0.11, sections=48))


def _ball() -> trimesh.Trimesh:
    """Ball of 3.5 cm radius (seed 003's sphere, sized for a hand), centred on the origin:
    the in-hand objects are held in the fingers, never stood on a table."""
    return creation.icosphere(subdivisions=3, radius=0.035)


def _cube() -> trimesh.Trimesh:
    """Cube of 5 cm sides, centred on the origin (in-hand)."""
    return creation.box(extents=(0.05, 0.05, 0.05))


def _roll() -> trimesh.Trimesh:
    """Short cylinder, 2.5 cm radius and 6 cm long along z, centred on the origin (in-hand)."""
    return creation.cylinder(radius=0.025, height=0.06, sections=32)


def _upright(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    """The mesh moved so the origin is the centre of its base footprint (minimum z = 0)."""
    mesh.apply_translation([0.0, 0.0, -mesh.bounds[0, 2]])
    return mesh


_BUILTINS: dict[str, Callable[[], trimesh.Trimesh]] = {"statuette": _statuette, "mug": _mug, "block": _block,
                                                       "can": _can, "ball": _ball, "cube": _cube, "roll": _roll}


def builtin_names() -> tuple[str, ...]:
    """Names of the procedural objects, usable as ``builtin:NAME``."""
    return tuple(_BUILTINS)


def make_builtin(name: str) -> trimesh.Trimesh:
    """Build the procedural object ``name`` (without the ``builtin:`` prefix).

    All built-ins are deterministic, in metres, object frame at the centre of the base
    footprint, +z up (minimum z = 0).  ``statuette`` and ``mug`` are non-convex, 1,000-3,000
    triangles, about 0.2 m tall, with parts 1-8 cm thick; ``block`` and ``can`` are the
    small convex objects a narrow parallel-jaw gripper can hold.  They are built from trimesh primitives: with trimesh's
    ``manifold`` boolean engine (package ``manifold3d``) the parts are united into one
    watertight shell; without it the parts are concatenated into a multi-shell mesh
    (like a real scan): each shell is closed, so trimesh still calls it watertight, but
    the shells interpenetrate, so it is not a clean solid (its ``volume`` over-counts).

    Raises:
        KeyError: ``name`` is not in :func:`builtin_names`.
    """
    return _BUILTINS[name]()


# --------------------------------------------------------------------------- loading


@dataclass(frozen=True, eq=False)
class ObjectMesh:
    """A loaded object.

    Attributes:
        name: ``builtin:NAME`` or the mesh file's name.
        source: the spec as given (``builtin:NAME`` or the path as written).
        mesh: triangle mesh in the object frame, metres, already scaled.
        watertight: every edge is shared by exactly two consistently wound faces.
        n_shells: number of connected components (shells) of the mesh.
    """

    name: str
    source: str
    mesh: trimesh.Trimesh
    watertight: bool
    n_shells: int

    @property
    def n_triangles(self) -> int:
        return int(len(self.mesh.faces))

    @property
    def extents(self) -> np.ndarray:
        """(3,) size of the axis-aligned bounding box in the object frame, metres."""
        return np.asarray(self.mesh.extents, dtype=float)

    def to_stl_bytes(self) -> bytes:
        """Binary STL of the (scaled) mesh; deterministic for a given geometry."""
        return trimesh.exchange.stl.export_stl(self.mesh)


def _sibling_field(field: str, name: str) -> str:
    """``object.mesh`` -> ``object.scale``: the field next to ``field`` called ``name``."""
    head, _, _ = field.rpartition(".")
    return f"{head}.{name}" if head else name


def load_object_mesh(
    spec: str,
    *,
    base_dir: Path,
    scale: float = 1.0,
    file: str | None = None,
    field: str = "object.mesh",
) -> ObjectMesh:
    """Load the object named by ``spec`` (``builtin:NAME`` or a mesh path).

    Args:
        spec: ``builtin:NAME`` or a path to a mesh file, relative to ``base_dir`` unless
            absolute.  Scenes (e.g. GLB) are flattened into one mesh.
        base_dir: directory relative paths are resolved against.
        scale: factor applied to the vertices (e.g. 0.001 for a file in millimetres).
        file: the file that contains ``spec`` (for error messages).
        field: the field of ``file`` that holds ``spec``; a bad ``scale`` is reported
            as the sibling field ``scale`` (``object.mesh`` -> ``object.scale``).

    Raises:
        InputError: unknown built-in, missing/unreadable file, mesh without faces or with
            zero area, non-finite vertices, ``scale`` not finite and > 0.

    Warns:
        UserWarning: the mesh is not watertight.
    """
    try:
        scale_ok = math.isfinite(float(scale)) and float(scale) > 0.0
    except (TypeError, ValueError):
        scale_ok = False
    if not scale_ok:
        raise InputError(file, _sibling_field(field, "scale"), f"scale must be a finite number > 0, got {shown(scale)}")

    if spec.startswith(BUILTIN_PREFIX):
        key = spec[len(BUILTIN_PREFIX):]
        if key not in _BUILTINS:
            valid = ", ".join(BUILTIN_PREFIX + n for n in builtin_names())
            raise InputError(file, field, f"unknown built-in object {shown(spec)}; valid: {valid}")
        name, where, mesh = spec, spec, make_builtin(key)
    else:
        path = Path(base_dir) / spec
        name, where = path.name, str(path)
        if not path.exists():
            raise InputError(file, field, f"mesh file not found: {path}")
        if not path.is_file():
            raise InputError(file, field, f"mesh path is not a file: {path}")
        try:
            mesh = trimesh.load_mesh(path)
        except Exception as exc:  # trimesh raises many types on bad input
            raise InputError(file, field, f"cannot read mesh file {path}: {exc or type(exc).__name__}") from exc
        if not isinstance(mesh, trimesh.Trimesh):
            raise InputError(file, field, f"{path} does not contain a triangle mesh")

    if len(mesh.faces) == 0:
        raise InputError(file, field, f"mesh {where} has no faces (empty file, or not a valid {Path(where).suffix} mesh)")
    if not np.all(np.isfinite(mesh.vertices)):
        raise InputError(file, field, f"mesh {where} has non-finite vertex coordinates")
    if not mesh.area > 0.0:
        raise InputError(file, field, f"mesh {where} has zero surface area")

    mesh = mesh.copy()
    if scale != 1.0:
        mesh.apply_scale(float(scale))
    size = float(mesh.extents.max())
    if not MIN_EXTENT <= size <= MAX_EXTENT:
        raise InputError(file, _sibling_field(field, "scale"), f"mesh {where} scaled by {scale:g} is {size:.3g} m "
                                                               f"across; expected {MIN_EXTENT:g} to {MAX_EXTENT:g} m "
                                                               "(is the scale right for the mesh's units?)")
    n_shells = int(mesh.body_count)
    watertight = bool(mesh.is_watertight and mesh.is_winding_consistent)
    if not watertight:
        winding = "consistent" if mesh.is_winding_consistent else "inconsistent"
        warnings.warn(
            f"{where}: mesh is not watertight ({n_shells} shell(s), {winding} winding); "
            "volume and inside tests will be approximate",
            UserWarning,
            stacklevel=2,
        )
    return ObjectMesh(name=name, source=spec, mesh=mesh, watertight=watertight, n_shells=n_shells)


def mesh_sha256(obj: ObjectMesh) -> str:
    """SHA-256 hex digest of the scaled geometry.

    Canonical bytes: vertex and face counts as two little-endian uint64, then the
    (V, 3) vertices as float64 little-endian (``-0.0`` normalised to ``0.0``), then the
    (F, 3) vertex indices as int64 little-endian.
    """
    v = np.ascontiguousarray(np.asarray(obj.mesh.vertices, dtype="<f8") + 0.0)
    f = np.ascontiguousarray(np.asarray(obj.mesh.faces, dtype="<i8"))
    h = hashlib.sha256(struct.pack("<QQ", len(v), len(f)))
    h.update(v.tobytes())
    h.update(f.tobytes())
    return h.hexdigest()
