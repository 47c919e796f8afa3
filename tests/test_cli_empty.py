"""No silent emptiness (issue 15, item 4), through the CLI on small Baxter scenes: an empty
grasp list or roadmap is an error (exit 1, one line naming the cause, nothing written), a
rest configuration in collision is named (the pair) by `plan` and `roadmap build`, and two
robots sharing a cache keep their grasp lists apart."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
from click.testing import Result

from cli_helpers import ROBOT_YAML, assert_one_error_line, needs_separate_stderr, run, write_scene

pytestmark = needs_separate_stderr

BLOCK = {"mesh": "builtin:block", "friction": 0.5}
TASK = {"object_start": {"xyz": [0.75, -0.70, -0.20]}, "object_goal": {"xyz": [0.75, 0.70, -0.20]},
        "robot_start": "rest", "robot_goal": "rest"}
TABLE = {"name": "table", "box": {"size": [0.80, 1.80, 0.04]}, "pose": {"xyz": [0.80, 0.0, -0.22]}}


def baxter_scene(path: Path, obj: dict = BLOCK, obstacles: list | None = None, robot: str = "builtin:baxter") -> Path:
    """A scene on Baxter (as configs/scenes/baxter_handover.yaml) with the given object
    and obstacles."""
    return write_scene(path, {"format": "regrasp.scene/1", "robot": robot, "object": obj,
                              "obstacles": [TABLE] if obstacles is None else obstacles, "task": TASK,
                              "planning": {"seed": 0}})


def assert_one_failure_line(result: Result, *words: str) -> str:
    """Exit code 1 (no result), otherwise as :func:`assert_one_error_line`."""
    return assert_one_error_line(result, *words, exit_code=1)


def artefacts(cache: Path, folder: str) -> list[Path]:
    return sorted((cache / folder).glob("*.h5")) if (cache / folder).is_dir() else []


@pytest.fixture(scope="module")
def warm(tmp_path_factory, cache_dir) -> Path:
    """A cache holding the (slow to compute) self-collision pairs of Baxter and of the
    humanoid."""
    from regrasp_cli.scene import load_problem

    d = tmp_path_factory.mktemp("empty_warm")
    if (Path(cache_dir) / "self_collision").is_dir():
        shutil.copytree(Path(cache_dir) / "self_collision", d / "self_collision")
    load_problem(baxter_scene(d / "scene.yaml"), d)
    load_problem(baxter_scene(d / "humanoid.yaml", obstacles=[], robot=str(ROBOT_YAML)), d)
    return d


@pytest.fixture
def cache(tmp_path, warm) -> Path:
    """A fresh cache with only the self-collision pairs."""
    d = tmp_path / "cache"
    shutil.copytree(warm / "self_collision", d / "self_collision")
    return d


# --------------------------------------------------------------------------- empty grasp list

HUGE = {"mesh": "builtin:block", "scale": 2, "friction": 0.5}  # 8 x 8 x 24 cm: wider than either open jaw
FAR = {"object_start": {"xyz": [0.9, -0.9, -0.05]}, "object_goal": {"xyz": [0.9, 0.9, -0.05]},
       "robot_start": "rest", "robot_goal": "rest"}


def huge_scene(path: Path) -> Path:
    return write_scene(path, {"format": "regrasp.scene/1", "robot": "builtin:baxter", "object": HUGE,
                              "obstacles": [], "task": FAR, "planning": {"seed": 0}})


def test_empty_grasp_list_is_an_error_naming_the_hand_and_writes_nothing(tmp_path, cache):
    result = run("--cache-dir", cache, "grasps", "build", huge_scene(tmp_path / "s.yaml"), "--hand", "right",
                 "--jobs", "1")
    line = assert_one_failure_line(result, "the right hand's grasp list is empty", "antipodal pair",
                                   "builtin:block (0.08 x 0.08 x 0.24 m)", "jaw's pads")
    assert "0 of 0" not in line
    assert artefacts(cache, "grasps") == []


def test_plan_fails_at_grasps_with_the_empty_lists_reason(tmp_path, cache):
    out = tmp_path / "plan.json"
    result = run("--cache-dir", cache, "plan", huge_scene(tmp_path / "s.yaml"), "-o", out, "--planner", "rrt-connect",
                 "--jobs", "1", "--no-check")
    line = assert_one_failure_line(result, "stage 'grasps'", "the right hand's grasp list is empty", "antipodal pair")
    assert "clear the obstacles" not in line
    plan = json.loads(out.read_text())
    assert plan["status"] == "failed" and plan["failure"]["stage"] == "grasps"
    assert plan["failure"]["reason"].startswith("the right hand's grasp list is empty: ")
    assert artefacts(cache, "grasps") == []


# --------------------------------------------------------------------------- empty roadmap


def test_empty_roadmap_is_an_error_naming_the_obstacle_and_writes_nothing(tmp_path, cache):
    cage = {"name": "cage", "box": {"size": [3.0, 3.0, 3.0]}, "pose": {"xyz": [0.0, 0.0, 0.0]}}
    scene = baxter_scene(tmp_path / "s.yaml", obstacles=[cage])
    result = run("--cache-dir", cache, "roadmap", "build", scene, "--nodes", "5", "--jobs", "1")
    assert_one_failure_line(result, "the roadmap is empty", "R_r (torso + right arm) has no node",
                            "R_l (torso + left arm) has no node", "2000 of 2000 samples collide",
                            "–obstacle:cage", "rest configuration")
    assert artefacts(cache, "roadmap") == []


# --------------------------------------------------------------------------- rest in collision


@pytest.fixture(scope="module")
def post_scene(tmp_path_factory, warm) -> Path:
    """A scene with a 6 cm cube around Baxter's right fingertip at rest: the rest (and
    start) configuration collides with it."""
    import pinocchio as pin

    from regrasp_cli.scene import load_problem

    d = tmp_path_factory.mktemp("post")
    robot = load_problem(baxter_scene(d / "plain.yaml"), warm).robot
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, robot.to_pin(robot.q_rest))
    p = data.oMf[robot.model.getFrameId("r_gripper_l_finger_tip")].translation
    post = {"name": "post", "box": {"size": [0.06, 0.06, 0.06]}, "pose": {"xyz": [float(x) for x in p]}}
    return baxter_scene(d / "post.yaml", obstacles=[TABLE, post])


def test_plan_names_the_pair_of_a_start_in_collision_before_building_anything(tmp_path, cache, post_scene):
    out = tmp_path / "plan.json"
    result = run("--cache-dir", cache, "plan", post_scene, "-o", out, "--jobs", "1", "--no-check")
    assert_one_failure_line(result, "stage 'ends'", "start configuration is in collision", "r_gripper_l_finger_tip",
                            "obstacle:post")
    d = json.loads(out.read_text())
    assert d["failure"]["stage"] == "ends" and d["status"] == "failed"
    assert d["task"] == "manipulation graph"  # the task --style auto runs, not seed 000's hand-over
    assert artefacts(cache, "grasps") == [] and artefacts(cache, "roadmap") == []


def test_roadmap_build_warns_naming_the_pair_of_a_rest_in_collision(cache, post_scene):
    result = run("--cache-dir", cache, "roadmap", "build", post_scene, "--nodes", "3", "--jobs", "1")
    assert result.exit_code == 0, (result.output, result.exception)
    warnings = [ln for ln in result.stderr.splitlines() if ln.startswith("warning:")]
    assert any("rest configuration" in w and "r_gripper_l_finger_tip–obstacle:post" in w for w in warnings), \
        result.stderr
    assert len(artefacts(cache, "roadmap")) == 1


# --------------------------------------------------------------------------- artefact names


def test_two_robots_sharing_a_cache_keep_their_grasp_lists_apart(tmp_path, cache):
    from regrasp_cli.grasp.build import read_grasp_list
    from regrasp_cli.store import read_provenance

    small = ["--hand", "right", "--jobs", "1", "--positions", "8", "--orientations", "64", "--target", "1"]
    files = {}
    for name, robot in (("baxter", "builtin:baxter"), ("humanoid43", str(ROBOT_YAML))):
        scene = baxter_scene(tmp_path / f"{name}.yaml", obstacles=[], robot=robot)
        result = run("--cache-dir", cache, "grasps", "build", scene, *small)
        assert result.exit_code == 0, (result.output, result.exception)
        files[name] = [p for p in artefacts(cache, "grasps") if f"-{name}-" in p.name]
        assert len(files[name]) == 1, artefacts(cache, "grasps")
        assert f"right hand: {files[name][0]}" in result.stdout
    b, h = files["baxter"][0], files["humanoid43"][0]
    assert b != h and b.name.startswith("builtin_block-baxter-") and h.name.startswith("builtin_block-humanoid43-")
    assert set(artefacts(cache, "grasps")) == {b, h}  # nothing left under a name without the robot
    assert read_provenance(b).inputs["hand"] != read_provenance(h).inputs["hand"]
    assert len(read_grasp_list(b)) > 0 and len(read_grasp_list(h)) > 0
