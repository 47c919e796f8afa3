"""Query helpers over the Super Graph for online planning (Saut et al. 2010, §V-B).

The roadmap is immutable; everything a query learns (nodes and edges found invalid once
the object is taken into account, the start and goal connections) lives in a
:class:`QueryMemo` beside it, never in it.  Shortest paths use networkx with a weight
function that returns None for a hidden edge, networkx's hook for lazy invalidation.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import networkx as nx
import numpy as np

from regrasp_cli.roadmap.local import distance


@dataclass
class QueryMemo:
    """Per-query scratch: invalid nodes and edges, and validated ones (for lazy checks)."""

    invalid_nodes: set[int] = field(default_factory=set)
    invalid_edges: set[frozenset[int]] = field(default_factory=set)
    valid_edges: set[frozenset[int]] = field(default_factory=set)

    def weight(self, u: int, v: int, data: dict) -> float | None:
        if u in self.invalid_nodes or v in self.invalid_nodes or frozenset((u, v)) in self.invalid_edges:
            return None
        return data["length"]


def connect(nodes: np.ndarray, q: np.ndarray, weights: np.ndarray, segment_free: Callable[[np.ndarray, np.ndarray], bool],
            k: int = 10, memo: QueryMemo | None = None) -> list[tuple[int, float]]:
    """Super Graph nodes (index, length) that ``q`` (nq,) joins by the local planner, among
    its ``k`` nearest (weighted distance), nearest first."""
    d = distance(q, nodes, weights)
    out = []
    for i in np.argsort(d, kind="stable")[:k]:
        if memo is not None and int(i) in memo.invalid_nodes:
            continue
        if segment_free(q, nodes[i]):
            out.append((int(i), float(d[i])))
    return out


def shortest_path(graph: nx.Graph, sources: list[tuple[int, float]], targets: list[tuple[int, float]],
                  memo: QueryMemo | None = None) -> list[int] | None:
    """Shortest node path from any source to any target (each with the length of its
    connection), skipping what ``memo`` hides; None when there is none.  ``graph`` is not
    modified: the start and goal are joined through a copy-free view."""
    memo = memo or QueryMemo()
    best, best_cost = None, np.inf
    for s, ls in sources:
        if s in memo.invalid_nodes:
            continue
        try:
            lengths, paths = nx.single_source_dijkstra(graph, s, weight=memo.weight)
        except nx.NodeNotFound:
            continue
        for t, lt in targets:
            if t in lengths and t not in memo.invalid_nodes:
                cost = ls + lengths[t] + lt
                if cost < best_cost:
                    best, best_cost = paths[t], cost
    return best
