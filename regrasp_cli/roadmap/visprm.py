"""Visibility-based PRM (Siméon, Laumond & Nissoux 2000; reference [19] of Saut et al.
2010, used for the elementary roadmaps of §V-A, and by Harada et al. 2014 §IV-B-2 over the
manipulation graph's configurations, :mod:`regrasp_cli.manip.visprm`).

A sampled configuration that sees no guard becomes a new *guard*, starting a component;
one that sees guards of at least two components becomes a *connector*, joined to one
guard of each, merging them; any other sample is dropped.  :func:`grow_visibility` is
that growth once, for any kind of configuration: what "sees" means (and what it costs)
is the caller's.  It stops after ``max_failures`` consecutive dropped samples (the
coverage is then estimated at about 1 - 1/max_failures), ``max_nodes`` kept nodes,
``max_samples`` samples, or (``until_joined``) when the first two given components meet.

:func:`visibility_prm` is the joint-space version: a planner of callables (as
caelan/motion-planners does), so it works for any subsystem: ``sample() -> q``,
``is_free(q)``, ``segment_free(q0, q1)``, ``distance(q0, qs)``, and optionally
``maybe_free(q0, q1)``, a cheap necessary test.  With it, a sample that seems to see a
single component is dropped without certifying that segment (Vis-PRM would drop it anyway
if it does see it; if it does not, a guard is missed, which only costs coverage); on the
default robot this removed most of the checks of the elementary roadmaps, which are spent
certifying visible segments of samples that are then dropped.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Generic, TypeVar

import numpy as np

T = TypeVar("T")


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


@dataclass
class Visibility(Generic[T]):
    """A visibility roadmap: ``nodes`` in the order kept (the given ones first), whether
    each is a ``guard``, its component (``comp``: the index of the component's first
    node), ``links`` (guard index, connector index, the caller's witness of their
    visibility), the samples drawn, those ``valid`` refused, and whether the first two
    given components were joined."""

    nodes: list = field(default_factory=list)
    guard: list[bool] = field(default_factory=list)
    comp: list[int] = field(default_factory=list)
    links: list[tuple[int, int, object]] = field(default_factory=list)
    samples: int = 0
    invalid: int = 0
    joined: bool = False


SeenBy = Callable[[T, list, dict[int, list[int]]], "dict[int, tuple[int, object]] | None"]


def grow_visibility(sample: Callable[[], T], valid: Callable[[T], bool], seen_by: SeenBy,
                    initial: tuple[list, ...] = (), max_nodes: int | None = None, max_failures: int = 200,
                    max_samples: int = 20000, invalid_fails: bool = True, until_joined: bool = False,
                    known: Callable[[T, Visibility], bool] | None = None,
                    progress: Callable[[int], None] | None = None) -> Visibility:
    """Grow a Vis-PRM from the components ``initial`` (each a list of nodes, all guards).

    ``seen_by(q, nodes, guards)``: for the valid sample ``q``, the components it sees,
    ``{label: (index of a guard seen, witness)}`` (``guards``: label -> the indices of its
    guards, in the order they joined), or None to drop ``q`` as seen by one (when the
    caller did not prove it saw none).  A sample ``known(q, roadmap)`` says is there already,
    or (``invalid_fails``) one ``valid`` refuses, counts as a dropped sample.
    ``max_nodes`` counts the nodes kept besides the given ones; ``progress(n)`` is called
    with the node count after each kept node."""
    out = Visibility()
    guards: dict[int, list[int]] = {}
    for members in initial:
        label = len(out.nodes)
        guards[label] = list(range(label, label + len(members)))
        out.nodes += list(members)
        out.guard += [True] * len(members)
        out.comp += [label] * len(members)
    goal = list(guards)[1] if len(guards) > 1 else None
    given, failures = len(out.nodes), 0
    while (out.samples < max_samples and failures < max_failures
           and (max_nodes is None or len(out.nodes) - given < max_nodes)):
        out.samples += 1
        q = sample()
        if known is not None and known(q, out):
            failures += 1
            continue
        if not valid(q):
            out.invalid += 1
            failures += int(invalid_fails)
            continue
        seen = seen_by(q, out.nodes, guards)
        if seen is None or len(seen) == 1:
            failures += 1
            continue
        k = len(out.nodes)
        out.nodes.append(q)
        out.guard.append(not seen)
        if not seen:
            guards[k] = [k]
            out.comp.append(k)
        else:
            keep = min(seen)  # the initial component absorbs; the second disappears only into it
            out.comp.append(keep)
            for c, (g, witness) in sorted(seen.items()):
                out.links.append((g, k, witness))
                if c != keep:
                    guards[keep] += guards.pop(c)
            out.comp = [keep if c in seen else c for c in out.comp]
        failures = 0
        if progress:
            progress(len(out.nodes))
        if until_joined and goal is not None and goal not in guards:
            out.joined = True
            break
    return out


def visibility_prm(sample: Callable[[], np.ndarray], is_free: Callable[[np.ndarray], bool],
                   segment_free: Callable[[np.ndarray, np.ndarray], bool],
                   distance: Callable[[np.ndarray, np.ndarray], np.ndarray],
                   options: VisPRMOptions = VisPRMOptions(), progress: Callable[[int], None] | None = None,
                   maybe_free: Callable[[np.ndarray, np.ndarray], bool] | None = None) -> ElementaryRoadmap:
    """The elementary roadmap of :func:`grow_visibility` over configurations (d,);
    ``maybe_free(q0, q1)``: a cheap test that may only answer False for a segment that
    really collides (e.g. a few samples of it); defaults to ``segment_free``."""
    maybe_free = maybe_free or segment_free

    def seen_by(q, nodes, guards):
        comp = {g: c for c, members in guards.items() for g in members}
        order = sorted(comp)
        if order:  # nearest guards first: the likeliest to be visible
            d = distance(q, np.array([nodes[i] for i in order]))
            order = [order[k] for k in np.argsort(d, kind="stable")]
        # A cheap test first: a collision found among the first samples of a segment proves
        # it invisible; a segment that passes is only "maybe visible".  Every decision that
        # stores something is proven: a guard is only made when every guard was proven
        # invisible, a connector's edges are certified.  A sample that maybe sees one
        # component is dropped without certifying that segment (dropping is always safe):
        # this is where Vis-PRM spends most of its checks.
        maybe: dict[int, int] = {}  # component -> a guard that passed the cheap test
        for g in order:
            if comp[g] not in maybe and maybe_free(q, nodes[g]):
                maybe[comp[g]] = g
        if len(maybe) == 1:
            return None
        seen: dict[int, tuple[int, None]] = {}  # component -> a guard certified visible
        for c, g in maybe.items():
            for g2 in [g] + [h for h in order if comp[h] == c and h != g]:
                if segment_free(q, nodes[g2]):
                    seen[c] = (g2, None)
                    break
        return seen if len(seen) >= 2 or not maybe else None

    dim = [0]

    def draw() -> np.ndarray:
        q = sample()
        dim[0] = len(q)
        return q

    vis = grow_visibility(draw, is_free, seen_by, max_nodes=options.max_nodes, max_failures=options.max_failures,
                          max_samples=options.max_samples, progress=progress)
    e = np.array([(min(g, k), max(g, k)) for g, k, _ in vis.links], dtype=np.int64).reshape(-1, 2)
    lengths = np.array([float(distance(vis.nodes[k], vis.nodes[g])) for g, k, _ in vis.links], dtype=float)
    return ElementaryRoadmap(np.array(vis.nodes, dtype=float).reshape(len(vis.nodes), dim[0]), e, lengths,
                             np.array(vis.guard, dtype=bool), vis.samples)
