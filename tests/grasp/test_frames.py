"""Grasp frame sampling (Saut et al. 2010, §IV-A-1): SO(3) grid, position grid, grasp frames."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from regrasp_cli.grasp.frames import (
    grasp_frames,
    position_grid,
    so3_covering_radius_bound,
    so3_dispersion_estimate,
    so3_grid,
)

# Levels 0..3 complete: 4 + 32 + 256 + 2048 samples.
LEVEL_STARTS = [0, 4, 36, 292, 2340]
# Dispersion estimates (200 000 probes, seed 0): 1.27, 0.73, 0.46 rad; bounds with margin.
DISPERSION_BOUNDS = {32: 1.45, 256: 0.85, 2048: 0.55}


@pytest.fixture(scope="module")
def grid() -> np.ndarray:
    return so3_grid(LEVEL_STARTS[-1])


def nearest_angles(probes: np.ndarray, quats: np.ndarray) -> np.ndarray:
    """Geodesic angle (rad) from each probe quaternion to its nearest quaternion of the set."""
    best = np.abs(probes @ quats.T).max(axis=1)
    return 2.0 * np.arccos(np.clip(best, 0.0, 1.0))


def min_pairwise_angle(quats: np.ndarray) -> float:
    """Smallest geodesic angle between two distinct rotations of the set, via scipy."""
    R = Rotation.from_quat(quats)
    worst = math.inf
    for i in range(len(quats) - 1):
        worst = min(worst, float((R[i].inv() * R[i + 1 :]).magnitude().min()))
    return worst


# --- so3_grid -----------------------------------------------------------------------------


def test_quaternions_unit_and_canonical(grid):
    assert grid.shape == (2340, 4)
    np.testing.assert_allclose(np.linalg.norm(grid, axis=1), 1.0, atol=1e-12)
    assert np.all(grid[:, 3] >= 0.0)
    for q in grid[grid[:, 3] == 0.0]:  # w == 0: first non-zero of x, y, z positive
        assert q[np.flatnonzero(q[:3])[0]] > 0.0
    # scipy agrees that these are the rotations (round trip keeps them, up to sign)
    back = Rotation.from_quat(grid).as_quat(canonical=True)
    np.testing.assert_allclose(np.abs(np.sum(back * grid, axis=1)), 1.0, atol=1e-12)


def test_first_samples():
    q = so3_grid(4)  # level 0: identity and the three half-turns about x, y, z
    np.testing.assert_allclose(q, [[0, 0, 0, 1], [1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0]])
    assert so3_grid(0).shape == (0, 4)
    with pytest.raises(ValueError):
        so3_grid(-1)


@pytest.mark.parametrize("n", [1, 3, 4, 5, 31, 32, 33, 36, 37, 100, 256, 291, 292, 293, 2048])
def test_prefix_property(grid, n):
    np.testing.assert_array_equal(so3_grid(n), grid[:n])


def test_deterministic():
    np.testing.assert_array_equal(so3_grid(500), so3_grid(500))


@pytest.mark.parametrize("level", [0, 1, 2, 3])
def test_full_level_has_no_repeated_rotation(grid, level):
    q = grid[LEVEL_STARTS[level] : LEVEL_STARTS[level + 1]]
    assert len(q) == 4 * 8**level
    assert min_pairwise_angle(q) > 1e-6
    # 8^level cells on each of the 4 faces x_i = +1 (face = largest |component|)
    faces = np.argmax(np.abs(q), axis=1)
    assert np.bincount(faces, minlength=4).tolist() == [8**level] * 4


def test_levels_together_have_no_repeated_rotation(grid):
    dots = np.abs(grid @ grid.T)
    np.fill_diagonal(dots, 0.0)
    assert 2.0 * math.acos(min(1.0, dots.max())) > 1e-6


def test_dispersion_estimate_matches_scipy():
    quats = so3_grid(20)
    est = so3_dispersion_estimate(quats, 300, np.random.default_rng(7))
    probes = Rotation.random(300, random_state=np.random.default_rng(7))
    R = Rotation.from_quat(quats)
    ref = max(float((probes[i].inv() * R).magnitude().min()) for i in range(len(probes)))
    assert est == pytest.approx(ref, abs=1e-9)
    assert so3_dispersion_estimate(np.zeros((0, 4)), 10, 0) == pytest.approx(math.pi)


def test_dispersion_decreases_and_is_bounded():
    d = {n: so3_dispersion_estimate(so3_grid(n), 20000, 0) for n in DISPERSION_BOUNDS}
    assert d[32] > d[256] > d[2048]
    for n, bound in DISPERSION_BOUNDS.items():
        assert d[n] < bound, (n, d[n])


def test_covering_radius_bound_values():
    assert so3_covering_radius_bound(3) == pytest.approx(math.pi)
    for L, n in enumerate(LEVEL_STARTS[1:]):
        expected = 4.0 * math.atan(math.sqrt(3.0) / 2 ** (L + 1))
        assert so3_covering_radius_bound(n) == pytest.approx(expected)
        assert so3_covering_radius_bound(n - 1) > expected  # level L not complete yet
    assert so3_covering_radius_bound(2340) == pytest.approx(0.4313, abs=1e-4)


@pytest.mark.parametrize("n", [4, 32, 36, 256, 292, 2048, 2340])
def test_random_rotations_are_covered(grid, n):
    probes = Rotation.random(20000, random_state=123).as_quat()
    angles = nearest_angles(probes, grid[:n])
    assert angles.max() <= so3_covering_radius_bound(n) + 1e-12
    if n in DISPERSION_BOUNDS:
        assert angles.max() < DISPERSION_BOUNDS[n]
    # spot-check the quaternion-dot geodesic against scipy
    R = Rotation.from_quat(grid[:n])
    for i in range(3):
        ref = (Rotation.from_quat(probes[i]).inv() * R).magnitude().min()
        assert angles[i] == pytest.approx(ref, abs=1e-7)


# --- position_grid ------------------------------------------------------------------------


def test_position_grid_exact_cases():
    p = position_grid([[0, 0, 0], [1, 1, 1]], 27)
    assert p.shape == (27, 3)
    np.testing.assert_allclose(np.unique(p[:, 0]), [1 / 6, 1 / 2, 5 / 6])
    np.testing.assert_allclose(p[:3], [[1 / 6, 1 / 6, 1 / 6], [1 / 6, 1 / 6, 1 / 2], [1 / 6, 1 / 6, 5 / 6]])
    # step (0.001 / 1000)^(1/3) = 0.01 -> 20 x 10 x 5 cells
    p = position_grid([[0.0, 0.0, 0.0], [0.2, 0.1, 0.05]], 1000)
    assert [len(np.unique(np.round(p[:, a], 12))) for a in range(3)] == [20, 10, 5]
    assert len(p) == 1000


@pytest.mark.parametrize(
    "bounds",
    [
        [[-0.05, -0.03, 0.0], [0.05, 0.03, 0.12]],
        [[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]],
        [[-0.1, -0.1, -0.002], [0.1, 0.1, 0.002]],  # thin plate
        [[0.0, 0.0, 0.0], [0.3, 0.0, 0.1]],  # degenerate: zero extent in y
        [[0.0, 0.0, 0.0], [0.0, 0.0, 0.5]],  # a segment
    ],
)
@pytest.mark.parametrize("n", [1, 8, 50, 200, 1000])
def test_position_grid_count_and_inside(bounds, n):
    b = np.asarray(bounds, dtype=float)
    p = position_grid(b, n)
    counts = [len(np.unique(np.round(p[:, a], 12))) for a in range(3)]
    assert len(p) == int(np.prod(counts))  # exactly a product grid
    assert len(np.unique(np.round(p, 12), axis=0)) == len(p)
    assert np.all(p >= b[0] - 1e-12) and np.all(p <= b[1] + 1e-12)
    ext = b[1] - b[0]
    for a in range(3):  # interior of positive extents, centred cells
        if ext[a] > 0:
            assert np.all(p[:, a] > b[0, a]) and np.all(p[:, a] < b[1, a])
            assert p[:, a].min() - b[0, a] == pytest.approx(b[1, a] - p[:, a].max())
    if n >= 50:
        assert 0.5 * n <= len(p) <= 2.0 * n, len(p)
    else:
        assert 1 <= len(p) <= 8 * n


def test_position_grid_point_box():
    p = position_grid([[1, 2, 3], [1, 2, 3]], 100)
    np.testing.assert_array_equal(p, [[1, 2, 3]])


@pytest.mark.parametrize(
    "bounds, n",
    [([[0, 0, 0], [1, 1, 1]], 0), ([[0, 0, 0], [-1, 1, 1]], 10), ([[0, 0, 0]], 10), ([[0, 0, 0], [np.nan, 1, 1]], 10)],
)
def test_position_grid_rejects_bad_input(bounds, n):
    with pytest.raises(ValueError):
        position_grid(bounds, n)


# --- grasp_frames -------------------------------------------------------------------------


def test_grasp_frames_are_rigid_and_ordered():
    bounds = [[-0.04, -0.02, 0.0], [0.04, 0.02, 0.1]]
    P = position_grid(bounds, 20)
    Q = so3_grid(50)
    X = grasp_frames(bounds, 20, 50)
    assert X.shape == (len(P) * 50, 4, 4)
    R = X[:, :3, :3]
    np.testing.assert_allclose(np.einsum("kji,kjl->kil", R, R), np.broadcast_to(np.eye(3), R.shape), atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=1e-12)
    np.testing.assert_array_equal(X[:, 3], np.broadcast_to([0.0, 0.0, 0.0, 1.0], (len(X), 4)))
    for k in (0, 1, 49, 50, 51, len(X) - 1):
        ip, io = divmod(k, 50)
        np.testing.assert_allclose(X[k, :3, 3], P[ip])
        np.testing.assert_allclose(X[k, :3, :3], Rotation.from_quat(Q[io]).as_matrix(), atol=1e-12)
    np.testing.assert_array_equal(X, grasp_frames(bounds, 20, 50))
    assert grasp_frames(bounds, 20, 0).shape == (0, 4, 4)
