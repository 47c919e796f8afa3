"""Timing a solved mode path (regrasp_cli.manip.solve.time_steps) on a small 2-joint
case: blends where the curve check allows, stops where it does not, phases joined in
time, each phase starting where the previous one ended."""

from __future__ import annotations

import numpy as np

from regrasp_cli.manip.modes import Kind, Mode, Transition
from regrasp_cli.manip.solve import Step, join, time_steps
from regrasp_cli.motion.blend import trajectory, blended_path
from regrasp_cli.motion.timing import time_parameterise

V, A = np.array([1.0, 1.0]), np.array([2.0, 2.0])
LINE = np.array([[0.0, 0.0], [0.2, 0.0], [0.4, 0.05]])  # a fixed piece (an approach line)
PATH = np.array([[0.4, 0.05], [1.0, 1.0], [0.2, 1.5], [0.0, 2.0]])  # a query's path


def _steps():
    tr = Transition(Kind.TRANSIT, Mode.resting("start"), Mode.resting("start"), "start")
    return [Step(tr, (LINE, "q")), Step(tr, (PATH[-1:], np.array([[0.0, 2.5]])))]


def test_join_labels_each_segment_with_its_piece():
    w, seg = join([LINE, PATH], [None, "q"])
    np.testing.assert_array_equal(w, np.vstack([LINE, PATH[1:]]))
    assert seg == [None, None, "q", "q", "q"]


def test_blends_where_free_and_stops_where_not():
    asked = []

    def free(step, label, A_, C, B):
        asked.append(label)
        return label == "q"  # corners within the line collide

    phases = time_steps(_steps(), {"q": PATH}, V, A, free)
    first, second = phases
    # corner 1 is between two pieces of the line (label None): a stop; 2, where the line
    # meets the path, and 3 and 4 on it are checked in the query's world
    assert asked.count(None) == 2 and asked.count("q") == 3
    np.testing.assert_array_equal(first.radii > 0, [False, False, True, True, True, False])
    # the motion passes each stop exactly and at rest
    path = blended_path(first.waypoints, first.radii)
    q, qd, _ = trajectory(path, first.timing, first.times[:2])
    np.testing.assert_allclose(q, first.waypoints[:2], atol=1e-12)
    np.testing.assert_allclose(qd, 0.0, atol=1e-12)
    # a two-waypoint phase keeps the trapezoid, and starts when the first one ends
    assert second.timing is None and second.radii is None
    np.testing.assert_allclose(second.times, first.times[-1] + time_parameterise(second.waypoints, V, A))


def test_without_any_free_blend_every_waypoint_is_a_stop():
    phases = time_steps(_steps(), {"q": PATH}, V, A, lambda *_: False)
    w = phases[0].waypoints
    assert phases[0].timing is None
    np.testing.assert_allclose(phases[0].times, time_parameterise(w, V, A))
    blended = time_steps(_steps(), {"q": PATH}, V, A, lambda *_: True)
    assert blended[0].times[-1] < phases[0].times[-1]


def test_an_in_hand_step_keeps_its_poses_and_contacts_on_its_waypoints():
    """The fingers' step is timed stop to stop even where blends are free, with every
    waypoint kept (a repeated one too: it has its own contacts), its object poses and
    contacts beside them, and it starts where the step before it ends."""
    fingers = Mode(inhand="right")
    held = Mode.held(right="right-1")
    w = np.array([[0.0, 0.0], [0.2, 0.0], [0.2, 0.0], [0.2, 0.3]])
    X = np.repeat(np.eye(4)[None], 4, axis=0)
    X[:, 0, 3] = [0.0, 0.01, 0.01, 0.02]
    contacts = tuple(({"finger": "f", "point": np.zeros(3), "normal": np.array([0.0, 0.0, 1.0])},) for _ in range(4))
    steps = [Step(Transition(Kind.TRANSFER, held, held, "lift"), (np.array([[0.0, -0.2], [0.0, 0.0]]),)),
             Step(Transition(Kind.INHAND_TRANSFER, fingers, fingers, "turn", ("right",)), (w,), X, contacts)]
    out = time_steps(steps, {}, np.ones(2), np.ones(2), curve_free=lambda *a: True)
    turn = out[1]
    assert np.array_equal(turn.waypoints, w) and turn.radii is None and turn.timing is None
    assert turn.object_poses is X and turn.contacts is contacts
    assert turn.times[0] == out[0].times[-1] and np.all(np.diff(turn.times) >= 0)
    assert np.allclose(np.diff(turn.times), np.diff(time_parameterise(w, np.ones(2), np.ones(2))))


def test_a_held_object_moves_at_the_held_speed():
    """A transfer (the object held) is timed with the velocity limits times ``held_speed``
    and the accelerations times its square: the same path, ``1 / held_speed`` times as long,
    stops or blends; a transit (nothing held) keeps the arms' speed."""
    held = Mode.held(right="right-0")
    carry = Transition(Kind.TRANSFER, held, held, "carry")
    transit = Transition(Kind.TRANSIT, Mode.resting("start"), Mode.resting("start"), "transit")
    for free in (None, lambda *_: True):
        fast, slow = (time_steps([Step(carry, (LINE, "q"))], {"q": PATH}, V, A, free, k)[0] for k in (1.0, 0.5))
        np.testing.assert_allclose(slow.times, 2.0 * fast.times, rtol=1e-6)
        walk, = time_steps([Step(transit, (LINE, "q"))], {"q": PATH}, V, A, free, 0.5)
        np.testing.assert_allclose(walk.times, fast.times, rtol=1e-12)
