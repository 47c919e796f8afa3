"""`regrasp bench` on an in-hand suite (``regrasp.inhand-bench/1``): a one-goal suite on
`builtin:hand4` and the ball writes its scene, a plan that passes `regrasp validate` and a
record saying so; a missing optional mesh is skipped, a missing required one and a bad
field are one error line with exit 2, and the pick-and-place suite's options are refused,
not ignored."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import yaml

from cli_helpers import assert_one_error_line, needs_separate_stderr, run

from regrasp_cli.bench.inhand import load_inhand_suite
from regrasp_cli.errors import InputError
from regrasp_cli.validate import validate_plan


def suite(tmp_path: Path, **fields) -> Path:
    d = {"format": "regrasp.inhand-bench/1", "name": "tiny-inhand",
         "hands": [{"robot": "builtin:hand4", "label": "hand4", "objects": ["ball"]}], "goals": 1,
         "objects": [{"mesh": "builtin:ball", "label": "ball"},
                     {"mesh": "not_shipped.stl", "label": "scan", "optional": True}]}
    d.update(fields)
    p = tmp_path / "suite.yaml"
    p.write_text(yaml.safe_dump(d))
    return p


def test_a_one_goal_suite_plans_validates_and_records(tmp_path, cache_dir):
    out = tmp_path / "results"
    r = run("--cache-dir", cache_dir, "bench", suite(tmp_path), "-o", out, "--jobs", "1")
    assert r.exit_code == 0, (r.output, r.exception)
    (rec,) = [json.loads(line) for line in (out / "runs.jsonl").read_text().splitlines()]
    assert (rec["hand"], rec["object"], rec["goal"]) == ("hand4", "ball", 0)
    assert rec["solved"] and rec["stage"] is None, rec
    plan = out / "plans" / "hand4-ball-00.json"
    assert validate_plan(plan).valid
    assert (out / "scenes" / "hand4-ball-00.yaml").is_file()
    assert "| hand4 | ball | 1/1 |" in (out / "summary.md").read_text()
    assert json.loads((out / "meta.json").read_text())["suite"]["mode"] == "single-query"


def test_suite_fields_are_checked(tmp_path):
    s = load_inhand_suite(suite(tmp_path))
    assert [o.label for o in s.objects] == ["ball"] and s.skipped == ("scan",) and s.goals == (0,)
    for fields, field in [({"mode": "often"}, "mode"), ({"goals": 0}, "goals"),
                          ({"hands": [{"robot": "builtin:hand4", "objects": ["cup"]}]}, "hands[0].objects"),
                          ({"objects": [{"mesh": "missing.stl"}]}, "objects[0].mesh"), ({"colour": 1}, "colour")]:
        with pytest.raises(InputError) as e:
            load_inhand_suite(suite(tmp_path, **fields))
        assert e.value.field == field, (fields, str(e.value))


@needs_separate_stderr
def test_bad_input_is_one_line_with_exit_2(tmp_path, cache_dir):
    r = run("--cache-dir", cache_dir, "bench", suite(tmp_path, mode="often"), "-o", tmp_path / "o")
    assert_one_error_line(r, "mode")
    r = run("--cache-dir", cache_dir, "bench", suite(tmp_path), "-o", tmp_path / "o", "--planners", "roadmap")
    assert_one_error_line(r, "--planners")
