"""Composition of the elementary roadmaps into the Super Graph
(regrasp_cli.roadmap.compose): link parts, margins, pair filters, node assembly,
candidate edges on hand-made cases with exact answers, union-find, and purity (the
inputs are never modified)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from regrasp_cli.roadmap.compose import (COMMON, LEFT, OBSTACLE, RIGHT, UnionFind, candidate_edges, compose_nodes,
                                         edge_kind, hand_links, involving, link_parts, margin_rule, mixed,
                                         part_filter, subsystem)
from regrasp_cli.roadmap.visprm import ElementaryRoadmap

SCENE_YAML = Path(__file__).resolve().parents[2] / "configs" / "scenes" / "desk_handover.yaml"

OPTS_NODES = 10  # the same small roadmap as tests/roadmap/test_build.py (shared through the cache)


# --------------------------------------------------------------------------- parts and margins


def test_link_parts_of_the_default_robot(robot):
    parts = link_parts(robot)
    assert set(parts) == {f.name for f in robot.model.frames}
    for name, part in parts.items():
        if name.startswith("r_"):
            assert part == RIGHT, name
        elif name.startswith("l_"):
            assert part == LEFT, name
        else:
            assert part == COMMON, name
    for torso in ("base_link", "torso_1", "torso_2", "chest"):
        assert parts[torso] == COMMON
    for link in ("r_arm_link1", "r_arm_link4", "r_palm", "r_thumb_tip"):
        assert parts[link] == RIGHT
    for link in ("l_arm_link1", "l_arm_link4", "l_palm", "l_index_tip"):
        assert parts[link] == LEFT


def test_hand_links(robot):
    hands = hand_links(robot)
    for side in "rl":
        for link in ("palm", "index_tip", "thumb_proximal", "grasp_frame"):
            assert f"{side}_{link}" in hands
        for link in ("arm_link1", "arm_link4"):
            assert f"{side}_{link}" not in hands
    assert "chest" not in hands and "torso_1" not in hands


def test_margin_rule(robot):
    m = margin_rule(robot, 0.015)
    # two links of the same open hand: rigid with each other, no margin
    assert m("r_palm", "r_index_tip") == 0.0
    assert m("r_index_tip", "r_thumb_tip") == 0.0
    assert m("l_thumb_proximal", "l_palm") == 0.0
    # anything else keeps the margin
    assert m("r_palm", "l_palm") == 0.015
    assert m("r_index_tip", "l_index_tip") == 0.015
    assert m("r_palm", "chest") == 0.015
    assert m("r_palm", "r_arm_link4") == 0.015
    assert m("l_palm", "obstacle:desk_top") == 0.015
    assert m("chest", "obstacle:vase_body") == 0.015


def test_part_filter_and_rules():
    parts = {"r_a": RIGHT, "l_a": LEFT, "t": COMMON}
    seen = []
    f = part_filter(parts, lambda a, b: seen.append((a, b)) or True)
    f("r_a", "obstacle:box")
    f("l_a", "unknown_link")
    assert seen == [(RIGHT, OBSTACLE), (LEFT, COMMON)]

    right = part_filter(parts, subsystem(RIGHT))
    assert right("r_a", "t") and right("r_a", "obstacle:x") and right("t", "t") and right("r_a", "r_a")
    assert not right("l_a", "t") and not right("r_a", "l_a") and not right("l_a", "obstacle:x")
    left = part_filter(parts, subsystem(LEFT))
    assert left("l_a", "t") and not left("r_a", "obstacle:x")

    inv = involving(LEFT)
    assert inv(LEFT, COMMON) and inv(RIGHT, LEFT) and inv(OBSTACLE, LEFT)
    assert not inv(LEFT, LEFT) and not inv(RIGHT, COMMON) and not inv(COMMON, OBSTACLE)

    assert mixed(RIGHT, LEFT) and mixed(COMMON, COMMON) and mixed(RIGHT, OBSTACLE) and mixed(COMMON, LEFT)
    assert not mixed(RIGHT, RIGHT) and not mixed(LEFT, LEFT)


# --------------------------------------------------------------------------- nodes


def test_compose_nodes_assembles_configurations(robot):
    t, ra, la = robot.groups["torso"], robot.groups["right_arm"], robot.groups["left_arm"]
    nt = len(t)
    base = np.linspace(-0.1, 0.1, robot.nq)
    r_nodes = np.array([np.full(nt + len(ra), 0.1), np.full(nt + len(ra), 0.2)])
    l_nodes = np.array([np.full(nt + len(la), 0.3), np.full(nt + len(la), 0.1)])  # l1 shares r0's torso
    calls = {"right": [], "left": []}

    def right_ok(q):
        calls["right"].append(q.copy())
        return True

    def left_ok(q):
        calls["left"].append(q.copy())
        return not np.allclose(q[t], 0.3)  # every candidate with l0's torso collides

    nodes, source, tested = compose_nodes(robot, base, r_nodes, l_nodes, right_ok, left_ok)
    # (0,0): both torsos; (0,1): the same torso twice, tested once; (1,0), (1,1): both
    assert tested == 7
    assert len(calls["right"]) == 4 and len(calls["left"]) == 3
    assert source.tolist() == [[0, 0, 0], [0, 1, 0], [1, 0, 0], [1, 1, 0], [1, 1, 1]]
    assert nodes.shape == (5, robot.nq)
    other = np.setdiff1d(np.arange(robot.nq), np.concatenate([t, ra, la]))
    for q, (i, j, s) in zip(nodes, source):
        torso = (r_nodes[i] if s == 0 else l_nodes[j])[:nt]
        assert np.array_equal(q[t], torso)
        assert np.array_equal(q[ra], r_nodes[i][nt:])
        assert np.array_equal(q[la], l_nodes[j][nt:])
        assert np.array_equal(q[other], base[other])


def test_compose_nodes_with_nothing(robot):
    nt = len(robot.groups["torso"])
    empty = np.zeros((0, nt + 7))
    nodes, source, tested = compose_nodes(robot, robot.q_rest, empty, np.ones((3, nt + 7)), bool, bool)
    assert nodes.shape == (0, robot.nq) and source.shape == (0, 3) and tested == 0


# --------------------------------------------------------------------------- candidate edges


def all_eight_sources() -> np.ndarray:
    return np.array([(i, j, s) for i in (0, 1) for j in (0, 1) for s in (0, 1)], dtype=np.int64)


def _qualifies(source, r_adj, l_adj, a, b) -> bool:
    """The defining property of a candidate edge, the slow way: parts equal or adjacent on
    both sides, and the same torso source unless it is a torso swap."""
    (i, j, s), (i2, j2, s2) = source[a], source[b]
    parts = (i == i2 or i2 in r_adj[i]) and (j == j2 or j2 in l_adj[j])
    return bool(parts and (s == s2 or (i == i2 and j == j2)))


def test_candidate_edges_tiny_complete_case():
    """R_r: 0-1; R_l: 0-1; all 8 Super Graph candidates present: the 6 pairs within each
    torso source and the 4 torso swaps."""
    source = all_eight_sources()
    r_adj, l_adj = [{1}, {0}], [{1}, {0}]
    got = candidate_edges(source, r_adj, l_adj)
    expected = [(a, b) for a in range(8) for b in range(a + 1, 8) if _qualifies(source, r_adj, l_adj, a, b)]
    assert got.dtype == np.int64 and got.shape == (16, 2)
    assert [tuple(map(int, p)) for p in got] == expected


def test_candidate_edges_without_adjacency():
    """No elementary edge: only the pairs that differ by the torso source alone."""
    source = all_eight_sources()
    got = candidate_edges(source, [set(), set()], [set(), set()])
    assert [tuple(map(int, p)) for p in got] == [(0, 1), (2, 3), (4, 5), (6, 7)]


def test_candidate_edges_tiny_partial_case():
    """R_r: 0-1, 2 alone; R_l: 0-1; some candidates absent (rejected nodes)."""
    source = np.array([(0, 0, 0), (0, 1, 1), (1, 0, 1), (1, 1, 0), (2, 0, 0), (2, 1, 0)], dtype=np.int64)
    r_adj, l_adj = [{1}, {0}, set()], [{1}, {0}]
    got = [tuple(map(int, p)) for p in candidate_edges(source, r_adj, l_adj)]
    # same torso source: 0-3 (both from R_r, parts adjacent), 1-2 (both from R_l), 4-5
    # (R_r, right part 2 unchanged, left parts adjacent); no swap pair exists here
    assert got == [(0, 3), (1, 2), (4, 5)]
    for a in range(len(source)):
        for b in range(a + 1, len(source)):
            assert _qualifies(source, r_adj, l_adj, a, b) == ((a, b) in got)


def test_candidate_edges_empty():
    assert candidate_edges(np.zeros((0, 3), dtype=np.int64), [], []).shape == (0, 2)


def test_edge_kind():
    source = np.array([(0, 0, 0), (1, 0, 0), (0, 1, 1), (1, 1, 1)])
    assert edge_kind(source, 0, 1) == 0
    assert edge_kind(source, 2, 3) == 1
    assert edge_kind(source, 0, 2) == 2 and edge_kind(source, 3, 1) == 2


# --------------------------------------------------------------------------- union-find


def test_union_find_basics():
    uf = UnionFind(6)
    assert [uf.find(i) for i in range(6)] == list(range(6))
    assert uf.union(0, 1) is True
    assert uf.union(1, 0) is False
    assert uf.union(2, 3) is True and uf.union(3, 4) is True
    assert uf.find(4) == uf.find(2) != uf.find(0)
    assert uf.union(4, 1) is True
    assert len({uf.find(i) for i in range(5)}) == 1
    assert uf.find(5) == 5 and uf.union(2, 0) is False
    assert uf.find(3) == 0  # the smallest index represents its set


# --------------------------------------------------------------------------- purity


@pytest.fixture(scope="module")
def built(problem, cache_dir):
    from regrasp_cli.roadmap.build import RoadmapOptions, load_or_build

    options = RoadmapOptions(nodes=OPTS_NODES)
    return load_or_build(SCENE_YAML, cache_dir, options, jobs=2), options


def _frozen(a: np.ndarray) -> np.ndarray:
    c = np.array(a, copy=True)
    c.setflags(write=False)
    return c


def test_composition_does_not_mutate_its_inputs(built, problem):
    from regrasp_cli.roadmap.build import _worlds, q_base

    art, options = built
    right = ElementaryRoadmap(*(_frozen(getattr(art.right, k)) for k in ("nodes", "edges", "lengths", "guard")),
                            art.right.samples)
    left = ElementaryRoadmap(*(_frozen(getattr(art.left, k)) for k in ("nodes", "edges", "lengths", "guard")),
                           art.left.samples)
    copies = {(side, k): np.array(getattr(rm, k), copy=True) for side, rm in (("right", right), ("left", left))
              for k in ("nodes", "edges", "lengths", "guard")}
    base = _frozen(q_base(problem))
    base_copy = base.copy()
    worlds = _worlds(problem, options)

    nodes, source, tested = compose_nodes(problem.robot, base, right.nodes, left.nodes,
                                          worlds["node_right_torso"].is_free, worlds["node_left_torso"].is_free)
    # the stored Super Graph is what composition gives
    assert np.array_equal(nodes, art.graph.nodes) and np.array_equal(source, art.graph.source)
    assert tested == art.graph.candidates_nodes

    r_adj, l_adj = right.neighbours(), left.neighbours()
    r_adj_copy, l_adj_copy = [set(s) for s in r_adj], [set(s) for s in l_adj]
    source_ro = _frozen(source)
    cand = candidate_edges(source_ro, r_adj, l_adj)
    assert len(cand) == art.graph.candidates_edges
    assert {tuple(e) for e in art.graph.edges.tolist()} <= {tuple(e) for e in cand.tolist()}

    for (side, k), c in copies.items():
        rm = right if side == "right" else left
        assert np.array_equal(getattr(rm, k), c), (side, k)
    assert np.array_equal(base, base_copy)
    assert np.array_equal(source_ro, source)
    assert r_adj == r_adj_copy and l_adj == l_adj_copy
