"""`regrasp bench` end to end on the default scene with the small artefacts the plan
tests use (grasp lists of 20, roadmaps of 12 nodes, in the run's cache): a 2-seed suite
(tests/bench/conftest.py, run once) writes one record per run, each validated, with the
summary, Table I and the plot; a run over its budget is recorded with its reason and the suite goes on; bad
input is one error line with exit 2."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from bench.conftest import SEEDS, suite
from cli_helpers import assert_one_error_line, needs_separate_stderr, run, scene_dict, write_scene

PNG = b"\x89PNG\r\n\x1a\n"


def records(out: Path) -> list[dict]:
    return [json.loads(line) for line in (out / "runs.jsonl").read_text().splitlines()]


def test_tiny_suite_end_to_end(tiny_on_loky):
    out, stdout = tiny_on_loky
    recs = records(out)
    assert [(x["planner"], x["seed"]) for x in recs] == [("roadmap", s) for s in SEEDS]
    for x in recs:
        assert x["solved"], x
        assert x["validation"]["valid"] and x["validation"]["issues"] == 0
        assert x["regrasps"] == 1 and x["path_length"] > 0 and x["peak_rss_mb"] > 0
        assert x["total_s"] >= x["planner_s"] + x["validation_s"] > 0
        assert set(x["queries"]) == {"grasp", "carry", "place", "rest"}
        assert (out / "plans" / x["plan"]).is_file()
    text = (out / "summary.md").read_text()
    assert "| desk_handover | roadmap | 2/2 | 100 % |" in text
    assert "### desk_handover, roadmap" in text and "| total |" in text
    assert re.search(r"\| desk_handover \| grasp lists \| (built|cached) \| [0-9.]+ \| right \d+, left \d+ \|", text)
    assert (out / "times.png").read_bytes().startswith(PNG)
    log = (out / "ompl" / "desk_handover.log").read_text()  # OMPL's benchmark log (tests/bench/test_ompllog.py)
    assert log.startswith("regrasp version") and "Experiment tiny-desk_handover" in log and "2 runs" in log
    meta = json.loads((out / "meta.json").read_text())
    assert "pin" in meta["machine"]["libraries"] and "coal" in meta["machine"]["libraries"]
    assert meta["runs"] == 2 and meta["offline"]["desk_handover"]["grasp lists"]["status"] in ("built", "cached")
    assert "Table I: desk_handover, roadmap" in stdout


def test_a_run_over_budget_is_a_recorded_failure(cache_dir, tmp_path):
    out = tmp_path / "results"
    r = run("--cache-dir", cache_dir, "bench", suite(tmp_path, planners=["roadmap", "rrt-connect"]), "-o", out,
            "--jobs", "1", "--seeds", "1", "--budget-s", "0.01")
    assert r.exit_code == 0, (r.output, r.exception)
    recs = records(out)
    assert len(recs) == 2  # the first failure did not stop the suite
    for x in recs:
        assert (x["solved"], x["stage"]) == (False, "budget")
        assert x["reason"] == "exceeded the budget of 0.01 s (killed)"
    text = (out / "summary.md").read_text()
    assert "## Failures (2)" in text and "| 0/1 | 0 % |" in text


def test_an_object_with_no_stable_placement_is_planned_without_placements(cache_dir, tmp_path):
    """A ball has no stable placement, hence no placements file: under style auto its run
    goes on to plan without placements (it crashed when the run refused to build the file)."""
    d = scene_dict()
    d["object"] = {**d["object"], "mesh": "builtin:ball"}
    scene = write_scene(tmp_path / "ball.yaml", d)
    out = tmp_path / "results"
    r = run("--cache-dir", cache_dir, "bench", suite(tmp_path, scenes=[str(scene)], seeds=[0]), "-o", out, "--jobs", "1")
    assert r.exit_code == 0, (r.output, r.exception)
    (rec,) = records(out)
    assert rec["stage"] != "crash" and "placements" not in rec["reason"], rec["reason"]
    offline = json.loads((out / "meta.json").read_text())["offline"]["ball"]
    assert offline["placements"]["status"].startswith("empty (")


@needs_separate_stderr
def test_bad_suite_is_one_error_line(tmp_path):
    r = run("bench", suite(tmp_path, planners=["roadmap", "prm"]), "-o", tmp_path / "o")
    assert_one_error_line(r, "suite.yaml", "planners", "unknown planner 'prm'")
    r = run("bench", suite(tmp_path), "--planners", "roadmap,prm", "-o", tmp_path / "o")
    assert_one_error_line(r, "--planners")


def test_help():
    r = run("bench", "--help")
    assert r.exit_code == 0 and "--budget-s" in r.output and "--jobs" in r.output
