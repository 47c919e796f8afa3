"""Tests of regrasp_cli.grasp.quality: friction cones, force closure (cases known on
paper), force-ellipsoid axes and the weighted quality score of Saut et al. 2010 §IV-A-3."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from regrasp_cli.grasp.quality import (
    FORCE_CLOSURE_TOL,
    GraspScores,
    _cross,
    QualityWeights,
    combine_scores,
    contains_ball,
    default_torque_scale,
    default_torsion_mu,
    force_closure,
    force_ellipsoid_axis,
    friction_cone_edges,
    grasp_quality,
    is_force_closure,
    normalise_curvatures,
    primitive_wrenches,
    quality_terms,
)

ORIGIN = np.zeros(3)


def equator_contacts(n: int = 3) -> np.ndarray:
    """n contacts equally spaced on the equator of the unit sphere (points == normals)."""
    a = 2 * np.pi * np.arange(n) / n
    return np.c_[np.cos(a), np.sin(a), np.zeros(n)]


def sphere_fc(points, mu, contact="point", **kw):
    return force_closure(primitive_wrenches(points, points, mu, ORIGIN, 1.0, contact=contact), **kw)


TETRA = np.array([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]], float) / math.sqrt(3)
ANTIPODAL = np.array([[1.0, 0, 0], [-1.0, 0, 0]])


# ------------------------------------------------------------------------ friction cone


@pytest.mark.parametrize("normal", [[0, 0, 1], [1, 0, 0], [0.3, -0.5, 0.8], [0, 0, -2.0]])
@pytest.mark.parametrize("mu", [0.0, 0.2, 0.7])
def test_cone_edges_unit_inward_normal_component_on_cone(normal, mu):
    E = friction_cone_edges(normal, mu, n_edges=8)
    n = np.asarray(normal, float) / np.linalg.norm(normal)
    assert E.shape == (8, 3)
    np.testing.assert_allclose(E @ -n, 1.0, atol=1e-12)  # pushes into the object
    tangential = E - np.outer(E @ n, n)
    np.testing.assert_allclose(np.linalg.norm(tangential, axis=1), mu, atol=1e-12)
    np.testing.assert_allclose(E.mean(axis=0), -n, atol=1e-12)  # symmetric about -n


def test_cone_edges_validation():
    with pytest.raises(ValueError):
        friction_cone_edges([0, 0, 1], -0.1)
    with pytest.raises(ValueError):
        friction_cone_edges([0, 0, 1], 0.5, n_edges=2)
    with pytest.raises(ValueError):
        friction_cone_edges([0, 0, 0], 0.5)


# ------------------------------------------------------------------- primitive wrenches


def test_primitive_wrenches_shapes_and_torques():
    P = np.array([[0.1, 0.0, 0.0], [0.0, 0.2, 0.0], [0.0, 0.0, -0.05]])
    c = np.array([0.01, 0.02, 0.03])
    W = primitive_wrenches(P, P, 0.4, c, torque_scale=0.2, n_edges=6)
    assert W.shape == (18, 6)
    f = W[7, :3]  # contact 1, edge 1
    np.testing.assert_allclose(f, friction_cone_edges(P[1], 0.4, 6)[1])
    np.testing.assert_allclose(W[7, 3:], np.cross(P[1] - c, f) / 0.2)

    Ws = primitive_wrenches(P, P, 0.4, c, torque_scale=0.2, n_edges=6, contact="soft", torsion_mu=0.01)
    assert Ws.shape == (3 * 8, 6)
    n1 = P[1] / np.linalg.norm(P[1])
    for row, sign in ((Ws[8 + 6], 1.0), (Ws[8 + 7], -1.0)):
        np.testing.assert_allclose(row[:3], -n1)
        np.testing.assert_allclose(row[3:], (np.cross(P[1] - c, -n1) + sign * 0.01 * n1) / 0.2)


def test_default_torque_scale_and_torsion():
    P = np.array([[0.1, 0, 0], [0, -0.3, 0]])
    assert default_torque_scale(P, ORIGIN) == pytest.approx(0.3)
    assert default_torque_scale(np.zeros((2, 3)), ORIGIN) == 1.0
    W_default = primitive_wrenches(P, P, 0.5, ORIGIN)
    W_explicit = primitive_wrenches(P, P, 0.5, ORIGIN, torque_scale=0.3)
    np.testing.assert_allclose(W_default, W_explicit)
    assert default_torsion_mu(0.5) == pytest.approx(2 / 3 * 0.5 * 0.005)


def test_primitive_wrenches_validation():
    with pytest.raises(ValueError):
        primitive_wrenches(np.zeros((2, 3)), np.ones((3, 3)), 0.5, ORIGIN)
    with pytest.raises(ValueError):
        primitive_wrenches(ANTIPODAL, ANTIPODAL, 0.5, ORIGIN, contact="hard")
    with pytest.raises(ValueError):
        primitive_wrenches(ANTIPODAL, ANTIPODAL, 0.5, ORIGIN, torque_scale=0.0)


# ------------------------------------------------------- force closure: cases on paper


def test_three_contacts_on_sphere_equator_mu_half_is_force_closure():
    fc, eps = sphere_fc(equator_contacts(3), 0.5)
    assert fc and eps > 0.1


def test_two_antipodal_point_contacts_are_not_force_closure():
    # no torque about the line through the contacts
    assert sphere_fc(ANTIPODAL, 0.5) == (False, 0.0)
    assert sphere_fc(ANTIPODAL, 5.0) == (False, 0.0)


def test_two_antipodal_soft_finger_contacts_are_force_closure():
    fc, eps = sphere_fc(ANTIPODAL, 0.5, contact="soft")
    assert fc and eps > FORCE_CLOSURE_TOL
    W = primitive_wrenches(ANTIPODAL, ANTIPODAL, 0.5, ORIGIN, 1.0, contact="soft", torsion_mu=0.05)
    fc2, eps2 = force_closure(W)
    assert fc2 and eps2 > eps  # more torsional friction, better grasp
    # zero torsional friction degenerates to point contacts
    W0 = primitive_wrenches(ANTIPODAL, ANTIPODAL, 0.5, ORIGIN, 1.0, contact="soft", torsion_mu=0.0)
    assert force_closure(W0) == (False, 0.0)


def test_three_contacts_on_one_box_face_are_not_force_closure():
    # all applied forces have a -z component: nothing can pull the box down
    P = np.array([[0.01, 0.02, 0.05], [-0.03, 0.01, 0.05], [0.02, -0.03, 0.05]])
    N = np.tile([0.0, 0.0, 1.0], (3, 1))
    for mu in (0.5, 2.0):
        assert force_closure(primitive_wrenches(P, N, mu, ORIGIN)) == (False, 0.0)


def test_two_contacts_on_each_of_two_opposite_box_faces_are_force_closure():
    P = np.array([[0.05, 0.02, 0.0], [0.05, -0.02, 0.0], [-0.05, 0.02, 0.0], [-0.05, -0.02, 0.0]])
    N = np.sign(P[:, :1]) * np.array([[1.0, 0.0, 0.0]])
    fc, eps = force_closure(primitive_wrenches(P, N, 0.5, ORIGIN))
    assert fc and eps > 0.01


def test_regular_tetrahedron_contacts_mu_half_are_force_closure():
    fc, eps = sphere_fc(TETRA, 0.5)
    assert fc and eps > 0.1


def test_frictionless_three_contacts_on_equator_are_not_force_closure():
    assert sphere_fc(equator_contacts(3), 0.0) == (False, 0.0)
    assert sphere_fc(equator_contacts(3), 1e-6) == (False, 0.0)


def test_tiny_friction_is_force_closure_only_under_the_exact_test():
    # In exact arithmetic any mu > 0 on the equator gives force closure, with
    # epsilon ~ 0.45 mu; the default tolerance (1e-6) rejects it as frictionless.
    fc, eps = sphere_fc(equator_contacts(3), 1e-6, tol=1e-9)
    assert fc and 1e-9 < eps < FORCE_CLOSURE_TOL


def test_epsilon_increases_with_mu():
    mus = [0.05, 0.1, 0.2, 0.3, 0.5, 0.8, 1.2]
    eps = [sphere_fc(equator_contacts(3), mu)[1] for mu in mus]
    assert all(e > 0 for e in eps)
    assert all(b > a for a, b in zip(eps, eps[1:])), eps


def test_force_closure_degenerate_inputs():
    assert force_closure(np.zeros((0, 6))) == (False, 0.0)
    assert force_closure(np.eye(6)) == (False, 0.0)  # fewer than 7 wrenches
    assert force_closure(np.zeros((10, 6))) == (False, 0.0)
    # +-e_i contains the origin with epsilon = 1 / sqrt(6) (the cross-polytope's inradius)
    fc, eps = force_closure(np.vstack([np.eye(6), -np.eye(6)]))
    assert fc and eps == pytest.approx(1 / math.sqrt(6))
    with pytest.raises(ValueError):
        force_closure(np.zeros((8, 5)))


def test_the_cross_polytope_contains_exactly_its_inscribed_ball():
    # +-e_i: a hull whose inradius is 1 / sqrt(6), known on paper
    W = np.vstack([np.eye(6), -np.eye(6)])
    assert contains_ball(W, 0.99 / math.sqrt(6))
    assert not contains_ball(W, 1.01 / math.sqrt(6))


@pytest.mark.parametrize("points, mu", [(equator_contacts(3), 0.5), (TETRA, 0.5), (equator_contacts(4), 0.3)])
def test_contains_ball_never_claims_more_than_the_epsilon(points, mu):
    W = primitive_wrenches(points, points, mu, ORIGIN, 1.0)
    eps = force_closure(W)[1]
    assert eps > 0.05
    assert not contains_ball(W, 1.001 * eps)  # sound: never a ball the hull does not hold
    assert contains_ball(W, eps / math.sqrt(6) * 0.99)  # a cross-polytope fits inside the epsilon ball


@pytest.mark.parametrize("points, mu, expected", [
    (equator_contacts(3), 0.5, True), (TETRA, 0.5, True), (ANTIPODAL, 5.0, False),
    (equator_contacts(3), 0.0, False), (equator_contacts(3), 1e-6, False), (equator_contacts(3), 3e-6, True)])
def test_is_force_closure_on_paper_cases(points, mu, expected):
    # mu = 1e-6 on the equator: epsilon ~ 4.5e-7, under the margin; 3e-6: ~1.4e-6, over it
    W = primitive_wrenches(points, points, mu, ORIGIN, 1.0)
    assert is_force_closure(W) is expected
    assert force_closure(W)[0] is expected


def test_is_force_closure_agrees_with_the_hull_on_random_grasps():
    rng = np.random.default_rng(7)
    answers = []
    for _ in range(400):
        k = int(rng.integers(2, 5))
        P = rng.normal(size=(k, 3))
        P /= np.linalg.norm(P, axis=1, keepdims=True)
        N = P + rng.normal(scale=rng.choice([0.0, 0.01, 0.3]), size=(k, 3))
        N /= np.linalg.norm(N, axis=1, keepdims=True)
        W = primitive_wrenches(0.04 * P, N, float(rng.choice([0.0, 1e-6, 3e-6, 0.1, 0.8])), ORIGIN, 0.04)
        answers.append((is_force_closure(W), force_closure(W)[0]))
    assert all(a == b for a, b in answers)
    assert 20 < sum(b for _, b in answers) < 380  # both answers well represented


def test_force_closure_epsilon_is_that_of_qhulls_default_hull():
    """The epsilon comes from a hull of a few wrenches grown until its nearest facet is
    the whole hull's, hulls built without Qhull's pre-merging (a third of the time) and with
    its default where that fails: the same verdict and epsilon as the default's hull of
    every wrench, on random grasps and on contacts on a box's faces (coplanar wrenches,
    where pre-merging matters)."""
    from scipy.spatial import ConvexHull, QhullError

    rng = np.random.default_rng(11)
    for k in range(300):
        n = int(rng.integers(3, 5))
        if k % 2:
            N = np.eye(3)[rng.integers(0, 3, n)] * rng.choice([-1.0, 1.0], (n, 1))
            P = -0.03 * N + np.round(rng.normal(0, 0.01, (n, 3)), 2) * (1 - np.abs(N))
        else:
            N = rng.normal(size=(n, 3))
            N /= np.linalg.norm(N, axis=1, keepdims=True)
            P = -0.04 * N + rng.normal(0, 0.005, (n, 3))
        W = primitive_wrenches(P, N, 0.5, ORIGIN, 0.05)
        fc, eps = force_closure(W)
        try:
            default = -ConvexHull(W).equations[:, -1].max()
        except QhullError:  # flat: not force closure
            default = 0.0
        assert fc == (default > FORCE_CLOSURE_TOL)
        assert eps == (pytest.approx(default, abs=1e-12) if fc else 0.0)


# ----------------------------------------------------------------------- force ellipsoid


def planar_2link_jacobian(l1, l2, q1, q2):
    s1, c1, s12, c12 = math.sin(q1), math.cos(q1), math.sin(q1 + q2), math.cos(q1 + q2)
    return np.array([[-l1 * s1 - l2 * s12, -l2 * s12], [l1 * c1 + l2 * c12, l2 * c12], [0.0, 0.0]])


def assert_same_axis(a, b):
    a, b = np.asarray(a, float), np.asarray(b, float)
    assert abs(abs(a @ b) / np.linalg.norm(b) - 1.0) < 1e-9, (a, b)


def test_force_ellipsoid_axis_planar_two_link_hand_computation():
    # l1 = l2 = 1, q = (0, pi/2): J = [[-1, -1], [1, 0], [0, 0]], J J^T = [[2, -1], [-1, 1]]
    # (xy block), eigenvalues (3 -+ sqrt 5)/2; the smaller one, (3 - sqrt 5)/2, has the
    # eigenvector (1, (2 - lambda)) = (1, (1 + sqrt 5)/2) = (1, golden ratio).
    J = planar_2link_jacobian(1.0, 1.0, 0.0, math.pi / 2)
    np.testing.assert_allclose(J, [[-1, -1], [1, 0], [0, 0]], atol=1e-12)
    phi = (1 + math.sqrt(5)) / 2
    axis = force_ellipsoid_axis(J)
    assert np.linalg.norm(axis) == pytest.approx(1.0)
    assert_same_axis(axis, [1.0, phi, 0.0])
    assert_same_axis(force_ellipsoid_axis(-J), axis)  # sign-free


def test_force_ellipsoid_axis_rank_one_is_joint_motion_direction():
    col = np.array([0.02, -0.01, 0.03])
    assert_same_axis(force_ellipsoid_axis(col.reshape(3, 1)), col)
    # a planar 2-link finger stretched straight is rank 1: motion perpendicular to it
    J = planar_2link_jacobian(0.04, 0.03, 0.3, 0.0)
    assert_same_axis(force_ellipsoid_axis(J), [-math.sin(0.3), math.cos(0.3), 0.0])


def test_force_ellipsoid_axis_full_rank():
    J = np.diag([3.0, 1.0, 2.0])  # weakest motion (largest force) along y
    assert_same_axis(force_ellipsoid_axis(J), [0, 1, 0])
    R = np.linalg.qr(np.random.default_rng(0).normal(size=(3, 3)))[0]
    assert_same_axis(force_ellipsoid_axis(R @ J), R[:, 1])  # frame covariant
    with pytest.raises(ValueError):
        force_ellipsoid_axis(np.zeros((3, 2)))


def test_force_ellipsoid_axis_batch_is_row_by_row():
    """A batch of Jacobians (rank 1 to 3) gives each row's axis, sign included."""
    rng = np.random.default_rng(3)
    J = rng.normal(size=(40, 3, 4))
    J[:10, :, 1:] = 0.0  # rank 1
    J[10:20, :, 2:] = J[10:20, :, :2] @ rng.normal(size=(2, 2))  # rank 2
    batch = force_ellipsoid_axis(J)
    assert batch.shape == (40, 3)
    assert np.array_equal(batch, np.array([force_ellipsoid_axis(j) for j in J]))
    assert_same_axis(batch[0], J[0, :, 0])


# ------------------------------------------------------------------------ quality terms


def test_normalise_curvatures():
    surface = np.array([0.0, 5.0, -10.0, 2.0])
    np.testing.assert_allclose(normalise_curvatures([0.0, -5.0, 20.0], surface), [0.0, 0.5, 1.0])
    np.testing.assert_allclose(normalise_curvatures([1.0, 2.0], np.zeros(4)), [0.0, 0.0])


def test_quality_terms_extremes():
    P = equator_contacts(3)
    axes_along = P.copy()  # fingers push along their strongest direction
    axes_across = np.tile([0.0, 0.0, 1.0], (3, 1))
    best = quality_terms(0.3, P, P, ORIGIN, -axes_along, np.zeros(3), 1.0)  # sign-free axes
    np.testing.assert_allclose(best, [0.3, 1.0, 1.0, 1.0], atol=1e-12)
    worst = quality_terms(5.0, P + [0, 0, 2.0], P, ORIGIN, axes_across, np.ones(3), 1.0)
    np.testing.assert_allclose(worst, [1.0, 0.0, 0.0, 0.0], atol=1e-12)
    # documented intermediate values: centroid 0.25 rho off, 45 deg axes, mean kappa 0.5
    a45 = (P + axes_across) / math.sqrt(2)
    mid = quality_terms(0.0, P + [0.25, 0, 0], P, ORIGIN, a45, [0.0, 0.5, 1.0], 1.0)
    np.testing.assert_allclose(mid, [0.0, 0.75, 0.5, 0.5], atol=1e-12)


def test_quality_terms_in_unit_interval_random():
    rng = np.random.default_rng(1)
    for _ in range(50):
        k = int(rng.integers(1, 6))
        t = quality_terms(
            float(rng.uniform(-1, 3)),
            rng.normal(size=(k, 3)),
            rng.normal(size=(k, 3)),
            rng.normal(size=3),
            rng.normal(size=(k, 3)),
            rng.uniform(0, 1, size=k),
        )
        assert t.shape == (4,) and np.all((t >= 0) & (t <= 1))


def test_weights_combine_as_documented():
    w = QualityWeights()
    assert dataclasses.astuple(w) == (1.0, 1.0, 1.0, 6.0)
    terms = [0.2, 0.4, 0.6, 0.8]
    assert combine_scores(terms) == pytest.approx((0.2 + 0.4 + 0.6 + 6 * 0.8) / 9)
    assert combine_scores(terms, QualityWeights(0, 0, 0, 1)) == pytest.approx(0.8)
    assert combine_scores(terms, QualityWeights(2, 0, 1, 1)) == pytest.approx((0.4 + 0.6 + 0.8) / 4)
    with pytest.raises(dataclasses.FrozenInstanceError):
        w.curvature = 1.0  # type: ignore[misc]
    with pytest.raises(ValueError):
        combine_scores(terms, QualityWeights(0, 0, 0, 0))


def test_grasp_quality_sphere_grasp():
    P = equator_contacts(3) * 0.05  # 5 cm sphere
    s = grasp_quality(P, P, 0.5, ORIGIN, finger_axes=P, curvatures=np.full(3, 0.2))
    assert isinstance(s, GraspScores) and s.is_force_closure
    eps = sphere_fc(equator_contacts(3), 0.5)[1]  # scale-free with rho = radius
    assert s.epsilon == pytest.approx(eps)
    assert (s.centroid, s.ellipsoid, s.curvature) == pytest.approx((1.0, 1.0, 0.8))
    assert s.total == pytest.approx((eps + 1 + 1 + 6 * 0.8) / 9)
    with pytest.raises(dataclasses.FrozenInstanceError):
        s.total = 0.0  # type: ignore[misc]


def test_grasp_quality_rejects_non_force_closure():
    s = grasp_quality(ANTIPODAL, ANTIPODAL, 0.5, ORIGIN, ANTIPODAL, np.zeros(2))
    assert not s.is_force_closure
    assert s.epsilon == 0.0 and s.total == 0.0
    assert s.centroid == pytest.approx(1.0) and s.curvature == pytest.approx(1.0)
    soft = grasp_quality(ANTIPODAL, ANTIPODAL, 0.5, ORIGIN, ANTIPODAL, np.zeros(2), contact="soft")
    assert soft.is_force_closure and 0 < soft.total <= 1


@pytest.mark.parametrize("shape_a, shape_b", [((5, 3), (5, 3)), ((4, 1, 3), (4, 8, 3)), ((3,), (6, 3))])
def test_the_wrenches_cross_product_is_numpys_bit_for_bit(shape_a, shape_b):
    """The planner's plans are compared byte for byte across speed-ups: the hand-written
    cross product must round exactly as np.cross does, on any scale and broadcast."""
    rng = np.random.default_rng(0)
    for _ in range(100):
        a = rng.normal(size=shape_a) * 10.0 ** rng.uniform(-6, 3)
        b = rng.normal(size=shape_b) * 10.0 ** rng.uniform(-6, 3)
        assert np.array_equal(_cross(a, b), np.cross(a, b))
    assert np.array_equal(_cross(np.eye(3), np.roll(np.eye(3), -1, axis=0)), np.roll(np.eye(3), -2, axis=0))  # x*y=z
