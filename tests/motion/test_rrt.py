"""RRT-Connect and shortcut smoothing on a 2-D point robot with known free space."""

from __future__ import annotations

import numpy as np

from regrasp_cli.motion.rrt import RRTOptions, path_length, prune, rrt_connect, shortcut


def euclid(q, qs):
    return np.linalg.norm(np.asarray(qs) - q, axis=-1)


def wall_world(gap_y=(0.45, 0.55)):
    """Unit square with a vertical wall at x in [0.48, 0.52] except for a gap."""

    def free(q):
        inside = np.all((q >= 0.0) & (q <= 1.0))
        in_wall = 0.48 <= q[0] <= 0.52 and not (gap_y[0] <= q[1] <= gap_y[1])
        return bool(inside and not in_wall)

    def segment(q0, q1):
        n = max(2, int(np.ceil(np.linalg.norm(q1 - q0) / 0.002)) + 1)
        return all(free(q0 + t * (q1 - q0)) for t in np.linspace(0.0, 1.0, n))

    return free, segment


def test_straight_line_when_free():
    free, segment = wall_world()
    rng = np.random.default_rng(0)
    res = rrt_connect(np.array([0.1, 0.1]), np.array([0.3, 0.9]), lambda: rng.uniform(0, 1, 2), segment, euclid, rng)
    assert res.path.shape == (2, 2) and res.iterations == 0


def test_path_through_the_gap_is_collision_free():
    free, segment = wall_world()
    start, goal = np.array([0.1, 0.1]), np.array([0.9, 0.9])
    rng = np.random.default_rng(1)
    res = rrt_connect(start, goal, lambda: rng.uniform(0, 1, 2), segment, euclid, rng, RRTOptions(step=0.1))
    assert res.path is not None
    assert np.array_equal(res.path[0], start) and np.array_equal(res.path[-1], goal)
    assert all(segment(a, b) for a, b in zip(res.path[:-1], res.path[1:]))
    # it must cross the wall through the gap
    crossing = [q for q in res.path if 0.45 <= q[0] <= 0.55]
    assert all(0.45 <= q[1] <= 0.55 for q in crossing)


def test_same_seed_same_path():
    free, segment = wall_world()
    paths = []
    for _ in range(2):
        rng = np.random.default_rng(7)
        paths.append(rrt_connect(np.array([0.1, 0.5]), np.array([0.9, 0.2]), lambda: rng.uniform(0, 1, 2),
                                 segment, euclid, rng, RRTOptions(step=0.1)).path)
    assert np.array_equal(paths[0], paths[1])


def test_budget_exhausted_returns_none():
    free, segment = wall_world(gap_y=(2.0, 2.0))  # no gap: the sides are disconnected
    rng = np.random.default_rng(2)
    res = rrt_connect(np.array([0.1, 0.5]), np.array([0.9, 0.5]), lambda: rng.uniform(0, 1, 2), segment, euclid,
                      rng, RRTOptions(step=0.1, max_iterations=150))
    assert res.path is None and res.iterations == 150 and res.nodes > 2


def test_shortcut_keeps_ends_validity_and_never_lengthens():
    free, segment = wall_world()
    rng = np.random.default_rng(3)
    start, goal = np.array([0.1, 0.1]), np.array([0.9, 0.9])
    path = rrt_connect(start, goal, lambda: rng.uniform(0, 1, 2), segment, euclid, rng, RRTOptions(step=0.05)).path
    before = path_length(path, euclid)
    short = shortcut(path, segment, euclid, np.random.default_rng(4), iterations=200)
    assert np.array_equal(short[0], start) and np.array_equal(short[-1], goal)
    assert all(segment(a, b) for a, b in zip(short[:-1], short[1:]))
    assert path_length(short, euclid) <= before + 1e-12
    # the best path goes through the gap: at least start -> gap -> goal, at most a little longer
    best = np.linalg.norm(np.array([0.5, 0.45]) - start) + np.linalg.norm(goal - np.array([0.5, 0.55]))
    assert path_length(short, euclid) < 1.5 * best


def test_shortcut_of_a_zigzag_in_free_space_is_the_straight_line():
    path = np.array([[0.0, 0.0], [0.2, 0.5], [0.4, 0.0], [0.6, 0.5], [1.0, 0.0]])
    short = shortcut(path, lambda a, b: True, euclid, np.random.default_rng(0), iterations=200)
    assert path_length(short, euclid) < 1.05 * 1.0


def test_prune_keeps_only_the_waypoints_the_wall_needs():
    """A path from the left of the wall to the right through the gap, with extra
    waypoints on each straight stretch: only the two points that turn through the gap
    stay (a corner before and after the wall: a line from the start to the gap's middle
    meets the wall at y = 0.48, below the gap), the ends are kept, and it is free."""
    free, segment = wall_world(gap_y=(0.49, 0.51))
    a, g0, g1, b = np.array([0.1, 0.1]), np.array([0.47, 0.5]), np.array([0.53, 0.5]), np.array([0.9, 0.1])
    path = np.array([a, (a + g0) / 2, g0, (g0 + g1) / 2, g1, g1 + (b - g1) / 3, g1 + 2 * (b - g1) / 3, b])
    out = prune(path, segment)
    np.testing.assert_array_equal(out, np.array([a, g0, g1, b]))
    assert all(segment(p, q) for p, q in zip(out[:-1], out[1:]))
    assert path_length(out, euclid) <= path_length(path, euclid) + 1e-12


def test_prune_of_a_free_zigzag_is_the_straight_line_and_of_two_points_the_same():
    free, segment = wall_world(gap_y=(0.0, 1.0))  # no wall
    zigzag = np.array([[0.1, 0.1], [0.2, 0.4], [0.3, 0.1], [0.4, 0.4]])
    np.testing.assert_array_equal(prune(zigzag, segment), zigzag[[0, -1]])
    two = zigzag[:2]
    np.testing.assert_array_equal(prune(two, segment), two)


def test_partial_shortcut_straightens_one_joint_and_keeps_the_other():
    """Joint 0 detours (0 -> 1 -> 0) while joint 1 climbs: straightening joint 0 alone keeps
    joint 1's waypoints and removes the detour; a check that refuses x < 0.5 at y = 1
    keeps it."""
    from regrasp_cli.motion.rrt import partial_shortcut

    path = np.array([[0.0, 0.0], [1.0, 1.0], [0.0, 2.0]])
    groups = (np.array([0]), np.array([1]))
    out = partial_shortcut(path, lambda a, b: True, groups)
    np.testing.assert_allclose(out, [[0.0, 0.0], [0.0, 1.0], [0.0, 2.0]])
    # the ends exactly, bit for bit, also where a + (b - a) != b in floating point
    odd = np.array([[0.1, 0.0], [0.9, 1.0], [-0.45, 2.0]])  # 0.1 + (-0.45 - 0.1) != -0.45
    out = partial_shortcut(odd, lambda a, b: True, groups)
    assert out[0].tobytes() == odd[0].tobytes() and out[-1].tobytes() == odd[-1].tobytes()
    blocked = partial_shortcut(path, lambda a, b: min(a[0], b[0]) >= 0.5 or max(a[1], b[1]) < 1 or min(a[1], b[1]) > 1,
                               groups)
    np.testing.assert_array_equal(blocked, path)
