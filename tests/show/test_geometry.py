"""Shapes to draw, on the default robot and on tiny inputs with exact answers: link
shapes where pinocchio places the geometry, primitives of their nominal size, the hand's
links, triangles cut or meshes coarsened without changing what is seen."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
import trimesh

from regrasp_cli.model.robot import Kinematics
from regrasp_cli.show.geometry import Shape, decimate, hand_links, link_poses, robot_links, shape_triangles, subdivide


def _area(tri: np.ndarray) -> float:
    return float(np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1).sum() / 2)


# ------------------------------------------------------------------ shapes


@pytest.mark.parametrize("source", ["visual", "collision"])
def test_link_shapes_are_where_pinocchio_puts_the_geometry(robot, source):
    """X_WL @ X_LS equals pinocchio's own geometry placement, at random configurations."""
    gmodel = robot.visual_model if source == "visual" else robot.collision_model
    links = robot_links(robot, source)
    assert sum(len(ls.shapes) for ls in links) == len(gmodel.geometryObjects)
    gdata = pin.GeometryData(gmodel)
    data = robot.model.createData()
    rng = np.random.default_rng(3)
    for _ in range(3):
        q = robot.sample(rng)
        pin.forwardKinematics(robot.model, data, robot.to_pin(q))
        pin.updateGeometryPlacements(robot.model, data, gmodel, gdata)
        for ls, X_WL in zip(links, link_poses(Kinematics(robot), links, q)):
            for s in ls.shapes:
                X_WS = gdata.oMg[gmodel.getGeometryId(s.name)].homogeneous
                np.testing.assert_allclose(X_WL @ s.X_PS, X_WS, atol=1e-12)


def test_primitive_triangles_fit_their_size():
    """Triangulated primitives span their nominal extents (cylinders and capsules along z)."""
    cases = [(Shape("b", "box", (0.1, 0.2, 0.3), np.eye(4), (1, 1, 1, 1)), [0.1, 0.2, 0.3]),
             (Shape("s", "sphere", (0.05,), np.eye(4), (1, 1, 1, 1)), [0.1, 0.1, 0.1]),
             (Shape("c", "cylinder", (0.05, 0.3), np.eye(4), (1, 1, 1, 1)), [0.1, 0.1, 0.3]),
             (Shape("k", "capsule", (0.05, 0.3), np.eye(4), (1, 1, 1, 1)), [0.1, 0.1, 0.4])]
    for shape, extents in cases:
        p = shape_triangles(shape).reshape(-1, 3)
        np.testing.assert_allclose(p.max(axis=0) - p.min(axis=0), extents, atol=6e-3, err_msg=shape.kind)
        np.testing.assert_allclose(p.max(axis=0) + p.min(axis=0), 0.0, atol=1e-9, err_msg=shape.kind)


def test_subdivide_keeps_the_surface_and_bounds_the_edges():
    tri = np.array([[[0, 0, 0], [1.0, 0, 0], [0, 2.0, 0]], [[0, 0, 1.0], [0.05, 0, 1], [0, 0.05, 1]]])
    out = subdivide(tri, 0.3)
    edges = np.linalg.norm(out - np.roll(out, -1, axis=1), axis=2)
    assert edges.max() <= 0.3
    assert _area(out) == pytest.approx(_area(tri), rel=1e-12)
    assert any(np.allclose(t, tri[1]) for t in out)  # a small triangle is kept as it is
    with pytest.raises(ValueError):
        subdivide(tri, 0.0)


def test_hand_links_are_the_palm_and_fingers(robot):
    links = robot_links(robot)
    for side, other in (("right", "left"), ("left", "right")):
        names = {ls.link for ls in hand_links(robot, links, side)}
        for finger in robot.hands[side].spec.fingers:
            assert finger.tip_link in names
        assert not any(f.tip_link in names for f in robot.hands[other].spec.fingers)
        assert not any("torso" in n for n in names)


def test_decimate_coarsens_a_fine_mesh_and_keeps_its_shape():
    sphere = trimesh.creation.icosphere(subdivisions=5, radius=0.1)  # 20480 faces
    v, f = decimate(sphere.vertices, sphere.faces, 2000)
    assert 100 < len(f) <= 2000
    assert f.min() >= 0 and f.max() < len(v)
    r = np.linalg.norm(v, axis=1)
    assert np.all(np.abs(r - 0.1) < 0.01)  # every vertex still near the surface
    coarse = trimesh.Trimesh(v, f)
    assert coarse.area == pytest.approx(sphere.area, rel=0.1)
    small_v, small_f = decimate(sphere.vertices, sphere.faces, 10**6)  # small enough: untouched
    assert np.array_equal(small_v, sphere.vertices) and np.array_equal(small_f, sphere.faces)
