"""The shipped in-hand test hand (``builtin:hand4``, scripts/make_hand4_urdf.py): a hand
alone (empty groups, the wrist as base) of four 3-DoF fingers round a palm, as seed 003's
simulated hand; its URDF reproduced by the script; a pick-and-place scene naming it gets
one line (exit 2) saying it has no arm; and a robot.yaml with one arm still needs both."""

from __future__ import annotations

import runpy

import numpy as np
import yaml

from cli_helpers import assert_one_error_line, needs_separate_stderr, run, write_scene
from conftest import ROOT

from regrasp_cli.model.robot import Kinematics, load_robot

ROBOT_DIR = ROOT / "regrasp_cli" / "data" / "robots" / "hand4"
SCRIPT = ROOT / "scripts" / "make_hand4_urdf.py"


def test_a_hand_alone_with_four_fingers_round_the_palm():
    robot = load_robot(ROBOT_DIR / "robot.yaml")
    assert robot.nq == 12 and all(len(robot.groups[g]) == 0 for g in ("torso", "right_arm", "left_arm"))
    hand = robot.hands["right"]
    assert [len(i) for i in hand.finger_idx] == [3, 3, 3, 3] and len(hand.arm_idx) == 0
    kin = Kinematics(robot)
    tips = np.array([kin.fk(robot.q_rest, f)[:3, 3] for f in hand.tip_frames])
    azimuth = np.degrees(np.arctan2(tips[:, 1], tips[:, 0])) % 360
    assert np.allclose(azimuth, [0, 90, 180, 270], atol=1e-6)  # round the palm's axis
    assert np.allclose(np.linalg.norm(tips[:, :2], axis=1), np.linalg.norm(tips[0, :2]))
    assert robot.within_limits(robot.q_rest)


def test_generator_reproduces_the_urdf():
    module = runpy.run_path(str(SCRIPT))  # not run as __main__: nothing is written
    text = module["urdf_text"]()
    assert text == (ROBOT_DIR / "robot.urdf").read_text()
    assert module["OUT"].resolve() == (ROBOT_DIR / "robot.urdf").resolve()
    assert "<mesh" not in text and '<robot name="hand4">' in text


@needs_separate_stderr
def test_a_pick_and_place_scene_with_a_hand_alone_is_one_line(tmp_path):
    d = yaml.safe_load((ROOT / "configs" / "scenes" / "hironx_onearm.yaml").read_text())
    d["robot"] = "builtin:hand4"
    scene = write_scene(tmp_path / "hand.yaml", d)
    result = run("--cache-dir", tmp_path / "cache", "plan", scene, "-o", tmp_path / "p.json")
    assert_one_error_line(result, str(scene), "robot", "hand alone", "no arm")
    assert not (tmp_path / "p.json").exists()


def test_one_arm_missing_is_still_an_error(tmp_path):
    from regrasp_cli.config import load_robot_spec
    from regrasp_cli.errors import InputError

    d = yaml.safe_load((ROOT / "regrasp_cli" / "data" / "robots" / "hironx" / "robot.yaml").read_text())
    d["urdf"] = str(ROOT / "regrasp_cli" / "data" / "robots" / "hironx" / "robot.urdf")
    d["groups"]["left_arm"] = []
    path = tmp_path / "robot.yaml"
    path.write_text(yaml.safe_dump(d))
    try:
        load_robot_spec(path)
    except InputError as exc:
        assert exc.field.endswith("left_arm") and "at least one joint" in exc.message
    else:
        raise AssertionError("a robot.yaml with an empty left arm loaded")
