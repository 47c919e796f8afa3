"""Fixtures of the viewer tests: one small plan of the default scene, planned once per
session with the artefacts that tests/test_cli_plan.py uses (20 grasps per hand, 12
nodes per elementary roadmap, in the session cache), and its page and key frames
written once by `regrasp show`."""

from __future__ import annotations

from pathlib import Path

import pytest

from cli_helpers import SCENE_YAML, run

SMALL = ("--grasp-target", "20", "--roadmap-nodes", "12")
PNG_SIZE = (640, 480)


@pytest.fixture(scope="session")
def show_dir(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("show")


@pytest.fixture(scope="session")
def small_plan(cache_dir, show_dir) -> Path:
    """A solved plan of the default scene (seed 0), its file."""
    out = show_dir / "plan.json"
    result = run("--cache-dir", cache_dir, "plan", SCENE_YAML, "-o", out, *SMALL, "--seed", 0, "--no-check")
    assert result.exit_code == 0, (result.output, result.exception)
    return out


@pytest.fixture(scope="session")
def view(small_plan):
    from regrasp_cli.show.motion import load_plan_view

    return load_plan_view(small_plan)


@pytest.fixture(scope="session")
def shown(small_plan, show_dir):
    """`regrasp show PLAN --html ... --png ... --size 640x480`: (result, page, frame directory)."""
    page, frames = show_dir / "out" / "plan.html", show_dir / "out" / "frames"
    result = run("show", small_plan, "--html", page, "--png", frames, "--size", f"{PNG_SIZE[0]}x{PNG_SIZE[1]}")
    return result, page, frames
