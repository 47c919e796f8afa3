"""Shared fixtures: the default robot and scene, loaded once per session."""

from __future__ import annotations

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
ROBOT_YAML = ROOT / "configs" / "robots" / "humanoid43" / "robot.yaml"
SCENE_YAML = ROOT / "configs" / "scenes" / "desk_handover.yaml"


@pytest.fixture(scope="session")
def cache_dir(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("cache")


@pytest.fixture(scope="session")
def robot():
    from regrasp_cli.model.robot import load_robot

    return load_robot(ROBOT_YAML)


@pytest.fixture(scope="session")
def problem(cache_dir):
    from regrasp_cli.scene import load_problem

    return load_problem(SCENE_YAML, cache_dir)
