"""Tests of the configuration files (robot.yaml, scene.yaml): the defaults load, and every
malformed input gives an InputError that names the file and the dotted field at fault.

Bad files are built in tmp_path from the good ones (load, edit the dict, dump), with
``robot:`` / ``urdf:`` pointing at the real files by absolute path.
"""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import pytest
import trimesh
import yaml

from regrasp_cli.config import load_robot_spec, load_scene_spec
from regrasp_cli.errors import InputError
from regrasp_cli.model.robot import load_robot
from regrasp_cli.model.selfcollision import disabled_pairs
from regrasp_cli.scene import load_problem

ROOT = Path(__file__).resolve().parents[1]
ROBOT_YAML = ROOT / "configs" / "robots" / "humanoid43" / "robot.yaml"
URDF = ROBOT_YAML.parent / "robot.urdf"
SCENE_YAML = ROOT / "configs" / "scenes" / "desk_handover.yaml"

GOOD_SCENE = yaml.safe_load(SCENE_YAML.read_text())
GOOD_ROBOT = yaml.safe_load(ROBOT_YAML.read_text())


# --------------------------------------------------------------------------- helpers


def scene_dict() -> dict:
    d = copy.deepcopy(GOOD_SCENE)
    d["robot"] = str(ROBOT_YAML)
    return d


def robot_dict() -> dict:
    d = copy.deepcopy(GOOD_ROBOT)
    d["urdf"] = str(URDF)
    d["self_collision"] = {"samples": 20, "seed": 0, "never_margin": 0.02}  # keep it cheap
    return d


def write(tmp_path: Path, name: str, data) -> Path:
    path = tmp_path / name
    path.write_text(data if isinstance(data, str) else yaml.safe_dump(data, sort_keys=False))
    return path


def check(exc: InputError, file: Path, field: str | None) -> None:
    """The error names the file and the field, in its attributes and in its message."""
    assert exc.file is not None and Path(exc.file).resolve() == file.resolve(), str(exc)
    assert exc.field == field, str(exc)
    text = str(exc)
    assert str(file) in text or str(file.resolve()) in text
    if field is not None:
        assert f": {field}: " in text
    assert "\n" not in text


def scene_error(tmp_path: Path, data, field: str | None, name: str = "bad_scene.yaml") -> InputError:
    path = write(tmp_path, name, data)
    with pytest.raises(InputError) as ei:
        load_scene_spec(path)
    check(ei.value, path, field)
    return ei.value


def robot_error(tmp_path: Path, data, field: str | None) -> InputError:
    """Errors of robot.yaml, whether found when parsing or when resolving names in the URDF."""
    path = write(tmp_path, "bad_robot.yaml", data)
    with pytest.raises(InputError) as ei:
        load_robot(path)
    check(ei.value, path, field)
    return ei.value


def tiny_mesh_file(tmp_path: Path) -> Path:
    path = tmp_path / "cube.stl"
    trimesh.creation.box(extents=[0.05, 0.05, 0.05]).export(path)
    return path


# --------------------------------------------------------------------------- good files


def test_default_scene_loads():
    spec = load_scene_spec(SCENE_YAML)
    assert spec.file == SCENE_YAML.resolve()
    assert spec.robot == ROBOT_YAML.resolve()
    assert spec.object.mesh == "builtin:statuette"
    assert spec.object.scale == 1.0 and spec.object.friction == 0.5
    names = [ob.name for ob in spec.obstacles]
    assert len(names) == 13 and len(set(names)) == 13
    desk = spec.obstacles[names.index("desk_top")]
    assert desk.shape == "box" and desk.size == (0.80, 1.90, 0.04)
    np.testing.assert_allclose(desk.X_WO, np.array([[1, 0, 0, 0.72], [0, 1, 0, 0], [0, 0, 1, 0.72], [0, 0, 0, 1]]))
    vase = spec.obstacles[names.index("vase_body")]
    assert vase.shape == "sphere" and vase.size == (0.09,)
    np.testing.assert_allclose(spec.task.X_WO_start[:3, 3], [0.40, -0.85, 0.74])
    np.testing.assert_allclose(spec.task.X_WO_goal[:3, 3], [0.62, 0.78, 0.74])
    for X in (spec.task.X_WO_start, spec.task.X_WO_goal):
        np.testing.assert_allclose(X[:3, :3] @ X[:3, :3].T, np.eye(3), atol=1e-12)
    np.testing.assert_allclose(spec.task.X_WO_start[:3, 0], [0.0, 1.0, 0.0], atol=1e-4)  # yaw +pi/2
    assert spec.task.robot_start == "rest" and spec.task.robot_goal == "rest"
    assert spec.planning.seed == 0 and spec.planning.contact_tolerance > 0


def test_default_robot_spec_loads():
    spec = load_robot_spec(ROBOT_YAML)
    assert spec.urdf == URDF.resolve()
    assert [len(spec.groups[g]) for g in ("torso", "right_arm", "left_arm")] == [3, 7, 7]
    assert set(spec.hands) == {"right", "left"}
    for side, hand in spec.hands.items():
        assert hand.arm == f"{side}_arm"
        assert len(hand.fingers) == 4 and len(hand.joints) == 13 and len(hand.open) == 13
        assert all(f.tip_radius > 0 for f in hand.fingers)
    assert spec.rest == pytest.approx(GOOD_ROBOT["rest"])
    assert spec.disabled_collisions == ()
    assert spec.self_collision.samples == GOOD_ROBOT["self_collision"]["samples"]


def test_quaternion_pose_is_normalised(tmp_path):
    d = scene_dict()
    d["task"]["object_start"] = {"xyz": [0.4, -0.85, 0.74], "quat": [0, 0, 2.0, 2.0]}  # not unit
    spec = load_scene_spec(write(tmp_path, "scene.yaml", d))
    np.testing.assert_allclose(spec.task.X_WO_start[:3, :3], [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=1e-12)


def test_relative_paths_resolve_against_the_file(tmp_path):
    (tmp_path / "sub").mkdir()
    mesh = tiny_mesh_file(tmp_path)
    d = scene_dict()
    d["object"]["mesh"] = "../cube.stl"
    spec = load_scene_spec(write(tmp_path / "sub", "scene.yaml", d))
    assert Path(spec.object.mesh) == mesh.resolve()


# --------------------------------------------------------------------------- reading


def test_missing_file(tmp_path):
    path = tmp_path / "nowhere.yaml"
    with pytest.raises(InputError) as ei:
        load_scene_spec(path)
    check(ei.value, path, None)
    assert "no such file" in str(ei.value)
    with pytest.raises(InputError) as ei:
        load_robot_spec(path)
    check(ei.value, path, None)


def test_yaml_syntax_error(tmp_path):
    text = SCENE_YAML.read_text().replace("planning: {seed: 0}", "planning: {seed: 0")
    err = scene_error(tmp_path, text, None)
    assert "YAML syntax error" in str(err) and "line" in str(err)


def test_yaml_syntax_error_robot(tmp_path):
    path = write(tmp_path, "robot.yaml", "format: regrasp.robot/1\ngroups: [torso\n")
    with pytest.raises(InputError) as ei:
        load_robot_spec(path)
    check(ei.value, path, None)
    assert "YAML syntax error" in str(ei.value)


@pytest.mark.parametrize("text", ["", "- a list\n- of things\n", "just a string\n"])
def test_top_level_not_a_mapping(tmp_path, text):
    err = scene_error(tmp_path, text, None)
    assert "mapping" in str(err)


# --------------------------------------------------------------------------- scene.yaml


def _set(d: dict, dotted: str, value) -> None:
    keys = dotted.split(".")
    for k in keys[:-1]:
        d = d[int(k)] if isinstance(d, list) else d[k]
    if isinstance(d, list):
        d[int(keys[-1])] = value
    else:
        d[keys[-1]] = value


def _del(d: dict, dotted: str) -> None:
    keys = dotted.split(".")
    for k in keys[:-1]:
        d = d[int(k)] if isinstance(d, list) else d[k]
    del d[keys[-1]]


@pytest.mark.parametrize("where, key, field", [
    ("", "bogus", "bogus"),
    ("task", "robot_middle", "task.robot_middle"),
    ("object", "colour", "object.colour"),
    ("planning", "sed", "planning.sed"),
    ("task.object_start", "xyzw", "task.object_start.xyzw"),
    ("obstacles.0", "material", "obstacles[0].material"),
    ("obstacles.0.box", "radius", "obstacles[0].box.radius"),
])
def test_scene_unknown_key(tmp_path, where, key, field):
    d = scene_dict()
    target = d
    for k in filter(None, where.split(".")):
        target = target[int(k)] if isinstance(target, list) else target[k]
    target[key] = 1
    err = scene_error(tmp_path, d, field)
    assert "unknown key" in err.message


@pytest.mark.parametrize("dotted, field", [
    ("format", "format"),
    ("robot", "robot"),
    ("object", "object"),
    ("object.mesh", "object.mesh"),
    ("task", "task"),
    ("task.object_start", "task.object_start"),
    ("task.object_goal.xyz", "task.object_goal.xyz"),
    ("obstacles.1.name", "obstacles[1].name"),
    ("obstacles.1.pose", "obstacles[1].pose"),
    ("obstacles.0.box.size", "obstacles[0].box.size"),
    ("obstacles.11.sphere.radius", "obstacles[11].sphere.radius"),
])
def test_scene_missing_key(tmp_path, dotted, field):
    d = scene_dict()
    _del(d, dotted)
    err = scene_error(tmp_path, d, field)
    assert "missing" in err.message


def test_obstacle_without_shape(tmp_path):
    d = scene_dict()
    del d["obstacles"][2]["box"]
    err = scene_error(tmp_path, d, "obstacles[2]")
    assert "exactly one of" in err.message


def test_obstacle_with_two_shapes(tmp_path):
    d = scene_dict()
    d["obstacles"][2]["sphere"] = {"radius": 0.1}
    scene_error(tmp_path, d, "obstacles[2]")


@pytest.mark.parametrize("dotted, value, field", [
    ("format", "regrasp.scene/2", "format"),
    ("format", 1, "format"),
    ("robot", 3, "robot"),
    ("object", "statuette", "object"),
    ("object.scale", "big", "object.scale"),
    ("object.friction", True, "object.friction"),
    ("object.mesh", ["a.stl"], "object.mesh"),
    ("obstacles", {"name": "desk"}, "obstacles"),
    ("obstacles.3", "a box", "obstacles[3]"),
    ("obstacles.3.name", 7, "obstacles[3].name"),
    ("obstacles.0.box.size", "big", "obstacles[0].box.size"),
    ("obstacles.5.cylinder.radius", "thin", "obstacles[5].cylinder.radius"),
    ("obstacles.0.pose", [0.7, 0, 0.7], "obstacles[0].pose"),
    ("task", [1, 2], "task"),
    ("task.object_start.xyz", "here", "task.object_start.xyz"),
    ("task.object_start.rpy", [0, "a", 0], "task.object_start.rpy"),
    ("task.object_goal.xyz", [0.1, True, 0.2], "task.object_goal.xyz"),
    ("task.robot_start", 5, "task.robot_start"),
    ("task.robot_goal", "home", "task.robot_goal"),
    ("task.robot_start", {"r_arm_j1": "up"}, "task.robot_start.r_arm_j1"),
    ("planning", "fast", "planning"),
    ("planning.seed", "zero", "planning.seed"),
    ("planning.seed", 1.5, "planning.seed"),
    ("planning.seed", -1, "planning.seed"),
    ("planning.ik_restarts", 0, "planning.ik_restarts"),
    ("planning.segment_resolution", ".02", "planning.segment_resolution"),
])
def test_scene_wrong_type_or_value(tmp_path, dotted, value, field):
    d = scene_dict()
    _set(d, dotted, value)
    scene_error(tmp_path, d, field)


@pytest.mark.parametrize("dotted, value, field", [
    ("task.object_start.xyz", [0.4, -0.85], "task.object_start.xyz"),
    ("task.object_start.xyz", [0.4, -0.85, 0.74, 1.0], "task.object_start.xyz"),
    ("task.object_goal.rpy", [0, 0, 0, 0], "task.object_goal.rpy"),
    ("task.object_goal.rpy", [], "task.object_goal.rpy"),
    ("obstacles.0.pose.xyz", [0.72, 0.0], "obstacles[0].pose.xyz"),
    ("obstacles.0.box.size", [0.8, 1.9], "obstacles[0].box.size"),
])
def test_scene_wrong_vector_length(tmp_path, dotted, value, field):
    d = scene_dict()
    _set(d, dotted, value)
    err = scene_error(tmp_path, d, field)
    assert "expected a list of" in err.message


@pytest.mark.parametrize("quat", [[0, 0, 0, 0], [0.0, 0.0, 1e-12, 0.0]])
def test_zero_norm_quaternion(tmp_path, quat):
    d = scene_dict()
    d["task"]["object_goal"] = {"xyz": [0.62, 0.78, 0.74], "quat": quat}
    err = scene_error(tmp_path, d, "task.object_goal.quat")
    assert "zero norm" in err.message


def test_quaternion_wrong_length(tmp_path):
    d = scene_dict()
    d["obstacles"][0]["pose"] = {"xyz": [0.72, 0, 0.72], "quat": [0, 0, 1]}
    scene_error(tmp_path, d, "obstacles[0].pose.quat")


def test_rpy_and_quat_together(tmp_path):
    d = scene_dict()
    d["task"]["object_start"]["quat"] = [0, 0, 0, 1]
    scene_error(tmp_path, d, "task.object_start.quat")


def test_duplicate_obstacle_names(tmp_path):
    d = scene_dict()
    d["obstacles"][4]["name"] = "desk_leg_fr"
    err = scene_error(tmp_path, d, "obstacles")
    assert "duplicate" in err.message and "desk_leg_fr" in err.message


@pytest.mark.parametrize("dotted, value, field", [
    ("obstacles.0.box.size", [0.8, -1.9, 0.04], "obstacles[0].box.size"),
    ("obstacles.0.box.size", [0.8, 0.0, 0.04], "obstacles[0].box.size"),
    ("obstacles.5.cylinder.radius", -0.008, "obstacles[5].cylinder.radius"),
    ("obstacles.5.cylinder.length", -0.2, "obstacles[5].cylinder.length"),
    ("obstacles.11.sphere.radius", -0.09, "obstacles[11].sphere.radius"),
    ("object.scale", -1.0, "object.scale"),
    ("object.friction", -0.5, "object.friction"),
    ("planning.segment_resolution", -0.02, "planning.segment_resolution"),
    ("planning.contact_tolerance", 0.0, "planning.contact_tolerance"),
])
def test_negative_size(tmp_path, dotted, value, field):
    d = scene_dict()
    _set(d, dotted, value)
    scene_error(tmp_path, d, field)


def test_missing_robot_file(tmp_path):
    d = scene_dict()
    d["robot"] = "no_such_robot.yaml"
    err = scene_error(tmp_path, d, "robot")
    assert "no_such_robot.yaml" in err.message


def test_missing_object_mesh_file(tmp_path):
    d = scene_dict()
    d["object"]["mesh"] = "no_such_mesh.stl"
    scene_error(tmp_path, d, "object.mesh")


def test_missing_obstacle_mesh_file(tmp_path):
    d = scene_dict()
    d["obstacles"].append({"name": "rock", "mesh": {"file": "rock.stl"}, "pose": {"xyz": [2, 0, 0]}})
    scene_error(tmp_path, d, "obstacles[13].mesh.file")


# --------------------------------------------------------------------------- robot.yaml


@pytest.mark.parametrize("where, key, field", [
    ("", "base_link", "base_link"),
    ("groups", "head", "groups.head"),
    ("hands", "middle", "hands.middle"),
    ("hands.right", "palm", "hands.right.palm"),
    ("hands.left.fingers.2", "nail", "hands.left.fingers[2].nail"),
    ("self_collision", "margin", "self_collision.margin"),
])
def test_robot_unknown_key(tmp_path, where, key, field):
    d = robot_dict()
    target = d
    for k in filter(None, where.split(".")):
        target = target[int(k)] if isinstance(target, list) else target[k]
    target[key] = 1
    err = robot_error(tmp_path, d, field)
    assert "unknown key" in err.message


@pytest.mark.parametrize("dotted, field", [
    ("format", "format"),
    ("urdf", "urdf"),
    ("groups", "groups"),
    ("groups.left_arm", "groups.left_arm"),
    ("hands", "hands"),
    ("hands.right.grasp_frame", "hands.right.grasp_frame"),
    ("hands.right.fingers", "hands.right.fingers"),
    ("hands.left.fingers.0.joints", "hands.left.fingers[0].joints"),
    ("hands.left.fingers.1.tip_link", "hands.left.fingers[1].tip_link"),
    ("hands.left.fingers.1.tip_radius", "hands.left.fingers[1].tip_radius"),
])
def test_robot_missing_key(tmp_path, dotted, field):
    d = robot_dict()
    _del(d, dotted)
    err = robot_error(tmp_path, d, field)
    assert "missing" in err.message


@pytest.mark.parametrize("dotted, value, field", [
    ("format", "regrasp.scene/1", "format"),
    ("urdf", 42, "urdf"),
    ("groups", ["torso", "right_arm"], "groups"),
    ("groups.right_arm", "r_arm_j1", "groups.right_arm"),
    ("groups.right_arm", [], "groups.right_arm"),
    ("groups.torso", [1, 2], "groups.torso"),
    ("hands", [], "hands"),
    ("hands", {}, "hands"),
    ("hands.right.fingers", [], "hands.right.fingers"),
    ("hands.right.fingers.0", "thumb", "hands.right.fingers[0]"),
    ("hands.right.fingers.0.joints", [], "hands.right.fingers[0].joints"),
    ("hands.right.fingers.0.tip_radius", "small", "hands.right.fingers[0].tip_radius"),
    ("hands.right.fingers.0.tip_radius", -0.01, "hands.right.fingers[0].tip_radius"),
    ("hands.right.fingers.0.tip_link", None, "hands.right.fingers[0].tip_link"),
    ("hands.right.fingers.1.open", [0.0, 0.0], "hands.right.fingers[1].open"),
    ("hands.right.contact", "sticky", "hands.right.contact"),
    ("hands.right.tip_patch", -0.001, "hands.right.tip_patch"),
    ("hands.right.tip_patch", "soft", "hands.right.tip_patch"),
    ("hands.right.tip_patch", 0.5, "hands.right.tip_patch"),
    ("rest", [0.1, 0.2], "rest"),
    ("rest.r_arm_j1", "up", "rest.r_arm_j1"),
    ("disabled_collisions", "none", "disabled_collisions"),
    ("disabled_collisions", [["chest"]], "disabled_collisions[0]"),
    ("disabled_collisions", [["chest", "r_palm"], ["chest", 3]], "disabled_collisions[1]"),
    ("self_collision.samples", 0, "self_collision.samples"),
    ("self_collision.seed", "x", "self_collision.seed"),
])
def test_robot_wrong_type_or_value(tmp_path, dotted, value, field):
    d = robot_dict()
    _set(d, dotted, value)
    robot_error(tmp_path, d, field)


def test_unknown_joint_in_rest(tmp_path):
    d = robot_dict()
    d["rest"]["r_elbow"] = 0.3
    err = robot_error(tmp_path, d, "rest.r_elbow")
    assert "unknown joint" in err.message and "r_elbow" in err.message


def test_rest_outside_limits(tmp_path):
    d = robot_dict()
    d["rest"]["r_arm_j2"] = 10.0
    err = robot_error(tmp_path, d, "rest.r_arm_j2")
    assert "limits" in err.message


@pytest.mark.parametrize("group", ["torso", "right_arm", "left_arm"])
def test_unknown_joint_in_group(tmp_path, group):
    d = robot_dict()
    d["groups"][group] = [*d["groups"][group], "wrist_roll"]
    err = robot_error(tmp_path, d, f"groups.{group}")
    assert "wrist_roll" in err.message


def test_unknown_joint_in_finger(tmp_path):
    d = robot_dict()
    d["hands"]["left"]["fingers"][1]["joints"][1] = "l_index_knuckle"
    err = robot_error(tmp_path, d, "hands.left.fingers[1].joints")
    assert "l_index_knuckle" in err.message


def test_finger_open_outside_limits(tmp_path):
    d = robot_dict()
    d["hands"]["right"]["fingers"][0]["open"] = [-10.0, 0.0, 0.0, 0.0]
    robot_error(tmp_path, d, "hands.right.fingers")


def test_unknown_tip_link(tmp_path):
    d = robot_dict()
    d["hands"]["right"]["fingers"][2]["tip_link"] = "r_middle_nail"
    err = robot_error(tmp_path, d, "hands.right.fingers[2].tip_link")
    assert "r_middle_nail" in err.message


def test_unknown_grasp_frame(tmp_path):
    d = robot_dict()
    d["hands"]["left"]["grasp_frame"] = "l_tool0"
    err = robot_error(tmp_path, d, "hands.left.grasp_frame")
    assert "l_tool0" in err.message


def test_unknown_link_in_disabled_collisions(tmp_path):
    d = robot_dict()
    d["disabled_collisions"] = [["chest", "r_arm_link1"], ["chest", "r_shoulder"]]
    path = write(tmp_path, "robot.yaml", d)
    robot = load_robot(path)
    with pytest.raises(InputError) as ei:
        disabled_pairs(robot, None)
    check(ei.value, path, "disabled_collisions[1]")
    assert "r_shoulder" in ei.value.message


def test_user_disabled_collisions_are_added(tmp_path):
    d = robot_dict()
    d["disabled_collisions"] = [["r_palm", "l_palm"]]
    robot = load_robot(write(tmp_path, "robot.yaml", d))
    pairs = disabled_pairs(robot, None)
    assert pairs.pairs[("l_palm", "r_palm")] == "user"
    assert pairs.count("user") == 1


def test_missing_urdf(tmp_path):
    d = robot_dict()
    d["urdf"] = "nothing_here.urdf"
    err = robot_error(tmp_path, d, "urdf")
    assert "nothing_here.urdf" in err.message


@pytest.mark.parametrize("text", [
    "",
    "this is not XML <robot",
    '<robot name="x"></robot>',
    '<robot name="x"><link name="a"/><joint name="j" type="revolute"><parent link="a"/>'
    '<child link="nowhere"/><axis xyz="0 0 1"/></joint></robot>',
])
def test_urdf_that_fails_to_parse(tmp_path, text):
    urdf = tmp_path / "broken.urdf"
    urdf.write_text(text)
    d = robot_dict()
    d["urdf"] = str(urdf)
    err = robot_error(tmp_path, d, "urdf")
    assert "cannot parse URDF" in err.message and str(urdf) in err.message


def test_urdf_in_unknown_package(tmp_path):
    d = robot_dict()
    d["urdf"] = "package://no_such_package_xyz/robots/r.urdf"
    err = robot_error(tmp_path, d, "urdf")
    assert "no_such_package_xyz" in err.message


# --------------------------------------------------------------------------- problem (names, meshes)


def _problem_error(tmp_path: Path, d: dict, field: str, cache_dir: Path) -> InputError:
    path = write(tmp_path, "scene.yaml", d)
    with pytest.raises(InputError) as ei:
        load_problem(path, cache_dir)
    check(ei.value, path, field)
    return ei.value


def test_unknown_joint_in_robot_start(tmp_path, cache_dir):
    d = scene_dict()
    d["task"]["robot_start"] = {"r_arm_j1": 0.1, "r_wrist": 0.2}
    err = _problem_error(tmp_path, d, "task.robot_start.r_wrist", cache_dir)
    assert "unknown joint" in err.message


def test_robot_goal_outside_limits(tmp_path, cache_dir):
    d = scene_dict()
    d["task"]["robot_goal"] = {"l_arm_j4": 9.0}
    err = _problem_error(tmp_path, d, "task.robot_goal.l_arm_j4", cache_dir)
    assert "limits" in err.message


def test_robot_error_names_robot_yaml(tmp_path, cache_dir):
    """An error inside the robot file names robot.yaml, not the scene that points to it."""
    r = robot_dict()
    r["hands"]["right"]["grasp_frame"] = "r_nowhere"
    robot_path = write(tmp_path, "robot.yaml", r)
    d = scene_dict()
    d["robot"] = str(robot_path)
    scene = write(tmp_path, "scene.yaml", d)
    with pytest.raises(InputError) as ei:
        load_problem(scene, cache_dir)
    check(ei.value, robot_path, "hands.right.grasp_frame")


@pytest.mark.parametrize("name, content", [
    ("garbage.stl", b"solid junk\nthis is not an STL file\nendsolid\n"),
    ("empty.obj", b""),
    ("nofaces.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\n"),
    ("binary.ply", b"\x00\x01\x02\x03 not a ply"),
])
def test_object_mesh_that_fails_to_load_or_is_empty(tmp_path, cache_dir, name, content):
    (tmp_path / name).write_bytes(content)
    d = scene_dict()
    d["object"]["mesh"] = name
    err = _problem_error(tmp_path, d, "object.mesh", cache_dir)
    assert name in err.message


def test_unknown_builtin_object(tmp_path, cache_dir):
    d = scene_dict()
    d["object"]["mesh"] = "builtin:teapot"
    err = _problem_error(tmp_path, d, "object.mesh", cache_dir)
    assert "builtin:statuette" in err.message  # lists the valid ones


def test_obstacle_mesh_that_fails_to_load(tmp_path, cache_dir):
    (tmp_path / "rock.stl").write_bytes(b"solid rock\nnot really\nendsolid\n")
    d = scene_dict()
    d["obstacles"].append({"name": "rock", "mesh": {"file": "rock.stl"}, "pose": {"xyz": [2, 0, 0]}})
    err = _problem_error(tmp_path, d, "obstacles[13].mesh.file", cache_dir)
    assert "rock.stl" in err.message


def test_good_mesh_object_and_obstacle(tmp_path, cache_dir):
    """A scene with a user mesh object and a mesh obstacle loads and gives a world."""
    mesh = tiny_mesh_file(tmp_path)
    d = scene_dict()
    d["object"]["mesh"] = mesh.name
    d["obstacles"].append({"name": "rock", "mesh": {"file": mesh.name, "scale": 2.0}, "pose": {"xyz": [2, 0, 0.05]}})
    problem = load_problem(write(tmp_path, "scene.yaml", d), cache_dir)
    assert problem.object.n_triangles == 12
    assert problem.spec.obstacles[-1].size == (2.0,)
    assert problem.world().is_free(problem.q_start)
