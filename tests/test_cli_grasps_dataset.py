"""`regrasp grasps build SCENE --meshes DIR` (regrasp_cli.commands.dataset): the grasp lists
of a folder of meshes, one task per mesh x hand, on loky processes and on a local Dask
cluster.  A tiny dataset (a box, a can and an empty file) with small build options: both
backends write the same files with the same grasps, under the names a one-scene build
gives them; the empty file is reported and the others still built (exit 1); bad input is
one error line with exit 2."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
import trimesh
import yaml

from cli_helpers import ROBOT_YAML, SCENE_YAML, assert_one_error_line, needs_separate_stderr, run, scene_dict, \
    write_scene

# a grid of 8 positions x 64 orientations, no pinch pass, 20 grasps: about a second a list
SMALL = ("--hand", "right", "--target", "20", "--positions", "8", "--orientations", "64", "--pinch-frames", "0")
BUILT = ("box.stl", "can.stl")

pytestmark = needs_separate_stderr


@pytest.fixture(scope="module")
def dataset(tmp_path_factory) -> tuple[Path, Path]:
    """(scene, meshes folder): a scene naming its robot, object and a mesh obstacle by
    relative paths (its object the box), and a folder of a box, a can, an empty .stl and
    a text file that is no mesh."""
    root = tmp_path_factory.mktemp("dataset")
    meshes = root / "meshes"
    meshes.mkdir()
    trimesh.creation.box([0.05, 0.04, 0.06]).export(meshes / "box.stl")
    trimesh.creation.cylinder(radius=0.025, height=0.08, sections=16).export(meshes / "can.stl")
    (meshes / "empty.stl").write_bytes(b"")
    (meshes / "notes.txt").write_text("not a mesh\n")
    trimesh.creation.box([0.3, 0.3, 0.3]).export(root / "crate.stl")
    d = scene_dict()
    d["robot"] = os.path.relpath(ROBOT_YAML, root)
    d["object"]["mesh"] = "meshes/box.stl"
    d["obstacles"].append({"name": "crate", "mesh": {"file": "crate.stl"}, "pose": {"xyz": [2.0, 2.0, 0.15]}})
    return write_scene(root / "scene.yaml", d), meshes


def grasp_files(cache: Path) -> dict[str, Path]:
    return {p.name: p for p in sorted((cache / "grasps").glob("*.h5"))}


@pytest.fixture(scope="module")
def on_loky(dataset, tmp_path_factory):
    """The dataset built on two loky processes: (result, cache folder)."""
    scene, meshes = dataset
    cache = tmp_path_factory.mktemp("loky-cache")
    return run("grasps", "build", scene, "--meshes", meshes, *SMALL, "--jobs", "2", "--cache-dir", cache), cache


@pytest.fixture(scope="module")
def cluster():
    distributed = pytest.importorskip("distributed", reason="needs the dask extra: pip install 'regrasp[dask]'")
    # two threads in the worker process: its two tasks must still not run into each other
    with distributed.LocalCluster(n_workers=1, threads_per_worker=2, processes=True, dashboard_address=None) as c:
        yield c


def test_loky_builds_every_mesh_and_reports_the_empty_one(on_loky):
    result, cache = on_loky
    line = assert_one_error_line(result, "1 of 3 grasp lists failed", "empty.stl (right)", exit_code=1)
    assert "box.stl" not in line and "can.stl" not in line
    assert sorted(name.split("-")[0] for name in grasp_files(cache)) == list(BUILT)
    rows = {cells[0]: cells for cells in ([c.strip() for c in ln.strip("│").split("│")]
                                         for ln in result.stdout.splitlines() if ln.startswith("│"))}
    assert list(rows) == ["box.stl", "can.stl", "empty.stl"]  # sorted by name, the text file left out
    for mesh in BUILT:
        assert rows[mesh][1] == "right" and int(rows[mesh][2]) >= 20 and rows[mesh][4] == "ok"
    assert rows["empty.stl"][2] == "-" and rows["empty.stl"][4].startswith("failed: object.mesh")
    assert "empty.stl has no faces" in result.stdout
    assert "regrasp-scene-" not in result.output  # the failure does not name the task's temporary scene


def test_the_lists_are_where_a_one_scene_build_puts_them(dataset, on_loky):
    """`regrasp plan` of the scene (its object the box) would find the box's list, fresh."""
    from regrasp_cli.artefacts import build_options, grasp_list_path
    from regrasp_cli.grasp.build import provenance
    from regrasp_cli.scene import load_problem
    from regrasp_cli.store import is_fresh

    scene, _ = dataset
    _, cache = on_loky
    problem = load_problem(scene, cache)
    options = build_options(0, None, 1, 8, 64, 20, pinch_frames=0)
    path = grasp_list_path(cache.resolve(), problem, "right", options)
    assert path.name.startswith("box.stl-") and path in grasp_files(cache.resolve()).values()
    assert is_fresh(path, provenance(problem, "right", options))


def test_dask_gives_the_same_lists_as_loky(dataset, on_loky, cluster, tmp_path):
    from regrasp_cli.grasp.build import read_grasp_list

    scene, meshes = dataset
    _, loky_cache = on_loky
    result = run("grasps", "build", scene, "--meshes", meshes, *SMALL, "--backend", "dask",
                 "--scheduler", cluster.scheduler_address, "--cache-dir", tmp_path / "cache")
    assert_one_error_line(result, "1 of 3 grasp lists failed", "empty.stl (right)", exit_code=1)
    assert f"dask at {cluster.scheduler_address}" in result.stdout
    on_dask, on_loky_files = grasp_files(tmp_path / "cache"), grasp_files(loky_cache)
    assert list(on_dask) == list(on_loky_files) and len(on_dask) == len(BUILT)
    for name in on_dask:
        a, b = read_grasp_list(on_dask[name]), read_grasp_list(on_loky_files[name])
        assert len(a) >= 20 and a.finger_names == b.finger_names
        for field in ("X_OG", "finger_q", "in_contact", "points", "normals", "scores", "frame_index"):
            assert np.array_equal(getattr(a, field), getattr(b, field), equal_nan=field in ("points", "normals")), \
                (name, field)


# --------------------------------------------------------------------------- the parts


def test_mesh_files_are_sorted_and_not_recursive(tmp_path):
    from regrasp_cli.commands.dataset import mesh_files

    for name in ("b.STL", "a.obj", "c.glb", "readme.md"):
        (tmp_path / name).write_text("")
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "d.stl").write_text("")
    assert [p.name for p in mesh_files(tmp_path)] == ["a.obj", "b.STL", "c.glb"]
    assert all(p.is_absolute() for p in mesh_files(tmp_path))


def test_tasks_carry_the_scene_with_absolute_paths(dataset, tmp_path):
    """Mesh-major, one per hand; each task's scene loads from any folder, its object the mesh."""
    from regrasp_cli.artefacts import build_options
    from regrasp_cli.commands.dataset import mesh_files, tasks_of
    from regrasp_cli.config import load_scene_spec

    scene, meshes = dataset
    files = mesh_files(meshes)
    tasks = tasks_of(scene, files, ["right", "left"], build_options(0, None, 4, None, None), Path("cache"))
    assert [(t.mesh.name, t.hand) for t in tasks] == [(f.name, h) for f in files for h in ("right", "left")]
    assert all(t.options.jobs == 1 and t.cache_dir.is_absolute() for t in tasks)
    copy = tmp_path / "elsewhere.yaml"
    copy.write_text(tasks[2].scene_yaml)
    spec, original = load_scene_spec(copy), load_scene_spec(scene)
    assert spec.object.mesh == str(files[1]) and spec.robot == original.robot
    assert spec.obstacles[-1].mesh == original.obstacles[-1].mesh == scene.parent / "crate.stl"
    assert yaml.safe_load(tasks[0].scene_yaml)["task"] == yaml.safe_load(scene.read_text())["task"]


# --------------------------------------------------------------------------- bad input and help


def test_missing_folder(cache_dir, tmp_path):
    result = run("--cache-dir", cache_dir, "grasps", "build", SCENE_YAML, "--meshes", tmp_path / "nope")
    assert_one_error_line(result, "--meshes", "no such folder", "nope")


def test_folder_without_a_mesh(cache_dir, tmp_path):
    (tmp_path / "notes.txt").write_text("not a mesh\n")
    result = run("--cache-dir", cache_dir, "grasps", "build", SCENE_YAML, "--meshes", tmp_path)
    assert_one_error_line(result, "--meshes", "no mesh file", ".stl")


def test_scheduler_without_dask(cache_dir, dataset):
    _, meshes = dataset
    result = run("--cache-dir", cache_dir, "grasps", "build", SCENE_YAML, "--meshes", meshes,
                 "--scheduler", "tcp://127.0.0.1:8786")
    assert_one_error_line(result, "--scheduler", "only for --backend dask")


def test_dask_without_a_scheduler(cache_dir, dataset):
    _, meshes = dataset
    result = run("--cache-dir", cache_dir, "grasps", "build", SCENE_YAML, "--meshes", meshes, "--backend", "dask")
    assert_one_error_line(result, "--scheduler", "existing Dask cluster")


def test_backend_without_meshes(cache_dir):
    result = run("--cache-dir", cache_dir, "grasps", "build", SCENE_YAML, "--backend", "dask")
    assert_one_error_line(result, "--backend", "only with --meshes")


def test_help_names_the_dataset_options():
    result = run("grasps", "build", "--help")
    assert result.exit_code == 0, result.output
    for word in ("--meshes", "DIR", ".obj .stl .ply .off .glb", "subfolders", "--backend", "loky", "dask",
                 "--scheduler"):
        assert word in result.stdout, word
