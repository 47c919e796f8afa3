"""`regrasp bench --backend dask`: the tiny suite of tests/bench/conftest.py (grasp lists
of 20, roadmaps of 12 nodes, the run's cache), its first seed on a local Dask cluster of
one worker process, gives the same record and plan, apart from times, as on loky
processes; the run is still forked with its budget inside the (daemonic) Dask worker.  Without --scheduler, or
without the `distributed` package, the command is one error line with exit 2."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

from bench.conftest import SEEDS, suite
from bench.test_cli_bench import records
from cli_helpers import assert_one_error_line, needs_separate_stderr, run

distributed = pytest.importorskip("distributed", reason="needs the dask extra: pip install 'regrasp[dask]'")


@pytest.fixture(scope="module")
def cluster():
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=None) as c:
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


def test_the_tiny_suite_on_a_dask_cluster_matches_loky(cache_dir, cluster, tiny_on_loky):
    """The suite's first seed on Dask: the record and the plan of that seed on loky."""
    on_loky, _ = tiny_on_loky
    on_dask = on_loky.with_name("dask")  # same depth: same relative paths in the plans
    r = run("--cache-dir", cache_dir, "bench", on_loky.parent / "suite.yaml", "-o", on_dask, "--backend", "dask",
            "--scheduler", cluster.scheduler_address, "--seeds", "1")
    assert r.exit_code == 0, (r.output, r.exception)
    (rec,) = records(on_dask)
    assert (rec["planner"], rec["seed"], rec["solved"], rec["validation"]["valid"]) == ("roadmap", SEEDS[0], True, True)
    assert rec["peak_rss_mb"] > 0
    (same,) = [x for x in records(on_loky) if x["seed"] == rec["seed"]]
    assert untimed(rec) == untimed(same)
    on_dask_plans = plans(on_dask)
    assert list(on_dask_plans) == [rec["plan"]] and on_dask_plans[rec["plan"]] == plans(on_loky)[rec["plan"]]
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


def test_an_in_hand_suite_runs_on_a_dask_cluster_as_on_loky(tmp_path, cache_dir, cluster):
    """Issue 42: an in-hand suite's runs are any suite's, Dask included: one goal of
    hand4 and the ball gives the same record (times apart) and the same plan."""
    import yaml

    from regrasp_cli.validate import validate_plan

    d = {"format": "regrasp.inhand-bench/1", "name": "tiny-inhand", "goals": 1,
         "hands": [{"robot": "builtin:hand4", "label": "hand4", "objects": ["ball"]}],
         "objects": [{"mesh": "builtin:ball", "label": "ball"}]}
    (tmp_path / "suite.yaml").write_text(yaml.safe_dump(d))
    out = {}
    for backend in ("loky", "dask"):
        out[backend] = tmp_path / backend
        extra = ("--backend", "dask", "--scheduler", cluster.scheduler_address) if backend == "dask" else ()
        r = run("--cache-dir", cache_dir, "bench", tmp_path / "suite.yaml", "-o", out[backend], "--jobs", "1", *extra)
        assert r.exit_code == 0, (r.output, r.exception)
    (on_loky,), (on_dask,) = records(out["loky"]), records(out["dask"])
    assert on_dask["solved"] and (on_dask["hand"], on_dask["object"], on_dask["goal"]) == ("hand4", "ball", 0)
    assert untimed(on_dask) == untimed(on_loky)
    assert validate_plan(out["dask"] / "plans" / "hand4-ball-00.json").valid
    assert json.loads((out["dask"] / "meta.json").read_text())["backend"] == f"dask at {cluster.scheduler_address}"
