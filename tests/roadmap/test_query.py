"""Shortest paths over the Super Graph (regrasp_cli.roadmap.query) that skip what a
QueryMemo hides without modifying the graph."""

from __future__ import annotations

import numpy as np
import pytest

from regrasp_cli.roadmap import query
from regrasp_cli.roadmap.query import QueryMemo

# --------------------------------------------------------------------------- shortest_path


class Graph:
    """0 -1- 1 -1- 2 -1- 5, 0 -2- 3 -2- 5, 0 -10- 4 -10- 5, 6 alone."""

    def __init__(self):
        e = ((0, 1, 1.0), (1, 2, 1.0), (2, 5, 1.0), (0, 3, 2.0), (3, 5, 2.0), (0, 4, 10.0), (4, 5, 10.0))
        self.edges = np.array([(a, b) for a, b, _ in e])
        self.lengths = np.array([w for _, _, w in e])


@pytest.fixture
def graph() -> Graph:
    return Graph()


def snapshot(g: Graph):
    return g.edges.tolist(), g.lengths.tolist()


def shortest_path(g: Graph, sources, targets, memo=None):
    return query.shortest_path(g.edges, g.lengths, 7, sources, targets, memo)


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


def test_shortest_path_on_a_built_super_graph_is_a_chain_of_edges():
    """A real (tiny) Super Graph through the planner's Roadmap: the path follows stored edges."""
    from regrasp_cli.manip.queries import Roadmap as QueryRoadmap
    from regrasp_cli.roadmap.build import RoadmapArtefact
    from regrasp_cli.roadmap.compose import SuperGraph
    from regrasp_cli.roadmap.visprm import ElementaryRoadmap

    nodes = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0], [5.0, 5.0]])
    edges = np.array([[0, 1], [1, 2], [2, 3]])
    empty = ElementaryRoadmap(np.zeros((0, 2)), np.zeros((0, 2), dtype=np.int64), np.zeros(0),
                              np.zeros(0, dtype=bool), 0)
    art = RoadmapArtefact(empty, empty, SuperGraph(nodes, np.zeros((5, 3), dtype=np.int64), edges,
                                                   np.ones(3), 5, 3), ("a", "b"), np.ones(2))
    rm = QueryRoadmap.of(art)
    assert rm.giant.tolist() == [0, 1, 2, 3]  # node 4 is a component of its own
    assert rm.shortest_path([(0, 0.1)], [(3, 0.1)], QueryMemo()) == [0, 1, 2, 3]
    assert rm.shortest_path([(0, 0.1)], [(4, 0.1)], QueryMemo()) is None


def test_shortest_path_takes_the_shortest_of_two_connections_to_one_node(graph):
    # two connections to node 0 (lengths 5 and 1): the shorter one counts
    assert shortest_path(graph, [(0, 5.0), (0, 1.0), (4, 0.5)], [(5, 0.0)]) == [0, 1, 2, 5]
    assert shortest_path(graph, [(0, 9.0), (0, 8.0), (4, 0.5)], [(5, 0.0)]) == [4, 5]
