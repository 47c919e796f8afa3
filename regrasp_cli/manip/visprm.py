"""Visibility-PRM over CG_r∩CP and CG_l∩CP with Type-1 steering (Harada et al. 2014,
§IV-B-2; the algorithm of Siméon, Laumond and Nissoux 2000).

A configuration is a :class:`graph.Node` (hand, grasp, placement).  A sample is kept only
when it is a *guard* (no guard of any component sees it: it covers a region nothing
else does) or a *connector* (it sees guards of two components or more, which it joins);
every other sample is dropped.  Sampling stops when the initial and target components
are joined, or after ``max_failures`` samples in a row that were neither (the roadmap
then covers about 1 - 1/max_failures of the space, after Siméon et al.), or after
``samples`` samples.  The roadmap is small by design: few nodes, few regrasps (§IV-B-2).

Type-1 steering.  A Type-1 path (g1, p1) -> (g2, p2) moves grasp and placement at once
inside CG_h∩CP; it is not realizable, and by the reduction property (§III-D) it is
replaced by a Type-2 path: a transfer to (g1, p2) then a regrasp there, or a regrasp to
(g2, p1) then a transfer.  Our grasps are a finite list, so there is no straight line
between two of them to follow; the steering method here is that reduction itself: ``a``
sees ``b`` when they share a grasp (one transfer) or a placement (one regrasp, either
hand), or when one of the two corner configurations of :func:`graph.type2` exists.
The corners may be of two hands: (g1, p2) of ``a``'s hand, then the other hand takes
the object at p2, and the other way round; those are the Type-2 paths that join
components of CG_r∩CP and CG_l∩CP (§IV-C-1).  The
corners found are kept as nodes, so the graph holds the Type-2 pieces and its search
returns realizable paths.  Motions are not planned here: the search solves them lazily,
as it does for every edge.

Pure: nothing here knows a robot; ``sample`` and ``valid`` (IK and collision) are given.
The growth itself is the one of the elementary roadmaps
(:func:`regrasp_cli.roadmap.visprm.grow_visibility`); what is ours here is the seeing.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

from regrasp_cli.manip.graph import Node, type2
from regrasp_cli.roadmap.visprm import grow_visibility


@dataclass(frozen=True)
class VisOptions:
    samples: int = 60  # samples at most
    max_failures: int = 15  # samples in a row neither guard nor connector before stopping
    corners: int = 8  # distinct corner configurations tried per sample and component (each an IK)


@dataclass
class VisRoadmap:
    guards: list[Node] = field(default_factory=list)
    connectors: list[Node] = field(default_factory=list)
    nodes: set[Node] = field(default_factory=set)  # guards, connectors and the corners that join them
    links: list[tuple[Node, Node]] = field(default_factory=list)  # the Type-1 edges of the roadmap
    samples: int = 0
    invalid: int = 0  # samples with no configuration (IK or collision)
    joined: bool = False  # the initial and target components are one

    def counts(self) -> dict:
        return {"samples": self.samples, "invalid": self.invalid, "guards": len(self.guards),
                "connectors": len(self.connectors), "nodes": len(self.nodes), "joined": self.joined}


def sees(a: Node, b: Node, valid: Callable[[Node], bool], tried: set[Node], budget: int) -> list[Node] | None:
    """The corner nodes through which ``a`` sees ``b`` (none when they share a placement,
    or a hand and its grasp), or None when they do not see each other.  A corner is tried
    only while fewer than ``budget`` corners are in ``tried`` (to which it is added)."""
    if a.placement == b.placement or (a.hand == b.hand and a.grasp == b.grasp):
        return []
    for path in type2(a, b):
        via = path[0].b
        if via not in tried:
            if len(tried) >= budget:
                return None
            tried.add(via)
        if valid(via):
            return [via]
    return None


def visibility_roadmap(start: list[Node], goal: list[Node], sample: Callable[[], Node],
                       valid: Callable[[Node], bool], options: VisOptions = VisOptions()) -> VisRoadmap:
    """The Visibility-PRM whose first two components are the nodes at the initial
    placement (``start``: all reached from the robot's start, so one component) and at the
    target one (``goal``); ``sample()`` draws a configuration (at a new placement, or at
    one sampled before), ``valid(node)`` says whether it exists (memoise it: corners
    repeat).  Invalid samples do not count as failures (most samples of a placement are)."""
    goal = [n for n in goal if n not in start]
    if not start or not goal:
        return VisRoadmap()

    def seen_by(q: Node, nodes: list[Node], guards: dict[int, list[int]]):
        seen = {}
        for c, members in guards.items():
            tried: set[Node] = set()
            for g in sorted(members, key=lambda g: nodes[g].hand != q.hand):  # the same hand's first: fewer corners
                via = sees(q, nodes[g], valid, tried, options.corners)
                if via is not None:
                    seen[c] = (g, via)
                    break
        return seen

    def known(q: Node, vis) -> bool:  # kept, or a corner a connector was joined through
        return q in vis.nodes or any(q in via for _, _, via in vis.links)

    vis = grow_visibility(sample, valid, seen_by, (list(start), goal), max_failures=options.max_failures,
                          max_samples=options.samples, invalid_fails=False, until_joined=True, known=known)
    given = len(start) + len(goal)
    sampled = range(given, len(vis.nodes))
    return VisRoadmap(guards=[vis.nodes[i] for i in sampled if vis.guard[i]],
                      connectors=[vis.nodes[i] for i in sampled if not vis.guard[i]],
                      nodes={vis.nodes[i] for i in sampled} | {n for _, _, via in vis.links for n in via},
                      links=[(vis.nodes[k], vis.nodes[g]) for g, k, _ in vis.links],
                      samples=vis.samples, invalid=vis.invalid, joined=vis.joined)
