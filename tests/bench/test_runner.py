"""A run in its own process never stops the suite: one that raises, dies or outlives its
budget comes back as a failure record with its stage and reason (regrasp_cli.bench.runner
run_one with stand-in work functions: no planning, so fast); and the path measures of a
record on tiny hand-made phases."""

from __future__ import annotations

import os
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from regrasp_cli.bench.runner import RunItem, _stamp, path_length, regrasps, run_one


def item(tmp: Path, budget_s: float = 5.0) -> RunItem:
    return RunItem("desk", str(tmp / "missing" / "scene.yaml"), "rrt-connect", 3, str(tmp), str(tmp / "plan.json"),
                   budget_s, 12, 20)


def _solves(it: RunItem) -> dict:
    return {"scene": it.scene, "planner": it.planner, "seed": it.seed, "solved": True, "stage": None,
            "reason": None, "total_s": 0.0}


def _sleeps(it: RunItem) -> dict:
    time.sleep(30)
    return _solves(it)


def _raises(it: RunItem) -> dict:
    raise ModuleNotFoundError("No module named 'ompl'")


def _dies(it: RunItem) -> dict:
    os._exit(3)


def test_a_run_comes_back_with_its_peak_memory(tmp_path):
    rec = run_one(item(tmp_path), _solves)
    assert rec["solved"] and rec["seed"] == 3
    assert rec["peak_rss_mb"] > 1.0


def test_a_run_over_budget_is_killed_and_recorded(tmp_path):
    t0 = time.perf_counter()
    rec = run_one(item(tmp_path, budget_s=0.3), _sleeps)
    assert time.perf_counter() - t0 < 10.0  # not the 30 s of the work
    assert not rec["solved"] and rec["stage"] == "budget"
    assert "0.3 s" in rec["reason"] and (rec["scene"], rec["planner"], rec["seed"]) == ("desk", "rrt-connect", 3)


def test_an_exception_is_recorded_with_its_type_and_message(tmp_path):
    rec = run_one(item(tmp_path), _raises)
    assert not rec["solved"] and rec["stage"] == "crash"
    assert rec["reason"] == "ModuleNotFoundError: No module named 'ompl'"
    assert "Traceback" in rec["traceback"]


def test_a_dead_process_is_recorded(tmp_path):
    rec = run_one(item(tmp_path), _dies)
    assert (rec["solved"], rec["stage"]) == (False, "crash")
    assert "exit code 3" in rec["reason"]


def test_a_scene_that_does_not_load_is_a_crash_not_an_exception(tmp_path):
    rec = run_one(item(tmp_path))  # the real work: the scene file is missing
    assert rec["stage"] == "crash" and "no such file" in rec["reason"]


def test_path_length_and_regrasps_on_a_hand_over():
    w = np.array([1.0, 0.25])
    # ``holding`` as in a plan's phases: hand -> grasp id
    phases = [SimpleNamespace(holding={}, waypoints=np.array([[0.0, 0.0], [3.0, 0.0]])),
              SimpleNamespace(holding={"right": "right-3"}, waypoints=np.array([[3.0, 0.0], [3.0, 8.0], [3.0, 8.0]])),
              SimpleNamespace(holding={"right": "right-3", "left": "left-0"}, waypoints=np.array([[3.0, 8.0]])),
              SimpleNamespace(holding={"left": "left-0"}, waypoints=np.array([[3.0, 8.0]])),
              SimpleNamespace(holding={}, waypoints=np.zeros((0, 2)))]
    assert path_length(phases, w) == pytest.approx(3.0 + 4.0)  # sqrt(0.25 * 64) = 4
    assert regrasps(phases) == 1  # right to left; the two-hand phase is no change of grasp
    assert regrasps(phases[:3]) == 0
    # the same hand holding with another grasp is a regrasp too; the same grasp again is not
    again = [SimpleNamespace(holding={"right": "right-3"}, waypoints=np.zeros((0, 2))),
             SimpleNamespace(holding={"right": "right-3"}, waypoints=np.zeros((0, 2))),
             SimpleNamespace(holding={"right": "right-5"}, waypoints=np.zeros((0, 2)))]
    assert regrasps(again) == 1 and regrasps(again[:2]) == 0


def test_a_worker_context_is_keyed_by_its_inputs_so_a_rebuilt_artefact_is_reloaded(tmp_path):
    scene, cache = tmp_path / "scene.yaml", tmp_path / "cache"
    scene.write_text("a: 1\n")
    (cache / "grasps").mkdir(parents=True)
    (cache / "other").mkdir()
    lists = cache / "grasps" / "obj-right-abc.h5"
    lists.write_bytes(b"one")
    first = _stamp(str(scene), str(cache))
    assert [Path(p).name for p, _, _ in first] == ["scene.yaml", "obj-right-abc.h5"]
    (cache / "other" / "x.h5").write_bytes(b"not an input")
    assert _stamp(str(scene), str(cache)) == first
    lists.write_bytes(b"rebuilt")  # another size (and time)
    assert _stamp(str(scene), str(cache)) != first
    second = _stamp(str(scene), str(cache))
    (cache / "roadmap").mkdir()
    (cache / "roadmap" / "r.h5").write_bytes(b"r")
    assert _stamp(str(scene), str(cache)) != second


def test_an_empty_grasp_list_fails_its_scene_and_the_suite_goes_on(tmp_path, monkeypatch, problem, cache_dir):
    """A scene whose object no hand can grasp is recorded as such in the offline stages;
    the other scenes are still prepared (the runs of the first then fail on its missing
    list, each with its reason)."""
    import regrasp_cli.artefacts as artefacts
    import regrasp_cli.scene as scene_module
    from regrasp_cli.bench.runner import offline_stages
    from regrasp_cli.bench.suite import Suite
    from regrasp_cli.errors import EmptyGraspList

    root = Path(__file__).resolve().parents[2]
    first, second = tmp_path / "a.yaml", tmp_path / "b.yaml"
    for p in (first, second):
        p.write_text((root / "configs" / "scenes" / "desk_handover.yaml").read_text())

    def load(scene, *args, **kwargs):
        if Path(scene) == first:
            raise EmptyGraspList("right", "0 of 10 candidate grasp frames gave a grasp")
        return {"right": SimpleNamespace(X_OG=np.zeros((3, 4, 4))), "left": SimpleNamespace(X_OG=np.zeros((2, 4, 4)))}, \
            None, {}

    monkeypatch.setattr(artefacts, "load_artefacts", load)
    monkeypatch.setattr(scene_module, "load_problem", lambda *a, **k: problem)
    suite = Suite(tmp_path / "suite.yaml", "t", (first, second), ("rrt-connect",), (0,))
    out = offline_stages(suite, cache_dir, 1)
    assert out["a"]["grasp lists"]["status"].startswith("empty (the right hand's grasp list is empty: 0 of 10")
    assert out["b"]["grasp lists"]["size"] == {"right": 3, "left": 2}
