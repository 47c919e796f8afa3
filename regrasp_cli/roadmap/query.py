"""Query helpers over the Super Graph for online planning (Saut et al. 2010, §V-B).

The roadmap is immutable; everything a query learns (nodes and edges found invalid once
the object is taken into account) lives in a :class:`QueryMemo` beside it, never in it.
Shortest paths run Dijkstra (scipy's csgraph, in C: networkx's took a tenth of a planning
run) on the edges the memo does not hide, from a virtual node joined to the sources to one
joined to the targets, so that the lengths of the start and goal connections count.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra


@dataclass
class QueryMemo:
    """Per-query scratch: invalid nodes and edges, and validated edges (for lazy checks)."""

    invalid_nodes: set[int] = field(default_factory=set)
    invalid_edges: set[frozenset[int]] = field(default_factory=set)
    valid_edges: set[frozenset[int]] = field(default_factory=set)


def shortest_path(edges: np.ndarray, lengths: np.ndarray, n_nodes: int, sources: list[tuple[int, float]],
                  targets: list[tuple[int, float]], memo: QueryMemo | None = None) -> list[int] | None:
    """Shortest node path from any source to any target (each with the length of its
    connection) over the undirected ``edges`` (k, 2) of ``lengths`` (k,), skipping what
    ``memo`` hides; None when there is none.  Unknown or hidden sources and targets are
    ignored."""
    memo = memo or QueryMemo()
    edges = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    keep = np.ones(len(edges), dtype=bool)
    if memo.invalid_nodes:
        keep &= ~np.isin(edges, np.fromiter(memo.invalid_nodes, dtype=np.int64)).any(axis=1)
    if memo.invalid_edges:
        # one integer key per undirected edge, so that a re-search does not loop in Python
        # over every edge of the graph
        lo, hi = np.sort(edges, axis=1).T
        hidden = np.array([min(e) * (n_nodes + 1) + max(e) for e in memo.invalid_edges], dtype=np.int64)
        keep &= ~np.isin(lo * (n_nodes + 1) + hi, hidden)
    usable = lambda i: 0 <= i < n_nodes and i not in memo.invalid_nodes  # noqa: E731
    src = [(int(i), float(d)) for i, d in sources if usable(i)]
    dst = [(int(i), float(d)) for i, d in targets if usable(i)]
    if not src or not dst:
        return None
    e, w = edges[keep], np.asarray(lengths, float)[keep] + 1e-12  # csgraph drops zero weights
    S, T = n_nodes, n_nodes + 1
    rows = np.concatenate([e[:, 0], e[:, 1], np.full(len(src), S), [i for i, _ in dst]]).astype(np.int64)
    cols = np.concatenate([e[:, 1], e[:, 0], [i for i, _ in src], np.full(len(dst), T)]).astype(np.int64)
    data = np.concatenate([w, w, [d + 1e-12 for _, d in src], [d + 1e-12 for _, d in dst]])
    # several virtual edges may join the same pair: csr_matrix would add them up
    order = np.lexsort((data, cols, rows))
    rows, cols, data = rows[order], cols[order], data[order]
    first = np.ones(len(rows), dtype=bool)
    first[1:] = (rows[1:] != rows[:-1]) | (cols[1:] != cols[:-1])
    graph = csr_matrix((data[first], (rows[first], cols[first])), shape=(n_nodes + 2, n_nodes + 2))
    dist, pred = dijkstra(graph, directed=True, indices=S, return_predecessors=True)
    if not np.isfinite(dist[T]):
        return None
    path, k = [], int(pred[T])
    while k != S:
        path.append(k)
        k = int(pred[k])
    return path[::-1]
