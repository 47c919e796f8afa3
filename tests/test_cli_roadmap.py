"""`regrasp roadmap build` and `regrasp roadmap show` (click.testing.CliRunner on
regrasp_cli.cli.main): one small build end to end, show (with and without a scene), a
roadmap stale for a moved obstacle refused, help, and bad input as exit code 2 with one
`error:` line and no traceback."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
import yaml

from cli_helpers import assert_one_error_line, needs_separate_stderr, run, scene_dict, write_scene

ROOT = Path(__file__).resolve().parents[1]
ROBOT_DIR = ROOT / "configs" / "robots" / "humanoid43"
ROBOT_YAML = ROBOT_DIR / "robot.yaml"
SCENE_YAML = ROOT / "configs" / "scenes" / "desk_handover.yaml"

pytestmark = needs_separate_stderr










def fresh_cache(tmp: Path, cache_dir: Path) -> Path:
    """An empty cache holding only the (slow to compute) self-collision pairs."""
    d = tmp / "cache"
    src = Path(cache_dir) / "self_collision"
    if src.is_dir():
        shutil.copytree(src, d / "self_collision")
    return d


def table_rows(out: str) -> dict[str, str]:
    rows = {}
    for ln in out.splitlines():
        if ln.startswith("│"):
            cells = [c.strip() for c in ln.strip().strip("│").split("│")]
            if len(cells) == 2:
                rows[cells[0]] = cells[1]
    return rows


@pytest.fixture(scope="module")
def built(problem, cache_dir, tmp_path_factory):
    """One small `roadmap build` into a fresh cache: (result, cache dir, roadmap file)."""
    d = fresh_cache(tmp_path_factory.mktemp("cli_roadmap"), cache_dir)
    result = run("--cache-dir", d, "roadmap", "build", SCENE_YAML, "--nodes", "8", "--jobs", "1")
    files = sorted((d / "roadmap").glob("*.h5")) if (d / "roadmap").is_dir() else []
    return result, d, files


# --------------------------------------------------------------------------- build and show


def test_build_prints_the_summary_and_writes_the_roadmap(built):
    result, d, files = built
    assert result.exit_code == 0, (result.output, result.exception)
    assert len(files) == 1, files
    out = result.stdout
    assert "graph mode, 8 nodes per elementary roadmap" in out
    rows = table_rows(out)
    for key in ("R_r (torso + right arm)", "R_l (torso + left arm)", "Super Graph", "collision checks",
                "collision checks / s"):
        assert key in rows, (key, rows)
    assert rows["R_r (torso + right arm)"].startswith("8 nodes")
    assert rows["R_l (torso + left arm)"].startswith("8 nodes")
    assert int(rows["collision checks"].replace(",", "")) > 0
    assert "Time per stage" in out
    for stage in ("elementary roadmaps", "Super Graph nodes", "Super Graph edges", "write", "total"):
        assert stage in rows, stage
        float(rows[stage])
    assert f"roadmap: {files[0]}" in out
    # the printed summary is the stored roadmap's
    from regrasp_cli.roadmap.build import read_roadmap, summary

    art = read_roadmap(files[0])
    for k, v in summary(art).items():
        assert rows[k] == v


def test_show_prints_provenance_and_summary(built):
    _, _, files = built
    result = run("roadmap", "show", files[0])
    assert result.exit_code == 0, (result.output, result.exception)
    rows = table_rows(result.stdout)
    assert rows["format"] == "regrasp.roadmap v2"
    for key in ("software", "created", "sha256 urdf", "sha256 robot_yaml", "sha256 obstacles", "sha256 params",
                "R_r (torso + right arm)", "R_l (torso + left arm)", "Super Graph"):
        assert key in rows, key
    assert rows["R_r (torso + right arm)"].startswith("8 nodes")


def test_show_accepts_its_own_scene(built):
    _, d, files = built
    result = run("--cache-dir", d, "roadmap", "show", files[0], "--scene", SCENE_YAML)
    assert result.exit_code == 0, (result.output, result.exception)
    assert "Super Graph" in result.stdout


def test_show_refuses_a_roadmap_for_a_moved_obstacle(built, tmp_path):
    _, d, files = built
    s = scene_dict()
    s["obstacles"][0]["pose"]["xyz"][0] += 0.1
    other = write_scene(tmp_path / "moved.yaml", s)
    result = run("--cache-dir", d, "roadmap", "show", files[0], "--scene", other)
    line = assert_one_error_line(result, str(files[0]), "obstacles")
    assert "rebuild" in line and "roadmap build" in line


def test_show_missing_file(tmp_path):
    missing = tmp_path / "nope.h5"
    assert_one_error_line(run("roadmap", "show", missing), str(missing))


def test_build_with_no_free_configuration_is_an_error_naming_the_cause(problem, cache_dir, tmp_path):
    """A box around the shoulders: every sample collides.  The roadmap is not written as
    a success (this used to write one with 0 nodes, and before that to crash with a numpy
    reshape error): exit 1, one line naming the pairs that rejected the samples."""
    s = scene_dict()
    s["obstacles"].append({"name": "cage", "box": {"size": [0.3, 0.3, 0.3]}, "pose": {"xyz": [0.0, 0.0, 1.2]}})
    scene = write_scene(tmp_path / "cage.yaml", s)
    d = fresh_cache(tmp_path, cache_dir)
    result = run("--cache-dir", d, "roadmap", "build", scene, "--nodes", "4", "--jobs", "1", "--tree")
    assert result.exit_code == 1, (result.output, result.exception)
    assert "Traceback" not in result.output
    errors = [ln for ln in result.stderr.splitlines() if ln.startswith("error:")]
    assert len(errors) == 1, result.stderr
    for words in ("the roadmap is empty", "R_r (torso + right arm) has no node", "samples collide",
                  "–obstacle:cage", "rest configuration"):
        assert words in errors[0], (words, errors[0])
    assert not list((d / "roadmap").glob("*.h5"))


# --------------------------------------------------------------------------- help


def test_roadmap_help():
    result = run("roadmap", "--help")
    assert result.exit_code == 0, result.output
    assert "build" in result.stdout and "show" in result.stdout and "Super Graph" in result.stdout


def test_build_help():
    result = run("roadmap", "build", "--help")
    assert result.exit_code == 0, result.output
    for word in ("SCENE", "--nodes", "--tree", "--seed", "--jobs"):
        assert word in result.stdout, word


def test_show_help():
    result = run("roadmap", "show", "--help")
    assert result.exit_code == 0, result.output
    for word in ("FILE", "--scene"):
        assert word in result.stdout, word


# --------------------------------------------------------------------------- bad input


@pytest.mark.parametrize("option,value", [("--nodes", "0"), ("--nodes", "-3"), ("--jobs", "0")])
def test_bad_numbers(tmp_path, option, value):
    d = tmp_path / "cache"
    line = assert_one_error_line(run("--cache-dir", d, "roadmap", "build", SCENE_YAML, option, value), option)
    assert value in line
    assert not (d / "roadmap").exists()


def scene_with_robot(tmp_path: Path, edit) -> tuple[Path, Path]:
    """A copy of the default robot (robot.yaml edited by ``edit(dict)``) and a scene using
    it: (scene path, robot.yaml path)."""
    r = yaml.safe_load(ROBOT_YAML.read_text())
    edit(r)
    shutil.copy(ROBOT_DIR / "robot.urdf", tmp_path / "robot.urdf")
    robot_yaml = tmp_path / "robot.yaml"
    robot_yaml.write_text(yaml.safe_dump(r, sort_keys=False))
    s = scene_dict()
    s["robot"] = str(robot_yaml)
    return write_scene(tmp_path / "scene.yaml", s), robot_yaml


def test_unknown_joint_in_the_robot_groups(tmp_path):
    def edit(r):
        r["groups"]["right_arm"] = r["groups"]["right_arm"][:-1] + ["r_arm_j99"]

    scene, robot_yaml = scene_with_robot(tmp_path, edit)
    d = tmp_path / "cache"
    assert_one_error_line(run("--cache-dir", d, "roadmap", "build", scene, "--nodes", "4", "--jobs", "1"),
                          "r_arm_j99", "groups.right_arm", str(robot_yaml))
    assert not (d / "roadmap").exists()


def test_unknown_group_in_the_robot(tmp_path):
    scene, robot_yaml = scene_with_robot(tmp_path, lambda r: r["groups"].update(head=["torso_yaw"]))
    line = assert_one_error_line(run("--cache-dir", tmp_path / "cache", "roadmap", "build", scene, "--nodes", "4"),
                                 "groups.head", str(robot_yaml))
    assert "torso, right_arm, left_arm" in line


def test_missing_scene_file(tmp_path):
    missing = tmp_path / "nope.yaml"
    assert_one_error_line(run("--cache-dir", tmp_path / "cache", "roadmap", "build", missing, "--nodes", "4"),
                          str(missing))


def test_nodes_must_be_an_integer():
    result = run("roadmap", "build", SCENE_YAML, "--nodes", "many")
    assert result.exit_code == 2
    assert "Traceback" not in result.output
    assert "Invalid value for '--nodes'" in result.stderr
