"""Query helpers over the Super Graph (regrasp_cli.roadmap.query): connecting a
configuration to its nearest nodes, and shortest paths that skip what a QueryMemo hides
without modifying the graph."""

from __future__ import annotations

import networkx as nx
import numpy as np
import pytest

from regrasp_cli.roadmap.query import QueryMemo, connect, shortest_path

# --------------------------------------------------------------------------- connect

NODES = np.array([[3.0, 0.0], [1.0, 0.0], [-2.0, 0.0], [0.0, 4.0], [0.5, 0.0]])
W = np.ones(2)


def blocked_at(*bad: int):
    calls = []

    def segment_free(q0, q1):
        calls.append(q1.copy())
        return not any(np.array_equal(q1, NODES[b]) for b in bad)

    return segment_free, calls


def test_connect_returns_joined_nodes_nearest_first():
    seg, calls = blocked_at(1)
    got = connect(NODES, np.zeros(2), W, seg, k=10)
    # distances: 4 -> 0.5, 1 -> 1 (blocked), 2 -> 2, 0 -> 3, 3 -> 4
    assert [i for i, _ in got] == [4, 2, 0, 3]
    assert [d for _, d in got] == pytest.approx([0.5, 2.0, 3.0, 4.0])
    assert len(calls) == 5
    assert all(isinstance(i, int) and isinstance(d, float) for i, d in got)


def test_connect_only_tries_the_k_nearest():
    seg, calls = blocked_at(4)
    got = connect(NODES, np.zeros(2), W, seg, k=3)
    assert [i for i, _ in got] == [1, 2]
    assert len(calls) == 3


def test_connect_uses_the_weights():
    seg, _ = blocked_at()
    got = connect(NODES, np.zeros(2), np.array([1.0, 0.01]), seg, k=2)  # y is cheap: node 3 at 0.4
    assert [i for i, _ in got] == [3, 4]
    assert got[0][1] == pytest.approx(0.4)


def test_connect_skips_invalid_nodes_without_checking_them():
    seg, calls = blocked_at()
    memo = QueryMemo(invalid_nodes={4, 0})
    got = connect(NODES, np.zeros(2), W, seg, k=10, memo=memo)
    assert [i for i, _ in got] == [1, 2, 3]
    assert len(calls) == 3


# --------------------------------------------------------------------------- shortest_path


@pytest.fixture
def graph() -> nx.Graph:
    """0 -1- 1 -1- 2 -1- 5, 0 -2- 3 -2- 5, 0 -10- 4 -10- 5, 6 alone."""
    g = nx.Graph()
    g.add_nodes_from(range(7))
    for a, b, w in ((0, 1, 1.0), (1, 2, 1.0), (2, 5, 1.0), (0, 3, 2.0), (3, 5, 2.0), (0, 4, 10.0), (4, 5, 10.0)):
        g.add_edge(a, b, length=w)
    return g


def snapshot(g: nx.Graph):
    return sorted(g.nodes(data=True)), sorted((min(a, b), max(a, b), dict(d)) for a, b, d in g.edges(data=True))


def test_shortest_path_known(graph):
    before = snapshot(graph)
    assert shortest_path(graph, [(0, 0.0)], [(5, 0.0)]) == [0, 1, 2, 5]
    assert snapshot(graph) == before


def test_shortest_path_avoids_a_hidden_edge(graph):
    before = snapshot(graph)
    memo = QueryMemo(invalid_edges={frozenset((1, 2))})
    assert shortest_path(graph, [(0, 0.0)], [(5, 0.0)], memo) == [0, 3, 5]
    memo.invalid_edges.add(frozenset((5, 3)))
    assert shortest_path(graph, [(0, 0.0)], [(5, 0.0)], memo) == [0, 4, 5]
    assert snapshot(graph) == before


def test_shortest_path_avoids_a_hidden_node(graph):
    assert shortest_path(graph, [(0, 0.0)], [(5, 0.0)], QueryMemo(invalid_nodes={2})) == [0, 3, 5]


def test_shortest_path_none_when_every_route_is_hidden(graph):
    before = snapshot(graph)
    memo = QueryMemo(invalid_edges={frozenset((2, 5)), frozenset((3, 5)), frozenset((4, 5))})
    assert shortest_path(graph, [(0, 0.0)], [(5, 0.0)], memo) is None
    assert shortest_path(graph, [(0, 0.0)], [(6, 0.0)]) is None  # another component
    assert shortest_path(graph, [(0, 0.0)], [(5, 0.0)], QueryMemo(invalid_nodes={5})) is None
    assert shortest_path(graph, [(0, 0.0)], [(5, 0.0)], QueryMemo(invalid_nodes={0})) is None
    assert snapshot(graph) == before


def test_shortest_path_counts_the_connections(graph):
    # from 0 (connection 5) the cheapest total is 5 + 3 = 8; from 4 (connection 0.5): 0.5 + 10
    assert shortest_path(graph, [(0, 5.0), (4, 0.5)], [(5, 0.0)]) == [0, 1, 2, 5]
    # from 3 (connection 0.1): 0.1 + 2 beats 0 + 3 via 0 -> 1 -> 2 -> 5
    assert shortest_path(graph, [(0, 0.0), (3, 0.1)], [(5, 0.0)]) == [3, 5]
    # two targets: 2 is reached at 2 + 4 = 6, 5 at 3 + 0 = 3
    assert shortest_path(graph, [(0, 0.0)], [(2, 4.0), (5, 0.0)]) == [0, 1, 2, 5]
    # a single node when a source is a target
    assert shortest_path(graph, [(1, 0.0)], [(1, 0.0)]) == [1]


def test_shortest_path_ignores_unknown_sources(graph):
    assert shortest_path(graph, [(99, 0.0), (0, 0.0)], [(5, 0.0)]) == [0, 1, 2, 5]


def test_memo_weight():
    memo = QueryMemo(invalid_nodes={3}, invalid_edges={frozenset((1, 2))})
    assert memo.weight(0, 1, {"length": 2.5}) == 2.5
    assert memo.weight(2, 1, {"length": 2.5}) is None
    assert memo.weight(3, 0, {"length": 2.5}) is None
    assert QueryMemo().valid_edges == set()


def test_shortest_path_on_a_built_super_graph_is_a_chain_of_edges():
    """A real (tiny) Super Graph through the same helpers: the path follows stored edges."""
    from regrasp_cli.roadmap.compose import SuperGraph
    from regrasp_cli.roadmap.build import RoadmapArtefact
    from regrasp_cli.roadmap.visprm import Roadmap

    nodes = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    edges = np.array([[0, 1], [1, 2], [2, 3]])
    empty = Roadmap(np.zeros((0, 2)), np.zeros((0, 2), dtype=np.int64), np.zeros(0), np.zeros(0, dtype=bool), 0)
    art = RoadmapArtefact(empty, empty, SuperGraph(nodes, np.zeros((4, 3), dtype=np.int64), edges,
                                                   np.ones(3), 4, 3), ("a", "b"), np.ones(2))
    g = art.networkx()
    assert nx.get_edge_attributes(g, "length") == {(0, 1): 1.0, (1, 2): 1.0, (2, 3): 1.0}
    start = connect(nodes, np.array([-0.1, 0.0]), art.weights, lambda a, b: True, k=1)
    goal = connect(nodes, np.array([-0.1, 1.0]), art.weights, lambda a, b: True, k=1)
    assert start == [(0, pytest.approx(0.1))] and goal == [(3, pytest.approx(0.1))]
    assert shortest_path(g, start, goal) == [0, 1, 2, 3]
