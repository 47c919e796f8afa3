"""Sampled object surface (regrasp_cli.grasp.surface): sampling density, outward normals,
curvature, mass centre, determinism, kd-tree, bad input.  Self-contained meshes only."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import trimesh

from regrasp_cli.errors import InputError
from regrasp_cli.grasp.surface import Surface, build_surface, sampling_step

BOX_EXTENTS = np.array([0.1, 0.06, 0.04])


def _build(mesh, step, seed=0) -> Surface:
    return build_surface(mesh, step, np.random.default_rng(seed))


@pytest.fixture(scope="module")
def sphere() -> trimesh.Trimesh:
    return trimesh.creation.icosphere(subdivisions=3, radius=0.05)


@pytest.fixture(scope="module")
def sphere_surface(sphere) -> Surface:
    with warnings.catch_warnings():
        warnings.simplefilter("error", UserWarning)  # watertight: no mass-centre warning
        return _build(sphere, 0.005)


@pytest.fixture(scope="module")
def box() -> trimesh.Trimesh:
    return trimesh.creation.box(extents=BOX_EXTENTS)


def _broken_box(box: trimesh.Trimesh, removed: int = 3) -> tuple[trimesh.Trimesh, np.ndarray]:
    """The box with every other triangle's winding inverted and triangle ``removed``
    deleted; also returns the box's true outward normal of each remaining face."""
    faces = box.faces.copy()
    faces[::2] = faces[::2, ::-1]
    keep = np.delete(np.arange(len(faces)), removed)
    broken = trimesh.Trimesh(box.vertices.copy(), faces[keep], process=False)
    return broken, np.asarray(box.face_normals)[keep]


# --------------------------------------------------------------------------- sphere


def test_sphere_sample_count_follows_area_over_step_squared(sphere, sphere_surface):
    s = sphere_surface
    expected = sphere.area / 0.005**2
    assert abs(len(s) - expected) <= 0.3 * expected
    assert s.points.shape == (len(s), 3)
    assert s.normals.shape == (len(s), 3)
    assert s.curvature.shape == (len(s),)
    assert s.face_index.shape == (len(s),)
    assert s.step == 0.005
    assert s.watertight


def test_sphere_samples_lie_on_the_surface_and_cover_it(sphere_surface):
    r = np.linalg.norm(sphere_surface.points, axis=1)
    assert np.all(np.abs(r - 0.05) < 0.002)  # facets of the icosphere are within 1 mm
    # evenly spread: every sample has a neighbour within ~1.5 steps, none closer than 0.6
    d, _ = sphere_surface.tree.query(sphere_surface.points, k=2)
    assert d[:, 1].max() < 1.6 * 0.005
    assert d[:, 1].min() >= 0.6 * 0.005 - 1e-12


def test_sphere_normals_are_unit_and_radial_outward(sphere_surface):
    s = sphere_surface
    np.testing.assert_allclose(np.linalg.norm(s.normals, axis=1), 1.0, atol=1e-9)
    radial = s.points / np.linalg.norm(s.points, axis=1, keepdims=True)
    assert np.all(np.einsum("ij,ij->i", s.normals, radial) > 0.95)


def test_sphere_mass_centre_is_the_origin(sphere_surface):
    np.testing.assert_allclose(sphere_surface.mass_centre, 0.0, atol=1e-6)


def test_sphere_curvature_is_nearly_uniform(sphere_surface):
    c = sphere_surface.curvature
    assert c.min() >= 0.0 and c.max() <= 1.0
    assert c.std() < 0.2
    assert np.median(c) > 0.5  # curved everywhere: nothing looks flat


def test_arrays_are_read_only(sphere_surface):
    with pytest.raises(ValueError):
        sphere_surface.points[0, 0] = 1.0
    with pytest.raises(ValueError):
        sphere_surface.normals[0, 0] = 1.0


# --------------------------------------------------------------------------- box


def test_box_flat_faces_have_low_curvature_edges_high(box):
    step = 0.004
    s = _build(box, step)
    gap = BOX_EXTENTS / 2.0 - np.abs(s.points)  # one ~0 (the face the sample is on)
    to_edge = np.sort(gap, axis=1)[:, 1]  # distance to the nearest edge of that face
    near_edge = to_edge < step
    flat = to_edge > 3.0 * step
    assert near_edge.sum() > 50 and flat.sum() > 50
    assert np.median(s.curvature[flat]) < 0.05
    assert np.median(s.curvature[near_edge]) > 0.5
    assert np.median(s.curvature[near_edge]) > np.median(s.curvature[flat]) + 0.4


def test_box_normals_are_the_face_normals(box):
    s = _build(box, 0.005)
    truth = np.asarray(box.face_normals)[s.face_index]
    assert np.all(np.einsum("ij,ij->i", truth, s.normals) > 0.999)
    np.testing.assert_allclose(s.mass_centre, 0.0, atol=1e-9)


def test_inverted_watertight_mesh_gets_outward_normals(box):
    inverted = box.copy()
    inverted.invert()
    s = _build(inverted, 0.005)
    assert s.watertight
    truth = np.asarray(box.face_normals)[s.face_index]
    assert np.all(np.einsum("ij,ij->i", truth, s.normals) > 0.999)
    assert not np.allclose(inverted.face_normals, box.face_normals)  # input untouched


@pytest.mark.parametrize("removed", [0, 3, 8])
def test_open_mesh_with_inconsistent_winding_gets_outward_normals(box, removed):
    broken, true_normals = _broken_box(box, removed)
    assert not broken.is_watertight and not broken.is_winding_consistent
    faces_before = broken.faces.copy()
    with pytest.warns(UserWarning, match="mass centre"):
        s = _build(broken, 0.004, seed=removed)
    assert not s.watertight
    np.testing.assert_array_equal(broken.faces, faces_before)  # input untouched
    truth = true_normals[s.face_index]
    outward = np.einsum("ij,ij->i", truth, s.normals) > 0.99
    assert outward.mean() >= 0.95
    # area-weighted surface centroid: near the box centre, shifted away from the hole
    assert np.linalg.norm(s.mass_centre) < 0.01


def test_a_few_samples_of_each_patch_vote_on_its_side(box):
    """A patch of consistent winding larger than VOTERS_PER_PATCH samples is oriented by
    its first voters alone: the normals are as outward as with every sample voting."""
    from regrasp_cli.grasp import surface as surface_module

    patch = np.array([2, 0, 2, 1, 2, 0, 2, 2])
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(surface_module, "VOTERS_PER_PATCH", 2)
        np.testing.assert_array_equal(surface_module._voters(patch), [0, 1, 2, 3, 5])
        broken, true_normals = _broken_box(box, 3)
        with pytest.warns(UserWarning, match="mass centre"):
            s = _build(broken, 0.004, seed=3)
    assert len(s) > 20 * 2 * len(broken.faces)  # patches of a few faces: far more samples than the 2 voters each
    outward = np.einsum("ij,ij->i", true_normals[s.face_index], s.normals) > 0.99
    assert outward.mean() >= 0.95


def test_a_finer_surface_takes_the_faces_orientation_of_a_coarser_one(box):
    """The pinch passes' surface (half the step) reads the grid surface's face orientation
    instead of casting rays again: its normals are as outward as the coarse one's."""
    broken, true_normals = _broken_box(box, 3)
    with pytest.warns(UserWarning, match="mass centre"):
        coarse = _build(broken, 0.008, seed=3)
        fine = build_surface(broken, 0.004, np.random.default_rng(4), like=coarse)
    assert len(fine) > 3 * len(coarse)
    np.testing.assert_array_equal(fine.face_flip, coarse.face_flip)
    outward = np.einsum("ij,ij->i", true_normals[fine.face_index], fine.normals) > 0.99
    assert outward.mean() >= 0.95


def test_triangle_soup_is_merged_and_treated_as_watertight(box):
    # every triangle stored separately (as in STL files), random windings
    faces = box.faces.copy()
    flip = np.random.default_rng(1).random(len(faces)) < 0.5
    faces[flip] = faces[flip, ::-1]
    soup = trimesh.Trimesh(box.vertices[faces].reshape(-1, 3), np.arange(3 * len(faces)).reshape(-1, 3), process=False)
    s = _build(soup, 0.005)
    assert s.watertight
    truth = np.asarray(box.face_normals)[s.face_index]
    assert np.all(np.einsum("ij,ij->i", truth, s.normals) > 0.999)


# --------------------------------------------------------------------------- misc


def test_same_seed_gives_identical_surfaces(box):
    broken, _ = _broken_box(box)
    for mesh in (box, broken):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)
            a, b = _build(mesh, 0.006, seed=42), _build(mesh, 0.006, seed=42)
            c = _build(mesh, 0.006, seed=43)
        for name in ("points", "normals", "curvature", "face_index", "mass_centre"):
            np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
        assert not np.array_equal(a.points, c.points)


def test_kd_tree_ball_query_matches_brute_force(sphere_surface):
    s = sphere_surface
    radius = 0.012
    for i in (0, 17, len(s) // 2):
        centre = s.points[i] + 0.003 * s.normals[i]
        brute = np.flatnonzero(np.linalg.norm(s.points - centre, axis=1) <= radius)
        np.testing.assert_array_equal(s.within(centre, radius), brute)
        np.testing.assert_array_equal(np.sort(s.tree.query_ball_point(centre, radius)), brute)
        assert i in brute
    # a ball far from the object holds no sample
    assert len(s.within([1.0, 0.0, 0.0], radius)) == 0


def test_sampling_step_is_the_tip_radius():
    assert sampling_step(0.01) == 0.01
    for bad in (0.0, -0.01, float("nan"), float("inf"), "x"):
        with pytest.raises(InputError) as err:
            sampling_step(bad)
        assert err.value.field == "tip_radius"


def test_zero_area_mesh_is_an_input_error():
    flat = trimesh.Trimesh([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]], [[0, 1, 2]], process=False)
    empty = trimesh.Trimesh(np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64), process=False)
    for mesh in (flat, empty):
        with pytest.raises(InputError) as err:
            _build(mesh, 0.01)
        assert err.value.field == "object.mesh"
        assert err.value.file is None


@pytest.mark.parametrize("step", [0.0, -0.01, float("nan"), float("inf"), 1e-9])
def test_bad_step_is_an_input_error(box, step):
    with pytest.raises(InputError) as err:
        _build(box, step)
    assert err.value.field == "step"


# --------------------------------------------------------------------------- distance grid


def _signed_distance_to_box(p: np.ndarray, half: np.ndarray) -> np.ndarray:
    """The exact signed distance of points (n, 3) to the box [-half, half] (negative inside)."""
    q = np.abs(p) - half
    return np.linalg.norm(np.maximum(q, 0.0), axis=1) + np.minimum(q.max(axis=1), 0.0)


def test_distance_grid_of_a_box_is_within_a_few_millimetres_of_the_exact_distance(box):
    from regrasp_cli.grasp.surface import distance_grid

    grid = distance_grid(_build(box, 0.003), 0.02)
    rng = np.random.default_rng(0)
    p = rng.uniform(-BOX_EXTENTS / 2 - 0.018, BOX_EXTENTS / 2 + 0.018, (5000, 3))
    exact = _signed_distance_to_box(p, BOX_EXTENTS / 2)
    err = np.abs(grid(p) - exact)
    assert np.quantile(err, 0.99) < 0.004 and np.median(err) < 0.002
    # the sign: right wherever the point is more than 5 mm off the surface (the grid's
    # 2 mm cells read a point up to 1.7 mm away)
    clear = np.abs(exact) > 0.005
    assert np.all(np.sign(grid(p)[clear]) == np.sign(exact[clear]))
    assert grid(np.array([[1.0, 1.0, 1.0]]))[0] == pytest.approx(0.02)  # off the grid: the margin


def test_distance_grid_of_a_cup_is_positive_in_its_cavity():
    """A cup, its cavity open space connected to the outside through its opening: the
    grid's sign agrees with the exact signed distance wherever that is more than 5 mm,
    the cavity included, and its value is within a few millimetres."""
    from pathlib import Path

    from regrasp_cli.grasp.surface import distance_grid

    root = Path(__file__).resolve().parents[2]
    cup = trimesh.load(root / "configs" / "bench" / "tune" / "meshes" / "cup.stl")
    grid = distance_grid(_build(cup, 0.003), 0.02)
    rng = np.random.default_rng(1)
    lo, hi = cup.bounds
    p = rng.uniform(lo - 0.015, hi + 0.015, (3000, 3))
    exact = -trimesh.proximity.signed_distance(cup, p)  # trimesh: positive inside
    in_cavity = (np.linalg.norm(p[:, :2], axis=1) < 0.02) & (np.abs(p[:, 2]) < 0.02)
    assert in_cavity.sum() > 20 and np.all(exact[in_cavity] > 0)
    clear = np.abs(exact) > 0.005
    assert np.all(np.sign(grid(p)[clear]) == np.sign(exact[clear]))
    assert np.quantile(np.abs(grid(p) - exact), 0.99) < 0.004


def test_the_sample_under_a_point_near_an_edge_lies_on_its_face(box):
    """A point of the top face 0.3 mm from an edge: its nearest sample may be on the side
    face (normal 90 degrees off, which the validator refuses); the sample under it is on
    the top face."""
    s = _build(box, 0.004)
    top = box.bounds[1, 2]
    edge = box.bounds[1, 0]
    side = s.points[(np.abs(s.points[:, 0] - edge) < 1e-9) & (s.points[:, 2] < top - 1e-4)]
    q = side[np.argmax(side[:, 2])]  # the side face's sample nearest the top edge
    w = np.array([edge - 3e-4, q[1], top])  # on the top face, just inside the edge
    nearest = int(s.tree.query(w)[1])
    assert np.allclose(s.normals[nearest], [1, 0, 0])  # the trap: the nearest sample is on the side
    assert np.allclose(s.normals[s.under(w)], [0, 0, 1])
