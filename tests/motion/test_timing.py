"""Time parameterisation of piecewise-linear joint paths (regrasp_cli.motion.timing):
hand-computed trapezoid and triangle, the limiting joint, the limits and the path on
sampled trajectories, rest and exact positions at the waypoints, zero-length segments,
longer given durations, and input validation."""

from __future__ import annotations

import math

import numpy as np
import pytest

from regrasp_cli.motion.timing import (
    evaluate_trajectory,
    sample_trajectory,
    scaling_limits,
    segment_duration,
    segment_profile,
    time_parameterise,
)

# --------------------------------------------------------------------------- one segment


def test_trapezoid_single_joint_by_hand():
    # dq = 1 rad, v = 0.5 rad/s, a = 1 rad/s^2: ramp 0.5 s (0.125 rad each), cruise
    # 0.75 rad at 0.5 rad/s = 1.5 s, total 0.5 + 1.5 + 0.5 = 2.5 s
    p = segment_profile([1.0], [0.5], [1.0])
    assert p.duration == pytest.approx(2.5, abs=1e-12)
    assert p.ramp == pytest.approx(0.5, abs=1e-12)
    assert p.duration - 2 * p.ramp == pytest.approx(1.5, abs=1e-12)
    assert p.rate == pytest.approx(0.5) and p.accel == pytest.approx(1.0)
    assert not p.triangular
    assert segment_duration([1.0], [0.5], [1.0]) == pytest.approx(2.5, abs=1e-12)
    assert segment_duration([-1.0], [0.5], [1.0]) == pytest.approx(2.5, abs=1e-12)


def test_triangle_single_joint_by_hand():
    # dq = 0.1, v = 1, a = 1: v^2 / a = 1 > 0.1, so 0.05 rad up in sqrt(0.1) s, same down
    p = segment_profile([0.1], [1.0], [1.0])
    assert p.triangular
    assert p.duration == pytest.approx(2 * math.sqrt(0.1), abs=1e-12)
    assert p.ramp == pytest.approx(math.sqrt(0.1), abs=1e-12)
    assert segment_duration([0.1], [1.0], [1.0]) == pytest.approx(2 * math.sqrt(0.1), abs=1e-12)


def test_slower_joint_limits_the_duration():
    v, a = np.array([1.0, 0.5]), np.array([2.0, 1.0])
    # 1 rad on each joint.  Joint 0 alone (v 1, a 2): 1 / 1 + 1 / 2 = 1.5 s; joint 1
    # alone (v 0.5, a 1): 1 / 0.5 + 0.5 / 1 = 2.5 s, so joint 1 sets the duration
    dq = np.array([1.0, 1.0])
    assert segment_duration(dq, v, a) == pytest.approx(2.5, abs=1e-12)
    assert segment_duration(dq[:1], v[:1], a[:1]) == pytest.approx(1.5, abs=1e-12)
    assert segment_duration(dq[1:], v[1:], a[1:]) == pytest.approx(2.5, abs=1e-12)
    s_dot, s_ddot = scaling_limits(dq, v, a)
    assert (s_dot, s_ddot) == (pytest.approx(0.5), pytest.approx(1.0))
    # velocity limited by one joint, acceleration by the other
    s_dot, s_ddot = scaling_limits([2.0, 0.1], [1.0, 1.0], [100.0, 1.0])
    assert (s_dot, s_ddot) == (pytest.approx(0.5), pytest.approx(10.0))
    # a joint that does not move imposes nothing
    assert segment_duration([0.0, 1.0], [1e-6, 0.5], [1e-6, 1.0]) == pytest.approx(2.5, abs=1e-12)


def test_zero_length_segment_takes_no_time():
    assert segment_duration([0.0, 0.0], [1.0, 1.0], [1.0, 1.0]) == 0.0
    assert scaling_limits([0.0, 0.0], [1.0, 1.0], [1.0, 1.0]) == (math.inf, math.inf)


# --------------------------------------------------------------------------- a path

V = np.array([1.0, 0.6, 2.0])
A = np.array([2.0, 1.5, 0.8])
PATH = np.array(
    [
        [0.0, 0.0, 0.0],
        [0.8, -0.4, 0.1],  # trapezoid on joint 0
        [0.8, -0.4, 0.1],  # zero-length segment
        [0.85, -0.38, 0.12],  # short: triangle
        [-0.5, 0.9, -1.0],
        [-0.5, 0.9, 1.5],  # single joint
    ]
)


def test_times_of_a_path():
    times = time_parameterise(PATH, V, A)
    assert times.shape == (len(PATH),) and times[0] == 0.0
    steps = np.diff(times)
    expected = [segment_duration(PATH[i + 1] - PATH[i], V, A) for i in range(len(PATH) - 1)]
    assert steps == pytest.approx(expected, abs=1e-12)
    moves = np.any(np.diff(PATH, axis=0) != 0, axis=1)
    assert np.all(steps[moves] > 0) and np.all(steps[~moves] == 0)
    assert time_parameterise(PATH[:1], V, A).tolist() == [0.0]


@pytest.fixture(scope="module")
def sampled():
    times = time_parameterise(PATH, V, A)
    dt = 1e-3
    t, q, qd = sample_trajectory(PATH, times, V, A, dt)
    return times, dt, t, q, qd


def test_sampling_grid(sampled):
    times, dt, t, q, qd = sampled
    assert t[0] == 0.0 and np.allclose(np.diff(t), dt)
    assert t[-1] >= times[-1] and t[-1] - dt < times[-1]
    assert q.shape == qd.shape == (len(t), PATH.shape[1])
    assert np.allclose(q[0], PATH[0]) and np.allclose(q[-1], PATH[-1]) and np.all(qd[[0, -1]] == 0)


def test_velocity_and_acceleration_limits(sampled):
    times, dt, t, q, qd = sampled
    assert np.all(np.abs(qd) <= V + 1e-9)
    # the velocity is piecewise linear with slopes <= a_max: its difference quotients are
    # averages of the acceleration, so they obey the limit up to rounding
    assert np.all(np.abs(np.diff(qd, axis=0)) / dt <= A * (1 + 1e-6))
    # second differences of positions: averages of the acceleration too
    qdd = (q[2:] - 2 * q[1:-1] + q[:-2]) / dt**2
    assert np.all(np.abs(qdd) <= A * (1 + 1e-4) + 1e-6)
    # the limits are reached: the profiles are time optimal, not merely feasible
    assert np.max(np.abs(qd) / V) > 0.999


def test_samples_stay_on_the_segments(sampled):
    times, dt, t, q, qd = sampled
    k = np.clip(np.searchsorted(times, t, side="right") - 1, 0, len(PATH) - 2)
    q0, dq = PATH[k], PATH[k + 1] - PATH[k]
    norm2 = np.einsum("ij,ij->i", dq, dq)
    moving = norm2 > 0
    s = np.where(moving, np.einsum("ij,ij->i", q - q0, dq) / np.where(moving, norm2, 1.0), 0.0)
    assert np.all(s >= -1e-12) and np.all(s <= 1 + 1e-12)
    assert np.max(np.linalg.norm(q - (q0 + s[:, None] * dq), axis=1)) < 1e-12
    # the velocity points along the segment
    cross = qd - (np.einsum("ij,ij->i", qd, dq) / np.where(moving, norm2, 1.0))[:, None] * dq
    assert np.max(np.abs(cross)) < 1e-12


def test_rest_and_exact_positions_at_the_waypoints():
    times = time_parameterise(PATH, V, A)
    q, qd = evaluate_trajectory(PATH, times, V, A, times)
    assert np.array_equal(q, PATH)
    assert np.all(qd == 0)
    # just around each waypoint the speed is small: it is continuous
    eps = 1e-6
    for t0 in times:
        _, qd_near = evaluate_trajectory(PATH, times, V, A, [t0 - eps, t0 + eps])
        assert np.all(np.abs(qd_near) <= A * eps * (1 + 1e-6))
    # outside the time span the trajectory rests at its end waypoints
    q, qd = evaluate_trajectory(PATH, times, V, A, [-1.0, times[-1] + 1.0])
    assert np.array_equal(q, PATH[[0, -1]]) and np.all(qd == 0)


def test_waypoint_times_on_the_sampling_grid():
    # one joint, 2.5 s trapezoid then 2 sqrt(0.1) s triangle; dt divides 2.5
    path = np.array([[0.0], [1.0], [1.1]])
    times = time_parameterise(path, [0.5], [1.0])
    assert times == pytest.approx([0.0, 2.5, 2.5 + 2 * math.sqrt(0.1)], abs=1e-12)
    t, q, qd = sample_trajectory(path, times, [0.5], [1.0], 0.25)
    i = 10  # t = 2.5 s
    assert t[i] == 2.5 and q[i, 0] == 1.0 and qd[i, 0] == 0.0
    assert qd[2, 0] == pytest.approx(0.5) and q[1, 0] == pytest.approx(1.0 * 0.25**2 / 2)  # a t^2 / 2 at t = 0.25 s
    # cruise from 0.5 to 2 s at 0.5 rad/s
    assert np.allclose(qd[2:9, 0], 0.5)


def test_zero_length_segments_are_kept_as_repeated_times():
    path = np.array([[0.0, 0.0], [0.0, 0.0], [1.0, 0.5], [1.0, 0.5], [1.0, 0.5]])
    v, a = np.array([0.5, 1.0]), np.array([1.0, 1.0])
    times = time_parameterise(path, v, a)
    assert times == pytest.approx([0.0, 0.0, 2.5, 2.5, 2.5], abs=1e-12)
    t, q, qd = sample_trajectory(path, times, v, a, 0.01)
    assert np.all(np.abs(qd) <= v + 1e-9) and np.allclose(q[-1], path[-1])
    q_w, qd_w = evaluate_trajectory(path, times, v, a, times)
    assert np.array_equal(q_w, path) and np.all(qd_w == 0)
    # all waypoints equal: a single sample at rest
    same = np.zeros((3, 2))
    assert time_parameterise(same, v, a).tolist() == [0.0, 0.0, 0.0]
    t, q, qd = sample_trajectory(same, [0.0, 0.0, 0.0], v, a, 0.1)
    assert t.tolist() == [0.0] and np.all(q == 0) and np.all(qd == 0)


def test_longer_given_durations_slow_down_within_limits():
    path = np.array([[0.0, 0.0], [1.0, -0.5], [1.0, -0.5], [0.2, 0.3]])
    v, a = np.array([0.5, 1.0]), np.array([1.0, 2.0])
    fastest = time_parameterise(path, v, a)
    times = np.array([0.0, fastest[1] * 1.7, fastest[1] * 1.7 + 0.4, fastest[1] * 1.7 + 0.4 + 3.0 * fastest[3]])
    q_w, qd_w = evaluate_trajectory(path, times, v, a, times)
    assert np.array_equal(q_w, path) and np.all(qd_w == 0)
    t, q, qd = sample_trajectory(path, times, v, a, 1e-3)
    assert np.all(np.abs(qd) <= v + 1e-9)
    assert np.all(np.abs(np.diff(qd, axis=0)) / 1e-3 <= a * (1 + 1e-6))
    dwell = (t > times[1]) & (t < times[2])
    assert np.all(q[dwell] == path[1]) and np.all(qd[dwell] == 0)
    with pytest.raises(ValueError, match="times: segment 0 -> 1"):
        evaluate_trajectory(path, fastest * 0.99, v, a, [0.0])


# --------------------------------------------------------------------------- validation


@pytest.mark.parametrize(
    "args, match",
    [
        (([1.0, 2.0], [1.0], [1.0]), r"dq: expected shape \(d,\) = \(1,\)"),
        (([1.0], [1.0, 2.0], [1.0]), r"a_max: expected shape \(d,\) = \(2,\)"),
        (([[1.0]], [1.0], [1.0]), r"dq: expected shape"),
        (([1.0], [0.0], [1.0]), r"v_max: .*finite and > 0"),
        (([1.0], [1.0], [-1.0]), r"a_max: .*finite and > 0"),
        (([1.0], [np.inf], [1.0]), r"v_max: .*finite and > 0"),
        (([1.0], [1.0], [np.nan]), r"a_max: .*finite and > 0"),
        (([np.nan], [1.0], [1.0]), r"dq: .*finite"),
        (([1.0], 1.0, [1.0]), r"v_max: expected shape \(d,\)"),
    ],
)
def test_segment_duration_rejects_bad_inputs(args, match):
    with pytest.raises(ValueError, match=match):
        segment_duration(*args)


@pytest.mark.parametrize(
    "waypoints, v, a, match",
    [
        (np.zeros(3), [1.0] * 3, [1.0] * 3, r"waypoints: expected shape \(n, d\)"),
        (np.zeros((0, 3)), [1.0] * 3, [1.0] * 3, r"waypoints: expected shape \(n, d\)"),
        (np.zeros((2, 3)), [1.0] * 2, [1.0] * 3, r"v_max: expected shape \(d,\) = \(3,\)"),
        (np.zeros((2, 3)), [1.0] * 3, [1.0] * 4, r"a_max: expected shape \(d,\) = \(3,\)"),
        (np.array([[0.0, np.inf]]), [1.0] * 2, [1.0] * 2, r"waypoints: .*finite"),
        (np.zeros((2, 2)), [1.0, 0.0], [1.0] * 2, r"v_max: .*> 0"),
        ([["a", "b"]], [1.0] * 2, [1.0] * 2, r"waypoints: expected a float array"),
    ],
)
def test_time_parameterise_rejects_bad_inputs(waypoints, v, a, match):
    with pytest.raises(ValueError, match=match):
        time_parameterise(waypoints, v, a)


def test_sampling_rejects_bad_inputs():
    path = np.array([[0.0], [1.0]])
    times = time_parameterise(path, [0.5], [1.0])
    with pytest.raises(ValueError, match=r"times: expected shape \(n,\) = \(2,\)"):
        sample_trajectory(path, times[:1], [0.5], [1.0], 0.1)
    with pytest.raises(ValueError, match="times: .*finite"):
        sample_trajectory(path, [0.0, np.nan], [0.5], [1.0], 0.1)
    with pytest.raises(ValueError, match="times: segment 0 -> 1"):
        sample_trajectory(path, [0.0, 2.0], [0.5], [1.0], 0.1)
    with pytest.raises(ValueError, match="times: segment 0 -> 1"):
        sample_trajectory(path, [3.0, 0.0], [0.5], [1.0], 0.1)
    for dt in (0.0, -0.1, np.inf, np.nan, "x"):
        with pytest.raises(ValueError, match="dt: "):
            sample_trajectory(path, times, [0.5], [1.0], dt)
    with pytest.raises(ValueError, match="dt: "):
        sample_trajectory(path, times, [0.5], [1.0], 1e-12)
    with pytest.raises(ValueError, match=r"t: expected finite times of shape \(m,\)"):
        evaluate_trajectory(path, times, [0.5], [1.0], [[0.0]])
