"""Stable placements on paper-known shapes (placement.stable): a cube rests on any of its 6
faces, an equilateral triangular prism (as long as its side) on its 3 sides and 2 ends, a
cylinder on its 2 caps only (its side rolls); each placement puts the facet on z = 0, the
object above it and the mass centre over the origin."""

from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh
from scipy.spatial.transform import Rotation

from regrasp_cli.placement.stable import PlacementOptions, stable_placements


def _prism(side: float, length: float) -> trimesh.Trimesh:
    tri = [[0.0, 0.0], [side, 0.0], [side / 2, side * math.sqrt(3) / 2]]
    m = trimesh.creation.extrude_polygon(trimesh.path.polygons.Polygon(tri), length)
    m.apply_translation(-m.center_mass)
    return m


def _check_poses(mesh, placements):
    for p in placements:
        v = trimesh.transform_points(mesh.vertices, p.X_SO)
        assert v[:, 2].min() == pytest.approx(0.0, abs=1e-9)  # resting on z = 0, nothing below
        c = p.X_SO[:3, :3] @ mesh.center_mass + p.X_SO[:3, 3]
        assert np.allclose(c, [0.0, 0.0, p.height], atol=1e-9)  # mass centre over the origin
        assert np.allclose(p.X_SO[:3, :3] @ p.normal_O, [0.0, 0.0, -1.0], atol=1e-9)


@pytest.mark.parametrize("seed", range(2))
def test_a_cube_rests_on_its_six_faces(seed):
    cube = trimesh.creation.box(extents=[0.05, 0.05, 0.05])
    cube.apply_transform(trimesh.transformations.rotation_matrix(0.3 + seed, [1.0, 2.0, 0.5]))
    ps = stable_placements(cube, cube.center_mass)
    assert len(ps) == 6
    assert all(p.tipping_angle == pytest.approx(math.pi / 4) for p in ps)  # atan(25 mm / 25 mm)
    normals = np.array([p.normal_O for p in ps])
    assert np.allclose(np.abs(normals @ normals.T) > 0.5, np.eye(6) + (normals @ normals.T < -0.5))  # 3 opposite pairs
    _check_poses(cube, ps)


def test_a_prism_rests_on_its_sides_then_its_ends():
    side = 0.06
    prism = _prism(side, side)
    ps = stable_placements(prism, prism.center_mass)
    assert len(ps) == 5
    # on a side: the mass centre at the inradius, its projection half a side from the long edges
    inradius = side / (2 * math.sqrt(3))
    assert [p.tipping_angle for p in ps[:3]] == pytest.approx([math.atan2(side / 2, inradius)] * 3)
    assert [p.height for p in ps[:3]] == pytest.approx([inradius] * 3)
    # on an end: height half the length, the projection an inradius from the triangle's edges
    assert [p.tipping_angle for p in ps[3:]] == pytest.approx([math.atan2(inradius, side / 2)] * 2)
    _check_poses(prism, ps)


def test_a_cylinder_rests_on_its_caps_and_rolls_on_its_side():
    can = trimesh.creation.cylinder(radius=0.03, height=0.1, sections=48)
    ps = stable_placements(can, can.center_mass)
    assert len(ps) == 2
    assert sorted(abs(p.normal_O[2]) for p in ps) == pytest.approx([1.0, 1.0])
    assert all(p.tipping_angle == pytest.approx(math.atan2(0.03 * math.cos(math.pi / 48), 0.05), abs=1e-6)
               for p in ps)
    # without the margin and the tipping-angle floor the side's facets count too (each a
    # few degrees: the projection is 2 mm from the edges of a facet 4 mm wide)
    every = stable_placements(can, can.center_mass, PlacementOptions(margin=0.0, min_tipping_angle=0.0))
    assert len(every) == 2 + 48 and max(p.tipping_angle for p in every[2:]) < 0.1
    _check_poses(can, ps)


def test_the_mass_centre_decides():
    """A 100 x 40 x 40 mm box whose mass centre is 5 mm from its +x end: on a long face its
    projection is 5 mm from an edge, so with a 6 mm margin only the two ends hold it (20 mm
    from their edges); with 4 mm, all six faces.  Turning the box turns nothing else."""
    box = trimesh.creation.box(extents=[0.1, 0.04, 0.04])
    c = np.array([0.045, 0.0, 0.0])
    ps = stable_placements(box, c, PlacementOptions(margin=0.006, min_tipping_angle=0.0))
    assert sorted(np.round([p.normal_O for p in ps]).astype(int).tolist()) == [[-1, 0, 0], [1, 0, 0]]
    assert ps[0].height == pytest.approx(0.005) and ps[0].margin == pytest.approx(0.02)  # the +x end, most stable
    assert len(stable_placements(box, c, PlacementOptions(margin=0.004, min_tipping_angle=0.0))) == 6
    R = Rotation.random(random_state=0).as_matrix()
    turned = box.copy()
    turned.vertices = box.vertices @ R.T
    assert len(stable_placements(turned, R @ c, PlacementOptions(margin=0.006, min_tipping_angle=0.0))) == 2


def test_a_scanned_box_with_a_bumpy_surface_still_rests_on_its_six_faces():
    """A box whose faces are many triangles, each vertex moved by 0.2 mm (a scan's noise):
    no two hull triangles are coplanar, yet each face is one facet (facet_angle)."""
    rng = np.random.default_rng(0)
    box = trimesh.creation.box(extents=[0.06, 0.05, 0.04]).subdivide().subdivide()
    box.vertices += rng.normal(0.0, 0.0002, box.vertices.shape)
    hull = box.convex_hull
    assert len(hull.facets) == 0 or max(len(f) for f in hull.facets) < 8  # trimesh sees no planar face
    ps = stable_placements(box, box.center_mass)
    assert len(ps) == 6
    downs = np.round([p.normal_O for p in ps]).astype(int)
    assert {tuple(d) for d in downs} == {(1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1)}
