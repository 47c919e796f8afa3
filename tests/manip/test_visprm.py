"""The Visibility-PRM over CG_h∩CP (manip.visprm, Harada et al. 2014 §IV-B-2) on toy
worlds known on paper, where ``valid`` is a table: the initial and target components
joined through a placement where a grasp of the start and one of the goal both exist
(and the graph's search then finds the Type-2 path: one regrasp); a hand that gives the
object to the other at a placement; no roadmap where nothing connects, within its sample
budget; and, on random worlds, guards that see no guard before them, connectors that see
two components or more."""

from __future__ import annotations

import numpy as np
import pytest

from regrasp_cli.manip.graph import GOAL, START, STYLES, Node, search, successors
from regrasp_cli.manip.visprm import VisOptions, sees, visibility_roadmap


def _sampler(rng: np.random.Generator, hands=("right",), grasps=4, placements=3):
    def sample() -> Node:
        return Node(hands[rng.integers(len(hands))], int(rng.integers(grasps)), f"p{rng.integers(placements) + 1}")
    return sample


def _path(nodes):
    return search(successors(nodes, STYLES["place-regrasp"], lambda a, b: True), lambda e: 1.0)


def test_upside_down_joins_start_and_goal_through_one_regrasp():
    # grasp 0 holds the object standing (start) and on its side at p2; grasp 1 holds it on
    # its side at p2 and upside down (goal); nothing else exists
    table = {Node("right", 0, START), Node("right", 0, "p2"), Node("right", 1, "p2"), Node("right", 1, GOAL)}
    rm = visibility_roadmap([Node("right", 0, START)], [Node("right", 1, GOAL)], _sampler(np.random.default_rng(0)),
                            table.__contains__, VisOptions(samples=200))
    assert rm.joined and rm.connectors and rm.nodes <= table
    path = _path(set(rm.nodes) | {Node("right", 0, START), Node("right", 1, GOAL)})
    assert [e.kind.value for e in path] == ["arrive", "transfer", "regrasp", "transfer", "leave"]
    assert {e.a.placement for e in path[1:]} == {START, "p2", GOAL}


def test_one_hand_puts_the_object_down_for_the_other():
    # the right hand reaches the start only, the left the goal only; both reach p1
    table = {Node("right", 0, START), Node("right", 0, "p1"), Node("left", 5, "p1"), Node("left", 5, GOAL)}
    rm = visibility_roadmap([Node("right", 0, START)], [Node("left", 5, GOAL)],
                            _sampler(np.random.default_rng(1), ("right", "left"), grasps=6, placements=2),
                            table.__contains__, VisOptions(samples=300))
    assert rm.joined
    path = _path(set(rm.nodes) | {Node("right", 0, START), Node("left", 5, GOAL)})
    assert [e.kind.value for e in path] == ["arrive", "transfer", "regrasp", "transfer", "leave"]
    assert path[2].a.hand == "right" and path[2].b.hand == "left" and path[2].a.placement == "p1"


def test_nothing_joins_where_no_placement_holds_both_grasps():
    table = {Node("right", 0, START), Node("right", 0, "p1"), Node("right", 1, "p2"), Node("right", 1, GOAL)}
    calls = []

    def valid(n: Node) -> bool:
        calls.append(n)
        return n in table

    o = VisOptions(samples=500, max_failures=30)
    rm = visibility_roadmap([Node("right", 0, START)], [Node("right", 1, GOAL)], _sampler(np.random.default_rng(2)),
                            valid, o)
    assert not rm.joined and rm.samples <= o.samples and not rm.connectors
    # (right, 0, p1) sees the start only, (right, 1, p2) the goal only: neither is kept
    assert not rm.guards and not rm.nodes and set(calls) <= table | {Node("right", 1, "p1"), Node("right", 0, "p2"),
                                                                     Node("right", 0, GOAL), Node("right", 1, START)} | {
        Node("right", k, p) for k in range(4) for p in ("p1", "p2", "p3")}
    assert _path(set(rm.nodes) | {Node("right", 0, START), Node("right", 1, GOAL)}) is None


def test_guards_see_no_earlier_guard_and_connectors_join_components():
    """Random sparse worlds (two hands, 10 grasps, 10 placements, 12 % of the nodes
    exist), every corner tried so that visibility is exact."""
    kept = {"guards": 0, "connectors": 0, "joined": 0}
    for seed in range(12):
        rng = np.random.default_rng(seed)
        hands, grasps, places = ("right", "left"), 10, 10
        table = {Node(h, k, f"p{i + 1}") for h in hands for k in range(grasps) for i in range(places)
                 if rng.random() < 0.12}
        start, goal = [Node("right", 0, START)], [Node("left", 1, GOAL)]
        table |= set(start) | set(goal)
        rm = visibility_roadmap(start, goal, _sampler(np.random.default_rng(seed + 100), hands, grasps, places),
                                table.__contains__, VisOptions(samples=400, max_failures=60, corners=1000))
        assert rm.nodes <= table and rm.samples <= 400
        earlier = [start, goal]
        for g in rm.guards:
            for component in earlier:
                assert all(sees(g, other, table.__contains__, set(), 1000) is None for other in component)
            earlier.append([g])
        links = {}
        for q, g in rm.links:
            links.setdefault(q, []).append(g)
        assert set(links) == set(rm.connectors) and all(len(v) >= 2 for v in links.values())
        if rm.joined:  # the graph's search finds the path through the roadmap's nodes
            assert _path(set(rm.nodes) | set(start) | set(goal)) is not None
        kept["guards"] += len(rm.guards)
        kept["connectors"] += len(rm.connectors)
        kept["joined"] += rm.joined
    assert all(kept.values())  # each property was exercised
