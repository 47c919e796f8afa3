"""``regrasp.plan/2`` beyond the hand-over of the default task, through the command line
(click.testing.CliRunner on regrasp_cli.cli.main).

(a) A regrasp through an intermediate placement, made here by hand from two real plans
of the planner: the default scene's (the right hand picks the statuette at ``start``,
hands it over to the left, which puts it down behind the lamp) and the plan of a copy of
the scene whose task starts where the first ends (the left hand picks it up again, hands
it over to the right, which puts it down near the start).  Joined, the object goes
``start`` -> ``middle`` -> ``goal`` held by the right hand, the left, the left again and the
right (the grasps of one list, so some may repeat), the second half's times shifted and its
phases renamed.
The robot is at rest where the halves meet and the object at the first plan's goal, which
is the second one's start, so the joined plan is as valid as its halves: `regrasp
validate` must accept it, reject it when the intermediate placement is moved (the object
would jump there), and `regrasp show` must draw its key frames, the second pick included.

(b) Malformed plan/2 files (an unknown kind, a holding naming no grasp of the plan, a hand
holding the object while it rests) and a plan/1 file: one line naming the field, exit
code 2, from `validate` and `show`.  An in-hand phase in a pick-and-place plan: `validate`
says in one line it checks those in in-hand plans only; `show` draws it.
"""

from __future__ import annotations

import copy
import json
import re
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from cli_helpers import SMALL, assert_one_error_line, needs_separate_stderr, run, scene_dict, write_scene

pytestmark = needs_separate_stderr

# the second task: from the first one's goal (behind the lamp, left hand only) to near its start
BACK_START = {"xyz": [0.62, 0.78, 0.74], "rpy": [0, 0, -1.5708]}
BACK_GOAL = {"xyz": [0.45, -0.75, 0.74], "rpy": [0, 0, 1.5708]}
SAME = ("joint_names", "limits", "robot", "object", "obstacles", "collision")  # identical in both halves
KEY_FRAMES = ("start", "pick", "exchange", "place", "pick-2", "exchange-2", "place-2", "end")


def _plan(cache_dir: Path, scene: Path, out: Path) -> dict:
    # a hand-over, as the default scene's (under auto a place-and-regrasp, as few regrasps, may come first)
    result = run("--cache-dir", cache_dir, "plan", scene, "-o", out, *SMALL, "--seed", 0, "--no-check",
                 "--style", "handover")
    assert result.exit_code == 0, (result.output, result.stderr, result.exception)
    return json.loads(out.read_text())


def join(first: dict, second: dict) -> dict:
    """``first`` then ``second`` (which starts where ``first`` ends) as one plan: the first
    one's goal and the second one's start become the placement ``middle``; the second
    half's phases are renamed ``<name>-2`` and its times follow the first half's."""
    for key in SAME:
        assert first[key] == second[key], key
    first_places = {p["id"]: p["pose"] for p in first["placements"]}
    second_places = {p["id"]: p["pose"] for p in second["placements"]}
    assert first_places["goal"] == second_places["start"]
    assert first["phases"][-1]["waypoints"][-1] == second["phases"][0]["waypoints"][0]
    grasps = {g["id"]: g for g in first["grasps"]}
    for g in second["grasps"]:
        assert grasps.setdefault(g["id"], g) == g, g["id"]  # one id, one grasp

    def moved(phase: dict, rename: dict, suffix: str, dt: float) -> dict:
        p = copy.deepcopy(phase)
        p["name"] += suffix
        p["placement"] = rename.get(p["placement"], p["placement"])
        p["times"] = [t + dt for t in p["times"]]
        if p.get("timing"):
            p["timing"]["t"] = [t + dt for t in p["timing"]["t"]]
        return p

    t_end = first["phases"][-1]["times"][-1]
    plan = copy.deepcopy(first)
    plan.update(
        task="regrasp (joined by tests/test_plan2.py)", stats={},
        grasps=list(grasps.values()),
        placements=[{"id": "start", "pose": first_places["start"]}, {"id": "middle", "pose": first_places["goal"]},
                    {"id": "goal", "pose": second_places["goal"]}],
        phases=[moved(p, {"goal": "middle"}, "", 0.0) for p in first["phases"]]
        + [moved(p, {"start": "middle"}, "-2", t_end) for p in second["phases"]])
    return plan


@pytest.fixture(scope="module")
def regrasp(cache_dir, default_plan) -> tuple[Path, dict]:
    """The joined plan (see the module docstring): its file, beside its halves (the paths
    they record are relative to that folder), and its dict.  The first half is the
    default scene's plan of conftest.default_plan."""
    d = default_plan.parent
    s = scene_dict()
    s["task"].update(object_start=BACK_START, object_goal=BACK_GOAL)
    back = write_scene(d / "plan2-back.yaml", s)
    first = json.loads(default_plan.read_text())
    second = _plan(cache_dir, back, d / "plan2-back.json")
    plan = join(first, second)
    path = d / "plan2-regrasp.json"
    path.write_text(json.dumps(plan, indent=1))
    return path, plan


def _write(path: Path, d: dict) -> Path:
    path.write_text(json.dumps(d))
    return path


# --------------------------------------------------------------------------- (a) a regrasp


def test_the_joined_plan_regrasps_through_an_intermediate_placement(regrasp):
    """What the joined plan is made of: three placements, three grasps all used, the
    object released at ``middle`` and grasped there again, by other hands than before."""
    from regrasp_cli.trajectory import read_plan

    path, _ = regrasp
    p = read_plan(path)
    assert [pl.id for pl in p.placements] == ["start", "middle", "goal"]
    assert len({pl.X_WO.tobytes() for pl in p.placements}) == 3  # three different poses
    # both halves read the same grasp lists (they do not depend on the task), so a grasp of
    # the first half may come back in the second: ids are unique, both hands hold it
    assert len(p.grasps) >= 2 and len({g.id for g in p.grasps}) == len(p.grasps)
    assert {g.hand for g in p.grasps} == {"left", "right"}
    used = [gid for ph in p.phases for gid in ph.holding.values()]
    assert set(used) == {g.id for g in p.grasps}
    kinds = [ph.kind.value for ph in p.phases]
    assert kinds == 2 * ["transit", "grasp", "transfer", "handover", "handover", "transfer", "release", "transit"]
    assert [ph.placement for ph in p.phases if ph.placement] == ["start", "start", "middle", "middle", "middle",
                                                                 "middle", "goal", "goal"]
    # carried by the right hand, then the left one down to the middle; picked up again there by
    # the left hand, carried by the right one to the goal
    holders = [next(iter(ph.holding)) for ph in p.phases if ph.kind.value == "transfer"]
    assert holders == ["right", "left", "left", "right"]


def test_validate_accepts_the_regrasp(regrasp):
    path, plan = regrasp
    result = run("validate", path)
    assert result.exit_code == 0, (result.output, result.stderr, result.exception)
    out = result.stdout
    assert out.strip().splitlines()[-1] == "valid"
    for phase in plan["phases"]:
        assert re.search(rf"│ {re.escape(phase['name'])} +│ {phase['kind']} +│", out), phase["name"]


def test_validate_rejects_a_jump_to_a_moved_intermediate_placement(regrasp):
    """The middle placement 5 cm further from the robot than where the left hand put the
    object: it jumps as the left hand opens, and the second pick's grasp no longer holds it
    where it is.  (Coarse collision sampling: the attachment check does not depend on it.)"""
    path, plan = regrasp
    d = copy.deepcopy(plan)
    middle = next(p for p in d["placements"] if p["id"] == "middle")
    middle["pose"][0][3] += 0.05
    bad = _write(path.parent / "plan2-jump.json", d)  # beside the plan: the paths it records still resolve
    result = run("validate", bad, "--resolution", "0.1", "--cartesian-step", "0.05")
    assert result.exit_code == 1, (result.output, result.stderr, result.exception)
    out = result.stdout
    assert "INVALID" in out.strip().splitlines()[-1]
    m = re.search(r"^attachment open_left\[0\]: the object jumps by ([\d.]+) mm, [\d.e+-]+ rad between the end of "
                  r"phase place and placement 'middle'$", out, re.M)
    assert m and abs(float(m.group(1)) - 50.0) < 0.5, out  # 5 cm, plus the place's own sub-mm offset
    second_pick = next(p for p in plan["phases"] if p["name"] == "carry-2")
    gid = second_pick["holding"]["left"]
    m = re.search(rf"^attachment carry-2\[0\]: the left hand's grasp {gid} puts the object ([\d.]+) mm", out, re.M)
    assert m and abs(float(m.group(1)) - 50.0) < 0.5, out
    # nothing before the object reaches the middle: the first half is as it was
    attachment = {m.group(1) for m in re.finditer(r"^attachment ([\w-]+)\[", out, re.M)}
    assert not attachment & {p["name"] for p in plan["phases"][:6]}, attachment


def test_show_draws_the_regrasp(regrasp, tmp_path):
    """Eight key frames: the second pick, exchange and place follow the first ones; at the
    first place and the second pick the object is at the middle placement."""
    from regrasp_cli.show.motion import key_frames, load_plan_view
    from regrasp_cli.spatial import pose_error

    path, plan = regrasp
    frames = tmp_path / "frames"
    result = run("show", path, "--png", frames, "--size", "320x240")
    assert result.exit_code == 0, (result.output, result.stderr, result.exception)
    names = [f"{i:02d}_{name}.png" for i, name in enumerate(KEY_FRAMES, start=1)]
    assert sorted(p.name for p in frames.iterdir()) == names
    for name in names:
        assert f"png: {frames / name}" in result.stdout
        with Image.open(frames / name) as im:
            assert im.size == (320, 240)
            px = np.asarray(im.convert("RGB"), dtype=float)
        assert px.reshape(-1, 3).std(axis=0).max() > 20, name  # not blank

    kfs = {kf.name: kf for kf in key_frames(load_plan_view(path))}
    assert tuple(kfs) == KEY_FRAMES
    middle = np.array(next(p["pose"] for p in plan["placements"] if p["id"] == "middle"))
    for name in ("place", "pick-2"):
        dp, da = pose_error(kfs[name].X_WO, middle)
        assert dp < 2e-4 and da < 1e-3, (name, dp, da)  # IK: 0.1 mm, 1 mrad at the hand, 10 cm lever
    assert [plan["phases"][kfs[n].phase]["name"] for n in ("pick-2", "exchange-2", "place-2")] == \
        ["close_left-2", "close_right-2", "place-2"]


# --------------------------------------------------------------------------- (b) bad input


def _unknown_kind(d: dict) -> str:
    d["phases"][2]["kind"] = "teleport"
    return "phases[2].kind"


def _unknown_grasp(d: dict) -> str:
    d["phases"][2]["holding"] = {"right": "right-999"}
    return "phases[2].holding.right"


def _holding_while_resting(d: dict) -> str:
    right = next(g["id"] for g in d["grasps"] if g["hand"] == "right")
    assert d["phases"][0]["kind"] == "transit" and d["phases"][0]["placement"] == "start"
    d["phases"][0]["holding"] = {"right": right}
    return "phases[0].holding"


def _inhand(d: dict) -> str:
    """The carry made an in-hand transfer (well-formed, object poses and contacts given): the validator
    checks those in in-hand plans only, and says so rather than accepting it."""
    p = d["phases"][2]
    assert p["kind"] == "transfer"
    p.update(kind="inhand-transfer", holding={}, touching=["right"],
             object_poses=[np.eye(4).tolist()] * len(p["waypoints"]), contacts=[[]] * len(p["waypoints"]))
    return "phases[2].kind"


BAD = {"unknown kind": (_unknown_kind, "expected one of transit, transfer, grasp, release, handover"),
       "unknown grasp id": (_unknown_grasp, "grasp id 'right-999' is not in grasps[]"),
       "holding while resting": (_holding_while_resting, "rests at placement 'start' in a transit phase")}


@pytest.mark.parametrize("command", ["validate", "show"])
@pytest.mark.parametrize("case", list(BAD))
def test_malformed_plan2_is_one_line_naming_the_field(regrasp, tmp_path, case, command):
    change, words = BAD[case]
    path, plan = regrasp
    d = copy.deepcopy(plan)
    field = change(d)
    bad = _write(path.parent / f"bad-{tmp_path.name}.json", d)  # beside the plan: the files it names are found
    frames = tmp_path / "frames"
    args = ("validate", bad) if command == "validate" else ("show", bad, "--png", frames)
    result = run(*args)
    line = assert_one_error_line(result, str(bad), f": {field}: ", words)
    assert isinstance(result.exception, SystemExit)
    assert result.stdout == "" and not frames.exists(), line


def test_an_inhand_phase_in_a_pick_and_place_plan(regrasp, tmp_path):
    """`validate` gives an in-hand phase of a pick-and-place plan the in-hand checks (one
    validator, by kind): this one, made from a carry with no contacts and the object at
    the origin, is refused for both; `show` draws it, the object at its given poses."""
    path, plan = regrasp
    d = copy.deepcopy(plan)
    _inhand(d)
    bad = _write(path.parent / f"inhand-{tmp_path.name}.json", d)
    result = run("validate", bad)
    assert result.exit_code == 1, result.output
    name = d["phases"][2]["name"]
    assert re.search(rf"^kind {name}\[0\]: in a transfer every finger touches", result.stdout, re.M), result.stdout
    assert re.search(rf"^attachment {name}\[0\]: the object jumps by", result.stdout, re.M), result.stdout
    frames = tmp_path / "frames"
    result = run("show", bad, "--png", frames)
    assert result.exit_code == 0, result.output
    assert (frames / "01_start.png").is_file()


@pytest.mark.parametrize("command", ["validate", "show"])
def test_a_plan1_file_is_refused_saying_to_plan_again(tmp_path, command):
    """A plan of the earlier format (top-level object_poses, holding lists, no kinds)."""
    old = {"format": "regrasp.plan/1", "status": "solved", "failure": None, "joint_names": [], "grasps": [],
           "object_poses": {"start": np.eye(4).tolist(), "goal": np.eye(4).tolist()},
           "phases": [{"name": "grasp", "holding": [], "touching": [], "waypoints": [], "times": []}]}
    path = _write(tmp_path / "old.json", old)
    frames = tmp_path / "frames"
    args = ("validate", path) if command == "validate" else ("show", path, "--png", frames)
    result = run(*args)
    line = assert_one_error_line(result, str(path), "format", "regrasp.plan/1", "`regrasp plan")
    assert "regrasp.plan/2" in line
    assert result.stdout == "" and not frames.exists()
