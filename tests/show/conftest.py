"""Fixtures of the viewer tests: the default scene's small plan (conftest.default_plan,
which tests/test_cli_plan.py checks), and its page and key frames written once by
`regrasp show`."""

from __future__ import annotations

from pathlib import Path

import pytest

from cli_helpers import run

PNG_SIZE = (640, 480)


@pytest.fixture(scope="session")
def show_dir(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("show")


@pytest.fixture(scope="session")
def small_plan(default_plan) -> Path:
    """A solved plan of the default scene (seed 0), its file: conftest.default_plan."""
    return default_plan


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
