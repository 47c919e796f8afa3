"""`regrasp plan --style` end to end on our HiroNX-like robot (seed 001): one arm where it
suffices, a placement and a new grasp where the goal is upside down in a tray and the
other arm cannot help, no fewer regrasps over the same graph (the exhaustive check), and
styles that cannot work as one line: exit 1 with the reason, or exit 2 for bad input."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import trimesh
import yaml

from cli_helpers import assert_one_error_line, needs_separate_stderr, run, write_scene

ROOT = Path(__file__).resolve().parents[1]
SCENES = ROOT / "configs" / "scenes"
SMALL = ("--grasp-target", "60", "--roadmap-nodes", "12")

pytestmark = needs_separate_stderr


@pytest.fixture(scope="module")
def cache(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("styles-cache")


def _plan(cache: Path, scene: Path, out: Path, *args):
    result = run("--cache-dir", cache, "plan", scene, "-o", out, *SMALL, *args)
    return result, (json.loads(out.read_text()) if out.is_file() else None)


def test_one_arm_when_one_arm_suffices(cache, tmp_path):
    result, plan = _plan(cache, SCENES / "hironx_onearm.yaml", tmp_path / "plan.json")
    assert result.exit_code == 0, (result.output, result.exception)
    c = plan["stats"]["counts"]
    assert (c["style"], c["regrasps"], c["placements"]) == ("one-arm", 0, 0)
    assert [p["kind"] for p in plan["phases"]] == ["transit", "grasp", "transfer", "release", "transit"]
    assert "style: one-arm, 0 regrasps, 0 intermediate placements" in result.stdout
    assert "valid" in result.stdout


def test_upside_down_in_a_tray_is_put_down_and_grasped_again(cache, tmp_path):
    from regrasp_cli.validate import validate_plan

    out = tmp_path / "plan.json"
    result, plan = _plan(cache, SCENES / "hironx_upside_down.yaml", out)
    assert result.exit_code == 0, (result.output, result.exception)
    c = plan["stats"]["counts"]
    assert c["style"] == "place-regrasp" and c["regrasps"] >= 1 and c["placements"] >= 1
    assert set(c["styles"]) == {"one-arm", "handover", "place-regrasp", "inhand"}  # why the others were not used
    assert "left hand: neither" in c["styles"]["handover"]
    assert c["styles"]["inhand"].startswith("no hand can turn the object in its fingers")  # jaws (scene (c))
    # the object rests at an intermediate placement between two grasps of the right hand
    ids = {p["id"] for p in plan["placements"]}
    assert {"start", "goal"} < ids
    resting = [p["placement"] for p in plan["phases"] if p["kind"] == "transit"]
    assert resting[0] == "start" and resting[-1] == "goal" and set(resting[1:-1]) <= ids - {"start", "goal"}
    held = [tuple(p["holding"].items()) for p in plan["phases"] if p["kind"] == "transfer"]
    assert all(h[0][0] == "right" for h in held) and len(set(held)) == c["regrasps"] + 1
    # the goal pose is upside down: the object's z axis points down
    goal = next(np.array(p["pose"]) for p in plan["placements"] if p["id"] == "goal")
    assert goal[2, 2] == pytest.approx(-1.0)
    assert validate_plan(out).valid


def test_the_visibility_prm_puts_it_down_and_grasps_it_again_too(cache, tmp_path):
    """The same scene with the paper's Visibility-PRM for intermediate placements: its
    roadmap joins the start and the goal, and only its nodes join the graph."""
    from regrasp_cli.validate import validate_plan

    out = tmp_path / "plan.json"
    result, plan = _plan(cache, SCENES / "hironx_upside_down.yaml", out, "--style", "place-regrasp",
                         "--sampler", "vis-prm")
    assert result.exit_code == 0, (result.output, result.exception)
    c = plan["stats"]["counts"]
    assert c["style"] == "place-regrasp" and c["regrasps"] >= 1 and c["placements"] >= 1
    vis = c["vis_prm"][-1]
    assert vis["joined"] and vis["connectors"] >= 1 and vis["samples"] <= 60
    assert vis["nodes"] <= vis["configurations"]  # dropped samples are not in the graph
    assert validate_plan(out).valid


def test_the_regrasp_count_is_the_least_over_the_graph(cache):
    """The same run as above through the library: the exhaustive check, solving every
    edge a path with fewer regrasps would need, finds none."""
    from regrasp_cli.artefacts import load_artefacts, load_placements
    from regrasp_cli.manip.context import OnlineOptions
    from regrasp_cli.manip.queries import Roadmap
    from regrasp_cli.manip.tasks import manipulation
    from regrasp_cli.scene import load_problem

    scene = SCENES / "hironx_upside_down.yaml"
    problem = load_problem(scene, cache)
    lists, art, _ = load_artefacts(scene, cache, problem, True, 1, True, None, 12, 60)
    stable, _ = load_placements(cache, problem, True)
    keep = {}
    outcome = manipulation.plan(problem, lists, Roadmap.of(art), OnlineOptions(jobs=1), 0, stable, keep=keep)
    assert outcome.failure is None
    r = outcome.counts["regrasps"]
    fewer, solved = manipulation.fewer_regrasps(keep["graph"], stable, r, budget=400)
    assert fewer is False and solved <= 400


def test_a_forced_style_that_cannot_work_fails_with_its_reason(cache, tmp_path):
    result, plan = _plan(cache, SCENES / "hironx_upside_down.yaml", tmp_path / "plan.json", "--style", "one-arm")
    line = assert_one_error_line(result, "no hand can hold the object at both", "0 at both", exit_code=1)
    assert "handover" not in line and "place-regrasp" not in line
    assert plan["status"] == "failed"


def test_the_unreachable_scene_fails_at_once_for_every_style(cache, tmp_path):
    result, plan = _plan(cache, SCENES / "hironx_unreachable.yaml", tmp_path / "plan.json")
    line = assert_one_error_line(result, "stage 'grasps'", "one-arm (stage grasps):", "handover (stage grasps):",
                                 "place-regrasp (stage grasps):", "goal", exit_code=1)
    assert "no hand can hold the object at its goal pose" in line
    assert plan["failure"]["stage"] == "grasps"
    assert plan["stats"]["counts"]["single_checks"] == 0  # ruled out before any configuration is searched


def test_placing_needs_a_support_and_a_stable_placement(cache, tmp_path):
    d = yaml.safe_load((SCENES / "hironx_onearm.yaml").read_text())
    d["supports"] = []
    scene = write_scene(tmp_path / "nosupport.yaml", d)
    result = run("--cache-dir", cache, "plan", scene, "-o", tmp_path / "p.json", "--style", "place-regrasp", *SMALL)
    assert_one_error_line(result, str(scene), "obstacles", "no support surface")
    assert not (tmp_path / "p.json").exists()

    trimesh.creation.icosphere(subdivisions=3, radius=0.025).export(tmp_path / "ball.stl")
    d = yaml.safe_load((SCENES / "hironx_onearm.yaml").read_text())
    d["object"] = {"mesh": "ball.stl"}
    scene = write_scene(tmp_path / "ball.yaml", d)
    result = run("--cache-dir", cache, "plan", scene, "-o", tmp_path / "p.json", "--style", "place-regrasp", *SMALL)
    assert_one_error_line(result, str(scene), "object.mesh", "no stable placement")


def test_jaws_cannot_turn_the_object_in_the_hand(cache, tmp_path):
    """Scene (c) of issue 42: HiroNX's parallel jaws cannot finger-gait; asked to, the
    planner says so at once, and auto uses another move (place and regrasp, above)."""
    result, _ = _plan(cache, SCENES / "hironx_upside_down.yaml", tmp_path / "plan.json", "--style", "inhand")
    assert result.exit_code == 1
    assert "three or more fingertips" in " ".join(result.output.split())


def test_the_humanoid_cannot_turn_the_ball_firmly_between_cup_and_niche(tmp_path):
    """Issue 42's scene (a): no grasp serves both ends and nothing may hold the ball between
    them.  Turning it in the left hand's fingers (seed 003) needs, at every finger step,
    three fingers that hold a ball firmly (GsScratch.firm); the humanoid's thumb opposes
    three fingers, and its plans that stepped with less threw the ball in MuJoCo
    (docs/BENCHMARKS.md, "In-hand reorientation"): the in-hand style fails and says where,
    writing a failed plan, never a solved one."""
    out = tmp_path / "plan.json"
    result = run("--cache-dir", tmp_path / "cache", "plan", SCENES / "humanoid_cup_to_niche.yaml", "-o", out,
                 "--style", "inhand", "--roadmap-nodes", "12")
    assert result.exit_code == 1, result.output
    assert "did not turn the object from one grasp to the other" in " ".join(result.output.split())
    plan = json.loads(out.read_text())
    assert plan["status"] == "failed" and plan["failure"]["stage"] == "transition"
    assert plan["failure"]["transition"].startswith("inhand left-")
