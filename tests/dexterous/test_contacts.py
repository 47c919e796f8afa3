"""Force closure of fingertip contacts on a sphere, known on paper (seed 003 §IV): three
contacts 120° apart on the equator hold the sphere with any friction and not without;
three on a circle of colatitude θ need mu > cot θ (friction must carry the inward pull
along the axis); four at a regular tetrahedron's vertices hold it with friction, never
without (on a sphere every normal passes through the centre: no torque); and for finger
gaiting every three of the four must hold it too.  Contact normals on a sphere meet in its
centre; on a cube's faces they do not."""

from __future__ import annotations

import math

import numpy as np
import pytest

from regrasp_cli.dexterous.contacts import closure, gaitable, holds, normals_meet

R = 0.03
O = np.zeros(3)


def _ring(colatitude: float, k: int = 3, phase: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    phi = phase + 2 * np.pi * np.arange(k) / k
    n = np.stack([np.sin(colatitude) * np.cos(phi), np.sin(colatitude) * np.sin(phi),
                  np.full(k, np.cos(colatitude))], axis=1)
    return R * n, n


def _tetrahedron() -> tuple[np.ndarray, np.ndarray]:
    n = np.array([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]], float) / math.sqrt(3)
    return R * n, n


@pytest.mark.parametrize("mu", [0.1, 0.5, 1.0])
def test_three_contacts_on_the_equator_hold_with_any_friction(mu):
    p, n = _ring(np.pi / 2)
    assert closure(p, n, mu, O, R) > 0


def test_no_contacts_on_a_sphere_hold_it_without_friction():
    for p, n in (_ring(np.pi / 2), _tetrahedron(), _ring(np.pi / 3, 6)):
        assert closure(p, n, 0.0, O, R) == 0.0


@pytest.mark.parametrize("mu, holds", [(0.4, False), (0.5, False), (0.8, True), (1.2, True)])
def test_three_contacts_on_one_side_need_friction_above_cot_colatitude(mu, holds):
    p, n = _ring(np.pi / 3)  # cot 60° = 0.577
    assert (closure(p, n, mu, O, R) > 0) == holds


def test_two_contacts_never_hold_and_one_lifted_finger_is_checked():
    p, n = _ring(np.pi / 2, 2)
    assert closure(p, n, 1.0, O, R) == 0.0  # antipodal points: free to spin about their axis
    p, n = _tetrahedron()
    eps4, eps3 = closure(p, n, 0.8, O, R), gaitable(p, n, 0.8, O, R)
    assert eps4 > 0 and 0 < eps3 <= eps4  # any three hold it, less well than four
    # the tetrahedron's three lower contacts are 109.5° from the top one: cot(109.5°) < 0,
    # but without the top contact they sit on one side (colatitude 70.5° about -z) and need
    # mu > cot 70.5° = 0.354; with mu = 0.3 four hold it and one lifted finger drops it
    assert closure(p, n, 0.3, O, R) > 0 and gaitable(p, n, 0.3, O, R) == 0.0


def test_the_quick_test_decides_as_the_epsilon_does():
    """``holds`` (no 6-D hull) against ``closure`` > 0 on 300 random sets of 3 and 4
    contacts on a sphere, half of them on one hemisphere: the same answer every time."""
    rng = np.random.default_rng(0)
    answers = []
    for i in range(300):
        n = rng.normal(size=(int(rng.integers(3, 5)), 3))
        if i % 2:
            n[:, 2] = np.abs(n[:, 2])
        n /= np.linalg.norm(n, axis=1, keepdims=True)
        eps = closure(R * n, n, 0.8, O, R)
        if 0 < eps < 1e-4:
            continue  # at the boundary the two margins differ
        assert holds(R * n, n, 0.8, O, R) == (eps > 0)
        answers.append(eps > 0)
    assert 50 < sum(answers) < len(answers) - 50  # both answers exercised


def _equator(angles_deg) -> tuple[np.ndarray, np.ndarray]:
    phi = np.radians(angles_deg)
    n = np.stack([np.cos(phi), np.sin(phi), np.zeros(len(phi))], axis=1)
    return R * n, n


def test_fingers_around_the_object_may_each_let_go_a_thumb_opposing_three_may_not():
    """Why finger gaiting needs the fingers around the object (§IV): four contacts 90°
    apart on the equator keep force closure without any one of them (mu 0.5 and up); a
    thumb opposite three fingers side by side (30° apart) holds the sphere, but without the
    thumb the three push from one side and nothing holds it."""
    p, n = _equator([0, 90, 180, 270])
    assert gaitable(p, n, 0.5, O, R) > 0.05 and gaitable(p, n, 0.8, O, R) > 0.2
    p, n = _equator([180, -30, 0, 30])
    assert closure(p, n, 0.8, O, R) > 0.1
    assert closure(p[1:], n[1:], 0.8, O, R) == 0.0 and gaitable(p, n, 0.8, O, R) == 0.0
    assert all(closure(np.delete(p, f, 0), np.delete(n, f, 0), 0.8, O, R) > 0 for f in (1, 2, 3))


def test_normals_on_a_sphere_meet_in_its_centre_on_a_cube_they_do_not():
    rng = np.random.default_rng(1)
    n = rng.normal(size=(3, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    c = np.array([0.01, -0.02, 0.005])
    assert normals_meet(c + R * n, n) < 1e-12  # any contacts on a sphere centred at c
    # a cube of side 2R: two fingers pinch opposite faces 2 cm off each other's line, a
    # third presses the top face: the lines pass 1 cm, 1 cm and 0 from the best point
    p = np.array([[R, 0.01, 0.0], [-R, -0.01, 0.0], [0.0, 0.0, R]])
    n = np.array([[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    assert normals_meet(p, n) == pytest.approx(np.sqrt(2 * 0.01 ** 2 / 3), rel=1e-9)
