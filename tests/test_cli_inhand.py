"""`regrasp inhand plan` end to end on the shipped ball scene (seed 003's experiment with
`builtin:hand4`), `regrasp validate` accepting the plan and rejecting it when a regrasp
breaks force closure, a fingertip leaves the surface or slips on it or the object jumps, and bad input
(a start grasp that does not hold, an object too big for the hand, an unreachable goal)
as one line with exit code 2 and no plan written."""

from __future__ import annotations

import copy
import json

import numpy as np
import pytest
import yaml
from scipy.spatial.transform import Rotation

from cli_helpers import assert_one_error_line, needs_separate_stderr, run, write_scene
from conftest import ROOT

from regrasp_cli.dexterous.contacts import closure
from regrasp_cli.validate import validate_plan

SCENE = ROOT / "regrasp_cli" / "data" / "scenes" / "inhand_ball.yaml"


def _scene(**changes) -> dict:
    d = yaml.safe_load(SCENE.read_text())
    d["robot"] = "builtin:hand4"
    d.update(changes)
    return d


@pytest.fixture(scope="module")
def planned(tmp_path_factory, cache_dir):
    tmp = tmp_path_factory.mktemp("inhand")
    out = tmp / "plan.json"
    result = run("--cache-dir", cache_dir, "inhand", "plan", SCENE, "-o", out, "--no-timings")
    assert result.exit_code == 0, result.output
    return out, json.loads(out.read_text())


def test_the_ball_is_turned_by_finger_gaits_and_the_plan_is_valid(planned):
    out, d = planned
    kinds = [p["kind"] for p in d["phases"]]
    assert set(kinds) == {"inhand-transfer", "inhand-regrasp"} and d["task"] == "inhand"
    goal = np.array(d["placements"][1]["pose"])
    assert np.allclose(d["phases"][-1]["object_poses"][-1], goal, atol=1e-9)
    assert d["stats"]["counts"]["finger_regrasps"] == kinds.count("inhand-regrasp") > 0
    assert validate_plan(out).valid


def _tampered(tmp_path, d, edit) -> list:
    d = copy.deepcopy(d)
    edit(d)
    path = tmp_path / "tampered.json"
    path.write_text(json.dumps(d))
    return validate_plan(path).issues


def _first(d, kind):
    return next(p for p in d["phases"] if p["kind"] == kind and len(p["waypoints"]) >= 3)


def test_validate_rejects_a_regrasp_that_lets_the_object_go(tmp_path, planned):
    out, d = planned

    def edit(d):  # a second finger lifts while one steps: two contacts cannot hold a ball
        p = _first(d, "inhand-regrasp")
        for c in p["contacts"][1:-1]:
            c.pop(0)
    issues = _tampered(tmp_path, d, edit)
    assert any(i.check == "grasp" and "not force closure" in i.message for i in issues)


def test_validate_rejects_a_fingertip_off_the_surface(tmp_path, planned):
    out, d = planned

    def edit(d):
        p = _first(d, "inhand-transfer")
        for c in p["contacts"]:
            c[0]["point"] = list(np.array(c[0]["point"]) + 0.005 * np.array(c[0]["normal"]))
    issues = _tampered(tmp_path, d, edit)
    assert any(i.check == "grasp" and "off the object's surface" in i.message for i in issues)


def test_validate_rejects_fingertips_that_slip(tmp_path, planned):
    """The ball spun under fingers that do not move (0.1 rad about its centre over a
    transfer, each contact turned back with it): every fingertip stays on its contact, on
    the surface, in force closure, but slips R * 0.1 = 3.5 mm on the ball."""
    out, d = planned
    assert not [i for i in validate_plan(out).issues if "slips" in i.message]

    def edit(d):
        p = _first(d, "inhand-transfer")
        k = len(p["object_poses"])
        for i in range(k):
            R_z = Rotation.from_rotvec([0.0, 0.0, 0.1 * i / (k - 1)]).as_matrix()
            X = np.array(p["object_poses"][i])
            X[:3, :3] = X[:3, :3] @ R_z
            p["object_poses"][i] = X.tolist()
            for c in p["contacts"][i]:
                c["point"], c["normal"] = (list(R_z.T @ np.array(c[key])) for key in ("point", "normal"))
    issues = _tampered(tmp_path, d, edit)
    assert any(i.check == "grasp" and "slips on the object" in i.message for i in issues)
    assert not any(i.check == "grasp" and "slips" not in i.message for i in issues)


def test_validate_rejects_an_object_that_jumps(tmp_path, planned):
    out, d = planned

    def edit(d):
        p = _first(d, "inhand-transfer")
        p["object_poses"][1][2][3] += 0.02
    issues = _tampered(tmp_path, d, edit)
    assert any(i.check == "continuity" and "jumps" in i.message for i in issues)


@needs_separate_stderr
def test_a_start_grasp_that_does_not_hold_is_one_line(tmp_path, cache_dir, planned):
    _, d = planned
    start = {c["finger"]: [float(x) for x in c["point"]] for c in d["phases"][0]["contacts"][0]}
    p = np.array(list(start.values()))
    n = p / np.linalg.norm(p, axis=1, keepdims=True)  # a ball's normals
    assert closure(p, n, 0.02, np.zeros(3), 0.035) == 0.0  # the planned start, with little friction
    scene = write_scene(tmp_path / "s.yaml", _scene(start_grasp=start, object={"mesh": "builtin:ball",
                                                                               "friction": 0.02}))
    result = run("--cache-dir", cache_dir, "inhand", "plan", scene, "-o", tmp_path / "p.json")
    assert_one_error_line(result, str(scene), "start_grasp", "not force closure")
    assert not (tmp_path / "p.json").exists()


@needs_separate_stderr
def test_an_object_too_big_for_the_hand_is_one_line(tmp_path, cache_dir):
    scene = write_scene(tmp_path / "s.yaml", _scene(object={"mesh": "builtin:ball", "scale": 5.0}))
    result = run("--cache-dir", cache_dir, "inhand", "plan", scene, "-o", tmp_path / "p.json")
    assert_one_error_line(result, str(scene), "object.mesh", "wider than")
    assert not (tmp_path / "p.json").exists()


@needs_separate_stderr
def test_a_goal_out_of_the_fingers_reach_is_one_line(tmp_path, cache_dir):
    scene = write_scene(tmp_path / "s.yaml", _scene(object_goal={"xyz": [0.0, 0.0, 0.3], "rpy": [0, 0, 0]}))
    result = run("--cache-dir", cache_dir, "inhand", "plan", scene, "-o", tmp_path / "p.json")
    assert_one_error_line(result, str(scene), ": object_goal: ", "beyond the reach")
    assert not (tmp_path / "p.json").exists()


@needs_separate_stderr
@pytest.mark.parametrize("changes, words", [
    ({"hand": "left"}, ("hand", "no left hand")),
    ({"robot": "builtin:hironx"}, ("hand", "three fingertips")),
    ({"object_goal": {"rpy": [0, 0]}}, ("object_goal.rpy", "3 numbers")),
    ({"start_grasp": "somehow"}, ("start_grasp", "'find'")),
    ({"planning": {"nodes": 0}}, ("planning.nodes", ">= 1")),
    ({"planning": {"smooth": "yes"}}, ("planning.smooth", "true or false")),
])
def test_bad_scene_fields_are_one_line(tmp_path, cache_dir, changes, words):
    scene = write_scene(tmp_path / "s.yaml", _scene(**changes))
    result = run("--cache-dir", cache_dir, "inhand", "plan", scene, "-o", tmp_path / "p.json")
    assert_one_error_line(result, str(scene), *words)
    assert not (tmp_path / "p.json").exists()


def test_show_follows_the_object_through_the_fingers(planned):
    """`regrasp show` replays an in-hand plan: the object is at the plan's pose at every
    waypoint, and half-way along a transfer's segment between the poses at its ends."""
    from regrasp_cli.show.motion import key_frames, load_plan_view

    out, _ = planned
    view = load_plan_view(out)
    moved = 0
    for i, phase in enumerate(view.plan.phases):
        for q, X in zip(phase.waypoints, phase.object_poses):
            assert np.allclose(view.X_WO(i, q), X, atol=1e-9)
        for (qa, qb), (A, B) in zip(zip(phase.waypoints, phase.waypoints[1:]),
                                    zip(phase.object_poses, phase.object_poses[1:])):
            if np.allclose(A, B):
                continue
            moved += 1
            X = view.X_WO(i, (qa + qb) / 2)
            assert np.allclose(X[:3, 3], (A[:3, 3] + B[:3, 3]) / 2, atol=1e-9)
            half = Rotation.from_matrix(A[:3, :3].T @ B[:3, :3]).magnitude() / 2
            assert abs(Rotation.from_matrix(A[:3, :3].T @ X[:3, :3]).magnitude() - half) < 1e-3
    assert moved > 0
    assert [k.name for k in key_frames(view)] == ["start", "end"]


def test_validate_rejects_a_hand_through_an_obstacle(tmp_path, planned):
    _, d = planned

    def edit(d):  # a plate through the ball and the fingers
        d["obstacles"] = [{"name": "plate", "shape": "box", "size": [0.2, 0.2, 0.01], "mesh": None,
                           "pose": d["placements"][0]["pose"]}]
    issues = _tampered(tmp_path, d, edit)
    assert any(i.check == "collision" and "obstacle:plate" in i.message for i in issues)


def test_the_fingers_keep_off_a_wall_the_open_hand_would_hit(tmp_path, cache_dir):
    """inhand_ball_wall.yaml: the open hand runs into the wall beside it, and the plan
    keeps every link and the ball off it (the validator checks the obstacles)."""
    from regrasp_cli.dexterous.task import load_inhand_problem
    from regrasp_cli.model.collision import collision_world

    scene = ROOT / "regrasp_cli" / "data" / "scenes" / "inhand_ball_wall.yaml"
    problem = load_inhand_problem(scene, cache_dir)
    world = collision_world(problem.robot, problem.spec.obstacles, problem.disabled.links())
    assert ("f0_distal", "obstacle:wall") in world.colliding_pairs(problem.q_start)  # the hand open
    out = tmp_path / "wall.json"
    result = run("--cache-dir", cache_dir, "inhand", "plan", scene, "-o", out, "--no-timings")
    assert result.exit_code == 0, result.output
    d = json.loads(out.read_text())
    assert [o["name"] for o in d["obstacles"]] == ["wall"]
    assert validate_plan(out).valid


def test_progress_counts_every_expansion_of_every_tree(cache_dir, planned):
    """The spinner's count: one call per expansion, over the restarts' trees, against the
    budget, ending at the outcome's expansions (and the same plan as without it)."""
    from regrasp_cli.dexterous.task import load_inhand_problem, plan_inhand

    problem = load_inhand_problem(SCENE, cache_dir)
    calls = []
    out = plan_inhand(problem, problem.spec.planning.seed, lambda done, budget: calls.append((done, budget)))
    assert out.failure is None
    n = out.counts["iterations"]
    assert calls == [(k, problem.spec.planning.nodes) for k in range(1, n + 1)]
    _, d = planned
    assert d["stats"]["counts"]["iterations"] == n


def test_validate_rejects_a_lifted_fingertip_that_grazes_the_object(tmp_path, planned):
    """Issue 42: a fingertip that has let go gets no contact tolerance.  The stepping
    finger's first lifted waypoint put back 1 mm into the ball (by the finger's IK) was
    accepted while every fingertip of the touching hand could enter it by 2 mm."""
    from regrasp_cli.model.ik import finger_ik
    from regrasp_cli.model.robot import load_robot

    out, d = planned
    robot = load_robot(ROOT / "regrasp_cli" / "data" / "robots" / "hand4" / "robot.yaml")
    k = next(k for k, p in enumerate(d["phases"]) if p["kind"] == "inhand-regrasp" and len(p["waypoints"]) >= 4)
    p = d["phases"][k]
    hand = p["touching"][0]
    names = [f.name for f in robot.hands[hand].spec.fingers]
    lifted = (set(names) - {c["finger"] for c in p["contacts"][1]}).pop()
    f = names.index(lifted)
    c = next(c for c in p["contacts"][0] if c["finger"] == lifted)
    r = robot.hands[hand].spec.fingers[f].tip_radius
    X = np.array(p["object_poses"][0])
    target = X[:3, :3] @ (np.array(c["point"]) + (r - 0.001) * np.array(c["normal"])) + X[:3, 3]
    ik = finger_ik(robot, hand, f, target, np.array(p["waypoints"][1]), np.random.default_rng(0))
    assert ik.success

    def edit(d):
        d["phases"][k]["waypoints"][1] = [float(x) for x in ik.q]
    issues = _tampered(tmp_path, d, edit)
    assert any("lifted" in i.message and lifted in i.message for i in issues), issues
