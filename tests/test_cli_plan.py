"""`regrasp plan` and `regrasp validate` end to end (click.testing.CliRunner on
regrasp_cli.cli.main), on the default scene with small artefacts: grasp lists of 20
grasps per hand and a roadmap of 12 nodes per elementary roadmap, built once into the
run's cache by the first `plan` (tests/manip/test_online.py uses the same grasp lists).

A solved plan (``regrasp.plan/2``) passes the independent checker and has the eight
phases of a hand-over with their kinds, holdings and placements; the same seed writes the
same bytes; tampered plans are rejected with the issue named;
missing artefacts with --no-build and planning failures give their exit codes and one
clear line; the RRT-Connect baseline solves the scene too.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from cli_helpers import (SMALL, assert_one_error_line, copy_artefacts, needs_separate_stderr, run, scene_dict,
                         write_scene)

ROOT = Path(__file__).resolve().parents[1]
SCENE_YAML = ROOT / "configs" / "scenes" / "desk_handover.yaml"
SEED = 0  # the scene's planning.seed
RRT_SEED = 3  # the baseline does not solve every seed with its default budget; it solves this one
PHASES = ("grasp", "close_right", "carry", "close_left", "open_right", "place", "open_left", "rest")
# (kind, holding hands, touching, placement) of each phase: the right hand picks at the start
# placement, hands over to the left, which places at the goal placement
ROLES = (("transit", (), (), "start"), ("grasp", (), ("right",), "start"), ("transfer", ("right",), (), None),
         ("handover", ("right",), ("left",), None), ("handover", ("left",), ("right",), None),
         ("transfer", ("left",), (), None), ("release", (), ("left",), "goal"), ("transit", (), (), "goal"))


def roles(p) -> tuple:
    return tuple((ph.kind.value, tuple(ph.holding), ph.touching, ph.placement) for ph in p.phases)


def assert_holds_its_grasps(p) -> None:
    """Each hand holds with one grasp of its own, its id ``hand-<index in the cached list>``."""
    assert [g.hand for g in p.grasps] == ["right", "left"]
    for g in p.grasps:
        assert g.id == f"{g.hand}-{g.list_index}"
    for ph in p.phases:
        for hand, gid in ph.holding.items():
            assert gid == next(g.id for g in p.grasps if g.hand == hand), ph.name

pytestmark = needs_separate_stderr


def plan(cache_dir: Path, out: Path, *args):
    return run("--cache-dir", cache_dir, "plan", SCENE_YAML, "-o", out, *SMALL, *args)


def without_stats(path: Path) -> dict:
    d = json.loads(path.read_text())
    del d["stats"]
    return d


@pytest.fixture(scope="module")
def plan_dir(default_plan) -> Path:
    """One directory for every plan of the default scene: the paths a plan records are
    relative to it, so plans written elsewhere would differ in those."""
    return default_plan.parent


@dataclass(frozen=True)
class Ran:
    """What a finished `regrasp plan` said (the run's own Result stays in the worker that ran it)."""

    exit_code: int
    stdout: str


@pytest.fixture(scope="module")
def solved(default_plan):
    """`plan` of the default scene (building the small artefacts first, when missing),
    with timings and the validation: (what it printed, plan file); conftest.default_plan."""
    return Ran(0, default_plan.with_suffix(".stdout").read_text()), default_plan


# --------------------------------------------------------------------------- a solved plan


def test_plan_solves_the_default_scene(solved, problem):
    from regrasp_cli.trajectory import read_plan
    from regrasp_cli.validate import validate_plan

    result, out = solved
    assert result.exit_code == 0
    assert "valid" in result.stdout and f"plan: {out}" in result.stdout
    report = validate_plan(out)
    assert report.valid, [str(i) for i in report.issues]
    p = read_plan(out)
    assert (p.status, p.failure, p.planner, p.seed) == ("solved", None, "roadmap", SEED)
    assert tuple(ph.name for ph in p.phases) == PHASES
    assert roles(p) == ROLES
    assert_holds_its_grasps(p)
    assert np.array_equal(p.phases[0].waypoints[0], problem.q_start)  # rest
    assert np.array_equal(p.phases[-1].waypoints[-1], problem.q_goal)  # rest
    assert [pl.id for pl in p.placements] == ["start", "goal"]
    assert np.array_equal(p.placement("start").X_WO, problem.spec.task.X_WO_start)
    assert np.array_equal(p.placement("goal").X_WO, problem.spec.task.X_WO_goal)
    assert json.loads(out.read_text())["format"] == "regrasp.plan/2"


def test_validate_accepts_the_solved_plan(solved):
    _, out = solved
    result = run("validate", out)
    assert result.exit_code == 0, (result.output, result.exception)
    assert result.stdout.strip().splitlines()[-1] == "valid"


# --------------------------------------------------------------------------- determinism


def test_the_same_seed_gives_the_same_plan(solved, cache_dir, plan_dir):
    """The solved plan again, with one worker process instead of two (each query has its
    own random stream) and --no-timings: the same plan, and ``stats`` without a clock."""
    _, timed = solved
    a = plan_dir / "untimed.json"
    result = plan(cache_dir, a, "--seed", SEED, "--no-check", "--no-build", "--no-timings", "--jobs", 1)
    assert result.exit_code == 0, (result.output, result.exception)
    assert set(json.loads(a.read_text())["stats"]) == {"software_version", "artefacts", "counts"}  # no clock
    assert without_stats(timed) == without_stats(a)
    assert json.loads(timed.read_text())["stats"]["counts"] == json.loads(a.read_text())["stats"]["counts"]


# --------------------------------------------------------------------------- tampered plans


def tampered(src: Path, name: str, change) -> Path:
    """A copy of the plan ``src`` beside it (so that its relative paths still resolve),
    edited by ``change(dict)``."""
    d = json.loads(src.read_text())
    change(d)
    out = src.parent / name
    out.write_text(json.dumps(d))
    return out


def validate_rejects(path: Path) -> str:
    result = run("validate", path)
    assert result.exit_code == 1, (result.exit_code, result.output, result.exception)
    assert "INVALID" in result.stdout
    return result.stdout


def test_validate_rejects_a_waypoint_in_the_desk(solved, problem):
    """The last-but-one waypoint of the rest phase (the object at its goal, on the left)
    replaced by the rest posture with the right elbow opened so that the forearm and hand
    go down into the desk top; the segment from it to rest moves only that joint."""
    _, src = solved
    robot = problem.robot
    q = robot.q_rest.copy()
    q[robot.joint_names.index("r_arm_j4")] = 0.7
    pairs = problem.world(problem.object_at(problem.spec.task.X_WO_goal)).colliding_pairs(q)
    assert any("obstacle:desk_top" in p for p in pairs) and not any("object" in p for p in pairs), pairs

    def change(d):
        wp = d["phases"][-1]["waypoints"]
        assert d["phases"][-1]["name"] == "rest" and len(wp) >= 3
        assert wp[-1] == robot.q_rest.tolist()
        wp[-2] = q.tolist()
        d["phases"][-1].pop("blends", None), d["phases"][-1].pop("timing", None)  # stop at every waypoint

    out = validate_rejects(tampered(src, "in_desk.json", change))
    assert re.search(r"^collision rest\[\d+\]: .*obstacle:desk_top", out, re.M), out


def test_validate_rejects_a_jump(solved, problem):
    """The interior waypoint with the shortest segments on both sides, one joint of the free
    arm moved by 1 rad, the times unchanged: a segment next to it is too short for that move."""
    _, src = solved
    robot = problem.robot
    d0 = json.loads(src.read_text())

    def slack(k: int, i: int) -> float:  # the longer of the two segments around waypoint i of phase k
        t = d0["phases"][k]["times"]
        return max(t[i] - t[i - 1], t[i + 1] - t[i])

    k, i = min(((k, i) for k, p in enumerate(d0["phases"]) for i in range(1, len(p["waypoints"]) - 1)),
               key=lambda ki: slack(*ki))
    phase = d0["phases"][k]
    free = "left" if "left" not in phase["holding"] else "right"
    j = int(robot.hands[free].arm_idx[1])
    value = phase["waypoints"][i][j]
    value += 1.0 if value + 1.0 <= robot.upper[j] else -1.0

    def change(d):
        d["phases"][k]["waypoints"][i][j] = value

    out = validate_rejects(tampered(src, "jump.json", change))
    if phase.get("timing"):  # the speed grid no longer fits the path
        assert re.search(rf"^timing {phase['name']}: the speed grid spans s in \[0, [\d.e+-]+\], but the path "
                         r"through the waypoints is [\d.e+-]+ long", out, re.M), out
        return
    # the segment in, or out, or both (one of them may have been slow enough already)
    found = re.findall(rf"^timing {phase['name']}\[(\d+)\]: segment (\d+)->(\d+) lasts [\d.e+-]+ s but needs",
                       out, re.M)
    assert found and {(int(a), int(b), int(c)) for a, b, c in found} <= {(i, i - 1, i), (i + 1, i, i + 1)}, out


def test_validate_rejects_a_contact_off_the_surface(solved):
    """The first contact of the first grasp moved 4 mm out along its normal (not farther:
    on the statuette a point 1 cm out may come nearer another part of the surface)."""
    _, src = solved
    d0 = json.loads(src.read_text())
    contact = d0["grasps"][0]["contacts"][0]
    n = np.array(contact["normal"])

    def change(d):
        d["grasps"][0]["contacts"][0]["point"] = (np.array(contact["point"]) + 0.004 * n / np.linalg.norm(n)).tolist()

    out = validate_rejects(tampered(src, "off_surface.json", change))
    g = d0["grasps"][0]
    m = re.search(rf"^grasp: grasp {g['id']} \({g['hand']} hand\): {contact['finger']} contact ([\d.]+) mm off the "
                  r"object surface", out, re.M)
    assert m, out
    assert float(m.group(1)) == pytest.approx(4.0, abs=0.3)


def test_validate_rejects_a_moved_goal_placement(solved):
    """The goal placement 2 cm from where the placing hand leaves the object: the object
    would jump as the left hand opens, which the replay does not hide."""
    _, src = solved

    def change(d):
        goal = next(p for p in d["placements"] if p["id"] == "goal")
        goal["pose"][1][3] += 0.02

    out = validate_rejects(tampered(src, "moved_goal.json", change))
    m = re.search(r"^attachment open_left\[0\]: the object jumps by ([\d.]+) mm, [\d.e+-]+ rad between the end of "
                  r"phase place and placement 'goal'$", out, re.M)
    assert m, out
    assert float(m.group(1)) == pytest.approx(20.0, abs=0.2)  # the arm IK places the object within 0.1 mm


def test_validate_rejects_a_swapped_holding(solved):
    """The carry said to be held by the right hand with the left hand's grasp: refused
    when the plan is read (a grasp id names a grasp of another hand), exit code 2."""
    _, src = solved
    d0 = json.loads(src.read_text())
    left = next(g["id"] for g in d0["grasps"] if g["hand"] == "left")

    def change(d):
        d["phases"][2]["holding"] = {"right": left}

    bad = tampered(src, "swapped.json", change)
    assert_one_error_line(run("validate", bad), str(bad), "phases[2].holding.right", f"grasp {left!r}",
                          "of the left hand")


def test_validate_rejects_a_grasp_that_misses_the_object(solved):
    """The right hand's grasp recorded 1 cm off along the grasp frame's x: where it holds,
    the object is not where its grasp puts it."""
    _, src = solved
    d0 = json.loads(src.read_text())
    gid = d0["phases"][2]["holding"]["right"]
    i = next(i for i, g in enumerate(d0["grasps"]) if g["id"] == gid)

    def change(d):
        d["grasps"][i]["hand_in_object"][0][3] += 0.01

    out = validate_rejects(tampered(src, "missed.json", change))
    m = re.search(rf"^attachment carry\[0\]: the right hand's grasp {gid} puts the object ([0-9.]+) mm", out, re.M)
    assert m and abs(float(m.group(1)) - 10.0) < 0.1, out  # 10 mm (the JSON's rounding leaves a few micrometres)


# --------------------------------------------------------------------------- missing artefacts


ORDER = ("placements", "grasps", "roadmap")  # the artefacts `plan` loads, in turn


@pytest.mark.parametrize("missing, build", [("placements", "regrasp placements build"),
                                            ("grasps", "regrasp grasps build"), ("roadmap", "regrasp roadmap build")])
def test_no_build_refuses_a_missing_artefact(solved, cache_dir, tmp_path, missing, build):
    """A cache with the self-collision pairs (slow to compute, not an artefact of `plan`)
    and the artefacts `plan` loads before the missing one: that one is named."""
    d = tmp_path / "cache"
    copy_artefacts(Path(cache_dir) / "self_collision", d / "self_collision")
    for before in ORDER[:ORDER.index(missing)]:
        copy_artefacts(Path(cache_dir) / before, d / before)
    out = tmp_path / "plan.json"
    result = plan(d, out, "--no-build")
    line = assert_one_error_line(result, str(d / missing), "no such artefact", build)
    assert line.endswith(".h5: no such artefact (file does not exist); build it with `" + build + "`")
    assert not out.exists() and not (d / missing).exists()  # nothing built, no plan written


# --------------------------------------------------------------------------- failures


def test_unreachable_object_fails_at_grasps(solved, cache_dir, tmp_path):
    """The statuette on a small table 2.5 m to the robot's right: out of reach of both
    arms.  The grasp lists keep the grasps usable at the task's poses, so they are built
    for this scene; RRT-Connect needs no roadmap."""
    s = scene_dict()
    s["obstacles"].append({"name": "far_table", "box": {"size": [0.4, 0.4, 0.04]}, "pose": {"xyz": [0.4, -2.5, 0.72]}})
    s["task"]["object_start"]["xyz"] = [0.4, -2.5, 0.74]
    scene = write_scene(tmp_path / "far.yaml", s)
    out = tmp_path / "plan.json"
    result = run("--cache-dir", cache_dir, "plan", scene, "-o", out, "--planner", "rrt-connect", *SMALL)
    assert result.exit_code == 1, (result.exit_code, result.output, result.exception)
    assert "Traceback" not in result.output
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    m = re.fullmatch(r"error: planning failed at stage 'grasps': (.+)", lines[0])
    assert m, lines[0]
    reason = m.group(1)
    # every style says where and why: no hand reaches the statuette at its start pose
    # at once, from the grasps usable at each end (no configuration searched)
    assert reason.startswith("one-arm (stage grasps): no hand can hold the object at both the start and the goal "
                             "with one grasp")
    assert "right hand 0 at the start" in reason and "left hand 0 at the start" in reason
    assert "handover (stage grasps): no hand can hold the object at its start pose" in reason
    assert "place-regrasp (stage grasps): no hand can hold the object at its start pose" in reason
    d = json.loads(out.read_text())
    assert (d["format"], d["status"]) == ("regrasp.plan/2", "failed")
    assert d["failure"] == {"stage": "grasps", "transition": None, "reason": reason}
    assert d["phases"] == [] and d["grasps"] == [] and d["planner"] == "rrt-connect"
    # the checker reports the failure as the plan's one issue
    checked = run("validate", out)
    assert checked.exit_code == 1, checked.output
    assert "status: the planner failed at stage grasps" in checked.stdout


# --------------------------------------------------------------------------- the baseline


def test_rrt_connect_solves_the_default_scene(solved, cache_dir, plan_dir):
    """The single-query baseline, default budget (3000 iterations per query).  It does not
    solve every seed: RRT_SEED is one it solves."""
    from regrasp_cli.trajectory import read_plan
    from regrasp_cli.validate import validate_plan

    out = plan_dir / "rrt.json"
    result = plan(cache_dir, out, "--planner", "rrt-connect", "--seed", RRT_SEED, "--no-build", "--no-check")
    assert result.exit_code == 0, (result.output, result.stderr, result.exception)
    p = read_plan(out)
    assert (p.status, p.planner, p.seed) == ("solved", "rrt-connect", RRT_SEED)
    assert tuple(ph.name for ph in p.phases) == PHASES
    assert roles(p) == ROLES
    assert_holds_its_grasps(p)
    assert "roadmap" not in p.stats["artefacts"]  # no roadmap was loaded
    report = validate_plan(out)
    assert report.valid, [str(i) for i in report.issues]


def test_a_moved_obstacle_reuses_the_roadmap_and_the_plan_is_valid(default_plan, cache_dir, tmp_path):
    """The vase moved 5 cm: the default scene's roadmap is reused, not rebuilt (with
    --no-build a rebuild would be refused), the queries check the vase online, and the
    plan passes the checker, which knows where the vase now stands."""
    s = scene_dict()
    for ob in s["obstacles"]:
        if ob["name"].startswith("vase"):
            ob["pose"]["xyz"][1] += 0.05
    scene = write_scene(tmp_path / "moved.yaml", s)
    out = tmp_path / "plan.json"
    result = run("--cache-dir", cache_dir, "plan", scene, "-o", out, *SMALL, "--seed", 0, "--no-build")
    assert result.exit_code == 0, (result.output, result.exception)
    assert "roadmap: reusing" in result.stdout and "vase_body, vase_neck" in result.stdout
    assert "\nvalid" in result.stdout or result.stdout.startswith("valid")
    used = json.loads(out.read_text())["stats"]["artefacts"]["roadmap"]
    assert used == json.loads(default_plan.read_text())["stats"]["artefacts"]["roadmap"]


def test_a_plan_its_validation_refuses_is_written_failed(solved, cache_dir, plan_dir, monkeypatch):
    """The plan is written, then validated: when the validator refuses it, the file is
    written again with status failed at stage validation (it said solved, exit 1)."""
    from regrasp_cli import pipeline
    from regrasp_cli.checks import Issue, ValidationReport

    def refuse(out_file, jobs):
        return ValidationReport((Issue(None, None, "grasp", "a test's refusal"),), 0, {})

    monkeypatch.setattr(pipeline, "validate_plan", refuse)
    out = plan_dir / "refused.json"
    result = plan(cache_dir, out)
    assert result.exit_code == 1, (result.output, result.exception)
    d = json.loads(out.read_text())
    assert d["status"] == "failed" and len(d["phases"]) == len(PHASES)
    assert d["failure"] == {"stage": "validation", "transition": None,
                            "reason": "the written plan fails 1 check(s); first: grasp: a test's refusal"}
