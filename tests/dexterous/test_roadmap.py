"""Finger gaiting on `builtin:hand4` (four 3-DoF fingers round a palm, seed 003's hand)
holding a 7 cm sphere: the GS_n tree reaches a goal orientation more than a radian away,
and what it returns is physically feasible piece by piece (§IV): every transfer keeps the
fingertips on its contacts (rolling on) while the object moves a little at a time, every
regrasp keeps the object still while the other fingers hold it in force closure and ends
on a force-closure grasp, and each piece starts where the previous one ended."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from regrasp_cli.dexterous.gait import GaitOptions, Regrasp, Transfer, carry, finger_step, reduce_path, reversed_path
from regrasp_cli.dexterous.gsn import GsScratch, gs_path
from regrasp_cli.dexterous.hand import tip_targets
from regrasp_cli.dexterous.roadmap import (GaitTreeOptions, _reach_ahead, _turns, aimed_regrasp, connect, grow,
                                           grow_connect, start_config, step_towards, tree_budgets)
from regrasp_cli.dexterous.smooth import smooth
from regrasp_cli.spatial import inverse


@pytest.fixture(scope="module")
def gs(hand4_ball):
    return hand4_ball


def _goal(angle: float, axis) -> np.ndarray:
    X = np.eye(4)
    X[:3, :3] = Rotation.from_rotvec(angle * np.asarray(axis, float) / np.linalg.norm(axis)).as_matrix()
    return X


def _assert_feasible(s: GsScratch, pieces, start):
    state_q, state_X, p = start.q, start.X_GO, start.p
    for piece in pieces:
        assert np.allclose(piece.q[0], state_q, atol=1e-9)
        if isinstance(piece, Transfer):
            assert np.allclose(piece.X_GO[0], state_X) and np.allclose(piece.p[0], p)
            for X, q, pk, nk in zip(piece.X_GO, piece.q, piece.p, piece.n):
                tips = s.hand.tips(s.kin, q)
                assert np.abs(tips - tip_targets(s.X_WG @ X, pk, nk, s.hand.radii)).max() < 3e-4
                assert s.closure(pk, nk) > 0
            # the fingertips roll: their contacts move on, less than the tip's travel
            assert np.linalg.norm(piece.p[-1] - piece.p[0], axis=1).max() < 0.02
            dX = [np.linalg.norm(a[:3, 3] - b[:3, 3]) for a, b in zip(piece.X_GO, piece.X_GO[1:])]
            dR = [Rotation.from_matrix(a[:3, :3].T @ b[:3, :3]).magnitude() for a, b in zip(piece.X_GO, piece.X_GO[1:])]
            assert max(dX, default=0) <= s.options.step_m + 1e-9 and max(dR, default=0) <= s.options.step_rad + 1e-9
            state_X = piece.X_GO[-1]
        else:
            assert isinstance(piece, Regrasp)
            f = piece.finger
            assert np.allclose(piece.before.X_GO, state_X) and np.allclose(piece.before.p, p)
            assert s.holds(piece.before.p, piece.before.n, f)  # the others hold it
            assert s.closure(piece.after.p, piece.after.n) > 0
            others = [k for k in range(len(p)) if k != f]
            assert np.allclose(piece.after.p[others], p[others])  # only finger f moved
            fixed = [i for i in range(len(state_q)) if i not in set(s.hm.hand.finger_idx[f])]
            assert np.allclose(piece.q[:, fixed], piece.q[0, fixed])  # only its joints
            tips = s.hand.tips(s.kin, piece.q[-1])
            assert np.abs(tips - tip_targets(s.X_WG @ state_X, piece.after.p, piece.after.n,
                                             s.hand.radii)).max() < 3e-4
        state_q, p = piece.q[-1], piece.end.p
    return state_X


def test_the_tree_turns_a_sphere_by_finger_gaiting(gs):
    s = gs
    rng = np.random.default_rng(0)
    o = GaitTreeOptions(nodes=150)
    start = start_config(s, np.eye(4), rng, o)
    assert start is not None and len(s.liftable(start)) == 4
    goal = _goal(1.3, [1.0, 0.5, 0.2])
    pieces, tree, stats = grow(s, start, goal, rng, o)
    assert pieces is not None and stats.kept >= 2
    end = _assert_feasible(s, pieces, start)
    assert np.allclose(end, goal, atol=1e-9)
    kinds = {type(p) for p in pieces}
    assert kinds == {Transfer, Regrasp}  # it had to gait: the fingers alone cannot turn it 1.3 rad


def test_two_trees_turn_a_sphere_from_the_start_grasp_to_a_grasp_at_the_goal(gs):
    """The goal tree's path is run backwards: the whole path starts at the start grasp, is
    feasible piece by piece, and ends exactly on the goal tree's root grasp."""
    s = gs
    rng = np.random.default_rng(6)
    o = GaitTreeOptions(nodes=300)
    start = start_config(s, np.eye(4), rng, o)
    goal = start_config(s, _goal(2.5, [0.3, 1.0, -0.4]), rng, o)
    pieces, trees, stats = grow_connect(s, start, goal, rng, o)
    assert pieces is not None and len(trees[1].nodes) >= 2  # the goal tree grew
    assert np.allclose(_assert_feasible(s, pieces, start), goal.X_GO, atol=1e-9)
    assert np.allclose(pieces[-1].q[-1], goal.q) and np.allclose(pieces[-1].end.p, goal.p)


def test_a_path_run_backwards_is_feasible_from_its_end(gs):
    s = gs
    rng = np.random.default_rng(7)
    o = GaitTreeOptions(nodes=60)
    start = start_config(s, np.eye(4), rng, o)
    pieces, _, _ = grow(s, start, _goal(0.8, [0, 1, 0]), rng, o)
    assert pieces is not None and {type(p) for p in pieces} == {Transfer, Regrasp}
    back = reversed_path(pieces)
    assert np.allclose(_assert_feasible(s, back, pieces[-1].end), start.X_GO)
    assert np.allclose(back[-1].q[-1], start.q)


def test_two_grasps_at_nearby_poses_are_joined_by_a_transfer_and_regrasps(gs):
    """§V's transfer-regrasp sequence between two GS_n configurations: it ends exactly on
    the second one (pose, contacts and joints)."""
    s = gs
    rng = np.random.default_rng(8)
    o = GaitTreeOptions()
    a = start_config(s, np.eye(4), rng, o)
    joined = 0
    for k in range(6):
        b = start_config(s, _goal(0.2, [1.0, k, 0.5]), rng, GaitTreeOptions(start_samples=10))
        link = None if b is None else connect(s, a, b, rng, o, GaitOptions())
        if link is None:
            continue
        joined += 1
        assert np.allclose(_assert_feasible(s, link, a), b.X_GO)
        assert np.allclose(link[-1].q[-1], b.q) and np.allclose(link[-1].end.p, b.p)
    assert joined >= 2


def test_a_gs_n_path_reduces_to_transfers_and_regrasps_near_it(gs):
    """Over eight seeds (start grasps and paths), the GS_n paths that reduce end at their
    goal, on the path's contacts, through feasible pieces; about half the seeds get there
    (a GS_n path or its reduction may fail: the roadmap then tries other edges)."""
    s = gs
    reduced = 0
    for seed in range(8):
        rng = np.random.default_rng(seed)
        start = start_config(s, np.eye(4), rng, GaitTreeOptions())
        X = step_towards(start.X_GO, _goal(1.0, [0, 1, 0]), 0.3, 0.01)
        # the contacts slide to where the fingertips are once the sphere has turned
        c_G = (inverse(s.X_WG) @ np.c_[s.hand.tips(s.kin, start.q), np.ones(4)].T)
        tri, uv = s.surface.locate((inverse(X) @ c_G)[:3].T)
        steps = gs_path(s, start, X, s.surface.points(tri, uv), rng)
        pieces = reduce_path(s, [start] + steps, rng) if steps else None
        if pieces is None:
            continue
        reduced += 1
        assert np.allclose(_assert_feasible(s, pieces, start), X)
        assert np.abs(pieces[-1].end.p - steps[-1].p).max() < 0.004  # ends on the path's contacts
    assert reduced >= 3


def test_a_finger_that_the_others_cannot_spare_does_not_step(gs):
    s = gs
    rng = np.random.default_rng(2)
    start = start_config(s, np.eye(4), rng, GaitTreeOptions())
    # three contacts on one side of the sphere cannot hold it: drop all but two fingers'
    # support by moving them to the first finger's side, then no finger may step
    p, n = start.p.copy(), start.n.copy()
    p[1:3], n[1:3] = p[0], n[0]
    weak = type(start)(start.X_GO, p, n, start.q)
    assert not s.holds(p, n, 3)
    assert finger_step(s, weak, 3, start.p[3], start.n[3], rng) is None


def _turns_of(s, c, poses):
    each = np.stack([_reach_ahead(s, f, c.p[f:f + 1], c.n[f:f + 1], poses)[:, 0] for f in range(len(c.p))], axis=1)
    return int(_turns(each.all(axis=1)[:, None])[0])


def test_an_aimed_regrasp_lets_the_object_turn_further_towards_the_goal(gs):
    """Where the fingertips cannot follow the next turns (a contact leaves its finger's
    workspace), the aimed regrasp moves one finger so that they can follow more of them,
    then carries the object one edge towards the goal when it can, all physically
    feasible."""
    s, o = gs, GaitTreeOptions(regrasp_carry=True)
    rng = np.random.default_rng(3)
    start = start_config(s, np.eye(4), rng, o)
    tried = improved = carried = 0
    for k, axis in enumerate(([1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 0], [0, 1, 1], [1, 0, 1])):
        goal = _goal(3.0, axis)
        poses = np.stack([step_towards(start.X_GO, goal, j * o.step_rad, j * o.step_m) for j in (1, 2, 3)])
        before = _turns_of(s, start, poses)
        if before == 3:
            continue  # nothing to aim for
        tried += 1
        pieces = aimed_regrasp(s, start, goal, np.random.default_rng(k), o, GaitOptions())
        if pieces is None:
            continue
        improved += 1
        assert isinstance(pieces[0], Regrasp) and _turns_of(s, pieces[0].after, poses) > before
        end = poses[0] if len(pieces) == 2 else start.X_GO
        assert [type(p) for p in pieces] in ([Regrasp], [Regrasp, Transfer])
        carried += len(pieces) == 2
        assert np.allclose(_assert_feasible(s, pieces, start), end)
    assert tried >= 4 and improved >= 2 and carried >= 1


def test_smoothing_steps_a_finger_once_where_it_stepped_twice(gs):
    """A finger that steps twice between two transfers steps once, straight to where it
    ended, and the path still starts and ends at the same configurations."""
    s = gs
    rng = np.random.default_rng(5)
    start = start_config(s, np.eye(4), rng, GaitTreeOptions())
    f = next(iter(s.liftable(start)))
    first = None
    for k in rng.permutation(len(s.sampled.points)):  # two steps of finger f, the second onwards
        p, n = s.sampled.points[k], s.sampled.normals[k]
        if np.linalg.norm(p - start.p[f]) > 0.012 or np.linalg.norm(p - start.p[f]) < 0.004:
            continue
        step = finger_step(s, start if first is None else first.after, f, p, n, rng)
        if step is not None and first is None:
            first = step
        elif step is not None and s.liftable(first.after):
            second = step
            break
    else:
        pytest.fail("no two steps of one finger found")
    turn = carry(s, second.after, _goal(0.2, [0, 0, 1]), rng, s.options.step_m, s.options.step_rad, GaitOptions())
    assert turn is not None
    pieces = [first, second, turn]
    smoothed = smooth(s, pieces, rng)
    assert [type(p) for p in smoothed] == [Regrasp, Transfer]
    assert np.array_equal(smoothed[0].after.q, second.after.q)
    assert np.allclose(_assert_feasible(s, smoothed, start), _assert_feasible(s, pieces, start))


@pytest.mark.parametrize("total, first", [(1500, 0), (1500, 150), (1500, 200), (100, 150), (1000, 1)])
def test_tree_budgets_spend_the_budget_on_doubling_trees(total, first):
    b = tree_budgets(total, first)
    assert sum(b) == total and all(x > 0 for x in b)
    if first == 0:
        assert b == [total]
    else:
        assert b[0] == min(first, total)
        assert all(b[k + 1] == 2 * b[k] for k in range(len(b) - 2))  # doubling, but the last
        assert len(b) == 1 or b[-1] >= b[-2] // 2  # the last is not a stub


def test_a_step_whose_other_fingers_hold_only_at_the_boundary_is_refused(gs, monkeypatch):
    """The quick closure test (no epsilon) says the others hold; the exact one, with the
    validator's margin, says they do not: the step is not kept."""
    s = gs
    rng = np.random.default_rng(9)
    start = start_config(s, np.eye(4), rng, GaitTreeOptions())
    f = next(iter(s.liftable(start)))
    target = next(k for k in rng.permutation(len(s.sampled.points))
                  if 0.004 < np.linalg.norm(s.sampled.points[k] - start.p[f]) < 0.012
                  and finger_step(s, start, f, s.sampled.points[k], s.sampled.normals[k],
                                  np.random.default_rng(1)) is not None)
    monkeypatch.setattr(s, "closed", lambda p, n, without=None: False)
    assert finger_step(s, start, f, s.sampled.points[target], s.sampled.normals[target],
                       np.random.default_rng(1)) is None


def test_a_lifted_fingertip_gets_no_contact_tolerance(gs):
    """Issue 42: a finger that lets go must stay off the object until its new contact.
    Lifting straight off along the normal and coming back is clear; the same with a
    waypoint that puts the fingertip back 1 mm into the ball (within the 2 mm that
    touching fingertips get) is not."""
    from regrasp_cli.dexterous.gait import lifts_clear
    from regrasp_cli.model.ik import finger_ik

    s = gs
    rng = np.random.default_rng(3)
    start = start_config(s, np.eye(4), rng, GaitTreeOptions())
    X_WO = s.X_WG @ start.X_GO

    def at(f, depth):  # finger f with its fingertip sphere ``depth`` off its contact (m), or None
        c_O = start.p[f] + (s.hand.radii[f] + depth) * start.n[f]
        ik = finger_ik(s.hm.robot, s.hm.hand.side, f, X_WO[:3, :3] @ c_O + X_WO[:3, 3], start.q, rng)
        return ik.q if ik.success else None

    # a finger that may let go and can rise 1 cm straight off its contact
    f = next(f for f in s.liftable(start) if at(f, 0.01) is not None)
    up, inside = at(f, 0.01), at(f, -0.001)
    assert inside is not None and lifts_clear(s, [start.q, up, start.q], f, X_WO, 0.01)
    assert not lifts_clear(s, [start.q, inside, up, start.q], f, X_WO, 0.01)
