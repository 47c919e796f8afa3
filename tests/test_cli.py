"""Tests of the `regrasp` command line (click.testing.CliRunner on regrasp_cli.cli.main):
help, one-line errors with exit code 2 for bad input, and one end-to-end `info` run."""

from __future__ import annotations

from importlib.metadata import version
from pathlib import Path

import click
import pytest
import yaml
from click.testing import CliRunner

from regrasp_cli import __version__
from regrasp_cli.cli import main
from regrasp_cli.errors import InputError

ROOT = Path(__file__).resolve().parents[1]
ROBOT_YAML = ROOT / "configs" / "robots" / "humanoid43" / "robot.yaml"
SCENE_YAML = ROOT / "configs" / "scenes" / "desk_handover.yaml"

CLICK_MAJOR_MINOR = tuple(int(x) for x in version("click").split(".")[:2])
pytestmark = pytest.mark.skipif(CLICK_MAJOR_MINOR < (8, 2), reason="needs click >= 8.2 (separate stderr)")


def run(*args: str) -> "click.testing.Result":
    return CliRunner().invoke(main, list(args))


def scene_dict() -> dict:
    d = yaml.safe_load(SCENE_YAML.read_text())
    d["robot"] = str(ROBOT_YAML)
    return d


def dump(path: Path, data) -> Path:
    path.write_text(data if isinstance(data, str) else yaml.safe_dump(data, sort_keys=False))
    return path


# --------------------------------------------------------------------------- help


@pytest.mark.parametrize("flag", ["--help", "-h"])
def test_help(flag):
    result = run(flag)
    assert result.exit_code == 0, result.output
    assert "info" in result.stdout
    assert "--cache-dir" in result.stdout and "--debug" in result.stdout


def test_info_help():
    result = run("info", "--help")
    assert result.exit_code == 0, result.output
    assert "info" in result.stdout and "SCENE" in result.stdout
    assert "--seed" in result.stdout
    assert "Summarise a scene" in result.stdout


def test_version():
    result = run("--version")
    assert result.exit_code == 0
    assert __version__ in result.stdout


def test_unknown_command_is_a_usage_error():
    result = run("plan-everything")
    assert result.exit_code == 2
    assert "Traceback" not in result.output


# --------------------------------------------------------------------------- bad input


def _missing(tmp_path):
    return tmp_path / "no_such_scene.yaml", tmp_path / "no_such_scene.yaml"


def _syntax(tmp_path):
    p = dump(tmp_path / "scene.yaml", SCENE_YAML.read_text().replace("task:", "task: [", 1))
    return p, p


def _unknown_key(tmp_path):
    d = scene_dict()
    d["task"]["object_middle"] = {"xyz": [0, 0, 0]}
    p = dump(tmp_path / "scene.yaml", d)
    return p, p


def _zero_quat(tmp_path):
    d = scene_dict()
    d["task"]["object_goal"] = {"xyz": [0.62, 0.78, 0.74], "quat": [0, 0, 0, 0]}
    p = dump(tmp_path / "scene.yaml", d)
    return p, p


def _negative_size(tmp_path):
    d = scene_dict()
    d["obstacles"][0]["box"]["size"] = [0.8, -1.9, 0.04]
    p = dump(tmp_path / "scene.yaml", d)
    return p, p


def _unknown_start_joint(tmp_path):
    d = scene_dict()
    d["task"]["robot_start"] = {"r_elbow": 0.5}
    p = dump(tmp_path / "scene.yaml", d)
    return p, p


def _bad_urdf(tmp_path):
    (tmp_path / "broken.urdf").write_text("<robot name='broken'><link name=")
    r = yaml.safe_load(ROBOT_YAML.read_text())
    r["urdf"] = "broken.urdf"
    robot = dump(tmp_path / "robot.yaml", r)
    d = scene_dict()
    d["robot"] = "robot.yaml"
    return dump(tmp_path / "scene.yaml", d), robot


def _bad_mesh(tmp_path):
    (tmp_path / "thing.stl").write_bytes(b"solid thing\nnonsense\nendsolid\n")
    d = scene_dict()
    d["object"]["mesh"] = "thing.stl"
    p = dump(tmp_path / "scene.yaml", d)
    return p, p


BAD = {"missing file": _missing, "YAML syntax": _syntax, "unknown key": _unknown_key,
       "zero quaternion": _zero_quat, "negative size": _negative_size,
       "unknown joint in task.robot_start": _unknown_start_joint, "bad URDF": _bad_urdf,
       "bad object mesh": _bad_mesh}


@pytest.mark.parametrize("case", list(BAD))
def test_bad_input_is_one_line_and_exit_code_2(tmp_path, cache_dir, case):
    scene, at_fault = BAD[case](tmp_path)
    result = run("--cache-dir", str(cache_dir), "info", str(scene))
    assert result.exit_code == 2, result.output
    lines = result.stderr.splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("error: ")
    assert str(at_fault) in lines[0]
    assert "Traceback" not in result.output and "Traceback" not in result.stderr
    assert result.stdout == ""


def test_error_names_the_field(tmp_path, cache_dir):
    scene, _ = _zero_quat(tmp_path)
    result = run("--cache-dir", str(cache_dir), "info", str(scene))
    assert result.stderr.strip() == (f"error: {scene}: task.object_goal.quat: "
                                     "quaternion of zero norm; expected [x, y, z, w] with norm 1")


def test_debug_shows_the_exception(tmp_path, cache_dir):
    scene, _ = _unknown_key(tmp_path)
    result = run("--debug", "--cache-dir", str(cache_dir), "info", str(scene))
    assert result.exit_code != 0
    assert isinstance(result.exception, InputError)
    assert result.exception.field == "task.object_middle"


# --------------------------------------------------------------------------- the default scene


def test_info_on_the_default_scene(cache_dir):
    result = run("--cache-dir", str(cache_dir), "info", str(SCENE_YAML))
    assert result.exit_code == 0, result.output
    out = " ".join(result.stdout.split())  # independent of line wrapping
    assert "start pose is reachable by the right arm only" in out
    assert "goal pose is reachable by the left arm only" in out
    assert "humanoid43" in out and "43" in out
    assert "desk_top" in out and "builtin:statuette" in out
    assert "error" not in result.stderr
    assert "Traceback" not in result.output
    assert list((cache_dir / "self_collision").glob("*.json"))  # the cache was used or written
