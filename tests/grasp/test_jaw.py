"""Parallel-jaw grasps (regrasp_cli.grasp.jaw) on the shipped Baxter (its URDF comes with
example-robot-data, a dev dependency):
the hand kind and the URDF mimic coupling, closing until contact on a box and a cylinder
at frames whose outcome is known on paper, and antipodal sampling."""

from __future__ import annotations

from importlib.resources import files

import numpy as np
import pytest
import trimesh

from regrasp_cli.errors import InputError
from regrasp_cli.grasp import jaw as J
from regrasp_cli.grasp.single import GraspOptions, HandModel
from regrasp_cli.grasp.surface import build_surface
from regrasp_cli.model.robot import load_robot

BAXTER = files("regrasp_cli") / "data/robots/baxter/robot.yaml"
MU = 0.5  # friction angle 26.6 degrees


@pytest.fixture(scope="module")
def baxter():
    return load_robot(str(BAXTER))


def _hand(robot, mesh):
    disabled = {tuple(sorted(p)) for p in robot.spec.srdf_disabled}
    return HandModel(robot, "right", mesh, disabled, 0.002)


def _grasp(robot, mesh, X_OG):
    hm = _hand(robot, mesh)
    jaw = J.jaw_geometry(hm)
    surface = build_surface(mesh, 0.002, np.random.default_rng(0))
    rho = float(np.linalg.norm(mesh.extents) / 2)
    return J.jaw_grasp(hm, jaw, surface, X_OG, 0, MU, rho, GraspOptions()), jaw


def _centred(jaw, p_O) -> np.ndarray:
    """X_OG with G's axes along O's and the pads' midpoint at p_O (3,)."""
    X = np.eye(4)
    X[:3, 3] = np.asarray(p_O) - jaw.centre_G
    return X


def test_baxter_hands_are_coupled_jaws(baxter):
    assert {h.kind for h in baxter.hands.values()} == {"jaw"}
    r = baxter.hands["right"].finger_idx
    lead, follow = int(r[0][0]), int(r[1][0])
    assert baxter.mimic[follow] == (lead, -1.0, 0.0)
    q = baxter.q_rest.copy()
    q[lead], q[follow] = 0.01, 0.0  # the follower's own value is ignored by the kinematics
    assert baxter.to_pin(q)[follow] == pytest.approx(-0.01)
    assert baxter.coupled(q)[follow] == pytest.approx(-0.01)


def test_a_jaw_needs_prismatic_fingers_and_open_values_that_follow_the_mimic(tmp_path, baxter):
    import yaml

    spec = yaml.safe_load(BAXTER.read_text())
    spec["urdf"] = str(baxter.spec.urdf)
    spec["srdf"] = str(baxter.spec.srdf)
    wrong = dict(spec, hands=dict(spec["hands"]))
    fingers = [dict(f) for f in spec["hands"]["right"]["fingers"]]
    fingers[1]["open"] = [-0.01]
    wrong["hands"]["right"] = dict(spec["hands"]["right"], fingers=fingers)
    path = tmp_path / "robot.yaml"
    path.write_text(yaml.safe_dump(wrong))
    with pytest.raises(InputError, match="mimic"):
        load_robot(path)


def test_jaw_geometry_of_baxter(baxter):
    jaw = J.jaw_geometry(_hand(baxter, trimesh.creation.box((0.04, 0.04, 0.12))))
    assert jaw.coupled
    assert np.allclose(jaw.closing_G[0], -jaw.closing_G[1], atol=1e-9)
    assert abs(jaw.axis_G @ jaw.depth_G) < 1e-9
    # the pads: 4.8 cm apart open, 1.5 cm closed (two 2.08 cm strokes)
    assert jaw.width_open - jaw.width_closed == pytest.approx(jaw.travel.sum(), abs=1e-6)
    assert 0.045 < jaw.width_open < 0.05


def test_a_box_between_the_pads_is_held_by_its_faces(baxter):
    """A 4 cm box centred between the pads, faces across the axis: each pad slides
    (4.8 - 4) / 2 cm to the face, the contacts are the faces' middles with opposite
    normals, a force-closure grasp."""
    box = trimesh.creation.box((0.04, 0.04, 0.12))
    hm = _hand(baxter, box)
    jaw = J.jaw_geometry(hm)
    (g, stats), _ = _grasp(baxter, box, _centred(jaw, [0.0, 0.0, -0.04]))
    assert g is not None, stats
    assert g.scores.is_force_closure
    idx = [int(i[0]) for i in baxter.hands["right"].finger_idx]
    stroke = np.abs(g.finger_q - baxter.hands["right"].open)
    assert stroke == pytest.approx([(jaw.width_open - 0.04) / 2] * 2, abs=2e-4)
    assert np.allclose(np.abs(g.points[:, 1]), 0.02, atol=1e-3)  # on the faces y = +-2 cm
    assert g.normals[0] @ g.normals[1] == pytest.approx(-1.0, abs=1e-3)
    assert baxter.coupled(baxter.q_rest)[idx[1]] == baxter.q_rest[idx[1]]


def test_an_off_centre_box_is_centred_by_the_coupled_jaw(baxter):
    """2 mm towards one pad (4 mm of clearance left on that side), the box is still held
    at both faces: the hand shifts 2 mm (the gripper centres what it closes on)."""
    box = trimesh.creation.box((0.04, 0.04, 0.12))
    jaw = J.jaw_geometry(_hand(baxter, box))
    X = _centred(jaw, [0.0, 0.002, -0.04])
    (g, stats), _ = _grasp(baxter, box, X)
    assert g is not None and g.scores.is_force_closure, stats
    assert g.X_OG[:3, 3] - X[:3, 3] == pytest.approx([0.0, -0.002, 0.0], abs=2e-4)


@pytest.mark.parametrize("lean, closure", [(10.0, True), (40.0, False)])
def test_a_cylinder_held_off_its_axis(baxter, lean, closure):
    """A 2 cm-radius cylinder along Baxter's rod-shaped pads (radius rho), the jaw's axis
    at d from the cylinder's: the contact normal lies along the line joining the two axes,
    leaning asin(d / (r + rho)) from the jaw's axis.  Inside the 26.6-degree friction cone
    (10 degrees) the two soft contacts are force closure; outside (40 degrees) not."""
    r = 0.02
    cyl = trimesh.creation.cylinder(radius=r, height=0.12, sections=192)
    hm = _hand(baxter, cyl)
    jaw = J.jaw_geometry(hm)
    tip = next(a for a, o in enumerate(hm.owner) if o == 0 and hm.erosion[a] > 0)
    rho = hm.gm.geometryObjects[tip].geometry.radius + hm.erosion[tip]
    d = (r + rho) * np.sin(np.radians(lean))
    (g, stats), _ = _grasp(baxter, cyl, _centred(jaw, [d, 0.0, -0.04]))
    if closure:
        assert g is not None and g.scores.is_force_closure, stats
        found = np.degrees(np.arccos(np.abs(g.normals[:, 1])))
        assert found == pytest.approx([lean, lean], abs=2.0)
    else:
        assert g is None and stats["not_force_closure"] == 1, stats


def test_a_box_wider_than_the_open_jaw_gives_no_grasp(baxter):
    box = trimesh.creation.box((0.06, 0.06, 0.12))
    jaw = J.jaw_geometry(_hand(baxter, box))
    (g, stats), _ = _grasp(baxter, box, _centred(jaw, [0.0, 0.0, -0.04]))
    assert g is None and stats["few_contacts"] == 1


def test_antipodal_pairs_of_a_box_lie_across_opposite_faces(baxter):
    box = trimesh.creation.box((0.04, 0.04, 0.12))
    surface = build_surface(box, 0.004, np.random.default_rng(1))
    p1, n1, p2, n2 = J.antipodal_pairs(box, surface, MU, (0.015, 0.048), 800, np.random.default_rng(2))
    assert len(p1) > 50
    u = (p2 - p1) / np.linalg.norm(p2 - p1, axis=1, keepdims=True)
    cone = np.cos(np.arctan(MU))
    assert np.all(-np.einsum("ij,ij->i", u, n1) >= cone - 1e-9)
    assert np.all(np.einsum("ij,ij->i", u, n2) >= cone - 1e-9)
    # only the 4 cm faces fit: the pairs join x = +-2 cm or y = +-2 cm, never the ends
    assert np.allclose(np.linalg.norm(p2 - p1, axis=1), 0.04, atol=0.04 * (1 / cone - 1) + 1e-6)
    assert np.all(np.abs(n1[:, 2]) < 1e-6)


def test_validator_measures_a_contact_from_the_pad_surface(baxter):
    """regrasp validate checks a jaw's contact against the finger's pads (anywhere on
    them), not a fingertip point: a point 5 mm off a pad box's face reads 5 mm; one on
    the face reads 0."""
    import pinocchio as pin

    from regrasp_cli.validate import _finger_distance

    hand = baxter.hands["right"]
    data = baxter.model.createData()
    pin.forwardKinematics(baxter.model, data, baxter.to_pin(baxter.q_rest))
    joint = baxter.model.getJointId(baxter.joint_names[hand.finger_idx[0][0]])
    box = next(go for go in baxter.collision_model.geometryObjects
               if go.parentJoint == joint and type(go.geometry).__name__ == "Box")
    X = (data.oMi[joint] * box.placement).homogeneous
    half = np.asarray(box.geometry.halfSide)
    for gap in (0.0, 0.005):
        p_W = X[:3, :3] @ np.array([half[0] + gap, 0.0, 0.0]) + X[:3, 3]
        d = _finger_distance(baxter, hand, 0, baxter.q_rest, p_W)
        if gap == 0.0:
            assert d < 1e-6
        else:  # at most the gap (another geometry of the finger could be nearer), never on it
            assert 1e-3 < d <= gap + 1e-6
