"""Cached artefacts a user can trust (issue 14): a damaged grasp list or roadmap (bytes
flipped in the middle, truncated, emptied) is refused with `--no-build`, one line naming
the file and what to do, and rebuilt otherwise, with a line saying so; two `plan`
processes on one fresh cache build each artefact once, and the hashes each plan records
are those of the files in the cache.

The artefacts are the small ones of tests/test_cli_plan.py (20 grasps per hand, 12-node
roadmaps), built once into the run's cache and copied for each test."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import h5py
import pytest

from cli_helpers import ROOT, SCENE_YAML, SMALL, assert_one_error_line, copy_artefacts, needs_separate_stderr, run
from regrasp_cli.store import sha256_file


pytestmark = needs_separate_stderr


def plan(cache_dir: Path, out: Path, *args):
    return run("--cache-dir", cache_dir, "plan", SCENE_YAML, "-o", out, *SMALL, *args)


@pytest.fixture(scope="module")
def built(cache_dir, default_plan) -> Path:
    """The run's cache with the small artefacts (conftest.default_plan built what was missing)."""
    return Path(cache_dir)


def _used(cache: Path, key: str) -> Path:
    """The artefact a `plan` of the small options reads from ``cache`` (``grasps_right``,
    ``grasps_left``, ``roadmap``), by the paths the planner itself computes: the cache
    also holds artefacts of other options, built by other tests.  The tests check the plan
    read it (the file named in its error line, or the hash it records)."""
    from regrasp_cli.artefacts import build_options, grasp_list_path, roadmap_options
    from regrasp_cli.roadmap.build import artefact_path
    from regrasp_cli.scene import load_problem

    problem = load_problem(SCENE_YAML, cache)
    if key == "roadmap":
        return artefact_path(cache, problem, roadmap_options(problem.spec, int(SMALL[3]), False, None))
    options = build_options(problem.spec.planning.seed, None, 1, None, None, int(SMALL[1]))
    return grasp_list_path(cache, problem, key.removeprefix("grasps_"), options)


def _damage(path: Path, how: str) -> None:
    data = bytearray(path.read_bytes())
    if how == "flipped":  # XOR 64 bytes in the middle: HDF5 may still open the file
        mid = len(data) // 2
        data[mid:mid + 64] = bytes(b ^ 0xFF for b in data[mid:mid + 64])
    elif how == "truncated":
        data = data[: len(data) // 2]
    else:
        data = bytearray()
    path.write_bytes(bytes(data))


def _checksum(path: Path) -> str:
    with h5py.File(path, "r") as f:
        return str(f.attrs["content_sha256"])


def _recorded(plan_file: Path) -> dict[str, str]:
    return json.loads(plan_file.read_text())["stats"]["artefacts"]


@pytest.mark.parametrize("folder, how", [("grasps", "flipped"), ("roadmap", "flipped"), ("roadmap", "truncated"),
                                         ("grasps", "empty")])
def test_a_damaged_artefact_is_refused_with_no_build(built, tmp_path, folder, how):
    cache = copy_artefacts(built, tmp_path / "cache")
    path = _used(cache, "grasps_right" if folder == "grasps" else "roadmap")
    _damage(path, how)
    out = tmp_path / "plan.json"
    result = plan(cache, out, "--no-build")
    line = assert_one_error_line(result, str(path), "damaged artefact", f"regrasp {folder} build")
    assert not out.exists(), line


def test_a_damaged_grasp_list_is_rebuilt_with_a_line_saying_so(built, tmp_path):
    cache = copy_artefacts(built, tmp_path / "cache")
    path = _used(cache, "grasps_right")
    before = _checksum(path)
    _damage(path, "flipped")
    out = tmp_path / "plan.json"
    result = plan(cache, out)
    assert result.exit_code == 0, (result.output, result.exception)
    assert f"rebuilding {path}: damaged artefact" in result.stdout
    assert _checksum(path) == before  # rebuilt from the same inputs: the same contents
    recorded = _recorded(out)
    assert recorded["grasps_right"] == sha256_file(path)


def test_two_plans_on_a_fresh_cache_build_once_and_record_the_files_they_used(built, tmp_path):
    """Two processes at once on a cache holding only the robot's self-collision pairs and
    finger workspaces (slow, and not what is tested): each grasp list and the roadmap are
    built by one of them, the other waits and reuses them."""
    cache = tmp_path / "cache"
    for folder in ("self_collision", "workspace"):
        copy_artefacts(built / folder, cache / folder)
    env = dict(os.environ, COLUMNS="250", PYTHONPATH=str(ROOT))
    outs = [tmp_path / f"plan{i}.json" for i in (0, 1)]
    procs = [subprocess.Popen([sys.executable, "-m", "regrasp_cli.cli", "--cache-dir", str(cache), "plan",
                               str(SCENE_YAML), "-o", str(o), *SMALL, "--jobs", "1", "--no-check"],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env) for o in outs]
    results = [p.communicate(timeout=900) for p in procs]
    for p, (stdout, stderr) in zip(procs, results):
        assert p.returncode == 0, (stdout, stderr)
    stdouts = [stdout for stdout, _ in results]
    # each build ends with the path it wrote: every artefact was built by exactly one process
    for what in ("right hand: ", "left hand: ", "roadmap: "):
        written = [ln for s in stdouts for ln in s.splitlines() if ln.startswith(what) and ln.endswith(".h5")]
        assert len(written) == 1, (what, stdouts)
    files = {sha256_file(p): p.name for p in cache.glob("*/*.h5")}
    for o in outs:
        for name, digest in _recorded(o).items():
            assert digest in files, (name, o)
    assert len(list((cache / "grasps").glob("*.h5"))) == 2 and len(list((cache / "roadmap").glob("*.h5"))) == 1


# --------------------------------------------------------------------------- outputs and values at the edge


@pytest.mark.parametrize("where", ["a_file", "sys"])
def test_an_unwritable_plan_output_is_refused_before_planning(tmp_path, where):
    """Before anything is loaded or built: the cache stays empty."""
    if where == "a_file":
        (tmp_path / "a_file").write_text("x")
        out, why = tmp_path / "a_file" / "plan.json", "is a file, not a folder"
    else:  # a folder nobody may write into, root included
        out, why = Path("/sys/plan.json"), "is not writable"
    cache = tmp_path / "cache"
    result = run("--cache-dir", cache, "plan", SCENE_YAML, "-o", out)
    assert_one_error_line(result, "--output", str(out), why)
    assert not cache.exists()


def test_an_output_folder_given_as_the_plan_file_is_refused(tmp_path):
    result = run("--cache-dir", tmp_path / "cache", "plan", SCENE_YAML, "-o", tmp_path)
    assert_one_error_line(result, "--output", "is a folder")


@pytest.mark.parametrize("option, value", [("--html", "a_file/x.html"), ("--png", "a_file")])
def test_unwritable_show_outputs_are_refused_before_drawing(tmp_path, option, value):
    (tmp_path / "a_file").write_text("x")
    result = run("show", tmp_path / "no_plan.json", option, tmp_path / value)  # checked before the plan is read
    assert_one_error_line(result, option)


def test_a_write_error_is_one_line(tmp_path):
    from regrasp_cli.errors import InputError
    from regrasp_cli.store import atomic_write_text

    (tmp_path / "a_file").write_text("x")
    with pytest.raises(InputError, match="cannot write the file") as e:
        atomic_write_text(tmp_path / "a_file" / "sub" / "out.txt", "text")
    assert e.value.file == str(tmp_path / "a_file" / "sub" / "out.txt")


@pytest.mark.parametrize("args", [("plan", SCENE_YAML), ("grasps", "build", SCENE_YAML), ("info", SCENE_YAML),
                                  ("roadmap", "build", SCENE_YAML)])
def test_a_negative_seed_is_one_line(tmp_path, args):
    result = run("--cache-dir", tmp_path / "cache", *args, "--seed", "-1")
    assert_one_error_line(result, "--seed", "expected an integer >= 0, found -1")
    assert not (tmp_path / "cache").exists()


def test_cache_dir_is_accepted_after_the_subcommand(built, tmp_path):
    """`plan S --cache-dir D` uses D: with only the self-collision pairs in it and
    --no-build, the missing artefact named (the placements, loaded first) is D's."""
    d = tmp_path / "elsewhere"
    copy_artefacts(built / "self_collision", d / "self_collision")
    result = run("plan", SCENE_YAML, "-o", tmp_path / "plan.json", *SMALL, "--no-build", "--cache-dir", d)
    assert_one_error_line(result, str(d / "placements"), "no such artefact")


@pytest.mark.parametrize("text, said", [("1.0e9", "write 1.0e+9"), ("'0.5'", "without quotes")])
def test_friction_written_as_text_says_how_to_write_a_number(tmp_path, text, said):
    from cli_helpers import scene_dict, write_scene

    scene = write_scene(tmp_path / "s.yaml", scene_dict())
    scene.write_text(scene.read_text().replace("friction: 0.5", f"friction: {text}"))
    assert f"friction: {text}" in scene.read_text()
    result = run("--cache-dir", tmp_path / "cache", "plan", scene, "-o", tmp_path / "p.json")
    assert_one_error_line(result, "object.friction", "found the text", said)


def test_friction_above_a_physical_value_is_refused(tmp_path):
    from cli_helpers import scene_dict, write_scene

    d = scene_dict()
    d["object"]["friction"] = 100.0
    result = run("--cache-dir", tmp_path / "cache", "plan", write_scene(tmp_path / "s.yaml", d), "-o", tmp_path / "p.json")
    assert_one_error_line(result, "object.friction", "<= 5", "100")
