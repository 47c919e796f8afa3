"""Contact paths on a polyhedral surface (seed 003 §VI): the geodesic between points on
two faces of a cube has the length of the straight line on the unfolded net, crosses the
shared edge where the net says, and stays on the surface; contacts on one triangle are
joined by their segment; sampling is uniform by area and ``locate`` inverts ``points``."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from regrasp_cli.dexterous.surface import MeshSurface, along, geodesic, length

CUBE = MeshSurface.of(trimesh.creation.box(extents=[0.06, 0.06, 0.06]))


def _contact(p):
    tri, uv = CUBE.locate(np.atleast_2d(p))
    return tri[0], uv[0]


@pytest.mark.parametrize("a, b, unfolded", [
    # +x face to +y face across the edge x = y = 0.03: +y face turned into the plane x = 0.03
    ((0.03, 0.01, 0.004), (-0.009, 0.03, -0.012), (0.03, 0.03 + 0.039, -0.012)),
    # +z face to -x face across the edge x = -0.03, z = 0.03
    ((0.02, -0.01, 0.03), (-0.03, 0.015, 0.0), (-0.03 - 0.03, 0.015, 0.03)),
])
def test_the_geodesic_on_a_cube_is_the_straight_line_of_the_unfolded_net(a, b, unfolded):
    (ta, ua), (tb, ub) = _contact(a), _contact(b)
    path = geodesic(CUBE, (ta, tb), (ua, ub))
    assert np.allclose(path[0], a, atol=1e-7) and np.allclose(path[-1], b, atol=1e-7)
    assert length(path) == pytest.approx(np.linalg.norm(np.subtract(unfolded, a)), rel=1e-6)
    # every point on the cube's surface: one coordinate at +-0.03, the others within
    assert np.all(np.isclose(np.abs(path), 0.03, atol=1e-9).any(axis=1))
    assert np.all(np.abs(path) <= 0.03 + 1e-9)


def test_the_geodesic_on_one_triangle_is_its_segment():
    tri, uv = CUBE.sample(np.random.default_rng(0), 1)
    uv2 = np.clip(uv[0] + [0.05, -0.02], 0.01, None)
    path = geodesic(CUBE, (tri[0], tri[0]), (uv[0], uv2))
    assert len(path) == 2 and length(path) == pytest.approx(np.linalg.norm(path[1] - path[0]))


def test_sampling_is_uniform_by_area_and_locate_inverts_points():
    mesh = trimesh.creation.box(extents=[0.02, 0.04, 0.08])
    s = MeshSurface.of(mesh)
    tri, uv = s.sample(np.random.default_rng(1), 4000)
    p = s.points(tri, uv)
    assert np.allclose(np.abs(mesh.nearest.signed_distance(p)), 0, atol=1e-9)
    # the 0.04 x 0.08 faces (x = +-0.01) hold 0.0064 / 0.0112 of the area
    share = np.mean(np.isclose(np.abs(p[:, 0]), 0.01))
    assert share == pytest.approx(0.0064 / 0.0112, abs=0.03)
    tri2, uv2 = s.locate(p[:50])
    assert np.allclose(s.points(tri2, uv2), p[:50], atol=1e-9)


def test_points_along_a_path_by_arc_length():
    path = np.array([[0, 0, 0], [1, 0, 0], [1, 2, 0]], float)
    q = along(path, np.array([0.0, 0.5, 1.0]))
    assert np.allclose(q, [[0, 0, 0], [1, 0.5, 0], [1, 2, 0]])


@pytest.mark.parametrize("mesh", [trimesh.creation.box(extents=[0.06, 0.06, 0.06]),
                                  trimesh.creation.icosphere(subdivisions=3, radius=0.035)],
                         ids=["cube", "sphere"])
def test_locate_finds_the_nearest_triangle_as_trimesh_does_on_edges_and_vertices_too(mesh):
    """``locate`` keeps its own vertex tree; where a point is as near two triangles (on an
    edge, over a vertex) it must give trimesh's answer, or plans would change in the last
    bits: points on the surface, off it, on edges, at vertices and over them, one by one
    and together."""
    s = MeshSurface.of(mesh)
    rng = np.random.default_rng(0)
    tri, uv = s.sample(rng, 200)
    on = s.points(tri, uv)
    for p in (on, on + 0.01 * rng.normal(size=on.shape), 0.5 * (s.V[s.F[tri, 0]] + s.V[s.F[tri, 1]]), s.V,
              s.V[s.F[tri, 2]] + 0.01 * s.normals[tri]):
        expected = trimesh.proximity.closest_point(s.mesh, p)[2]
        assert np.array_equal(s.locate(p)[0], expected)
        assert np.array_equal(np.concatenate([s.locate(p[k:k + 3])[0] for k in range(0, len(p), 3)]), expected)
    assert s.locate(np.zeros((0, 3)))[0].size == 0
