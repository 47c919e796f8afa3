"""`regrasp grasps build` and `regrasp grasps show` (click.testing.CliRunner on
regrasp_cli.cli.main): one small build end to end, show, help, a stale list refused, and
bad input as exit code 2 with one `error:` line and no traceback."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh

from cli_helpers import assert_one_error_line, needs_separate_stderr, run, scene_dict, write_scene

ROOT = Path(__file__).resolve().parents[1]
ROBOT_YAML = ROOT / "configs" / "robots" / "humanoid43" / "robot.yaml"
SCENE_YAML = ROOT / "configs" / "scenes" / "desk_handover.yaml"
SMALL = ["--hand", "right", "--positions", "8", "--orientations", "64", "--target", "0", "--pinch-frames", "256",
         "--jobs", "1"]

pytestmark = needs_separate_stderr


@pytest.fixture(scope="module")
def built(problem, cache_dir):
    """One small `grasps build` into the run's cache: (result, path of the list)."""
    from regrasp_cli.artefacts import build_options, grasp_list_path

    result = run("--cache-dir", cache_dir, "grasps", "build", SCENE_YAML, *SMALL)
    options = build_options(0, None, 1, 8, 64, 0, pinch_frames=256)
    return result, grasp_list_path(Path(cache_dir).resolve(), problem, "right", options)


# --------------------------------------------------------------------------- build and show


def test_build_prints_the_summary_and_writes_the_list(built, cache_dir):
    result, path = built
    assert result.exit_code == 0, (result.output, result.exception)
    out = result.stdout
    assert "Grasp lists" in out and "friction 0.5" in out and "builtin:statuette" in out
    for column in ("frames tried", "force closure", "kept (distinct)", "best quality"):
        assert column in out
    assert "Time per stage" in out and "grasp search (frames)" in out
    assert "left" not in out.split("Grasp lists")[1]  # --hand right: one row
    assert path.is_file() and path.parent == Path(cache_dir).resolve() / "grasps"
    assert f"right hand: {path}" in out
    # the row of the summary: frames tried = positions grid x 64 orientations, then (no
    # target: every frame) the pinch frames
    row = next(ln for ln in out.splitlines() if ln.startswith("│") and ln.strip("│ ").startswith("right"))
    cells = [c.strip() for c in row.strip("│┃ ").split("│")]
    frames, pinch, kept = int(cells[1]), int(cells[2]), int(cells[6])
    assert (frames - pinch) % 64 == 0 and frames - pinch >= 8 * 64 and pinch > 0
    from regrasp_cli.grasp.build import read_grasp_list

    assert kept == len(read_grasp_list(path))


def test_show_prints_provenance_and_grasps(built):
    _, path = built
    result = run("grasps", "show", path)
    assert result.exit_code == 0, (result.output, result.exception)
    out = result.stdout
    for word in ("provenance", "regrasp.grasps v1", "software", "created", "sha256 mesh", "sha256 params",
                 "sha256 hand", "hand", "right", "Best", "epsilon", "total", "thumb"):
        assert word in out, word
    from regrasp_cli.grasp.build import read_grasp_list

    g = read_grasp_list(path)
    rows = {cells[0]: cells[1] for cells in ([c.strip() for c in ln.strip("│").split("│")]
                                            for ln in out.splitlines() if ln.startswith("│")) if len(cells) == 2}
    assert rows["hand"] == "right" and rows["grasps"] == str(len(g))
    assert rows["format"] == "regrasp.grasps v1"
    # the best grasp's total is shown with 3 decimals
    assert f"{g.scores[0, -1]:.3f}" in out


def test_show_best_limits_the_rows(built):
    _, path = built
    result = run("grasps", "show", path, "--best", "1")
    assert result.exit_code == 0
    assert "Best 1 grasps" in result.stdout


def test_show_refuses_a_list_stale_for_the_scene(built, tmp_path, cache_dir):
    _, path = built
    d = scene_dict()
    d["object"]["friction"] = 0.3
    other = write_scene(tmp_path / "other_friction.yaml", d)
    result = run("--cache-dir", cache_dir, "grasps", "show", path, "--scene", other)
    line = assert_one_error_line(result, str(path))
    assert "params" in line and "rebuild" in line


def test_show_accepts_the_list_for_its_own_scene_whatever_the_options(built, cache_dir):
    """The list was built with small, non-default grids: it is still fresh for its scene."""
    _, path = built
    result = run("--cache-dir", cache_dir, "grasps", "show", path, "--scene", SCENE_YAML)
    assert result.exit_code == 0, (result.output, result.exception)
    assert "Best" in result.stdout


def test_show_refuses_a_list_for_another_object(built, tmp_path, cache_dir):
    _, path = built
    d = scene_dict()
    d["object"]["mesh"] = "builtin:mug"
    other = write_scene(tmp_path / "mug.yaml", d)
    result = run("--cache-dir", cache_dir, "grasps", "show", path, "--scene", other)
    line = assert_one_error_line(result, str(path))
    assert "mesh" in line


def test_show_missing_file(tmp_path):
    missing = tmp_path / "nope.h5"
    assert_one_error_line(run("grasps", "show", missing), str(missing))


def test_show_not_an_hdf5_file(tmp_path):
    bad = tmp_path / "bad.h5"
    bad.write_text("not hdf5")
    assert_one_error_line(run("grasps", "show", bad), str(bad))


# --------------------------------------------------------------------------- help


def test_grasps_help():
    result = run("grasps", "--help")
    assert result.exit_code == 0
    assert "build" in result.stdout and "show" in result.stdout


def test_build_help():
    result = run("grasps", "build", "--help")
    assert result.exit_code == 0, result.output
    for word in ("SCENE", "--hand", "right", "left", "both", "--seed", "--jobs", "--positions", "--orientations",
                 "--target"):
        assert word in result.stdout, word


def test_show_help():
    result = run("grasps", "show", "--help")
    assert result.exit_code == 0, result.output
    for word in ("FILE", "--best", "--scene"):
        assert word in result.stdout, word


# --------------------------------------------------------------------------- bad input


def test_unknown_hand_is_a_usage_error():
    result = run("grasps", "build", SCENE_YAML, "--hand", "middle")
    assert result.exit_code == 2
    assert "Traceback" not in result.output
    assert "Invalid value for '--hand'" in result.stderr and "middle" in result.stderr


def _degenerate_stl(tmp_path: Path) -> Path:
    """Every triangle has three identical vertices: no area at all."""
    v = np.repeat(np.array([[0.0, 0.0, 0.0], [0.1, 0.0, 0.0], [0.0, 0.1, 0.05], [0.05, 0.05, 0.1]]), 3, axis=0)
    mesh = trimesh.Trimesh(v, np.arange(len(v)).reshape(-1, 3), process=False)
    path = tmp_path / "degenerate.stl"
    path.write_bytes(trimesh.exchange.stl.export_stl(mesh))
    return path


def _flat_box_stl(tmp_path: Path) -> Path:
    path = tmp_path / "flat_box.stl"
    trimesh.creation.box([0.1, 0.1, 0.0]).export(path)
    return path


def _scene_with(tmp_path: Path, **object_fields) -> Path:
    d = scene_dict()
    d["object"].update(object_fields)
    return write_scene(tmp_path / "scene.yaml", d)


@pytest.mark.parametrize("case, words", [
    ("degenerate_mesh", ("scene.yaml", "object.mesh", "degenerate.stl")),
    ("flat_box", ("scene.yaml", "object.mesh", "flat_box.stl", "volume")),
    ("friction_0", ("scene.yaml", "object.friction")),
    ("friction_negative", ("scene.yaml", "object.friction")),
    ("statuette_x30", ("scene.yaml", "object.mesh", "far larger than the right hand", "object.scale")),
])
def test_bad_scene(tmp_path, cache_dir, case, words):
    if case == "degenerate_mesh":
        scene = _scene_with(tmp_path, mesh=str(_degenerate_stl(tmp_path)))
    elif case == "flat_box":
        scene = _scene_with(tmp_path, mesh=str(_flat_box_stl(tmp_path)))
    elif case == "friction_0":
        scene = _scene_with(tmp_path, friction=0)
    elif case == "statuette_x30":  # 6 m tall: a scale meant for a mesh in other units
        scene = _scene_with(tmp_path, scale=30.0)
    else:
        scene = _scene_with(tmp_path, friction=-0.5)
    result = run("--cache-dir", cache_dir, "grasps", "build", scene, *SMALL)
    assert_one_error_line(result, *words)
    assert not list((tmp_path).glob("**/*.h5"))


def test_flat_box_is_refused_by_info_too(tmp_path, cache_dir):
    """The check is on the scene's object, not on the grasp stage only."""
    scene = _scene_with(tmp_path, mesh=str(_flat_box_stl(tmp_path)))
    assert_one_error_line(run("--cache-dir", cache_dir, "info", scene), "object.mesh", "thickness")


def test_flat_box_obstacle_mesh_is_still_allowed(tmp_path):
    """Only the manipulated object needs a volume: a flat mesh obstacle loads."""
    from regrasp_cli.model.objects import load_object_mesh

    path = _flat_box_stl(tmp_path)
    with pytest.warns(UserWarning):
        obj = load_object_mesh(str(path), base_dir=tmp_path, field="obstacles[0].mesh.file")
    assert obj.extents[2] == 0.0


@pytest.mark.parametrize("option, value", [("--positions", "0"), ("--jobs", "0"), ("--orientations", "0"),
                                           ("--positions", "-3"), ("--target", "-1"), ("--pinch-frames", "-1")])
def test_bad_numbers(cache_dir, option, value):
    result = run("--cache-dir", cache_dir, "grasps", "build", SCENE_YAML, *SMALL, option, value)
    assert_one_error_line(result, option)


@pytest.mark.parametrize("weights", ["1,1,1", "a,b,c,d", "1,1,1,-6", "0,0,0,0"])
def test_bad_weights(cache_dir, weights):
    result = run("--cache-dir", cache_dir, "grasps", "build", SCENE_YAML, "--weights", weights)
    line = assert_one_error_line(result, "--weights")
    assert "four numbers" in line


def test_weights_change_the_ranking_inputs(problem):
    """Other weights are other parameters: the list is another artefact (own hash)."""
    from regrasp_cli.grasp.build import provenance
    from regrasp_cli.artefacts import build_options

    a = provenance(problem, "right", build_options(0, None, 1, 8, 64, 0))
    b = provenance(problem, "right", build_options(0, None, 1, 8, 64, 0, "1,1,1,1"))
    assert a.inputs["params"] != b.inputs["params"] and a.inputs["mesh"] == b.inputs["mesh"]
    c = provenance(problem, "right", build_options(0, None, 1, 8, 64, 0, pinch_frames=256))
    assert c.inputs["params"] != a.inputs["params"]  # the pinch pass's size too
