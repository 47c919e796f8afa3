"""Run records in OMPL's benchmark log format: OMPL's own converter
(``ompl_benchmark_statistics``, in the ``ompl`` package) reads the log into the SQLite
database Planner Arena plots, with one row per run holding what the records say."""

from __future__ import annotations

import sqlite3
import subprocess
import sys
from pathlib import Path

import pytest

from bench.test_aggregate import RECORDS
from bench.test_bench_docs import META
from regrasp_cli.bench.ompllog import OUTCOMES, experiment_log, scene_logs

pytest.importorskip("ompl", reason="needs the ompl extra: pip install 'regrasp[ompl]'")


def database(tmp_path: Path, log: str) -> sqlite3.Connection:
    (tmp_path / "x.log").write_text(log)
    converter = Path(sys.executable).parent / "ompl_benchmark_statistics"
    r = subprocess.run([str(converter), str(tmp_path / "x.log"), "-d", str(tmp_path / "x.db")],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    return sqlite3.connect(tmp_path / "x.db")


def test_ompl_reads_every_run_with_its_time_and_outcome(tmp_path):
    db = database(tmp_path, experiment_log(RECORDS, META, "desk"))
    (name, limit, count, version), = db.execute("SELECT name, timelimit, runcount, version FROM experiments")
    assert (name, limit, count, version) == ("tiny-desk", 60.0, 6, "regrasp 0.1.0")
    planners = dict(db.execute("SELECT id, name FROM plannerConfigs"))
    rows = db.execute("SELECT plannerid, seed, time, solved, outcome, memory, total_time, graph_states "
                      "FROM runs ORDER BY plannerid, seed").fetchall()
    assert len(rows) == len(RECORDS)
    by_key = {(r["planner"], r["seed"]): r for r in RECORDS}
    for pid, seed, time, solved, outcome, memory, total, states in rows:
        r = by_key[planners[pid], seed]
        assert time == pytest.approx(r["planner_s"]) and total == pytest.approx(r["total_s"])
        assert solved == int(r["solved"]) and memory == pytest.approx(r["peak_rss_mb"])
        assert OUTCOMES[outcome] == ("solved" if r["solved"] else r["stage"])
        assert states == sum(q["n"] for q in r["queries"].values())
    enum = dict(db.execute("SELECT value, description FROM enums WHERE name = 'outcome'"))
    assert enum[0] == "solved" and enum[OUTCOMES.index("transition")] == "transition"
    assert [enum[i] for i in range(len(OUTCOMES))] == list(OUTCOMES)  # every Stage value, then "other"


def test_a_run_killed_over_budget_has_its_time_and_empty_columns(tmp_path):
    killed = {"scene": "desk", "planner": "rrt-connect", "seed": 9, "solved": False, "stage": "budget",
              "reason": "exceeded", "total_s": 60.2, "planner_s": None, "write_s": None, "validation_s": None,
              "stages_s": {}, "queries": {}, "validation": None, "path_length": None, "regrasps": None,
              "motion_s": None, "waypoints": None, "plan": None, "peak_rss_mb": None}
    db = database(tmp_path, experiment_log([*RECORDS, killed], META, "desk"))
    row = db.execute("SELECT time, solved, outcome, memory, solution_length, graph_states FROM runs "
                     "WHERE seed = 9").fetchone()
    assert row == (pytest.approx(60.2), 0, OUTCOMES.index("budget"), None, None, None)


def test_one_log_per_scene():
    logs = scene_logs([*RECORDS, dict(RECORDS[0], scene="shelf/a")], META)
    assert sorted(logs) == ["desk.log", "shelf_a.log"]
    assert "Experiment tiny-shelf/a" in logs["shelf_a.log"] and "1 runs" in logs["shelf_a.log"]
