"""Where stable placements fit on a scene's supports (placement.supports): the tops found
from boxes and upright cylinders, every fit resting on its top and inside it, obstacles on a
top taking their place away, and supports a scene names that cannot hold anything refused."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from scipy.spatial.transform import Rotation

from regrasp_cli.config import ObstacleSpec
from regrasp_cli.errors import InputError
from regrasp_cli.model.collision import mesh_geometry
from regrasp_cli.model.handshape import hand_hits_static, single_shape, static_geometry
from regrasp_cli.placement.stable import stable_placements
from regrasp_cli.placement.supports import FitOptions, fit_placements, resting_gap, scene_supports, top_of


def _pose(xyz, rpy=(0.0, 0.0, 0.0)) -> np.ndarray:
    X = np.eye(4)
    X[:3, :3] = Rotation.from_euler("xyz", rpy).as_matrix()
    X[:3, 3] = xyz
    return X


def _box(name, size, xyz, rpy=(0.0, 0.0, 0.0)) -> ObstacleSpec:
    return ObstacleSpec(name, "box", tuple(size), _pose(xyz, rpy))


def test_a_box_top_is_found_whichever_axis_points_up():
    # a 0.2 x 0.4 x 0.1 box turned so that its y axis points down: its top is 0.2 above the centre
    ob = _box("b", (0.2, 0.4, 0.1), (1.0, 0.5, 0.3), (np.pi / 2, 0.0, 0.3))
    top = top_of(ob)
    assert top.X_WT[:3, 3] == pytest.approx([1.0, 0.5, 0.5])
    assert top.X_WT[:3, 2] == pytest.approx([0.0, 0.0, 1.0])
    half = np.sort(np.abs(top.outline).max(axis=0))
    assert half == pytest.approx([0.05, 0.1])  # the x and z sides


def test_tilted_boxes_spheres_and_lying_cylinders_have_no_top():
    assert top_of(_box("t", (0.2, 0.2, 0.2), (0, 0, 0), (0.1, 0.0, 0.0))) is None
    assert top_of(ObstacleSpec("s", "sphere", (0.1,), _pose((0, 0, 0)))) is None
    assert top_of(ObstacleSpec("c", "cylinder", (0.1, 0.3), _pose((0, 0, 0), (np.pi / 2, 0, 0)))) is None
    disc = top_of(ObstacleSpec("c", "cylinder", (0.1, 0.3), _pose((0, 0, 1.0), (np.pi, 0, 0))))
    assert disc.X_WT[:3, 3] == pytest.approx([0.0, 0.0, 1.15])
    assert np.linalg.norm(disc.outline, axis=1) == pytest.approx(np.full(len(disc.outline), 0.1))


def test_a_named_support_without_a_top_is_refused():
    obstacles = (_box("table", (1, 1, 0.04), (0, 0, 0.7)), _box("ramp", (0.3, 0.3, 0.02), (0, 0, 1), (0.3, 0, 0)))
    assert [s.name for s in scene_supports(obstacles)] == ["table"]
    with pytest.raises(InputError, match=r"supports\[1\].*'ramp' has no flat top"):
        scene_supports(obstacles, ("table", "ramp"))


def test_every_fit_of_a_cube_rests_on_the_top_inside_its_edges():
    cube = trimesh.creation.box(extents=[0.05, 0.05, 0.05])
    table = _box("table", (0.3, 0.2, 0.04), (0.5, 0.0, 0.7), (0.0, 0.0, 0.4))
    stable = stable_placements(cube, cube.center_mass)
    options = FitOptions(step=0.03, yaws=4, edge_margin=0.005)
    fitted = fit_placements(stable, scene_supports((table,)), cube, (table,), options)
    assert len(fitted) > 0 and set(fitted.stable) == set(range(6))
    to_table = np.linalg.inv(table.X_WO)
    for X in fitted.X_WO:
        v = trimesh.transform_points(cube.vertices, to_table @ X)  # in the table's frame
        assert v[:, 2].min() == pytest.approx(0.02, abs=1e-9)  # resting on its top
        bottom = v[np.abs(v[:, 2] - 0.02) < 1e-9]
        assert np.all(np.abs(bottom[:, 0]) <= 0.15 - 0.005 + 1e-9)
        assert np.all(np.abs(bottom[:, 1]) <= 0.10 - 0.005 + 1e-9)


def test_an_obstacle_on_the_top_takes_its_place_away():
    cube = trimesh.creation.box(extents=[0.05, 0.05, 0.05])
    table = _box("table", (0.4, 0.4, 0.04), (0.0, 0.0, 0.7))
    crate = _box("crate", (0.1, 0.1, 0.1), (0.1, 0.1, 0.77))  # on the table's +x +y quarter
    stable = stable_placements(cube, cube.center_mass)
    options = FitOptions(step=0.04, yaws=2)
    free = fit_placements(stable, scene_supports((table,), ("table",)), cube, (table,), options)
    both = fit_placements(stable, scene_supports((table, crate), ("table",)), cube, (table, crate), options)
    assert 0 < len(both) < len(free)
    near = np.all(np.abs(free.X_WO[:, :2, 3] - [0.1, 0.1]) < 0.05 + 0.025 - 1e-9, axis=1)  # overlaps the crate
    assert near.any()
    kept = {tuple(np.round(X[:3, 3], 9)) for X in both.X_WO}
    assert not any(tuple(np.round(X[:3, 3], 9)) in kept for X in free.X_WO[near])
    assert all(tuple(np.round(X[:3, 3], 9)) in kept for X in free.X_WO[~near])


def test_the_fits_are_those_a_check_against_every_obstacle_keeps():
    """The fit skips coal for what cannot touch (obstacles wholly below the lifted object,
    boxes far from its bounding sphere): its fits are exactly those that a check of every
    candidate against every obstacle keeps.  A shelf 4 cm over the table (lower than the
    cube), a bar tilted through the top's height, a crate below it beside the table."""
    cube = trimesh.creation.box(extents=[0.05, 0.05, 0.05])
    table = _box("table", (0.4, 0.4, 0.04), (0.0, 0.0, 0.7))
    others = (_box("shelf", (0.15, 0.4, 0.01), (0.12, 0.0, 0.765)),
              _box("bar", (0.5, 0.02, 0.02), (-0.05, -0.1, 0.73), (0.0, 0.3, 0.4)),
              _box("crate", (0.2, 0.2, 0.2), (0.4, 0.4, 0.5)))
    stable = stable_placements(cube, cube.center_mass)
    options = FitOptions(step=0.03, yaws=3)
    supports = scene_supports((table,), ("table",))
    free = fit_placements(stable, supports, cube, (table,), options)
    fitted = fit_placements(stable, supports, cube, (table, *others), options)
    shape, env = single_shape(mesh_geometry(cube)), static_geometry((table, *others))
    lift = np.eye(4)
    lift[2, 3] = options.lift
    kept = [not hand_hits_static(shape, lift @ X, env) for X in free.X_WO]
    assert 0 < sum(kept) < len(kept)
    assert np.array_equal(fitted.X_WO, free.X_WO[kept])
    assert len(env.reaching_above(0.721).geometries) == 2  # the shelf and the bar, not the table or the crate


def test_a_mat_on_the_low_end_of_a_slightly_tilted_table_takes_its_places_away():
    """A 2 m table pitched by 1.3 mrad still has a top (within VERTICAL_COS); its low end
    lies 1.3 mm below the top's centre, under a 2.1 mm mat there: the fits that overlap the
    mat are refused, as a check of every candidate against every obstacle refuses them."""
    cube = trimesh.creation.box(extents=[0.05, 0.05, 0.05])
    table = _box("table", (2.0, 0.4, 0.04), (0.0, 0.0, 0.7), (0.0, 1.3e-3, 0.0))
    top = top_of(table)
    p_mat = top.X_WT @ [0.95, 0.0, 0.00105, 1.0]  # lying on the top's low end (the pitch lowers +x)
    mat = ObstacleSpec("mat", "box", (0.1, 0.4, 0.0021), _pose(p_mat[:3], (0.0, 1.3e-3, 0.0)))
    stable = stable_placements(cube, cube.center_mass)
    options = FitOptions(step=0.05, yaws=2)
    free = fit_placements(stable, [top], cube, (table,), options)
    fitted = fit_placements(stable, [top], cube, (table, mat), options)
    shape, env = single_shape(mesh_geometry(cube)), static_geometry((table, mat))
    lift = np.eye(4)
    lift[2, 3] = options.lift
    kept = [not hand_hits_static(shape, top.X_WT @ lift @ np.linalg.inv(top.X_WT) @ X, env) for X in free.X_WO]
    assert 0 < sum(kept) < len(kept)
    assert np.array_equal(fitted.X_WO, free.X_WO[kept])


def test_the_gap_under_a_resting_object_is_measured_to_the_top_beneath_it():
    """A 4 x 4 x 12 cm block (origin at its base) over a table whose top is at z = 0.72:
    standing on it, 5 cm above it (PR2's scene before 0e5d0f1), 5 mm into it; beside the
    table nothing is under it.  Its lowest point decides (the block upside down too)."""
    block = trimesh.creation.box(extents=(0.04, 0.04, 0.12))
    block.apply_translation([0.0, 0.0, 0.06])
    table = (_box("table", (0.6, 1.8, 0.04), (0.75, 0.0, 0.70)),)
    assert resting_gap(block.vertices, _pose((0.55, -0.7, 0.72)), table) == pytest.approx(0.0, abs=1e-9)
    assert resting_gap(block.vertices, _pose((0.55, -0.7, 0.77)), table) == pytest.approx(0.05)
    assert resting_gap(block.vertices, _pose((0.55, -0.7, 0.715)), table) == pytest.approx(-0.005)
    assert resting_gap(block.vertices, _pose((0.55, -0.7, 0.84), (np.pi, 0, 0)), table) == pytest.approx(0.0, abs=1e-9)
    assert resting_gap(block.vertices, _pose((0.20, -0.7, 0.72)), table) is None
