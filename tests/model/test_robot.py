"""Tests of regrasp_cli.model.robot: forward kinematics against a hand-computed toy robot,
and the shape of the default 43-DoF robot.

The toy robot is planar: a torso joint about z at the base, and two arms (right at
y = -0.3, left at y = +0.3, both at z = 0.5) of two links (0.4 m, 0.3 m) with a one-joint
"finger" (0.1 m) each, every joint about z.  The finger joints are continuous (two
coordinates in pinocchio, one in our configurations), so the pinocchio q and v indices of
the arm that comes second in pinocchio's order differ.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from regrasp_cli.errors import InputError
from regrasp_cli.model.ik import arm_ik, finger_ik
from regrasp_cli.model.robot import Kinematics, load_robot

L1, L2, LF = 0.4, 0.3, 0.1  # m: upper arm, forearm, finger
SHOULDER_Y, SHOULDER_Z = 0.3, 0.5

_INERTIAL = ('<inertial><mass value="0.1"/><origin xyz="0 0 0"/>'
             '<inertia ixx="1e-4" ixy="0" ixz="0" iyy="1e-4" iyz="0" izz="1e-4"/></inertial>')


def _link(name: str, geometry: str | None = None, origin: str = "0 0 0") -> str:
    col = f'<collision><origin xyz="{origin}" rpy="0 0 0"/><geometry>{geometry}</geometry></collision>' if geometry else ""
    return f'<link name="{name}">{_INERTIAL}{col}</link>'


def _joint(name: str, kind: str, parent: str, child: str, xyz: str, limits: str = "") -> str:
    axis = '<axis xyz="0 0 1"/>' if kind != "fixed" else ""
    limit = f'<limit {limits} effort="10" velocity="2"/>' if kind in ("revolute", "prismatic") else ""
    if kind == "continuous":
        limit = '<limit effort="10" velocity="2"/>'
    return (f'<joint name="{name}" type="{kind}"><parent link="{parent}"/><child link="{child}"/>'
            f'<origin xyz="{xyz}" rpy="0 0 0"/>{axis}{limit}</joint>')


def toy_urdf() -> str:
    parts = [_link("base_link", '<box size="0.1 0.1 0.1"/>'), _link("torso", '<box size="0.1 0.1 0.1"/>', "0 0 0.3"),
             _joint("torso_yaw", "revolute", "base_link", "torso", "0 0 0", 'lower="-1" upper="1"')]
    for s, sign in (("r", -1), ("l", 1)):
        parts += [
            _joint(f"{s}_j1", "revolute", "torso", f"{s}_link1", f"0 {sign * SHOULDER_Y} {SHOULDER_Z}",
                   'lower="-3" upper="3"'),
            _link(f"{s}_link1", f'<box size="{L1} 0.04 0.04"/>', f"{L1 / 2} 0 0"),
            _joint(f"{s}_j2", "revolute", f"{s}_link1", f"{s}_link2", f"{L1} 0 0", 'lower="-2.5" upper="2.5"'),
            _link(f"{s}_link2", f'<box size="{L2} 0.04 0.04"/>', f"{L2 / 2} 0 0"),
            _joint(f"{s}_grasp_joint", "fixed", f"{s}_link2", f"{s}_grasp", f"{L2} 0 0"),
            _link(f"{s}_grasp"),
            _joint(f"{s}_f1", "continuous", f"{s}_link2", f"{s}_finger", f"{L2} 0 0"),
            _link(f"{s}_finger", f'<box size="{LF} 0.02 0.02"/>', f"{LF / 2} 0 0"),
            _joint(f"{s}_tip_joint", "fixed", f"{s}_finger", f"{s}_tip", f"{LF} 0 0"),
            _link(f"{s}_tip", '<sphere radius="0.01"/>'),
        ]
    return '<?xml version="1.0"?>\n<robot name="toy">\n' + "\n".join(parts) + "\n</robot>\n"


def toy_robot_yaml(urdf: Path) -> dict:
    def hand(s):
        return {"grasp_frame": f"{s}_grasp",
                "fingers": [{"name": "finger", "joints": [f"{s}_f1"], "tip_link": f"{s}_tip", "tip_radius": 0.01}]}

    return {"format": "regrasp.robot/1", "urdf": str(urdf),
            "groups": {"torso": ["torso_yaw"], "right_arm": ["r_j1", "r_j2"], "left_arm": ["l_j1", "l_j2"]},
            "hands": {"right": hand("r"), "left": hand("l")},
            "rest": {"r_j2": 0.5, "l_j2": -0.5},
            "disabled_collisions": [],
            "self_collision": {"samples": 50, "seed": 0, "never_margin": 0.02}}


@pytest.fixture(scope="module")
def toy(tmp_path_factory):
    d = tmp_path_factory.mktemp("toy")
    (d / "toy.urdf").write_text(toy_urdf())
    (d / "robot.yaml").write_text(yaml.safe_dump(toy_robot_yaml(Path("toy.urdf"))))  # relative path
    return load_robot(d / "robot.yaml")


def rz(theta: float) -> np.ndarray:
    c, s = np.cos(theta), np.sin(theta)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def closed_form(side: str, t: float, q1: float, q2: float, qf: float, frame: str) -> np.ndarray:
    """X_WF of the grasp frame or fingertip of one arm, by hand."""
    sign = -1.0 if side == "r" else 1.0
    a1, a12, a12f = q1, q1 + q2, q1 + q2 + qf
    x = L1 * np.cos(a1) + L2 * np.cos(a12)
    y = sign * SHOULDER_Y + L1 * np.sin(a1) + L2 * np.sin(a12)
    angle = a12
    if frame == "tip":
        x, y, angle = x + LF * np.cos(a12f), y + LF * np.sin(a12f), a12f
    X = np.eye(4)
    X[:3, :3] = rz(t + angle)
    X[:3, 3] = rz(t) @ np.array([x, y, SHOULDER_Z])
    return X


CASES = [
    (0.0, 0.0, 0.0, 0.0),
    (0.0, np.pi / 2, 0.0, 0.0),
    (0.0, 0.0, np.pi / 2, -np.pi / 2),
    (0.3, -0.7, 1.2, 0.4),
    (-0.9, 2.5, -2.0, 1.4),
    (0.5, -3.0, 2.4, -1.5),
]


def test_toy_robot_structure(toy):
    assert toy.nq == 7
    assert set(toy.joint_names) == {"torso_yaw", "r_j1", "r_j2", "r_f1", "l_j1", "l_j2", "l_f1"}
    assert {g: len(i) for g, i in toy.groups.items()} == {"torso": 1, "right_arm": 2, "left_arm": 2}
    assert toy.model.nq == 9  # a continuous joint has two coordinates in pinocchio
    i = toy.joint_index("r_f1")
    assert (toy.lower[i], toy.upper[i]) == (-np.pi, np.pi)
    j = toy.joint_index("l_f1")
    assert (toy.lower[j], toy.upper[j]) == (-np.pi, np.pi)
    assert toy.q_rest[toy.joint_index("r_j2")] == 0.5 and toy.q_rest[toy.joint_index("l_j2")] == -0.5
    assert toy.q_rest[toy.joint_index("torso_yaw")] == 0.0


@pytest.mark.parametrize("t, q1, q2, qf", CASES)
@pytest.mark.parametrize("side", ["r", "l"])
def test_fk_matches_closed_form(toy, side, t, q1, q2, qf):
    q = toy.configuration({"torso_yaw": t, f"{side}_j1": q1, f"{side}_j2": q2, f"{side}_f1": qf}, "test")
    hand = toy.hands["right" if side == "r" else "left"]
    for frame, fid in (("grasp", hand.grasp_frame), ("tip", hand.tip_frames[0])):
        expected = closed_form(side, t, q1, q2, qf, frame)
        np.testing.assert_allclose(Kinematics(toy).fk(q, fid), expected, atol=1e-9)
        np.testing.assert_allclose(Kinematics(toy).fk(q, f"{side}_{frame}"), expected, atol=1e-9)  # by name
    many = Kinematics(toy).fk_many(q, [hand.grasp_frame, hand.tip_frames[0]])
    np.testing.assert_allclose(many[0], closed_form(side, t, q1, q2, qf, "grasp"), atol=1e-9)
    np.testing.assert_allclose(many[1], closed_form(side, t, q1, q2, qf, "tip"), atol=1e-9)


def test_continuous_joint_conversion(toy):
    q = toy.q_rest.copy()
    i = toy.joint_index("r_f1")
    q[i] = 0.7
    qp = toy.to_pin(q)
    assert qp.shape == (toy.model.nq,)
    iq = toy.model.joints[toy.model.getJointId("r_f1")].idx_q
    np.testing.assert_allclose(qp[iq:iq + 2], [np.cos(0.7), np.sin(0.7)], atol=1e-15)


def test_toy_ik_through_the_continuous_joint(toy):
    """IK maps Jacobian columns correctly when pinocchio's q and v orders differ."""
    m = toy.model
    shifted = [n for n in toy.joint_names if m.joints[m.getJointId(n)].idx_q != m.joints[m.getJointId(n)].idx_v]
    assert {"r_j1", "l_j1"} & set(shifted)  # one arm comes after a continuous joint
    rng = np.random.default_rng(0)
    for side in ("r", "l"):
        hand = "right" if side == "r" else "left"
        for _ in range(5):
            q = toy.sample(rng)
            p = Kinematics(toy).fk(q, f"{side}_tip")[:3, 3]
            res = finger_ik(toy, hand, 0, p, _with(toy, q, f"{side}_f1"), rng)
            assert res.success
            np.testing.assert_allclose(Kinematics(toy).fk(res.q, f"{side}_tip")[:3, 3], p, atol=1e-3)
            target = Kinematics(toy).fk(q, f"{side}_grasp")
            res = arm_ik(toy, hand, target, _with(toy, q, f"{side}_j1", f"{side}_j2"), rng)
            assert res.success
            np.testing.assert_allclose(Kinematics(toy).fk(res.q, f"{side}_grasp"), target, atol=1e-3)


def _with(robot, q, *names):
    """``q`` with the named joints moved back to rest (an IK seed away from the answer)."""
    q = q.copy()
    for n in names:
        q[robot.joint_index(n)] = robot.q_rest[robot.joint_index(n)]
    return q


def test_configuration_checks_names_and_limits(toy):
    with pytest.raises(InputError) as ei:
        toy.configuration({"r_j3": 0.1}, "task.robot_start")
    assert ei.value.field == "task.robot_start.r_j3"
    with pytest.raises(InputError) as ei:
        toy.configuration({"r_j2": 2.6}, "task.robot_start")
    assert ei.value.field == "task.robot_start.r_j2" and "limits" in ei.value.message


# --------------------------------------------------------------------------- default robot


def test_default_robot_dof(robot):
    assert robot.nq == 43
    assert len(set(robot.joint_names)) == 43
    assert {g: len(i) for g, i in robot.groups.items()} == {"torso": 3, "right_arm": 7, "left_arm": 7}
    assert set(robot.hands) == {"right", "left"}
    for side, hand in robot.hands.items():
        assert len(hand.idx) == 13
        assert len(hand.finger_idx) == 4 and len(hand.tip_frames) == 4
        np.testing.assert_array_equal(hand.arm_idx, robot.groups[f"{side}_arm"])
        assert all(robot.joint_names[i].startswith(side[0] + "_") for i in hand.idx)
    # groups and hands partition the joints
    every = np.concatenate([*robot.groups.values(), *(h.idx for h in robot.hands.values())])
    assert sorted(every.tolist()) == list(range(43))


def test_default_rest_is_within_limits(robot):
    assert robot.within_limits(robot.q_rest)
    assert np.all(robot.lower < robot.upper)
    spec_rest = robot.spec.rest
    for name, v in spec_rest.items():
        assert robot.q_rest[robot.joint_index(name)] == pytest.approx(v)
    for hand in robot.hands.values():
        np.testing.assert_allclose(robot.q_rest[hand.idx], hand.open)


def test_sample_is_within_limits_and_keeps_other_joints(robot):
    rng = np.random.default_rng(0)
    idx = robot.groups["left_arm"]
    for _ in range(20):
        q = robot.sample(rng, idx)
        assert robot.within_limits(q)
        others = np.setdiff1d(np.arange(robot.nq), idx)
        np.testing.assert_array_equal(q[others], robot.q_rest[others])
    assert robot.within_limits(robot.sample(rng))


def test_fk_of_unknown_frame(robot):
    with pytest.raises(InputError):
        Kinematics(robot).fk(robot.q_rest, "no_such_link")


# ---------------------------------------------------------------- robot.yaml for real robots

HUMANOID = Path(__file__).resolve().parents[2] / "configs" / "robots" / "humanoid43"


def _humanoid_yaml(tmp_path: Path, edit) -> Path:
    """A copy of the default robot.yaml (its URDF referenced by absolute path), edited."""
    data = yaml.safe_load((HUMANOID / "robot.yaml").read_text())
    data["urdf"] = str(HUMANOID / "robot.urdf")
    edit(data)
    path = tmp_path / "robot.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def test_grasp_frame_as_link_and_offset_matches_the_urdf_frame(robot, tmp_path):
    """r_grasp_frame is a URDF link fixed to r_palm at xyz (0.135, 0, 0.065); given in
    robot.yaml as r_palm plus that offset (and with a turn about z, as a rotated frame
    added to the URDF would be), the grasp frame lands on the same pose."""
    def edit(d):
        d["hands"]["right"]["grasp_frame"] = {"link": "r_palm", "xyz": [0.135, 0, 0.065], "rpy": [0, 0, 0.5]}
    other = load_robot(_humanoid_yaml(tmp_path, edit))
    kin, kin2 = Kinematics(robot), Kinematics(other)
    turn = np.eye(4)
    turn[:3, :3] = rz(0.5)
    for q in (robot.q_rest, robot.sample(np.random.default_rng(3))):
        X = kin.fk(q, robot.hands["right"].grasp_frame) @ turn
        assert np.allclose(kin2.fk(q, other.hands["right"].grasp_frame), X, atol=1e-12)
    # the left hand, given as a plain link, is untouched
    assert other.hands["left"].grasp_frame == robot.hands["left"].grasp_frame


@pytest.mark.parametrize("edit, field", [
    (lambda d: d["hands"]["right"].update(grasp_frame={"link": "no_such_link"}), "hands.right.grasp_frame.link"),
    (lambda d: d["hands"]["right"].update(grasp_frame={"link": "r_palm", "xyz": [0, 0]}), "hands.right.grasp_frame.xyz"),
    (lambda d: d["hands"]["right"].update(grasp_frame={"link": "r_palm", "rot": [0, 0, 0]}), "hands.right.grasp_frame.rot"),
    (lambda d: d["hands"]["right"].update(opposing="pinky"), "hands.right.opposing"),
    (lambda d: d["hands"]["right"].pop("opposing"), "hands.right.opposing"),
])
def test_bad_grasp_frame_or_opposing_finger_is_named(tmp_path, edit, field):
    with pytest.raises(InputError) as e:
        load_robot(_humanoid_yaml(tmp_path, edit))
    assert field in str(e.value)


def test_opposing_finger_is_stated_not_the_first(robot, tmp_path):
    """Listing the thumb last changes nothing once ``opposing`` names it."""
    def edit(d):
        d["hands"]["right"]["fingers"] = d["hands"]["right"]["fingers"][1:] + d["hands"]["right"]["fingers"][:1]
    other = load_robot(_humanoid_yaml(tmp_path, edit))
    h = other.hands["right"]
    assert h.spec.fingers[h.opposing].name == "thumb" and h.opposing == 3
    assert robot.hands["right"].opposing == 0


def test_visual_geometry_is_read_only_when_asked_for(tmp_path):
    """Planning reads the collision geometry alone: a visual mesh that is missing does not
    stop it, and asking for the visual model then gets one error naming the URDF."""
    visual = '<visual><geometry><mesh filename="meshes/gone.stl"/></geometry></visual>'
    urdf = toy_urdf().replace('<link name="torso">', f'<link name="torso">{visual}')
    (tmp_path / "toy.urdf").write_text(urdf)
    (tmp_path / "robot.yaml").write_text(yaml.safe_dump(toy_robot_yaml(Path("toy.urdf"))))
    robot = load_robot(tmp_path / "robot.yaml")
    assert robot.collision_model.ngeoms == 10 and robot.frame_id("r_grasp") >= 0
    with pytest.raises(InputError, match=r"cannot parse URDF .*toy\.urdf") as err:
        robot.visual_model
    assert err.value.field == "urdf"
