"""The manipulation graph's search (manip.graph) on hand-made graphs known on paper: one
arm when a transfer joins the start and the goal, a hand-over or an intermediate placement
when it does not, fewest regrasps before length, styles that forbid what a path needs, and
the search's regrasp count equal to a plain fix-point count on random graphs."""

from __future__ import annotations

import numpy as np
import pytest

from regrasp_cli.manip.graph import GOAL, START, STYLES, EdgeKind, Node, fewest_regrasps, search, style_of, \
    successors

R0S, R0G = Node("right", 0, START), Node("right", 0, GOAL)
L1G = Node("left", 1, GOAL)
R0P, R1P, R1G = Node("right", 0, "p1"), Node("right", 1, "p1"), Node("right", 1, GOAL)


def _always(a, b) -> bool:
    return True


def _kinds(path):
    return [e.kind.value for e in path]


def test_one_arm_when_a_transfer_joins_start_and_goal():
    out = successors([R0S, R0G, L1G], STYLES["auto"], _always)
    path = search(out, lambda e: 1.0)
    assert _kinds(path) == ["arrive", "transfer", "leave"] and style_of(path) == "one-arm"


def test_a_hand_over_when_the_transfer_fails_and_nothing_when_one_arm_is_forced():
    nodes = [R0S, R0G, L1G]
    out = successors(nodes, STYLES["auto"], _always)
    blocked = {e for e in out(R0S) if e.kind == EdgeKind.TRANSFER}
    path = search(out, lambda e: 1.0, blocked)
    assert _kinds(path) == ["arrive", "handover", "leave"] and path[1].b == L1G
    assert style_of(path) == "handover"
    assert search(successors(nodes, STYLES["one-arm"], _always), lambda e: 1.0, blocked) is None
    # hands whose grasps collide cannot hand over
    assert search(successors(nodes, STYLES["auto"], lambda a, b: False), lambda e: 1.0, blocked) is None


def test_fewest_regrasps_before_length():
    out = successors([R0S, R0G, L1G], STYLES["auto"], _always)
    path = search(out, lambda e: 100.0 if e.kind == EdgeKind.TRANSFER else 0.0)
    assert style_of(path) == "one-arm"


def test_an_intermediate_placement_turns_the_grasp():
    # grasp 0 picks at the start, only grasp 1 places at the goal: put down at p1, grasp again
    nodes = [R0S, R0P, R1P, R1G]
    path = search(successors(nodes, STYLES["auto"], _always), lambda e: 1.0)
    assert _kinds(path) == ["arrive", "transfer", "regrasp", "transfer", "leave"]
    assert [e.b for e in path[:-1]] == [R0S, R0P, R1P, R1G] and style_of(path) == "place-regrasp"
    assert search(successors(nodes, STYLES["handover"], _always), lambda e: 1.0) is None
    forced = search(successors(nodes, STYLES["place-regrasp"], _always), lambda e: 1.0)
    assert _kinds(forced) == _kinds(path)


def test_the_search_finds_the_fewest_regrasps_on_random_graphs():
    seen = set()
    for seed in range(40):  # half of the edges infeasible: from no path to 3 regrasps
        rng = np.random.default_rng(seed)
        places = [START, GOAL, "p1", "p2"]
        nodes = {Node(h, int(k), p) for h in ("right", "left") for k in range(3) for p in places if rng.random() < 0.5}
        out = successors(nodes, STYLES["auto"], lambda a, b: (a.grasp + b.grasp) % 3 != 0)
        infeasible = {e for a in [None, *nodes] for e in out(a) if rng.random() < 0.5}
        lengths = {}
        path = search(out, lambda e: lengths.setdefault(e, float(rng.random())), infeasible)
        least = fewest_regrasps(nodes, out, lambda e: e not in infeasible)
        seen.add(least)
        _check(path, least, infeasible)
    assert {None, 0, 1, 2, 3} <= seen


def _check(path, least, infeasible):
    if least is None:
        assert path is None
    else:
        assert sum(e.kind.regrasps for e in path) == least
        assert all(e not in infeasible for e in path)
        assert path[0].kind == EdgeKind.ARRIVE and path[-1].kind == EdgeKind.LEAVE
        assert all(e.b == f.a for e, f in zip(path, path[1:]))  # a connected chain
