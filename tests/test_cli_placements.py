"""`regrasp placements build` and `regrasp placements show`: the artefact written, read back
and drawn, a file for another object refused, and bad input (an object that rolls, a
support that is not there, a picture without the object) as one line and exit 2."""

from __future__ import annotations

from pathlib import Path

import pytest
import trimesh
import yaml

from cli_helpers import assert_one_error_line, needs_separate_stderr, run, write_scene

ROOT = Path(__file__).resolve().parents[1]
BAXTER_SCENE = ROOT / "configs" / "scenes" / "baxter_handover.yaml"
DESK_SCENE = ROOT / "configs" / "scenes" / "desk_handover.yaml"

pytestmark = needs_separate_stderr


def _scene(tmp_path: Path, **changes) -> Path:
    d = yaml.safe_load(BAXTER_SCENE.read_text())
    d.update(changes)
    return write_scene(tmp_path / "scene.yaml", d)


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    cache = tmp_path_factory.mktemp("placements")
    result = run("--cache-dir", cache, "placements", "build", BAXTER_SCENE)
    return result, cache, sorted((cache / "placements").glob("*.h5"))


def test_build_lists_the_block_s_six_faces_and_their_fits(built):
    result, _, files = built
    assert result.exit_code == 0, (result.output, result.exception)
    assert "builtin:block: 6 stable placements" in result.stdout
    assert "fits on table" in result.stdout and "fits on crate" in result.stdout
    assert len(files) == 1 and f"placements: {files[0]}" in result.stdout


def test_show_reads_checks_and_draws(built, tmp_path):
    _, _, files = built
    png = tmp_path / "p.png"
    result = run("placements", "show", files[0], "--scene", BAXTER_SCENE, "--png", png)
    assert result.exit_code == 0, (result.output, result.exception)
    assert "regrasp.placements v1" in result.stdout and "6 stable placements" in result.stdout
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_a_file_for_another_object_is_refused(built):
    _, _, files = built
    result = run("placements", "show", files[0], "--scene", DESK_SCENE)
    assert_one_error_line(result, str(files[0]), "different mesh", "regrasp placements build")


def test_a_ball_has_no_stable_placement_and_nothing_is_written(tmp_path):
    trimesh.creation.icosphere(subdivisions=3, radius=0.04).export(tmp_path / "ball.stl")
    scene = _scene(tmp_path, object={"mesh": "ball.stl"})
    result = run("--cache-dir", tmp_path / "cache", "placements", "build", scene)
    assert_one_error_line(result, str(scene), "object.mesh", "no stable placement", "rolls")
    assert not list((tmp_path / "cache").rglob("*.h5"))


def test_a_support_that_is_not_an_obstacle_is_refused(tmp_path):
    scene = _scene(tmp_path, supports=["table", "shelf"])
    result = run("--cache-dir", tmp_path / "cache", "placements", "build", scene)
    assert_one_error_line(result, str(scene), "supports[1]", "'shelf'")


def test_a_picture_needs_the_scene(built, tmp_path):
    _, _, files = built
    result = run("placements", "show", files[0], "--png", tmp_path / "p.png")
    assert_one_error_line(result, "--png", "--scene")
    assert not (tmp_path / "p.png").exists()
