"""The manipulation graph's search (manip.graph) on hand-made graphs known on paper: one
arm when a transfer joins the start and the goal, a hand-over or an intermediate placement
when it does not, fewest regrasps before length, styles that forbid what a path needs, and
the search's regrasp count equal to a plain fix-point count on random graphs."""

from __future__ import annotations

import numpy as np
import pytest

from regrasp_cli.manip.graph import GOAL, START, STYLES, Edge, EdgeKind, Node, Style, fewest_regrasps, optimise, \
    ruled_out, search, style_of, successors, type2

R0S, R0G = Node("right", 0, START), Node("right", 0, GOAL)
L1G = Node("left", 1, GOAL)
R0P, R1P, R1G = Node("right", 0, "p1"), Node("right", 1, "p1"), Node("right", 1, GOAL)
ANY = Style("any", True, True, True)  # every move, turning the object in the hand too


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


def test_the_in_hand_regrasp_when_it_is_the_only_way():
    """One hand reaches both ends but with no grasp usable at both, no other hand, nowhere
    to put the object down: the hand turns it in its fingers (one regrasp); a hand that
    cannot finger-gait has no path, nor has the one-arm style."""
    nodes = [R0S, R1G]
    path = search(successors(nodes, ANY, _always, _always), lambda e: 1.0)
    assert _kinds(path) == ["arrive", "inhand", "leave"] and (path[1].a, path[1].b) == (R0S, R1G)
    assert style_of(path) == "inhand" and sum(e.kind.regrasps for e in path) == 1
    assert fewest_regrasps(nodes, successors(nodes, ANY, _always, _always), lambda e: True) == 1
    assert search(successors(nodes, ANY, _always), lambda e: 1.0) is None  # no finger gaiting
    assert style_of(search(successors(nodes, STYLES["auto"], _always, _always), lambda e: 1.0)) == "inhand"
    assert search(successors(nodes, STYLES["one-arm"], _always, _always), lambda e: 1.0) is None
    forced = search(successors(nodes, STYLES["inhand"], _always, _always), lambda e: 1.0)
    assert _kinds(forced) == ["arrive", "inhand", "leave"]
    # where a transfer keeps the grasp, no regrasp is needed and none is made
    path = search(successors([R0S, R0G, R1G], ANY, _always, _always), lambda e: 1.0)
    assert style_of(path) == "one-arm"


@pytest.mark.parametrize("turnable", [False, True])
def test_the_search_finds_the_fewest_regrasps_on_random_graphs(turnable):
    seen = set()
    for seed in range(60):  # half of the edges infeasible: from no path to 4 regrasps
        rng = np.random.default_rng(seed)
        places = [START, GOAL, "p1", "p2"]
        nodes = {Node(h, int(k), p) for h in ("right", "left") for k in range(3) for p in places if rng.random() < 0.5}
        out = successors(nodes, ANY, lambda a, b: (a.grasp + b.grasp) % 3 != 0,
                         (lambda a, b: a.hand == "right" and (a.grasp * b.grasp) % 2 == 0) if turnable else
                         (lambda a, b: False))
        infeasible = {e for a in [None, *sorted(nodes)] for e in out(a) if rng.random() < 0.5}
        lengths = {}
        path = search(out, lambda e: lengths.setdefault(e, float(rng.random())), infeasible)
        least = fewest_regrasps(nodes, out, lambda e: e not in infeasible)
        seen.add(least)
        _check(path, least, infeasible)
        count, witness = fewest_regrasps(nodes, out, lambda e: e not in infeasible, witness=True)
        assert count == least
        _check(witness, least, infeasible)  # the fix point's own path is one of fewest regrasps too
    assert {None, 0, 1, 2} | (set() if turnable else {3, 4}) <= seen  # turning in the hand needs fewer


def _check(path, least, infeasible):
    if least is None:
        assert path is None
    else:
        assert sum(e.kind.regrasps for e in path) == least
        assert all(e not in infeasible for e in path)
        assert path[0].kind == EdgeKind.ARRIVE and path[-1].kind == EdgeKind.LEAVE
        assert all(e.b == f.a for e, f in zip(path, path[1:]))  # a connected chain


def test_a_type1_edge_expands_into_the_two_type2_paths():
    a, b = Node("right", 0, "p1"), Node("right", 1, "p2")
    t2a, t2b = type2(a, b)
    assert [(e.kind, e.a, e.b) for e in t2a] == [(EdgeKind.TRANSFER, a, Node("right", 0, "p2")),
                                                 (EdgeKind.REGRASP, Node("right", 0, "p2"), b)]
    assert [(e.kind, e.a, e.b) for e in t2b] == [(EdgeKind.REGRASP, a, Node("right", 1, "p1")),
                                                 (EdgeKind.TRANSFER, Node("right", 1, "p1"), b)]
    assert type2(a, Node("right", 0, "p2"))[0] == [Edge(EdgeKind.TRANSFER, a, Node("right", 0, "p2"))]


def _chain(*nodes_kinds):
    return [Edge(k, a, b) for a, k, b in nodes_kinds]


def test_the_optimiser_merges_two_transfers_and_two_type2_pairs():
    p2 = Node("right", 0, "p2")
    found = _chain((None, EdgeKind.ARRIVE, R0S), (R0S, EdgeKind.TRANSFER, R0P), (R0P, EdgeKind.TRANSFER, p2),
                   (p2, EdgeKind.REGRASP, Node("right", 1, "p2")), (Node("right", 1, "p2"), EdgeKind.TRANSFER, R1G),
                   (R1G, EdgeKind.LEAVE, None))
    tried = []

    def connect(edges):
        tried.append(edges)
        return True
    merged = optimise(found, connect)
    assert tried[0] == [Edge(EdgeKind.TRANSFER, R0S, p2)]  # transfer-transfer first
    assert _kinds(merged) == ["arrive", "transfer", "regrasp", "transfer", "leave"]
    assert merged[1] == Edge(EdgeKind.TRANSFER, R0S, p2)

    # two Type-2 pairs: via p1 and then p2, two regrasps, become one Type-2a pair into goal's grasp
    q1, q2 = Node("right", 2, "p2"), Node("right", 2, GOAL)
    two = _chain((None, EdgeKind.ARRIVE, R0S), (R0S, EdgeKind.TRANSFER, R0P), (R0P, EdgeKind.REGRASP, R1P),
                 (R1P, EdgeKind.TRANSFER, Node("right", 1, "p2")), (Node("right", 1, "p2"), EdgeKind.REGRASP, q1),
                 (q1, EdgeKind.TRANSFER, q2), (q2, EdgeKind.LEAVE, None))
    merged = optimise(two, lambda edges: Node("right", 0, "p2") in [e.b for e in edges])
    assert sum(e.kind.regrasps for e in merged) == 1
    assert merged[1:3] == [Edge(EdgeKind.TRANSFER, R0S, Node("right", 0, "p2")),
                           Edge(EdgeKind.REGRASP, Node("right", 0, "p2"), q1)]
    # nothing connects: the path is kept as found
    assert optimise(two, lambda edges: False) == two


def _usable(rs, rg, ls, lg):
    """(hand, end) -> grasps usable there: right at start, right at goal, left at start, left at goal."""
    return {("right", START): frozenset(rs), ("right", GOAL): frozenset(rg), ("left", START): frozenset(ls),
            ("left", GOAL): frozenset(lg)}


def test_styles_are_ruled_out_by_the_grasps_usable_at_each_end():
    one, over, place = STYLES["one-arm"], STYLES["handover"], STYLES["place-regrasp"]
    # the default scene: the right hand at the start only, the left at the goal only
    u = _usable({1, 2}, set(), set(), {3})
    assert "with one grasp" in ruled_out(one, u, True) and "right hand 2 at the start, 0 at the goal" in \
        ruled_out(one, u, True)
    assert ruled_out(over, u, True) == "" and ruled_out(place, u, True) == ""
    # one hand at both ends, but with different grasps: a transfer keeps the grasp
    u = _usable({1}, {2}, set(), set())
    assert ruled_out(one, u, True) and ruled_out(place, u, True) == ""
    assert "while the other" in ruled_out(over, u, True)
    assert ruled_out(one, _usable({1, 2}, {2}, set(), set()), False) == ""
    # nothing at the goal rules out every style; no stable placement, placing
    u = _usable({1}, set(), {1}, set())
    assert all("at its goal pose" in ruled_out(s, u, True) for s in (over, place))
    assert "stable placement" in ruled_out(place, _usable({1}, {2}, set(), set()), False)
    # in the hand: a hand that can finger-gait, at both ends (any grasps: it turns the object)
    inhand = STYLES["inhand"]
    u = _usable({1}, {2}, set(), set())
    assert ruled_out(inhand, u, False, frozenset({"right"})) == ""
    assert "three or more fingertips" in ruled_out(inhand, u, False)
    assert "at both the start and the goal" in ruled_out(inhand, _usable({1}, set(), set(), {2}), False,
                                                         frozenset({"right", "left"}))
