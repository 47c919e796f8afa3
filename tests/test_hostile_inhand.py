"""Hostile and broken input on the in-hand surface (issue 40): malformed contacts in a plan
and an in-hand phase without any are one line naming the plan and the field (exit 2) for
`regrasp validate` and `regrasp show`; a speed grid 100x too fast, or a blend, in an
in-hand plan is caught by the checks every plan gets (exit 1); a damaged cached in-hand
roadmap is learned again with a line saying why."""

from __future__ import annotations

import copy
import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from cli_helpers import assert_one_error_line, needs_separate_stderr, run
from conftest import ROOT

from regrasp_cli.artefacts import QuietBuilder
from regrasp_cli.dexterous.gait import GaitOptions
from regrasp_cli.dexterous.multiquery import LearnOptions
from regrasp_cli.dexterous.roadmap import GaitTreeOptions
from regrasp_cli.dexterous.task import inhand_roadmap, load_inhand_problem, roadmap_path, roadmap_provenance
from regrasp_cli.motion.blend import blended_path, time_optimal
from regrasp_cli.validate import validate_plan

SCENE = ROOT / "regrasp_cli" / "data" / "scenes" / "inhand_ball.yaml"


@pytest.fixture(scope="module")
def planned(tmp_path_factory, cache_dir) -> tuple[Path, dict]:
    """A solved in-hand plan of the ball scene: its folder (with the files it names) and
    the plan as a dict."""
    out = tmp_path_factory.mktemp("hostile_inhand") / "plan.json"
    result = run("--cache-dir", cache_dir, "inhand", "plan", SCENE, "-o", out, "--no-timings", "--no-check")
    assert result.exit_code == 0, result.output
    return out.parent, json.loads(out.read_text())


def _write(planned: tuple[Path, dict], name: str, edit=None, d: dict | None = None) -> Path:
    """A copy of the plan (or ``d``), changed by ``edit``, beside it: its files are relative to it."""
    folder, original = planned
    d = copy.deepcopy(original if d is None else d)
    if edit is not None:
        edit(d)
    path = folder / name
    path.write_text(json.dumps(d))
    return path


def _with_contacts(d: dict) -> int:
    """Index of the first phase whose second waypoint has two contacts or more."""
    return next(k for k, p in enumerate(d["phases"]) if len(p["contacts"]) >= 2 and len(p["contacts"][1]) >= 2)


# ------------------------------------------------------------------ case 1: malformed contacts


def _contact(value):
    def edit(d):
        d["phases"][_with_contacts(d)]["contacts"][1][1] = value
    return edit


def _point(value):
    def edit(d):
        c = d["phases"][_with_contacts(d)]["contacts"][1][1]
        if value is None:
            del c["point"]
        else:
            c["point"] = value
    return edit


def _twice(d):
    c = d["phases"][_with_contacts(d)]["contacts"][1]
    c[1]["finger"] = c[0]["finger"]


@needs_separate_stderr
@pytest.mark.parametrize("edit, field, words", [
    (_point(None), "[1][1].point", ("missing",)),
    (_contact("f1"), "[1][1]", ("expected a contact", "found str")),
    (_contact(7), "[1][1]", ("expected a contact", "found int")),
    (_point([float("nan"), 0.0, 0.0]), "[1][1].point", ("finite",)),
    (_point([0.01, 0.02]), "[1][1].point", ("shape (3,)", "(2,)")),
    (_twice, "[1][1].finger", ("two contacts",)),
], ids=["no-point", "string", "int", "nan", "2-vector", "finger-twice"])
def test_a_malformed_contact_is_one_line_naming_its_field(planned, edit, field, words):
    path = _write(planned, "contact.json", edit)
    result = run("validate", path)
    assert_one_error_line(result, str(path), f"phases[{_with_contacts(planned[1])}].contacts{field}", *words)


@needs_separate_stderr
def test_show_refuses_a_malformed_contact_before_writing(planned, tmp_path):
    path = _write(planned, "contact.json", _point([0.01, 0.02]))
    result = run("show", path, "--html", tmp_path / "view.html")
    assert_one_error_line(result, str(path), f"phases[{_with_contacts(planned[1])}].contacts[1][1].point")
    assert not (tmp_path / "view.html").exists()


# ------------------------------------------------------------------ case 2: an in-hand phase without contacts


@needs_separate_stderr
def test_an_inhand_phase_without_contacts_is_malformed(planned):
    k = _with_contacts(planned[1])
    path = _write(planned, "no_contacts.json", lambda d: d["phases"][k].pop("contacts"))
    result = run("validate", path)
    assert_one_error_line(result, str(path), f"phases[{k}].contacts", "expected their contacts at every waypoint")


# ------------------------------------------------------------------ case 3: timing of in-hand phases


def _timed(d: dict, speedup: float = 1.0, radius: float = 0.0) -> dict:
    """``d`` with blends (``radius`` at a phase's inner waypoints where it fits, else 0)
    and the time-optimal speed grid of every phase, then every time divided by
    ``speedup`` and every speed multiplied by it."""
    d = copy.deepcopy(d)
    v, a = np.array(d["limits"]["velocity"]), np.array(d["limits"]["acceleration"])
    t0 = 0.0
    for p in d["phases"]:
        q = np.array(p["waypoints"])
        seg = np.r_[0.0, np.linalg.norm(np.diff(q, axis=0), axis=1), 0.0]
        blends = np.where(np.minimum(seg[:-1], seg[1:]) > 3 * radius, radius, 0.0)
        blends[[0, -1]] = 0.0
        path = blended_path(q, blends)
        tm = time_optimal(path, v, a).shifted(t0)
        p["blends"] = blends.tolist()
        p["times"] = (np.interp(path.knots, tm.s, tm.t) / speedup).tolist()
        p["timing"] = {"s": tm.s.tolist(), "speed": (tm.sd * speedup).tolist(), "t": (tm.t / speedup).tolist()}
        t0 = float(tm.t[-1])
    return d


def test_a_speed_grid_100x_too_fast_is_caught_in_an_inhand_plan(planned):
    assert validate_plan(_write(planned, "timed.json", d=_timed(planned[1]))).valid  # the grid as timed: fair
    path = _write(planned, "fast.json", d=_timed(planned[1], speedup=100.0))
    result = run("validate", path)
    assert result.exit_code == 1, result.output
    first = planned[1]["phases"][0]["name"]
    assert f"timing {first}" in result.output and "velocity" in result.output and "exceeds its limit" in result.output


def test_a_blend_in_an_inhand_phase_is_refused(planned):
    issues = validate_plan(_write(planned, "blended.json", d=_timed(planned[1], radius=0.002))).issues
    assert any(i.check == "kind" and "blend of radius" in i.message for i in issues), issues


# ------------------------------------------------------------------ case 4: a damaged cached roadmap


class _Told(QuietBuilder):
    def __init__(self):
        self.notices = []

    def notice(self, message: str) -> None:
        self.notices.append(message)


def test_a_damaged_roadmap_is_learned_again_with_a_line_saying_why(tmp_path, cache_dir):
    problem = replace(load_inhand_problem(SCENE, cache_dir), cache_dir=tmp_path)  # its own roadmap folder
    o = LearnOptions(roots=2)
    r = replace(GaitTreeOptions(), step_rad=problem.spec.planning.step_rad)  # as inhand_roadmap reads them
    g = GaitOptions(gait_m=problem.spec.planning.gait_m)
    path = roadmap_path(tmp_path, problem, roadmap_provenance(problem, o, r, g))
    path.parent.mkdir(parents=True)
    path.write_bytes(b"\x89HDF\r\n\x1a\n truncated")
    told = _Told()
    _, _, built = inhand_roadmap(problem, o, builder=told)
    assert built and len(told.notices) == 1
    assert told.notices[0].startswith(f"rebuilding {path}: damaged artefact: ")
    _, _, built = inhand_roadmap(problem, o, builder=told)
    assert not built and len(told.notices) == 1  # the file learned again is fresh


# ------------------------------------------------------------------ the object out of the fingertips' reach


@pytest.mark.parametrize("x, goal_xyz, words", [
    (1.0e6, None, (": object_start.xyz: ", "within +-1000")),  # 1000 km: refused as a position
    (10.0, None, (": object_start: ", "beyond the reach")),  # the goal inherits the start's position
    (10.0, [0.0, 0.0, 0.0], (": object_start: ", "beyond the reach"))])
def test_an_object_start_out_of_reach_is_blamed_on_object_start(tmp_path, cache_dir, x, goal_xyz, words):
    """Not on the goal, which the planner tried first."""
    import yaml

    d = yaml.safe_load(SCENE.read_text())
    d["robot"] = "builtin:hand4"
    d["object_start"] = {"xyz": [x, 0.0, 0.0]}
    if goal_xyz is not None:
        d["object_goal"] = dict(d["object_goal"], xyz=goal_xyz)
    scene = tmp_path / "scene.yaml"
    scene.write_text(yaml.safe_dump(d))
    result = run("--cache-dir", cache_dir, "inhand", "plan", scene, "-o", tmp_path / "plan.json")
    assert_one_error_line(result, str(scene), *words)
    assert not (tmp_path / "plan.json").exists()


# ------------------------------------------------------------------ what the GS_n checks leave out


def test_a_palm_inside_an_obstacle_is_refused_naming_robot_config(tmp_path, cache_dir):
    """The GS_n checks see only what moves while the wrist is held (the fingers and the
    object against the rest): a palm already inside an obstacle is refused before
    planning, naming ``robot_config``, not planned around."""
    import yaml

    from regrasp_cli.dexterous.task import finger_links, still_collisions
    from regrasp_cli.model.handshape import palm_and_finger_links
    from regrasp_cli.model.robot import Kinematics

    humanoid = ROOT / "regrasp_cli" / "data" / "scenes" / "inhand_humanoid_ball.yaml"  # a palm on an arm
    problem = load_inhand_problem(humanoid, cache_dir)
    robot, hand, kin = problem.robot, problem.spec.hand, Kinematics(problem.robot)
    palm = sorted(palm_and_finger_links(robot, hand) - finger_links(robot, hand))[0]  # the wrist's link
    X_WG = kin.fk(problem.q_start, robot.hands[hand].grasp_frame)
    p_GP = np.linalg.solve(X_WG, kin.fk(problem.q_start, robot.model.getFrameId(palm)) @ [0, 0, 0, 1])[:3]
    d = yaml.safe_load(humanoid.read_text())
    d["obstacles"] = [{"name": "post", "box": {"size": [0.02, 0.02, 0.02]},
                       "pose": {"xyz": [float(x) for x in p_GP]}}]
    scene = tmp_path / "scene.yaml"
    scene.write_text(yaml.safe_dump(d))
    moved = load_inhand_problem(scene, cache_dir)
    pairs = still_collisions(robot, hand, moved.disabled.links(), moved.q_start, moved.spec.obstacles)
    assert pairs and all("obstacle:post" in p for p in pairs)
    assert not still_collisions(robot, hand, problem.disabled.links(), problem.q_start, problem.spec.obstacles)
    result = run("--cache-dir", cache_dir, "inhand", "plan", scene, "-o", tmp_path / "plan.json")
    assert_one_error_line(result, str(scene), ": robot_config: ", "in collision")
    assert not (tmp_path / "plan.json").exists()
