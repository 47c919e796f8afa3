"""Tests of regrasp_cli.model.objects: built-in objects, mesh loading, hashing."""

from __future__ import annotations

import io
import warnings
from pathlib import Path

import numpy as np
import pytest
import trimesh

from regrasp_cli.errors import InputError
from regrasp_cli.model.objects import (
    ObjectMesh,
    builtin_names,
    load_object_mesh,
    make_builtin,
    mesh_sha256,
)

NAMES = builtin_names()


@pytest.fixture(params=["union", "concatenate"])
def engine(request, monkeypatch):
    """Build the built-ins both with trimesh's manifold union (if installed) and with the
    concatenation fallback used when it is not."""
    if request.param == "union":
        if "manifold" not in trimesh.boolean.engines_available:
            pytest.skip("manifold3d not installed")
    else:
        monkeypatch.setattr(trimesh.boolean, "engines_available", {None})
    return request.param


def test_builtin_names():
    assert {"statuette", "mug", "block", "can"} <= set(NAMES)


@pytest.mark.parametrize("name", ["statuette", "mug"])
def test_builtin_shape(name, engine):
    mesh = make_builtin(name)
    assert 1000 <= len(mesh.faces) <= 3000
    lo, hi = mesh.bounds
    assert lo[2] >= -1e-9 and abs(lo[2]) < 1e-6  # rests on z = 0
    assert 0.15 <= hi[2] <= 0.30  # height, metres
    # Non-convexity.  Every shell is closed, so the volume of the solid they bound is at
    # most the sum of the shell volumes (equal for one watertight shell, larger when
    # concatenated shells overlap).  A convex hull 1.5x larger than that upper bound thus
    # proves the solid is far from convex, whichever way the parts were combined.
    shells = mesh.split(only_watertight=False)
    assert all(s.is_watertight for s in shells)
    solid_volume_bound = sum(abs(s.volume) for s in shells)
    assert mesh.convex_hull.volume > 1.5 * solid_volume_bound
    # Footprint centred on the origin for the base (the lowest 5 mm of the object).
    base = mesh.vertices[mesh.vertices[:, 2] < 0.005]
    centre = (base[:, :2].min(axis=0) + base[:, :2].max(axis=0)) / 2.0
    assert np.allclose(centre, 0.0, atol=1e-6)


@pytest.mark.parametrize("name, extents", [("block", (0.04, 0.04, 0.12)), ("can", (0.04, 0.04, 0.11))])
def test_builtin_jaw_objects(name, extents):
    """The small convex objects: closed, convex, the stated size, standing on z = 0 with
    the footprint centred, and narrower than Baxter's open jaw (4.8 cm)."""
    mesh = make_builtin(name)
    assert mesh.is_watertight and mesh.is_winding_consistent
    assert np.isclose(mesh.convex_hull.volume, mesh.volume, rtol=1e-9)
    assert np.allclose(mesh.extents, extents, atol=2e-4)
    assert np.isclose(mesh.bounds[0, 2], 0.0, atol=1e-12)
    assert np.allclose(mesh.bounds[:, :2].mean(axis=0), 0.0, atol=1e-9)
    assert max(mesh.extents[:2]) < 0.048


@pytest.mark.parametrize("name", NAMES)
def test_builtin_deterministic(name):
    a, b = make_builtin(name), make_builtin(name)
    assert np.array_equal(a.vertices, b.vertices) and np.array_equal(a.faces, b.faces)
    oa = load_object_mesh(f"builtin:{name}", base_dir=Path("."))
    ob = load_object_mesh(f"builtin:{name}", base_dir=Path("."))
    assert mesh_sha256(oa) == mesh_sha256(ob)
    assert oa.to_stl_bytes() == ob.to_stl_bytes()


def test_load_builtin_fields():
    obj = load_object_mesh("builtin:statuette", base_dir=Path("."))
    assert isinstance(obj, ObjectMesh)
    assert obj.name == obj.source == "builtin:statuette"
    assert obj.n_triangles == len(obj.mesh.faces)
    assert obj.extents.shape == (3,)
    assert obj.n_shells >= 1
    stl = obj.to_stl_bytes()
    assert len(stl) == 84 + 50 * obj.n_triangles
    assert len(trimesh.load_mesh(io.BytesIO(stl), file_type="stl").faces) == obj.n_triangles


def test_scale_multiplies_extents_and_changes_hash():
    one = load_object_mesh("builtin:mug", base_dir=Path("."))
    two = load_object_mesh("builtin:mug", base_dir=Path("."), scale=2.0)
    assert np.allclose(two.extents, 2.0 * one.extents)
    assert mesh_sha256(one) != mesh_sha256(two)


@pytest.mark.parametrize("ext", ["stl", "obj", "ply", "off", "glb"])
def test_file_round_trip(tmp_path, ext):
    src = make_builtin("statuette")
    src.export(tmp_path / f"statuette.{ext}")
    obj = load_object_mesh(f"statuette.{ext}", base_dir=tmp_path)
    assert obj.name == f"statuette.{ext}" and obj.source == f"statuette.{ext}"
    assert obj.n_triangles == len(src.faces)
    assert np.allclose(obj.extents, src.extents, atol=1e-6)
    centi = load_object_mesh(f"statuette.{ext}", base_dir=tmp_path, scale=1e-2)  # 2.2 mm: objects.MIN_EXTENT is 1
    assert np.allclose(centi.extents, 1e-2 * obj.extents)


def test_scene_is_flattened(tmp_path):
    scene = trimesh.Scene([trimesh.creation.box(), trimesh.creation.icosphere(1)])
    scene.export(tmp_path / "two.glb")
    obj = load_object_mesh("two.glb", base_dir=tmp_path)
    assert obj.n_triangles == 12 + 80


def _write(tmp_path: Path, name: str, data: bytes | str) -> str:
    p = tmp_path / name
    p.write_bytes(data if isinstance(data, bytes) else data.encode())
    return name


@pytest.mark.parametrize(
    ("spec", "kwargs", "field", "words"),
    [
        ("builtin:cow", {}, "object.mesh", "builtin:statuette"),
        ("missing.stl", {}, "object.mesh", "not found"),
        ("garbage.stl", {}, "object.mesh", "garbage.stl"),
        ("empty.obj", {}, "object.mesh", "no faces"),
        ("point.obj", {}, "object.mesh", "zero surface area"),
        ("box.stl", {"scale": 0.0}, "object.scale", "scale"),
        ("box.stl", {"scale": float("inf")}, "object.scale", "scale"),
        ("box.stl", {"scale": -1.0}, "object.scale", "scale"),
    ],
)
def test_errors(tmp_path, spec, kwargs, field, words):
    _write(tmp_path, "garbage.stl", bytes(range(256)) * 3 + b"\xff\xfe not a mesh")
    _write(tmp_path, "empty.obj", "")
    _write(tmp_path, "point.obj", "v 1 2 3\nv 1 2 3\nv 1 2 3\nf 1 2 3\n")
    trimesh.creation.box().export(tmp_path / "box.stl")
    with pytest.raises(InputError) as info:
        load_object_mesh(spec, base_dir=tmp_path, file="task.yaml", **kwargs)
    err = info.value
    assert err.file == "task.yaml" and err.field == field
    assert field in str(err) and words in str(err)


def test_open_mesh_warns(tmp_path):
    box = trimesh.creation.box(extents=[0.05, 0.05, 0.1])
    open_box = trimesh.Trimesh(box.vertices, box.faces[:-2])  # one side removed
    open_box.export(tmp_path / "open.stl")
    with pytest.warns(UserWarning, match=r"open\.stl.*not watertight.*1 shell"):
        obj = load_object_mesh("open.stl", base_dir=tmp_path)
    assert not obj.watertight and obj.n_shells == 1 and obj.n_triangles == 10


def test_closed_mesh_does_not_warn(tmp_path):
    trimesh.creation.box().export(tmp_path / "box.stl")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        obj = load_object_mesh("box.stl", base_dir=tmp_path)
    assert obj.watertight and obj.n_shells == 1


def test_hash_is_canonical():
    obj = load_object_mesh("builtin:mug", base_dir=Path("."))
    copy = ObjectMesh(obj.name, obj.source, obj.mesh.copy(), obj.watertight, obj.n_shells)
    assert mesh_sha256(copy) == mesh_sha256(obj)
    assert len(mesh_sha256(obj)) == 64
