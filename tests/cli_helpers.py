"""Helpers shared by the CLI tests: run `regrasp` in-process, write scene copies, and
check the one-line error contract (exit 2, one `error:` line, no traceback)."""

from __future__ import annotations

import shutil
from importlib.metadata import version
from pathlib import Path

import pytest
import yaml
from click.testing import CliRunner, Result

from regrasp_cli.cli import main

ROOT = Path(__file__).resolve().parents[1]
ROBOT_YAML = ROOT / "configs" / "robots" / "humanoid43" / "robot.yaml"
SCENE_YAML = ROOT / "configs" / "scenes" / "desk_handover.yaml"
# the small artefacts of the end-to-end plans: 20 grasps per hand, 12 nodes per roadmap
SMALL = ("--grasp-target", "40", "--roadmap-nodes", "12")

CLICK_MAJOR_MINOR = tuple(int(x) for x in version("click").split(".")[:2])
needs_separate_stderr = pytest.mark.skipif(CLICK_MAJOR_MINOR < (8, 2), reason="needs click >= 8.2 (separate stderr)")


def run(*args) -> Result:
    # wide console: rich tables and paths are not wrapped
    return CliRunner(env={"COLUMNS": "250"}).invoke(main, [str(a) for a in args])


def scene_dict() -> dict:
    """The default scene as a dict, its robot path made absolute (for copies elsewhere)."""
    d = yaml.safe_load(SCENE_YAML.read_text())
    d["robot"] = str(ROBOT_YAML)
    return d


def write_scene(path: Path, d: dict) -> Path:
    path.write_text(yaml.safe_dump(d, sort_keys=False))
    return path


def assert_one_error_line(result: Result, *words: str, exit_code: int = 2) -> str:
    """Exit code 2 (bad input; 1: no result), no traceback, exactly one `error:` line on
    stderr (other lines, if any, are warnings) naming ``words``; returns the error line."""
    assert result.exit_code == exit_code, (result.exit_code, result.output, result.exception)
    assert "Traceback" not in result.output and "Traceback" not in result.stderr
    assert not isinstance(result.exception, Exception) or isinstance(result.exception, SystemExit)
    lines = result.stderr.strip().splitlines()
    errors = [ln for ln in lines if ln.startswith("error:")]
    assert len(errors) == 1, result.stderr
    assert all(ln.startswith(("error:", "warning:")) for ln in lines), result.stderr
    for w in words:
        assert w in errors[0], (w, errors[0])
    return errors[0]


def copy_artefacts(src: Path, dst: Path) -> Path:
    """Copy the cache folder ``src`` to ``dst`` with its finished files only: not the
    locks, nor the temp files of an artefact another test (or xdist worker) is writing
    into the shared cache at that moment."""
    shutil.copytree(src, dst, ignore=shutil.ignore_patterns("*.lock", ".*.tmp"))
    return dst
