"""`regrasp show` and `grasps show --png` on bad input: one clear line naming the option or
the file and field, exit code 2, nothing written."""

from __future__ import annotations

import json

import pytest

from cli_helpers import SCENE_YAML, assert_one_error_line, needs_separate_stderr, run

pytestmark = needs_separate_stderr


def test_show_help():
    result = run("show", "--help")
    assert result.exit_code == 0, result.output
    for word in ("PLAN", "--html", "--png", "--fps", "--size", "--geometry"):
        assert word in result.stdout
    result = run("grasps", "show", "--help")
    assert result.exit_code == 0 and "--png" in result.stdout


def test_show_needs_an_output(small_plan):
    assert_one_error_line(run("show", small_plan), "--html/--png", "nothing to do")


def test_show_of_a_missing_plan(tmp_path):
    missing = tmp_path / "no_plan.json"
    assert_one_error_line(run("show", missing, "--png", tmp_path / "frames"), str(missing), "cannot read the plan")
    assert not (tmp_path / "frames").exists()


def test_show_of_a_failed_plan(small_plan, tmp_path):
    d = json.loads(small_plan.read_text())
    d.update(status="failed", failure={"stage": "exchange", "reason": "no collision-free exchange pose"}, phases=[])
    failed = small_plan.parent / "show-failed.json"  # beside the plan: the paths it records stay valid
    failed.write_text(json.dumps(d))
    out = tmp_path / "plan.html"
    line = assert_one_error_line(run("show", failed, "--html", out), str(failed), "status",
                                 "failed at stage exchange", "no collision-free exchange pose")
    assert "no motion to show" in line
    assert not out.exists()


def test_show_of_a_malformed_plan(tmp_path):
    bad = tmp_path / "bad.json"
    bad.write_text('{"format": "regrasp.plan/2", "status": "solved"')
    assert_one_error_line(run("show", bad, "--html", tmp_path / "x.html"), str(bad), "not valid JSON")


@pytest.mark.parametrize("args, words", [
    (("--fps", "0"), ("--fps", "[1, 120]")),
    (("--size", "big"), ("--size", "WIDTHxHEIGHT")),
    (("--size", "20x20"), ("--size", "[160, 4096]")),
])
def test_show_bad_options(small_plan, tmp_path, args, words):
    out = tmp_path / "plan.html"
    assert_one_error_line(run("show", small_plan, "--html", out, *args), *words)
    assert not out.exists()


def test_show_into_a_file_or_a_directory(small_plan, tmp_path):
    a_file = tmp_path / "frames"
    a_file.write_text("not a directory")
    assert_one_error_line(run("show", small_plan, "--png", a_file), "--png", "is a file")
    assert_one_error_line(run("show", small_plan, "--html", tmp_path), "--html", "is a folder")


def test_grasps_png_needs_the_scene(cache_dir, tmp_path):
    out = tmp_path / "g.png"
    any_list = next((cache_dir / "grasps").glob("*.h5"), tmp_path / "list.h5")
    assert_one_error_line(run("--cache-dir", cache_dir, "grasps", "show", any_list, "--png", out), "--png", "--scene")
    assert_one_error_line(run("--cache-dir", cache_dir, "grasps", "show", any_list, "--png", out, "--scene", SCENE_YAML,
                              "--best", "0"), "--best")
    assert not out.exists()
