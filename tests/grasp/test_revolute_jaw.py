"""Jaws whose fingers turn, coupled by URDF mimics (issue 41): one joint closes both
fingers, whatever the multiplier (-1 with the fingers' axes alike, 1 with them opposed),
and the pads move on arcs.  On a synthetic gripper whose outcome is known on paper (two
8 cm fingers hinged 4 cm either side of the palm, a pad at each end, open 0.3 rad outwards)
closing on a 4 cm cube: the hand is kind ``jaw``, the jaw coupled and revolute; every grasp
found is force closure with its two contacts on opposite faces of the cube, normals
opposed, and both pads touching the cube (the gripper centred it).  And PR2 as
example-robot-data ships it (a leader and five followers): the same."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh
import yaml

from regrasp_cli.grasp import jaw as J
from regrasp_cli.grasp.single import GraspOptions, HandModel
from regrasp_cli.grasp.surface import build_surface
from regrasp_cli.model.robot import load_robot

CUBE = 0.04  # m
MU = 0.5


def _finger(side: str, y: float, axis: float, mimic: str) -> str:
    inward = -1.0 if y > 0 else 1.0  # the pad's face towards the other finger
    limits = '<limit lower="-0.6" upper="0.3" effort="1" velocity="1"/>' if axis * (1 if y > 0 else -1) > 0 else \
        '<limit lower="-0.3" upper="0.6" effort="1" velocity="1"/>'
    return f"""
  <joint name="{side}_joint" type="revolute">
    <parent link="palm"/><child link="{side}_finger"/>
    <origin xyz="0 {y} 0"/><axis xyz="0 0 {axis}"/>{limits}{mimic}
  </joint>
  <link name="{side}_finger">
    <collision><origin xyz="0.03 0 0"/><geometry><box size="0.04 0.004 0.01"/></geometry></collision>
  </link>
  <joint name="{side}_pad_joint" type="fixed">
    <parent link="{side}_finger"/><child link="{side}_pad"/><origin xyz="0.07 {0.003 * inward} 0"/>
  </joint>
  <link name="{side}_pad">
    <collision><geometry><box size="0.03 0.006 0.02"/></geometry></collision>
  </link>"""


def _gripper(tmp_path: Path, multiplier: int) -> Path:
    """Finger 'a' at y = +4 cm turning about +z (closing: negative angles); finger 'b' at
    -4 cm following it: about +z with multiplier -1, or about -z with multiplier 1."""
    mimic = f'\n    <mimic joint="a_joint" multiplier="{multiplier}" offset="0"/>'
    urdf = f"""<robot name="jaw{multiplier}">
  <link name="palm"><collision><origin xyz="-0.02 0 0"/><geometry><box size="0.02 0.12 0.03"/></geometry></collision></link>
  {_finger("a", 0.04, 1.0, "")}
  {_finger("b", -0.04, -float(multiplier), mimic)}
</robot>"""
    (tmp_path / "jaw.urdf").write_text(urdf)
    spec = {"format": "regrasp.robot/1", "urdf": "jaw.urdf", "groups": {},
            "hands": {"right": {"grasp_frame": "palm", "contact": "soft", "fingers": [
                {"name": "a", "joints": ["a_joint"], "tip_link": "a_pad", "tip_radius": 0.003, "open": [0.3]},
                {"name": "b", "joints": ["b_joint"], "tip_link": "b_pad", "tip_radius": 0.003,
                 "open": [0.3 * multiplier]}]}},
            "rest": {}, "disabled_collisions": [], "convex_hulls": False}
    path = tmp_path / "robot.yaml"
    path.write_text(yaml.safe_dump(spec))
    return path


def _grasps(robot, disabled=frozenset(), frames: int = 120):
    mesh = trimesh.creation.box((CUBE, CUBE, CUBE))
    hm = HandModel(robot, "right", mesh, set(disabled), 0.002)
    jaw = J.jaw_geometry(hm)
    surface = build_surface(mesh, 0.002, np.random.default_rng(0))
    rng = np.random.default_rng(1)
    p1, _, p2, _ = J.antipodal_pairs(mesh, surface, MU, (jaw.width_closed, jaw.width_open), frames, rng)
    X = J.jaw_frames(jaw, p1, p2, rng)
    found = [g for g in (J.jaw_grasp(hm, jaw, surface, X[k], k, MU, 0.035, GraspOptions())[0] for k in range(len(X)))
             if g is not None]
    return hm, jaw, found


def _check(robot, hm, jaw, found) -> None:
    assert robot.hands["right"].kind == "jaw" and jaw.coupled and jaw.revolute
    assert len(found) >= 5, len(found)
    for g in found:
        assert g.scores.is_force_closure
        n0, n1 = g.normals
        assert n0 @ n1 == pytest.approx(-1.0, abs=1e-6)  # opposite faces
        assert np.max(np.abs(n0)) == pytest.approx(1.0, abs=1e-6)  # a face of the cube, not an edge
        k = int(np.argmax(np.abs(n0)))
        assert abs(g.points[0][k]) == pytest.approx(CUBE / 2, abs=1e-4)
        assert abs(g.points[1][k]) == pytest.approx(CUBE / 2, abs=1e-4)
        # both pads touch: the closed hand, the cube at the grasp's frame
        q = hm.q.copy()
        q[robot.hands["right"].idx] = g.finger_q
        hm.set_object(g.X_OG)
        assert max(J._gap(hm, f, robot.coupled(q)) for f in (0, 1)) < 1e-3


@pytest.mark.parametrize("multiplier", [-1, 1])
def test_a_revolute_coupled_jaw_closes_symmetrically_on_a_cube(tmp_path, multiplier):
    robot = load_robot(_gripper(tmp_path, multiplier))
    a, b = (robot.joint_names.index(n) for n in ("a_joint", "b_joint"))
    assert robot.mimic[b] == (a, float(multiplier), 0.0)
    _check(robot, *_grasps(robot))


PR2 = Path(__file__).resolve().parents[2] / "regrasp_cli" / "data" / "robots" / "pr2" / "robot.yaml"


@pytest.mark.filterwarnings("ignore:.*parallel_root_joint")  # PR2's followers of multiplier -1: said at load
def test_pr2_s_stock_gripper_closes_on_a_cube():
    """The shipped PR2 (its fingers' proximal links curl in behind the pads: exact meshes)."""
    robot = load_robot(PR2)
    palm = {"r_gripper_palm_link", "r_gripper_l_finger_link", "r_gripper_r_finger_link"}
    adjacent = {(a, b) for a in palm for b in palm if a < b}  # hinged together: they touch by design
    _check(robot, *_grasps(robot, adjacent))
