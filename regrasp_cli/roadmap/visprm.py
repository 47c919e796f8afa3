"""Visibility-based PRM (Siméon, Laumond & Nissoux 2000; reference [19] of Saut et al.
2010, used for the elementary roadmaps of §V-A).

A sampled configuration that sees (connects by the local planner to) no guard becomes a
new *guard*, starting a component; one that sees guards of at least two components
becomes a *connector*, joined to one guard of each, merging them; any other sample is
dropped.  The roadmap is complete when ``max_failures`` consecutive samples were dropped
(the coverage is then estimated at about 1 - 1/max_failures) or ``max_nodes`` nodes exist.
The result is a compact roadmap, which keeps the composed Super Graph small.

A planner is a function of callables (as caelan/motion-planners does), so it works for any
subsystem: ``sample() -> q``, ``is_free(q)``, ``segment_free(q0, q1)``, ``distance(q0, qs)``,
and optionally ``maybe_free(q0, q1)``, a cheap necessary test.  With it, a sample that
seems to see a single component is dropped without certifying that segment (Vis-PRM would
drop it anyway if it does see it; if it does not, a guard is missed, which only costs
coverage); on the default robot this removed most of the checks of the elementary
roadmaps, which are spent certifying visible segments of samples that are then dropped.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np


@dataclass(frozen=True)
class VisPRMOptions:
    max_nodes: int = 50
    max_failures: int = 200  # consecutive dropped samples that end the construction
    max_samples: int = 20000  # hard budget of samples


@dataclass(frozen=True)
class ElementaryRoadmap:
    """Nodes (n, d) in the order they were added, edges (e, 2) with i < j, their lengths
    (e,), whether each node is a guard (n,), and the number of samples drawn."""

    nodes: np.ndarray
    edges: np.ndarray
    lengths: np.ndarray
    guard: np.ndarray
    samples: int

    def neighbours(self) -> list[set[int]]:
        adj: list[set[int]] = [set() for _ in range(len(self.nodes))]
        for a, b in self.edges:
            adj[int(a)].add(int(b))
            adj[int(b)].add(int(a))
        return adj


def visibility_prm(sample: Callable[[], np.ndarray], is_free: Callable[[np.ndarray], bool],
                   segment_free: Callable[[np.ndarray, np.ndarray], bool],
                   distance: Callable[[np.ndarray, np.ndarray], np.ndarray],
                   options: VisPRMOptions = VisPRMOptions(), progress: Callable[[int], None] | None = None,
                   maybe_free: Callable[[np.ndarray, np.ndarray], bool] | None = None) -> ElementaryRoadmap:
    """``maybe_free(q0, q1)``: a cheap test that may only answer False for a segment that
    really collides (e.g. a few samples of it); defaults to ``segment_free``."""
    maybe_free = maybe_free or segment_free
    nodes: list[np.ndarray] = []
    guard: list[bool] = []
    comp: list[int] = []  # component label of each node (the index of its first guard)
    edges: list[tuple[int, int, float]] = []
    failures = samples = dim = 0
    while len(nodes) < options.max_nodes and failures < options.max_failures and samples < options.max_samples:
        samples += 1
        q = sample()
        dim = len(q)
        if not is_free(q):
            failures += 1
            continue
        guards = [i for i in range(len(nodes)) if guard[i]]
        if guards:  # nearest guards first: the likeliest to be visible
            d = distance(q, np.array([nodes[i] for i in guards]))
            guards = [guards[k] for k in np.argsort(d, kind="stable")]
        # Which components does q see?  A cheap test first: a collision found among the
        # first samples of a segment proves it invisible; a segment that passes is only
        # "maybe visible".  Every decision that stores something is proven: a guard is only
        # made when every guard was proven invisible, a connector's edges are certified.
        # A sample that maybe sees one component is dropped without certifying that segment
        # (dropping is always safe): this is where Vis-PRM spends most of its checks.
        maybe: dict[int, int] = {}  # component -> a guard that passed the cheap test
        for g in guards:
            if comp[g] not in maybe and maybe_free(q, nodes[g]):
                maybe[comp[g]] = g
        seen: dict[int, int] = {}  # component -> a guard certified visible
        if len(maybe) >= 2:
            for c, g in maybe.items():
                for g2 in [g] + [h for h in guards if comp[h] == c and h != g]:
                    if segment_free(q, nodes[g2]):
                        seen[c] = g2
                        break
            if len(seen) < 2:
                failures += 1
                continue
        elif maybe:
            failures += 1
            continue
        if not seen:
            nodes.append(q)
            guard.append(True)
            comp.append(len(nodes) - 1)
        elif len(seen) >= 2:
            k = len(nodes)
            nodes.append(q)
            guard.append(False)
            merged = min(seen)
            comp.append(merged)
            for c, g in sorted(seen.items()):
                edges.append((min(g, k), max(g, k), float(distance(q, nodes[g]))))
            for i in range(len(comp)):
                if comp[i] in seen:
                    comp[i] = merged
        else:
            failures += 1
            continue
        failures = 0
        if progress:
            progress(len(nodes))
    e = np.array([(a, b) for a, b, _ in edges], dtype=np.int64).reshape(-1, 2)
    lengths = np.array([l for _, _, l in edges], dtype=float)
    return ElementaryRoadmap(np.array(nodes, dtype=float).reshape(len(nodes), dim), e, lengths,
                             np.array(guard, dtype=bool), samples)
