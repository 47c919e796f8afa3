"""The shipped Unitree G1 (example-robot-data, a dev dependency): a third-party robot with
scanned mesh links and three-finger hands, configured from its URDF alone."""

from __future__ import annotations

from importlib.resources import files

import coal
import numpy as np
import pytest
import trimesh
import yaml

from regrasp_cli.errors import InputError
from regrasp_cli.model.robot import Kinematics, load_robot

G1 = files("regrasp_cli") / "data/robots/g1/robot.yaml"


@pytest.fixture(scope="module")
def g1():
    return load_robot(str(G1))


def _copy(tmp_path, **changes):
    data = yaml.safe_load(G1.read_text())
    data.update(changes)
    path = tmp_path / "robot.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def test_hands_are_pad_hands_with_the_thumb_opposing(g1):
    for side in ("right", "left"):
        h = g1.hands[side]
        assert h.kind == "pads"  # a 3-joint thumb and two 2-joint fingers
        assert h.spec.fingers[h.opposing].name == "thumb"
        # the grasp frame is the palm link moved 8 cm along its x axis
        kin = Kinematics(g1)
        X_palm = kin.fk(g1.q_rest, f"{side}_hand_palm_link")
        X_G = kin.fk(g1.q_rest, h.grasp_frame)
        assert np.allclose(X_G[:3, :3], X_palm[:3, :3])
        assert np.allclose(X_palm[:3, :3].T @ (X_G[:3, 3] - X_palm[:3, 3]), [0.08, 0, 0], atol=1e-12)


def test_mesh_links_are_checked_as_their_convex_hulls(g1, tmp_path):
    hulls = [go for go in g1.collision_model.geometryObjects if isinstance(go.geometry, coal.ConvexBase)]
    assert len(hulls) > 30 and not any(isinstance(go.geometry, coal.BVHModelBase)
                                       for go in g1.collision_model.geometryObjects)
    meshes = load_robot(_copy(tmp_path, convex_hulls=False))
    by_name = {go.name: go.geometry for go in meshes.collision_model.geometryObjects}
    for go in hulls[:5]:  # each hull holds every vertex of its mesh: free with the hull is free
        mesh = by_name[go.name]
        assert isinstance(mesh, coal.BVHModelBase)
        hull = trimesh.convex.convex_hull(np.asarray(mesh.vertices()))
        V = np.asarray(go.geometry.points())
        assert np.allclose(np.sort(V, axis=0), np.sort(hull.vertices, axis=0))
        assert np.all(hull.contains(np.asarray(mesh.vertices()) * 0.999 + hull.centroid * 0.001))


def test_convex_hulls_must_be_a_boolean(tmp_path):
    with pytest.raises(InputError) as e:
        load_robot(_copy(tmp_path, convex_hulls="yes"))
    assert "convex_hulls" in str(e.value)


def test_the_grasp_search_lets_the_hull_fingertips_touch_the_object(g1):
    """The Dex3 fingertips are convex hulls: shrunk by the contact tolerance, they may
    enter the object by that much and are checked against it with no clearance, while
    every other hand link keeps GraspOptions.link_clearance (with it on the fingertips, no
    grasp of the block closed)."""
    from regrasp_cli.grasp.single import GraspOptions, HandModel

    clearance = GraspOptions().link_clearance
    hm = HandModel(g1, "right", trimesh.creation.box((0.06, 0.06, 0.18)), set(), 0.002, clearance)
    n = len(hm.owner)
    margins = {True: set(), False: set()}
    for k, cp in enumerate(hm.gm.collisionPairs):
        if cp.second == hm.obj:
            margins[bool(hm.is_tip[cp.first])].add(hm.gd.collisionRequests[k].security_margin)
    assert any(hm.is_tip) and [e == 0.002 for e in hm.erosion[:n]] == hm.is_tip  # the tips, eroded
    assert margins == {True: {0.0}, False: {clearance}}
