"""The suite file (regrasp.bench/1): the shipped default suite loads; every malformed
field is one InputError naming the file and the field; command-line overrides."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from regrasp_cli.bench.suite import PLANNERS, load_suite, with_overrides
from regrasp_cli.errors import InputError
from regrasp_cli.manip.context import OnlineOptions

ROOT = Path(__file__).resolve().parents[2]
DEFAULT = ROOT / "configs" / "bench" / "default.yaml"
SCENE = ROOT / "configs" / "scenes" / "desk_handover.yaml"


def write(tmp_path: Path, **fields) -> Path:
    d = {"format": "regrasp.bench/1", "name": "t", "scenes": [str(SCENE)], "planners": ["roadmap"], "seeds": 2}
    d.update(fields)
    d = {k: v for k, v in d.items() if v is not None}
    p = tmp_path / "suite.yaml"
    p.write_text(yaml.safe_dump(d))
    return p


def test_default_suite():
    s = load_suite(DEFAULT)
    assert s.name == "default" and s.scenes == (SCENE.resolve(),)
    assert s.planners == ("roadmap", "rrt-connect", "ompl-rrtconnect") and s.seeds == tuple(range(20))
    assert s.budget_s == 60.0 and s.roadmap_nodes == 50 and s.grasp_target is None
    assert s.iterations == OnlineOptions().rrt.max_iterations == 3000  # the planners' own default


def test_seeds_as_a_list_and_defaults(tmp_path):
    s = load_suite(write(tmp_path, seeds=[5, 1], planners=list(PLANNERS)))
    assert s.seeds == (5, 1) and s.planners == PLANNERS
    assert load_suite(write(tmp_path, seeds=None)).seeds == tuple(range(20))
    assert load_suite(write(tmp_path, sampler="vis-prm")).sampler == "vis-prm"
    assert load_suite(write(tmp_path)).sampler == "faces"
    assert load_suite(write(tmp_path)).held_speed is None
    assert load_suite(write(tmp_path, held_speed=1.0)).held_speed == 1.0


def test_a_suite_s_held_speed_reaches_each_run_s_planner(tmp_path):
    from regrasp_cli.bench.runner import items_of, request_of

    suite = load_suite(write(tmp_path, held_speed=0.75))
    item = items_of(suite, tmp_path / "cache", tmp_path / "plans")[0]
    assert request_of(item).options("pick-and-place").held_speed == 0.75


@pytest.mark.parametrize("fields, field, words", [
    ({"format": "regrasp.bench/2"}, "format", "regrasp.bench/1"),
    ({"name": "a b"}, "name", "results folder"),
    ({"scenes": []}, "scenes", "non-empty list"),
    ({"scenes": ["missing.yaml"]}, "scenes[0]", "no such file"),
    ({"planners": ["prm"]}, "planners", "unknown planner 'prm'"),
    ({"planners": ["roadmap", "roadmap"]}, "planners", "twice"),
    ({"planners": []}, "planners", "at least one"),
    ({"seeds": 0}, "seeds", "from 1 to"),
    ({"seeds": [1, -2]}, "seeds", "integers >= 0"),
    ({"seeds": [1, 1]}, "seeds", "twice"),
    ({"budget_s": 0}, "budget_s", "> 0"),
    ({"roadmap_nodes": 0}, "roadmap_nodes", ">= 1"),
    ({"iterations": 0}, "iterations", ">= 1"),
    ({"iterations": 2.5}, "iterations", "integer"),
    ({"grasp_target": "many"}, "grasp_target", "integer"),
    ({"extra": 1}, "extra", "unknown key"),
    ({"style": "two-arm"}, "style", "expected one of auto"),
    ({"sampler": "grid"}, "sampler", "expected one of faces, vis-prm"),
    ({"held_speed": 0}, "held_speed", "> 0"),
    ({"held_speed": 1.5}, "held_speed", "<= 1"),
])
def test_bad_fields_name_the_file_and_field(tmp_path, fields, field, words):
    path = write(tmp_path, **fields)
    with pytest.raises(InputError) as e:
        load_suite(path)
    assert e.value.field == field and e.value.file == str(path.resolve())
    assert words in e.value.message and "\n" not in str(e.value)


def test_overrides(tmp_path):
    s = with_overrides(load_suite(write(tmp_path)), seeds=3, planners="rrt-connect, roadmap", budget_s=5)
    assert s.seeds == (0, 1, 2) and s.planners == ("rrt-connect", "roadmap") and s.budget_s == 5.0
    with pytest.raises(InputError, match="--planners"):
        with_overrides(s, planners="roadmap,prm")
    with pytest.raises(InputError, match="--seeds"):
        with_overrides(s, seeds=0)
    with pytest.raises(InputError, match="--budget-s"):
        with_overrides(s, budget_s=-1.0)
    assert with_overrides(s, iterations=20000).iterations == 20000
    with pytest.raises(InputError, match="--iterations"):
        with_overrides(s, iterations=0)
