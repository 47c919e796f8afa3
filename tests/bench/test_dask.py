"""`regrasp bench --backend dask`: the tiny 2-seed suite of test_cli_bench (grasp lists of
20, roadmaps of 12 nodes, its own cache) on a local Dask cluster of two worker processes
gives the same records and plans, apart from times, as on loky processes; each run is
still forked with its budget inside the (daemonic) Dask worker.  Without --scheduler, or
without the `distributed` package, the command is one error line with exit 2."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

from bench.test_cli_bench import SEEDS, cache_dir, records, suite  # noqa: F401 - cache_dir: the small-artefact cache
from cli_helpers import assert_one_error_line, needs_separate_stderr, run

distributed = pytest.importorskip("distributed", reason="needs the dask extra: pip install 'regrasp[dask]'")


@pytest.fixture(scope="module")
def cluster():
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as c:
        yield c


def untimed(x):
    """``x`` without its measured times and memory (keys ending in ``_s``, ``peak_rss_mb``)."""
    if isinstance(x, dict):
        return {k: untimed(v) for k, v in x.items() if not k.endswith("_s") and k != "peak_rss_mb"}
    if isinstance(x, list):
        return [untimed(v) for v in x]
    return x


def plans(out: Path) -> dict[str, dict]:
    return {p.name: untimed(json.loads(p.read_text())) for p in sorted((out / "plans").glob("*.json"))}


def test_the_tiny_suite_on_a_dask_cluster_matches_loky(cache_dir, cluster, tmp_path):  # noqa: F811
    file = suite(tmp_path)
    on_loky, on_dask = tmp_path / "loky", tmp_path / "dask"  # same depth: same relative paths in the plans
    r = run("--cache-dir", cache_dir, "bench", file, "-o", on_loky, "--jobs", "2")
    assert r.exit_code == 0, (r.output, r.exception)
    r = run("--cache-dir", cache_dir, "bench", file, "-o", on_dask, "--backend", "dask",
            "--scheduler", cluster.scheduler_address)
    assert r.exit_code == 0, (r.output, r.exception)
    recs = records(on_dask)
    assert [(x["planner"], x["seed"], x["solved"], x["validation"]["valid"]) for x in recs] == \
        [("roadmap", s, True, True) for s in SEEDS]
    assert all(x["peak_rss_mb"] > 0 for x in recs)
    assert [untimed(x) for x in recs] == [untimed(x) for x in records(on_loky)]
    assert plans(on_dask) == plans(on_loky) and len(plans(on_dask)) == 2
    meta = json.loads((on_dask / "meta.json").read_text())
    assert meta["backend"] == f"dask at {cluster.scheduler_address}"
    assert f"joblib workers: dask at {cluster.scheduler_address}" in (on_dask / "summary.md").read_text()


@needs_separate_stderr
def test_dask_without_a_scheduler_is_one_error_line(tmp_path):
    r = run("bench", suite(tmp_path), "-o", tmp_path / "o", "--backend", "dask")
    assert_one_error_line(r, "--scheduler", "existing Dask cluster")
    r = run("bench", suite(tmp_path), "-o", tmp_path / "o", "--scheduler", "tcp://127.0.0.1:8786")
    assert_one_error_line(r, "--scheduler", "only for --backend dask")


@needs_separate_stderr
def test_dask_without_the_extra_names_it(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "distributed", None)  # import distributed: ImportError
    r = run("bench", suite(tmp_path), "-o", tmp_path / "o", "--backend", "dask", "--scheduler", "tcp://127.0.0.1:1")
    assert_one_error_line(r, "--backend", "pip install 'regrasp[dask]'")


def test_help_names_the_backends():
    r = run("bench", "--help")
    assert r.exit_code == 0 and "--backend" in r.output and "--scheduler" in r.output and "dask" in r.output
