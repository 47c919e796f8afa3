"""URDF mimic joints as the URDF means them (issue 41): a follower's value always comes from
the joint that follows none, through a chain of followers composed; the leader's limits
bind, and a follower whose own URDF limits cut its leader's range is said at load with one
warning (PR2's gripper joints of multiplier -1 and limits [0, 0.548]), its limits then the
leader's range mapped, so that the planner, the plan's recorded limits and the validator
agree.  On copies of the shipped HIRO-NX, whose right jaw is a prismatic leader and a
follower of multiplier -1."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from regrasp_cli.model.robot import load_robot

ROOT = Path(__file__).resolve().parents[2]
HIRONX = ROOT / "configs" / "robots" / "hironx"
FOLLOWER = '<joint name="r_gripper_r_finger_joint" type="prismatic">'


def _copy(tmp_path: Path, edit) -> Path:
    (tmp_path / "robot.urdf").write_text(edit((HIRONX / "robot.urdf").read_text()))
    robot = yaml.safe_load((HIRONX / "robot.yaml").read_text())
    path = tmp_path / "robot.yaml"
    path.write_text(yaml.safe_dump(dict(robot, urdf="robot.urdf")))
    return path


def _follower_limits(urdf: str, lower: str, upper: str) -> str:
    head, sep, tail = urdf.partition(FOLLOWER)
    return head + sep + tail.replace('<limit lower="-0.045" upper="0"', f'<limit lower="{lower}" upper="{upper}"', 1)


def test_shipped_followers_are_within_their_limits_and_take_the_mapped_range():
    r = load_robot(HIRONX / "robot.yaml")
    f = r.joint_names.index("r_gripper_r_finger_joint")
    lead, m, o = r.mimic[f]
    assert (r.joint_names[lead], m, o) == ("r_gripper_l_finger_joint", -1.0, 0.0)
    assert (r.lower[f], r.upper[f]) == pytest.approx((-r.upper[lead], -r.lower[lead]))


def test_a_follower_outside_its_own_limits_is_said_at_load_and_the_leader_binds(tmp_path):
    path = _copy(tmp_path, lambda u: _follower_limits(u, "0", "0.045"))  # PR2-like: -1 x [0, 0.045] is <= 0
    with pytest.warns(UserWarning, match=r"r_gripper_r_finger_joint follows r_gripper_l_finger_joint .* outside "
                                         r"its own limits \[0, 0.045\]; the leader's limits bind"):
        r = load_robot(path)
    f, lead = r.joint_names.index("r_gripper_r_finger_joint"), r.joint_names.index("r_gripper_l_finger_joint")
    assert (r.lower[f], r.upper[f]) == pytest.approx((-0.045, 0.0))
    rng = np.random.default_rng(0)
    for _ in range(50):  # every configuration the planner draws is within the limits the validator reads
        q = r.sample(rng)
        assert r.within_limits(q) and q[f] == pytest.approx(-q[lead])


def test_a_chain_of_followers_is_composed_down_to_its_leader(tmp_path):
    """The left jaw's follower made to follow the right jaw's follower (multiplier 2,
    offset 0.01): q = 2 (-q_lead) + 0.01."""
    def chain(urdf: str) -> str:
        return urdf.replace('<mimic joint="l_gripper_l_finger_joint" multiplier="-1" offset="0"/>',
                            '<mimic joint="r_gripper_r_finger_joint" multiplier="2" offset="0.01"/>', 1)

    with pytest.warns(UserWarning, match="l_gripper_r_finger_joint follows r_gripper_l_finger_joint"):
        r = load_robot(_copy(tmp_path, chain))
    f, lead = r.joint_names.index("l_gripper_r_finger_joint"), r.joint_names.index("r_gripper_l_finger_joint")
    assert r.mimic[f] == (lead, -2.0, pytest.approx(0.01))
    q = r.q_rest.copy()
    q[lead] = 0.02
    assert r.coupled(q)[f] == pytest.approx(-0.03)
    assert r.to_pin(q)[r.model.joints[r.model.getJointId("l_gripper_r_finger_joint")].idx_q] == pytest.approx(-0.03)


PR2 = ROOT / "regrasp_cli" / "data" / "robots" / "pr2" / "robot.yaml"


@pytest.mark.filterwarnings("ignore:.*l_gripper_r_parallel_root_joint")  # the left hand's, said alike
def test_the_hand_model_holds_every_link_that_moves_with_the_fingers(tmp_path):
    """PR2 as example-robot-data ships it: each fingertip hangs below a mimic joint of its
    own, the parallel links follow the leader with multipliers 1 and -1.  The tips belong
    to their fingers, the followers no finger lists to the leader's, and the grasp
    search's hand model has the tips' geometry."""
    import trimesh

    from regrasp_cli.grasp.single import HandModel

    from regrasp_cli.config import load_robot_spec

    stock = load_robot_spec(PR2).urdf  # a copy: the warning is said once per file and process
    (tmp_path / "pr2.urdf").write_bytes(stock.read_bytes())
    (tmp_path / "robot.yaml").write_text(PR2.read_text().replace(
        "package://example-robot-data/robots/pr2_description/urdf/pr2.urdf", str(tmp_path / "pr2.urdf")))
    with pytest.warns(UserWarning, match="r_gripper_r_parallel_root_joint follows r_gripper_l_finger_joint"):
        r = load_robot(tmp_path / "robot.yaml")
    owner = {r.model.names[j]: f for j, f in r.hand_joints("right").items()}
    assert owner == {"r_gripper_l_finger_joint": 0, "r_gripper_l_finger_tip_joint": 0, "r_gripper_r_finger_joint": 1,
                     "r_gripper_r_finger_tip_joint": 1, "r_gripper_l_parallel_root_joint": 0,
                     "r_gripper_r_parallel_root_joint": 0}
    hm = HandModel(r, "right", trimesh.creation.box((0.04, 0.04, 0.1)), set(), 0.002)
    links = {r.model.frames[go.parentFrame].name for go in hm.gm.geometryObjects}
    assert {"r_gripper_l_finger_tip_link", "r_gripper_r_finger_tip_link"} <= links
