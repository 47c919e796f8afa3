"""Grasps of two-joint fingers by approach and closing (regrasp_cli.grasp.pads), on a toy
planar gripper whose outcome is known on paper: two fingers of two revolute joints (axes
along z) face each other across y; closing turns each finger towards the other, both
joints together, so a finger's links lean by their joint angles when they touch.

* A box between the fingers: both touch its two y faces, normals +-y, mirror-image
  points: two opposite soft contacts, force closure.
* A cylinder (axis z): a straight link touches a circle where the circle's normal is the
  link's normal, so the contact normal leans from the y axis by the touching link's
  angle.  A wide cylinder is touched at a small lean (force closure, inside the 26.6
  degree friction cone of mu = 0.5); a thin one only once the fingers have turned far
  (no force closure).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
import trimesh
import yaml

from regrasp_cli.grasp import pads as P
from regrasp_cli.grasp.single import GraspOptions, HandModel
from regrasp_cli.grasp.surface import build_surface
from regrasp_cli.model.robot import load_robot
from regrasp_cli.model.selfcollision import disabled_pairs

MU = 0.5
FINGER_Y = 0.05  # m: the fingers' first joints at y = +-FINGER_Y
PROXIMAL, DISTAL, THICK = 0.05, 0.04, 0.01  # m: link lengths along x, link thickness in y

_INERTIAL = ('<inertial><mass value="0.1"/><origin xyz="0 0 0"/>'
             '<inertia ixx="1e-4" ixy="0" ixz="0" iyy="1e-4" iyz="0" izz="1e-4"/></inertial>')


def _link(name, size=None, centre="0 0 0"):
    col = (f'<collision><origin xyz="{centre}" rpy="0 0 0"/><geometry><box size="{size}"/></geometry></collision>'
           if size else "")
    return f'<link name="{name}">{_INERTIAL}{col}</link>'


def _joint(name, kind, parent, child, xyz, lower=-1.0, upper=1.0):
    limit = f'<axis xyz="0 0 1"/><limit lower="{lower}" upper="{upper}" effort="1" velocity="1"/>' \
        if kind == "revolute" else ""
    return (f'<joint name="{name}" type="{kind}"><parent link="{parent}"/><child link="{child}"/>'
            f'<origin xyz="{xyz}" rpy="0 0 0"/>{limit}</joint>')


def _urdf() -> str:
    parts = [_link("base"), _link("torso"), _joint("waist", "revolute", "base", "torso", "0 0 0")]
    for s, y in (("r", -1.0), ("l", 1.0)):
        parts += [_joint(f"{s}_j1", "revolute", "torso", f"{s}_palm", f"0.5 {y} 0"),
                  _link(f"{s}_palm", "0.02 0.12 0.04", "-0.01 0 0"),
                  _joint(f"{s}_g", "fixed", f"{s}_palm", f"{s}_grasp", "0 0 0"), _link(f"{s}_grasp")]
        for f, side, lo, hi in (("a", 1.0, -1.5, 0.2), ("b", -1.0, -0.2, 1.5)):
            parts += [_joint(f"{s}_{f}1", "revolute", f"{s}_palm", f"{s}_{f}1", f"0 {side * FINGER_Y} 0", lo, hi),
                      _link(f"{s}_{f}1", f"{PROXIMAL} {THICK} 0.02", f"{PROXIMAL / 2} 0 0"),
                      _joint(f"{s}_{f}2", "revolute", f"{s}_{f}1", f"{s}_{f}2", f"{PROXIMAL} 0 0", lo, hi),
                      _link(f"{s}_{f}2", f"{DISTAL} {THICK} 0.02", f"{DISTAL / 2} 0 0")]
    return '<?xml version="1.0"?>\n<robot name="gripper">\n' + "\n".join(parts) + "\n</robot>\n"


@pytest.fixture(scope="module")
def gripper(tmp_path_factory):
    d = tmp_path_factory.mktemp("gripper")
    (d / "gripper.urdf").write_text(_urdf())

    def hand(s):
        return {"grasp_frame": f"{s}_grasp", "contact": "soft", "fingers": [
            {"name": "a", "joints": [f"{s}_a1", f"{s}_a2"], "tip_link": f"{s}_a2", "tip_radius": 0.005,
             "closed": [-1.2, -1.2]},
            {"name": "b", "joints": [f"{s}_b1", f"{s}_b2"], "tip_link": f"{s}_b2", "tip_radius": 0.005,
             "closed": [1.2, 1.2]}]}

    spec = {"format": "regrasp.robot/1", "urdf": "gripper.urdf",
            "groups": {"torso": ["waist"], "right_arm": ["r_j1"], "left_arm": ["l_j1"]},
            "hands": {"right": hand("r"), "left": hand("l")}, "rest": {}, "disabled_collisions": [],
            "self_collision": {"samples": 20, "seed": 0, "never_margin": 0.02}}
    (d / "robot.yaml").write_text(yaml.safe_dump(spec))
    return load_robot(d / "robot.yaml")


def _grasp(robot, mesh, centre_G):
    """The grasp with the object's frame at ``centre_G`` (3,) in the grasp frame."""
    # the adjacent links (palm-proximal, proximal-distal) always touch: their pairs are off
    disabled = {tuple(sorted(p)) for s in "rl" for f in "ab"
                for p in ((f"{s}_palm", f"{s}_{f}1"), (f"{s}_{f}1", f"{s}_{f}2"))}
    hm = HandModel(robot, "right", mesh, disabled, 0.002)
    pads = P.pad_geometry(hm)
    surface = build_surface(mesh, 0.001, np.random.default_rng(0))
    X_OG = np.eye(4)
    X_OG[:3, 3] = -np.asarray(centre_G)
    rho = float(np.linalg.norm(mesh.extents) / 2)
    return P.pad_grasp(hm, pads, surface, X_OG, 0, MU, rho, GraspOptions()), hm, pads


def test_the_toy_hand_is_a_pad_hand(gripper):
    h = gripper.hands["right"]
    assert h.kind == "pads"
    hm = HandModel(gripper, "right", trimesh.creation.box((0.01, 0.01, 0.01)), set(), 0.002)
    pads = P.pad_geometry(hm)
    assert np.allclose(pads.closed, [-1.2, -1.2, 1.2, 1.2])
    # the grasp side is +x, in front of the palm, between the fingers
    assert pads.approach_G[0] > 0.9 and abs(pads.approach_G[1]) < 1e-6
    # reach bound: 1.2 rad on each joint, the farthest points of the links from each joint
    assert pads.reach[0] >= 1.2 * (PROXIMAL + DISTAL) + 1.2 * DISTAL


def test_box_between_two_joint_fingers_is_held_by_its_faces(gripper):
    box = trimesh.creation.box((0.12, 0.05, 0.04))
    (grasp, stats), hm, pads = _grasp(gripper, box, (0.065, 0.0, 0.0))
    assert grasp is not None, stats
    assert grasp.in_contact.all()
    n = grasp.normals
    assert np.allclose(np.abs(n[:, 1]), 1.0, atol=1e-6) and n[0, 1] * n[1, 1] < 0
    p = grasp.points
    assert np.allclose(np.abs(p[:, 1]), 0.025, atol=1e-6)  # on the y faces
    assert np.allclose(p[0] * [1, -1, 1], p[1], atol=2e-3)  # mirror images
    assert grasp.scores.is_force_closure
    # the fingers stopped at contact: closer than 1 mm, not inside
    q = hm.q.copy()
    q[hm.hand.idx] = grasp.finger_q
    pin.updateGeometryPlacements(gripper.model, hm.data, hm.gm, hm.gd, gripper.to_pin(q))
    for f in (0, 1):
        assert 0 <= P._finger_gap(hm, f)[0] < P.PAD_CONTACT
    assert not hm.collides(q, {0, 1}, None)


@pytest.mark.parametrize("radius, closure", [(0.03, True), (0.008, False)])
def test_cylinder_contact_normals_lean_by_the_link_angle(gripper, radius, closure):
    cyl = trimesh.creation.cylinder(radius=radius, height=0.04, sections=256)
    centre = np.array([0.03 + radius, 0.0, 0.0])
    (grasp, stats), hm, pads = _grasp(gripper, cyl, centre)
    assert (grasp is not None) == closure, stats
    # where each finger touches, from the closing alone
    X_OG = np.eye(4)
    X_OG[:3, 3] = -centre
    X_OG, q, touching = P.close_fingers(hm, pads, X_OG)
    assert touching.all()
    pin.updateGeometryPlacements(gripper.model, hm.data, hm.gm, hm.gd, gripper.to_pin(q))
    X_OW = X_OG @ np.linalg.inv(hm.X_WG)
    leans = []
    for f in (0, 1):
        k = P._finger_gap(hm, f)[1]
        w = X_OW[:3, :3] @ pin.computeDistance(hm.gm, hm.gd, k).getNearestPoint2() + X_OW[:3, 3]
        n = w[:2] / np.linalg.norm(w[:2])  # the cylinder's normal there
        lean = np.degrees(np.arctan2(abs(n[0]), abs(n[1])))
        q1, q2 = q[hm.hand.finger_idx[f]]
        # a straight link touches the circle where the circle's normal is the link's
        assert min(abs(lean - np.degrees(abs(q1))), abs(lean - np.degrees(abs(q1 + q2)))) < 3.0
        leans.append(lean)
    assert (max(leans) < np.degrees(np.arctan(MU))) == closure
    if grasp is not None:  # the stored normals are the same, mirror images of each other
        lean_stored = np.degrees(np.arctan2(np.abs(grasp.normals[:, 0]), np.abs(grasp.normals[:, 1])))
        assert np.allclose(lean_stored, leans, atol=3.0)


ALEX = Path(__file__).resolve().parents[2] / "regrasp_cli" / "data" / "robots" / "alex" / "robot.yaml"


@pytest.mark.filterwarnings("ignore:.*mimic names joint")  # the stock URDF's, said at load (tests/model/test_mimic.py)
def test_alex_s_stock_five_finger_hand_holds_a_can(tmp_path):
    """The shipped Alex: PSYONIC hands of a thumb and four fingers of two joints each, from
    the stock URDF.  Approach frames on a can (2 cm radius) give force-closure grasps with
    the thumb opposing the fingers in some, every contact on the can's side or ends, and
    the closed hand clear of the can."""
    robot = load_robot(ALEX)
    h = robot.hands["right"]
    assert h.kind == "pads" and len(h.finger_idx) == 5
    can = trimesh.creation.cylinder(radius=0.02, height=0.11, sections=32)
    hm = HandModel(robot, "right", can, disabled_pairs(robot, tmp_path).links(), 0.002)
    pads = P.pad_geometry(hm)
    rng = np.random.default_rng(0)
    surface = build_surface(can, 0.002, rng)
    frames = P.pad_frames(pads, can, surface, 200, rng)
    grasps = [g for i, X in enumerate(frames)
              if (g := P.pad_grasp(hm, pads, surface, X, i, 0.6, 0.06, GraspOptions())[0]) is not None]
    assert len(grasps) >= 3 and any(g.in_contact[h.opposing] for g in grasps), [g.in_contact for g in grasps]
    for g in grasps:
        assert g.scores.epsilon > 0 and g.in_contact.sum() >= 2
        p = g.points[g.in_contact]
        side = np.abs(np.hypot(p[:, 0], p[:, 1]) - 0.02) < 2e-3
        ends = np.abs(np.abs(p[:, 2]) - 0.055) < 2e-3
        assert np.all(side | ends)
        q = hm.q.copy()
        q[h.idx] = g.finger_q
        hm.set_object(g.X_OG)
        assert not hm.collides(q, set(range(5)), None)
