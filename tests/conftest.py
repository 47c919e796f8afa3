"""Shared fixtures: the default robot and scene, the artefact cache and the default
scene's small plan, each made once per test run, whichever xdist worker asks first."""

from __future__ import annotations

import os
import shutil
from collections.abc import Callable
from pathlib import Path

import pytest
from filelock import FileLock

ROOT = Path(__file__).resolve().parents[1]
ROBOT_YAML = ROOT / "configs" / "robots" / "humanoid43" / "robot.yaml"
SCENE_YAML = ROOT / "configs" / "scenes" / "desk_handover.yaml"


def _run_root(tmp_path_factory) -> Path:
    """The folder of this test run that every xdist worker sees (its own basetemp's parent)."""
    base = tmp_path_factory.getbasetemp()
    return base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base


@pytest.fixture(scope="session")
def cache_dir(tmp_path_factory) -> Path:
    """The artefact cache of the whole run, one folder for every worker: an artefact (grasp
    list, roadmap, workspace) is built once, the others wait on its file lock and load it
    (regrasp_cli.store: locked, atomic writes)."""
    d = _run_root(tmp_path_factory) / "cache"
    d.mkdir(exist_ok=True)
    return d


@pytest.fixture(scope="session")
def once(tmp_path_factory) -> Callable[[str, Callable[[Path], None]], Path]:
    """``once(name, make)``: the folder ``name`` of this run, filled by ``make(folder)``
    the first time any worker asks for it; the others wait on its lock and get the folder
    as made.  A ``make`` that raises leaves nothing behind, so every asker fails alike."""
    root = _run_root(tmp_path_factory) / "once"
    root.mkdir(exist_ok=True)

    def get(name: str, make: Callable[[Path], None]) -> Path:
        d, done = root / name, root / f"{name}.done"
        with FileLock(str(root / f"{name}.lock")):
            if not done.exists():
                shutil.rmtree(d, ignore_errors=True)
                d.mkdir()
                try:
                    make(d)
                except BaseException:
                    shutil.rmtree(d, ignore_errors=True)
                    raise
                done.touch()
        return d

    return get


@pytest.fixture(scope="session")
def default_plan(once, cache_dir) -> Path:
    """`regrasp plan` of the default scene with the small artefacts (seed 0, checked), run
    once for every test that reads a solved plan/2; beside it, ``plan.stdout``.  Tests that
    write more plans of this scene put them in the same folder, so that the relative paths
    they record are the same."""
    from cli_helpers import SMALL, run

    def make(d: Path) -> None:
        result = run("--cache-dir", cache_dir, "plan", SCENE_YAML, "-o", d / "plan.json", *SMALL, "--seed", 0)
        assert result.exit_code == 0, (result.output, result.exception)
        (d / "plan.stdout").write_text(result.stdout)

    return once("default-plan", make) / "plan.json"


@pytest.fixture(scope="session")
def robot():
    from regrasp_cli.model.robot import load_robot

    return load_robot(ROBOT_YAML)


@pytest.fixture(scope="session")
def problem(cache_dir):
    from regrasp_cli.scene import load_problem

    return load_problem(SCENE_YAML, cache_dir)
