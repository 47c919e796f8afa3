"""The tiny pick-and-place suite of the bench tests, run once on loky processes: the
default scene, the roadmap planner, two seeds, the small artefacts of the run's cache.
tests/bench/test_cli_bench.py checks its records, summary and plots;
tests/bench/test_dask.py runs the same suite on a Dask cluster and compares."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from cli_helpers import SCENE_YAML, run

# two seeds the tiny artefacts solve (lists of 40 grasps per hand)
SEEDS = (0, 1)


def suite(folder: Path, **fields) -> Path:
    """A tiny suite file in ``folder``; ``fields`` replace its defaults."""
    d = {"format": "regrasp.bench/1", "name": "tiny", "scenes": [str(SCENE_YAML)], "planners": ["roadmap"],
         "seeds": list(SEEDS), "budget_s": 120, "roadmap_nodes": 12, "grasp_target": 40}
    d.update(fields)
    p = folder / "suite.yaml"
    p.write_text(yaml.safe_dump(d))
    return p


@pytest.fixture(scope="session")
def tiny_on_loky(once, cache_dir) -> tuple[Path, str]:
    """`regrasp bench` of the tiny suite with two loky workers: (results folder, stdout).
    The folder's siblings are free for other results at the same depth (the plans record
    paths relative to themselves)."""

    def make(d: Path) -> None:
        r = run("--cache-dir", cache_dir, "bench", suite(d), "-o", d / "loky", "--jobs", "2")
        assert r.exit_code == 0, (r.output, r.exception)
        (d / "loky.stdout").write_text(r.stdout)

    d = once("bench-tiny", make)
    return d / "loky", (d / "loky.stdout").read_text()
