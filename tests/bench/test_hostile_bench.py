"""`regrasp bench` on hostile and broken input (issue 40): every refusal is one error line
naming the file and field the user wrote, exit 2, no traceback, and nothing written.

1. A bad hand or object of an in-hand suite (it only shows when the run's generated
   scene is loaded) names the suite file and its field, not OUT/scenes/; a bad scene of
   a pick-and-place suite is refused before any artefact is built; neither leaves OUT.
2. An in-hand suite's name is one folder inside bench-results/, as a pick-and-place
   suite's: ``../../..`` is refused.
3. Hand and object labels name the runs' files: a slash, or two runs of one file name,
   are refused.
4. A malformed Dask scheduler address is refused before a ``distributed.Client`` is made
   (a half-made one waited 20 s when collected, then printed a traceback).
"""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from bench.conftest import suite as pnp_suite
from cli_helpers import SCENE_YAML, assert_one_error_line, needs_separate_stderr, run, scene_dict, write_scene

pytestmark = needs_separate_stderr


def inhand_suite(folder: Path, hand: dict | None = None, obj: dict | None = None, **fields) -> Path:
    """A one-goal in-hand suite of hand4 and the ball with a budget of one expansion (its
    run fails at once); ``hand``, ``obj`` and ``fields`` replace its defaults."""
    d = {"format": "regrasp.inhand-bench/1", "name": "hostile", "goals": 1, "nodes": 1,
         "hands": [{"robot": "builtin:hand4", "label": "hand4", **(hand or {})}],
         "objects": [{"mesh": "builtin:ball", "label": "ball", **(obj or {})}]}
    d.update(fields)
    p = folder / "suite.yaml"
    p.write_text(yaml.safe_dump(d))
    return p


# ------------------------------------------------------- 1. errors name what the user wrote


@pytest.mark.parametrize("hand, obj, field", [
    ({"side": "bogus"}, {}, "hands[0].side"),
    ({"side": "left"}, {}, "hands[0].side"),  # hand4 has a right hand only
    ({"robot": "builtin:nohand"}, {}, "hands[0].robot"),
    ({}, {"friction": 9}, "objects[0].friction"),
    ({}, {"mesh": "builtin:nothing"}, "objects[0].mesh"),
])
def test_inhand_scene_errors_name_the_suite_field_and_write_nothing(tmp_path, cache_dir, hand, obj, field):
    out = tmp_path / "out"
    r = run("--cache-dir", cache_dir, "bench", inhand_suite(tmp_path, hand, obj), "-o", out)
    line = assert_one_error_line(r, f"suite.yaml: {field}: ")
    assert "scenes" not in line
    assert not out.exists()


def test_pick_and_place_bad_scene_is_refused_before_any_build(tmp_path):
    d = scene_dict()
    d["task"]["object_goal"]["xyz"] = [0, 0]
    bad = write_scene(tmp_path / "bad.yaml", d)
    cache, out = tmp_path / "cache", tmp_path / "out"
    s = pnp_suite(tmp_path, scenes=[str(SCENE_YAML), str(bad)], planners=["rrt-connect"], grasp_target=2, seeds=1)
    r = run("--cache-dir", cache, "bench", s, "-o", out, "--jobs", "1")
    assert_one_error_line(r, "bad.yaml: task.object_goal.xyz: ")
    assert not out.exists()
    assert not (cache / "grasps").exists()  # the good scene first: nothing built for it either


# ------------------------------------------------------- 2. the results folder stays inside bench-results/


def test_inhand_suite_name_cannot_leave_bench_results(tmp_path, cache_dir, monkeypatch):
    cwd = tmp_path / "a" / "b" / "c"
    cwd.mkdir(parents=True)
    monkeypatch.chdir(cwd)
    r = run("--cache-dir", cache_dir, "bench", inhand_suite(tmp_path, name="../../.."))
    assert_one_error_line(r, "suite.yaml: name: ", "results folder")
    assert [p.name for p in (tmp_path / "a").iterdir()] == ["b"] and not (cwd / "bench-results").exists()


# ------------------------------------------------------- 3. labels name files


@pytest.mark.parametrize("hands, obj, field", [
    ([{"robot": "builtin:hand4", "label": "hand4"}], {"label": "big/ball"}, "objects[0].label"),
    ([{"robot": "builtin:hand4", "label": "my/hand"}], {}, "hands[0].label"),
    ([{"robot": "builtin:hand4", "label": "h"}, {"robot": "builtin:hand4", "label": "h"}], {}, "hands"),
])
def test_labels_that_cannot_name_a_file_are_refused(tmp_path, cache_dir, hands, obj, field):
    out = tmp_path / "out"
    r = run("--cache-dir", cache_dir, "bench", inhand_suite(tmp_path, obj=obj, hands=hands), "-o", out)
    assert_one_error_line(r, f"suite.yaml: {field}: ")
    assert not out.exists()


def test_labels_whose_runs_would_share_a_scene_file_are_refused(tmp_path, cache_dir):
    """hand a-b with object c and hand a with object b-c: both a-b-c-00.yaml."""
    hands = [{"robot": "builtin:hand4", "label": "a-b", "objects": ["c"]},
             {"robot": "builtin:hand4", "label": "a", "objects": ["b-c"]}]
    objects = [{"mesh": "builtin:ball", "label": "c"}, {"mesh": "builtin:ball", "label": "b-c"}]
    out = tmp_path / "out"
    r = run("--cache-dir", cache_dir, "bench", inhand_suite(tmp_path, hands=hands, objects=objects), "-o", out)
    assert_one_error_line(r, "suite.yaml: hands[1].label: ", "a-b-c-00.yaml")
    assert not out.exists()


# ------------------------------------------------------- 4. a malformed Dask address


@pytest.fixture
def clients(monkeypatch) -> list:
    """Every ``distributed.Client`` the command makes.  One left started but not closed
    would, when collected, wait 20 s to close and print a traceback: it is marked closed
    after the test, so that a failing test fails at once."""
    distributed = pytest.importorskip("distributed", reason="needs the dask extra: pip install 'regrasp[dask]'")
    made = []

    class Recorded(distributed.Client):
        def __init__(self, *args, **kwargs):
            made.append(self)
            super().__init__(*args, **kwargs)

    monkeypatch.setattr(distributed, "Client", Recorded)
    yield made
    for c in made:
        if c.status not in ("newly-created", "closed"):
            c.status = "closed"


@pytest.mark.parametrize("address", ["bogus://nowhere:x", "tcp://nowhere:x", "tls://127.0.0.1:1"])
def test_malformed_scheduler_address_is_one_line_and_leaves_no_client_open(tmp_path, clients, address):
    """tls:// without Dask's TLS settings: a TypeError inside the Client before."""
    r = run("bench", pnp_suite(tmp_path), "-o", tmp_path / "o", "--backend", "dask", "--scheduler", address)
    assert_one_error_line(r, "--scheduler", address)
    assert [c.status for c in clients if c.status not in ("newly-created", "closed")] == []
    assert not (tmp_path / "o").exists()


# ------------------------------------------------------------------ counts that would stall on memory


def test_a_billion_seeds_is_refused_by_the_count(tmp_path):
    """`seeds: 1000000000` built a tuple of a billion seeds before the first run."""
    from regrasp_cli.bench.suite import MAX_SEEDS, seeds_of
    from regrasp_cli.errors import InputError

    assert len(seeds_of(None, "seeds", MAX_SEEDS)) == MAX_SEEDS
    with pytest.raises(InputError, match="seeds: expected a count from 1 to 10,000"):
        seeds_of(tmp_path / "suite.yaml", "seeds", 1_000_000_000)
