"""Blended paths and their TOPP-RA timing (regrasp_cli.motion.blend), on cases known on
paper: a straight segment (the time-optimal rest-to-rest motion is the trapezoid), a
right-angle corner in the plane (the blend's geometry, C1 continuity, the convex hull),
stops, the limits at a fine time step, and the choice of blend radii."""

from __future__ import annotations

import numpy as np
import pytest

from regrasp_cli.motion.blend import (
    bezier_points,
    bezier_steps,
    blended_path,
    choose_radii,
    corner,
    grid_times,
    time_optimal,
    trajectory,
)
from regrasp_cli.motion.timing import segment_duration

CORNER = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]])  # a right angle at (1, 0)
V, A = np.array([1.0, 0.5]), np.array([2.0, 3.0])


def limits_hold(path, timing, v, a, dt=1e-3):
    t = np.concatenate([np.arange(timing.t[0], timing.t[-1], dt), timing.t])
    _, qd, qdd = trajectory(path, timing, t)
    return np.abs(qd).max(axis=0) / v, np.abs(qdd).max(axis=0) / a


def test_a_straight_segment_is_timed_like_the_trapezoid():
    """Rest to rest on one straight segment, the time-optimal motion is the trapezoid of
    motion/timing.py: TOPP-RA's may not beat it and comes within 2 % of it."""
    w = np.array([[0.0, 0.0], [1.0, 0.4]])
    path = blended_path(w, [0.0, 0.0])
    timing = time_optimal(path, V, A)
    best = segment_duration(w[1] - w[0], V, A)
    assert best * (1 - 1e-9) <= timing.duration <= 1.02 * best
    vel, acc = limits_hold(path, timing, V, A)
    assert vel.max() <= 1 + 1e-9 and acc.max() <= 1 + 1e-9
    q, qd, _ = trajectory(path, timing, np.array([timing.t[0], timing.t[-1]]))
    np.testing.assert_array_equal(q, w)  # exactly at its ends, at rest
    np.testing.assert_array_equal(qd, 0.0)


def test_the_blend_of_a_right_angle():
    """Radius 0.25 at (1, 0): the blend runs from (0.75, 0) to (1, 0.25), its middle is
    (0.9375, 0.0625) = C + r (d1 - d0) / 4, the path is 2 - 2 r + 2 r = 2 long, and dq/ds
    is continuous with unit length at the blend's ends."""
    path = blended_path(CORNER, [0.0, 0.25, 0.0])
    assert len(path.A) == 3 and path.length == pytest.approx(2.0)
    np.testing.assert_allclose(path.starts, [0.0, 0.75, 1.25, 2.0])
    np.testing.assert_allclose(path.knots, [0.0, 1.0, 2.0])
    np.testing.assert_allclose(path.evaluate(np.array([1.0])), [[0.9375, 0.0625]])
    np.testing.assert_array_equal(path.stops, [True, False, False, True])
    for s in path.starts[1:-1]:
        before, after = path.evaluate(np.array([s - 1e-9]), 1), path.evaluate(np.array([s]), 1)
        np.testing.assert_allclose(before, after, atol=1e-6)
        assert np.linalg.norm(after) == pytest.approx(1.0)
    # the curve stays in the triangle (0.75, 0), (1, 0), (1, 0.25)
    q = path.evaluate(np.linspace(0.75, 1.25, 101))
    assert np.all(q[:, 0] >= 0.75 - 1e-12) and np.all(q[:, 0] <= 1.0 + 1e-12)
    assert np.all(q[:, 1] >= -1e-12) and np.all(q[:, 1] <= 0.25 + 1e-12)
    assert np.all(q[:, 1] <= 4 * (q[:, 0] - 0.75) + 1e-12)


def test_blending_is_faster_than_stopping_and_keeps_the_limits():
    stop = time_optimal(blended_path(CORNER, [0.0, 0.0, 0.0]), V, A)
    path = blended_path(CORNER, [0.0, 0.5, 0.0])
    blend = time_optimal(path, V, A)
    assert blend.duration < 0.9 * stop.duration
    vel, acc = limits_hold(path, blend, V, A)
    assert vel.max() <= 1 + 1e-6 and acc.max() <= 1 + 1e-6


def test_a_corner_without_a_blend_is_passed_at_rest():
    path = blended_path(CORNER, [0.0, 0.0, 0.0])
    timing = time_optimal(path, V, A)
    assert path.stops.tolist() == [True, True, True]
    t1 = float(np.interp(1.0, timing.s, timing.t))
    q, qd, _ = trajectory(path, timing, np.array([t1]))
    np.testing.assert_allclose(q, [[1.0, 0.0]], atol=1e-12)
    np.testing.assert_allclose(qd, 0.0, atol=1e-12)


def test_the_grid_times_follow_from_the_speeds():
    path = blended_path(CORNER, [0.0, 0.3, 0.0])
    timing = time_optimal(path, V, A)
    np.testing.assert_allclose(grid_times(timing.s, timing.sd), timing.t - timing.t[0], rtol=1e-12)
    assert timing.sd[0] == 0 and timing.sd[-1] == 0 and np.all(timing.sd[1:-1] > 0)


def test_blends_that_do_not_fit_are_refused():
    with pytest.raises(ValueError, match="fit"):
        blended_path(CORNER, [0.0, 1.5, 0.0])
    with pytest.raises(ValueError, match="fit"):
        blended_path(CORNER, [0.1, 0.2, 0.0])
    with pytest.raises(ValueError, match="differ"):
        blended_path(np.array([[0.0, 0.0], [0.0, 0.0], [1.0, 1.0]]), [0.0, 0.0, 0.0])


def test_choose_radii_shrinks_then_stops():
    w = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [2.0, 1.0]])
    asked = []

    def free(i, A_, C, B):  # corner 1 free only for radii <= 0.15, corner 2 never
        r = np.linalg.norm(C - A_)
        asked.append((i, round(float(r), 6)))
        return i == 1 and r <= 0.15

    r = choose_radii(w, free, fraction=0.4, shrink=0.25, tries=2)
    np.testing.assert_allclose(r, [0.0, 0.1, 0.0, 0.0])
    assert asked == [(1, 0.4), (1, 0.1), (2, 0.4), (2, 0.1)]
    A_, C, B = corner(w, 1, 0.1)
    np.testing.assert_allclose([A_, C, B], [[0.9, 0.0], [1.0, 0.0], [1.0, 0.1]])


def test_bezier_samples_keep_the_step():
    """Between two samples no joint moves more than the resolution, no point (reach 2 m/rad
    for joint 0) more than the Cartesian step."""
    A_, C, B = corner(CORNER, 1, 0.5)
    reach = np.array([2.0, 1.0])
    k = bezier_steps(A_, C, B, reach, 0.01, 0.005)
    q = bezier_points(A_, C, B, np.linspace(0, 1, 20 * k + 1))
    fine = np.abs(np.diff(q, axis=0))  # 20 fine steps per sample interval
    per_interval = fine.reshape(k, 20, 2).sum(axis=1)  # how far each joint travels per interval
    assert per_interval.max() <= 0.01 + 1e-12
    assert (per_interval @ reach).max() <= 0.005 + 1e-12


def test_just_before_a_stop_the_motion_decelerates_along_the_incoming_segment():
    """At a corner without a blend, the one-sided acceleration from below belongs to the
    segment that ends there (along x), not to the one that starts there (along y): the
    grid point's time itself and the time just before it differ."""
    path = blended_path(CORNER, [0.0, 0.0, 0.0])
    timing = time_optimal(path, V, A)
    t1 = float(np.interp(1.0, timing.s, timing.t))
    _, _, before = trajectory(path, timing, np.array([np.nextafter(t1, -np.inf)]))
    _, _, after = trajectory(path, timing, np.array([t1]))
    assert before[0, 0] < 0 and before[0, 1] == 0  # braking along +x
    assert after[0, 0] == 0 and after[0, 1] > 0  # accelerating along +y
