"""Visibility PRM (regrasp_cli.roadmap.visprm) on a 2-D point robot in [0, 1]^2 with a
disc obstacle: exact structural properties of guards and connectors, the stopping rules
and the node budget."""

from __future__ import annotations

import numpy as np
import pytest

from regrasp_cli.roadmap.compose import UnionFind
from regrasp_cli.roadmap.visprm import ElementaryRoadmap, VisPRMOptions, visibility_prm

CENTRE, RADIUS = np.array([0.5, 0.5]), 0.3


def is_free(q: np.ndarray) -> bool:
    return bool(np.linalg.norm(q - CENTRE) > RADIUS)


def segment_free(q0: np.ndarray, q1: np.ndarray) -> bool:
    t = np.linspace(0.0, 1.0, 401)[:, None]
    pts = q0 + t * (q1 - q0)
    return bool(np.all(np.linalg.norm(pts - CENTRE, axis=1) > RADIUS))


def euclid(q0: np.ndarray, qs: np.ndarray):
    return np.linalg.norm(np.asarray(qs) - q0, axis=-1)


def planner(seed: int, options: VisPRMOptions, free=is_free, seg=segment_free, progress=None) -> ElementaryRoadmap:
    rng = np.random.default_rng(seed)
    return visibility_prm(lambda: rng.uniform(0.0, 1.0, 2), free, seg, euclid, options, progress)


@pytest.fixture(scope="module")
def disc_roadmap() -> ElementaryRoadmap:
    return planner(3, VisPRMOptions(max_nodes=40, max_failures=150))


def test_shapes_and_free_nodes(disc_roadmap):
    rm = disc_roadmap
    n = len(rm.nodes)
    assert rm.nodes.shape == (n, 2) and rm.guard.shape == (n,) and rm.guard.dtype == bool
    assert rm.edges.shape == (len(rm.lengths), 2) and rm.edges.dtype == np.int64
    assert n >= 4  # the disc needs several guards around it
    assert rm.guard[0]  # the first node is always a guard
    assert all(is_free(q) for q in rm.nodes)
    assert np.all(rm.edges[:, 0] < rm.edges[:, 1])
    assert np.allclose(rm.lengths, np.linalg.norm(rm.nodes[rm.edges[:, 0]] - rm.nodes[rm.edges[:, 1]], axis=1))
    for a, b in rm.edges:
        assert segment_free(rm.nodes[a], rm.nodes[b])
    # an edge always joins a connector to a guard
    for a, b in rm.edges:
        assert rm.guard[a] != rm.guard[b]


def test_guards_are_pairwise_invisible(disc_roadmap):
    rm = disc_roadmap
    guards = np.flatnonzero(rm.guard)
    assert len(guards) >= 2
    for x in range(len(guards)):
        for y in range(x + 1, len(guards)):
            assert not segment_free(rm.nodes[guards[x]], rm.nodes[guards[y]]), (guards[x], guards[y])


def test_every_connector_joins_guards_of_different_components_at_creation(disc_roadmap):
    rm = disc_roadmap
    uf = UnionFind(len(rm.nodes))
    connectors = 0
    for k in range(len(rm.nodes)):
        mine = rm.edges[rm.edges[:, 1] == k]
        if rm.guard[k]:
            assert len(mine) == 0  # a guard is created alone
            continue
        connectors += 1
        others = [int(a) for a in mine[:, 0]]
        assert len(others) >= 2, (k, others)
        assert all(rm.guard[g] for g in others)
        roots = [uf.find(g) for g in others]
        assert len(set(roots)) == len(roots), (k, others)  # one guard per component, all different
        for g in others:
            uf.union(g, k)
    assert connectors >= 1
    # edges only ever come from connectors (no edge to a later node)
    assert sum(int((rm.edges[:, 1] == k).sum()) for k in range(len(rm.nodes)) if not rm.guard[k]) == len(rm.edges)


def test_no_obstacle_gives_a_single_guard():
    calls = []
    rm = planner(0, VisPRMOptions(max_nodes=50, max_failures=200), free=lambda q: True,
                 seg=lambda a, b: True, progress=calls.append)
    assert len(rm.nodes) == 1 and bool(rm.guard[0])
    assert rm.edges.shape == (0, 2) and rm.lengths.shape == (0,)
    # one sample makes the guard, then max_failures consecutive samples are dropped
    assert rm.samples == 1 + 200
    assert calls == [1]


@pytest.mark.parametrize("max_nodes", [1, 3, 6])
def test_node_budget_is_respected(max_nodes):
    rm = planner(5, VisPRMOptions(max_nodes=max_nodes, max_failures=10_000))
    assert len(rm.nodes) == max_nodes  # the disc leaves room for more: the budget stops it


def test_sample_budget_is_respected():
    # every sample collides: only max_samples are drawn (max_failures is larger)
    rm = planner(0, VisPRMOptions(max_nodes=10, max_failures=1000, max_samples=37), free=lambda q: False)
    assert rm.samples == 37 and len(rm.nodes) == 0
    assert rm.nodes.shape == (0, 2) and rm.edges.shape == (0, 2) and rm.guard.shape == (0,)


def test_same_seed_same_roadmap(disc_roadmap):
    again = planner(3, VisPRMOptions(max_nodes=40, max_failures=150))
    for name in ("nodes", "edges", "lengths", "guard"):
        assert np.array_equal(getattr(again, name), getattr(disc_roadmap, name)), name
    assert again.samples == disc_roadmap.samples


def test_neighbours(disc_roadmap):
    adj = disc_roadmap.neighbours()
    assert len(adj) == len(disc_roadmap.nodes)
    assert sum(len(s) for s in adj) == 2 * len(disc_roadmap.edges)
    for a, b in disc_roadmap.edges:
        assert int(b) in adj[int(a)] and int(a) in adj[int(b)]


def test_cheap_visibility_test_keeps_guards_invisible_and_connectors_certified():
    """With a cheap necessary test (only a few samples of each segment), guards are still
    pairwise invisible and every stored edge is certified by the exact test."""
    import numpy as np

    from regrasp_cli.roadmap.visprm import VisPRMOptions, visibility_prm

    centre, radius = np.array([0.5, 0.5]), 0.2

    def free(q):
        return np.linalg.norm(q - centre) > radius

    def segment(q0, q1, n=200):
        return all(free(q0 + t * (q1 - q0)) for t in np.linspace(0.0, 1.0, n))

    rng = np.random.default_rng(4)
    rm = visibility_prm(lambda: rng.uniform(0.0, 1.0, 2), free, segment,
                        lambda q, qs: np.linalg.norm(np.asarray(qs) - q, axis=-1),
                        VisPRMOptions(max_nodes=30, max_failures=300),
                        maybe_free=lambda q0, q1: segment(q0, q1, n=3))
    guards = np.flatnonzero(rm.guard)
    assert len(guards) >= 2
    for i in guards:
        for j in guards:
            if i < j:
                assert not segment(rm.nodes[i], rm.nodes[j])
    for a, b in rm.edges:
        assert segment(rm.nodes[a], rm.nodes[b])
