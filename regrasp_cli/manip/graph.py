"""The manipulation graph of Harada et al. 2014 (§IV, Fig. 5) and its search for the
fewest regrasps (§IV-C-5, §V).

A :class:`Node` is a configuration of CG_h∩CP: hand ``h`` holds the object with grasp
``k`` while it rests at placement ``p`` (the initial placement ``start``, the target
``goal``, or an intermediate one).  Edges, each one transition of the robot:

* ``arrive``: from the robot's start configuration, a transit to a node at ``start`` (the
  hand then closes);
* ``transfer``: the same hand and grasp, the object carried from one placement to another
  (a transfer path in CG_h);
* ``regrasp``: at an intermediate placement, the hand opens, the robot moves (a transit
  path in CP), a hand closes with another grasp: the Type-2 connection of two nodes of
  one placement (§III-D; a Type-1 edge (g1, p1) -> (g2, p2) is a transfer to (g1, p2)
  followed by this, so the graph holds only realizable Type-2 pieces);
* ``handover``: hand ``a`` lifts the object from its placement, hands it to the other
  hand in the air (CG_r∩CG_l, the exchange of Saut et al. 2010), which puts it down at
  its placement;
* ``inhand``: the hand lifts the object from its placement with one grasp, turns it in
  its fingers to another grasp of the same hand by finger gaiting while the arm holds
  still (seed 003), and puts it down at its placement: for hands that can gait (three
  or more fingertips, both grasps touching with every finger);
* ``leave``: from a node at ``goal``, the hand opens and the robot goes to its goal
  configuration.

A ``regrasp``, ``handover`` or ``inhand`` edge changes the grasp (one regrasp each): the search minimises their number
first and the path length second (Dijkstra on the pair), over edges not yet found
infeasible.  The graph is lazy: a task proposes the best path, solves its motions, and
blocks the edges that fail, as Saut et al. 2010's lazy revalidation does for paths
(§V-B); nothing here knows a robot.  :func:`fewest_regrasps` is a separate, plain
fix-point count used to check the search in tests and benchmarks.
"""

from __future__ import annotations

import heapq
import itertools
from dataclasses import dataclass
from enum import Enum
from typing import Callable, Iterable

START, GOAL = "start", "goal"


class EdgeKind(str, Enum):
    ARRIVE = "arrive"
    TRANSFER = "transfer"
    REGRASP = "regrasp"
    HANDOVER = "handover"
    INHAND = "inhand"
    LEAVE = "leave"

    @property
    def regrasps(self) -> int:
        return int(self in (EdgeKind.REGRASP, EdgeKind.HANDOVER, EdgeKind.INHAND))


@dataclass(frozen=True, order=True)
class Node:
    hand: str
    grasp: int
    placement: str


@dataclass(frozen=True)
class Edge:
    """``a`` None for ``arrive`` (from the robot's start), ``b`` None for ``leave``."""

    kind: EdgeKind
    a: Node | None
    b: Node | None


@dataclass(frozen=True)
class Style:
    """Which edges a manipulation may use (``--style``): ``one-arm`` picks and places with
    one hand; ``handover`` adds hand-overs in the air; ``inhand`` turns the object in the
    hand's fingers; ``place-regrasp`` puts the object down at intermediate placements and
    grasps it again; ``auto`` all of them (tried one style at a time, in the order of
    :data:`manip.tasks.manipulation.LEVELS`)."""

    name: str
    handover: bool
    placements: bool  # intermediate placements (regrasp edges)
    inhand: bool = False


# auto turns the object in the hand last (manip.tasks.manipulation.LEVELS says why)
STYLES = {s.name: s for s in (Style("auto", True, True, True), Style("one-arm", False, False),
                               Style("handover", True, False), Style("inhand", False, False, True),
                               Style("place-regrasp", False, True))}


def style_of(path: list[Edge]) -> str:
    """The style a path uses: ``one-arm`` without regrasp, ``handover``, ``inhand`` or
    ``place-regrasp`` when only that move changes the grasp, joined by ``+`` when several
    do (``handover+place-regrasp``)."""
    kinds = {e.kind for e in path}
    used = [name for name, kind in (("handover", EdgeKind.HANDOVER), ("inhand", EdgeKind.INHAND),
                                    ("place-regrasp", EdgeKind.REGRASP)) if kind in kinds]
    return "+".join(used) or "one-arm"


def ruled_out(style: Style, usable: dict[tuple[str, str], frozenset], placements: bool,
              gaits: frozenset[str] = frozenset()) -> str:
    """Why ``style`` cannot succeed, from necessary conditions alone, or "" when it may.

    ``usable[(hand, end)]``: the grasps of ``hand`` that may hold the object at ``end``
    (START or GOAL), a superset of those with a node there (every node's grasp is among
    them); ``placements``: whether intermediate placements exist.  Each style's paths
    need (Harada et al. 2014 §IV-C, Fig. 5): one arm, a node of one hand at both ends
    with the same grasp (a transfer keeps it); a hand-over, a node of one hand at the
    start and of the other at the goal; place and regrasp, a node at each end and a
    placement between; in the hand, a hand that can finger-gait (``gaits``) with a node at
    each end."""
    hands = list(dict.fromkeys(h for h, _ in usable))

    def count(h: str) -> str:
        return f"{h} hand {len(usable[h, START])} at the start, {len(usable[h, GOAL])} at the goal"

    if style.inhand and not style.handover and not style.placements:
        if not gaits:
            return "no hand can turn the object in its fingers (finger gaiting needs three or more fingertips)"
        if not any(usable[h, START] and usable[h, GOAL] for h in hands if h in gaits):
            return ("no hand that can turn the object in its fingers can hold it at both the start and the goal "
                    "(" + "; ".join(count(h) for h in hands if h in gaits) + ")")
        return ""
    if not style.handover and not style.placements:
        if not any(usable[h, START] & usable[h, GOAL] for h in hands):
            return ("no hand can hold the object at both the start and the goal with one grasp (grasps clear of the "
                    "obstacles that the arm reaches: " + "; ".join(
                        f"{count(h)}, {len(usable[h, START] & usable[h, GOAL])} at both" for h in hands) + ")")
        return ""
    at = {end: [h for h in hands if usable[h, end]] for end in (START, GOAL)}
    if not at[START] or not at[GOAL]:
        end = "start" if not at[START] else "goal"
        return (f"no hand can hold the object at its {end} pose (no grasp clears the obstacles where the arm "
                f"reaches: " + "; ".join(count(h) for h in hands) + ")")
    if style.handover and not style.placements and not any(h != o for h in at[START] for o in at[GOAL]):
        return ("no hand can hold the object at the start while the other holds it at the goal (grasps clear of the "
                "obstacles that the arm reaches: " + "; ".join(count(h) for h in hands) + ")")
    if style.placements and not style.handover and not placements:
        return "no intermediate placement: the object has no stable placement"
    return ""


def successors(nodes: Iterable[Node], style: Style, compatible: Callable[[Node, Node], bool],
               turnable: Callable[[Node, Node], bool] = lambda a, b: False):
    """``out(a)`` -> the edges leaving ``a`` (None: the robot's start) among ``nodes``
    that ``style`` allows; ``compatible(a, b)`` says whether two hands' grasps can hold
    the object together (for a hand-over), ``turnable(a, b)`` whether the hand can
    finger-gait from ``a``'s grasp to ``b``'s (same hand)."""
    nodes = sorted(set(nodes))
    by_grasp: dict[tuple[str, int], list[Node]] = {}
    by_place: dict[str, list[Node]] = {}
    for n in nodes:
        by_grasp.setdefault((n.hand, n.grasp), []).append(n)
        by_place.setdefault(n.placement, []).append(n)

    def out(a: Node | None) -> list[Edge]:
        if a is None:
            return [Edge(EdgeKind.ARRIVE, None, b) for b in by_place.get(START, [])]
        edges = [Edge(EdgeKind.TRANSFER, a, b) for b in by_grasp[(a.hand, a.grasp)] if b.placement != a.placement
                 and (style.placements or b.placement == GOAL)]
        if style.placements and a.placement not in (START, GOAL):
            edges += [Edge(EdgeKind.REGRASP, a, b) for b in by_place[a.placement] if b != a]
        if style.handover:
            edges += [Edge(EdgeKind.HANDOVER, a, b) for b in nodes if b.hand != a.hand and
                      b.placement != a.placement and (style.placements or b.placement == GOAL) and compatible(a, b)]
        if style.inhand:
            edges += [Edge(EdgeKind.INHAND, a, b) for b in nodes if b.hand == a.hand and b.grasp != a.grasp and
                      b.placement != a.placement and (style.placements or b.placement == GOAL) and turnable(a, b)]
        if a.placement == GOAL:
            edges.append(Edge(EdgeKind.LEAVE, a, None))
        return edges
    return out


def search(out, length: Callable[[Edge], float], blocked: set[Edge] = frozenset()) -> list[Edge] | None:
    """The path from the robot's start to its goal of fewest regrasps, then shortest
    (``length`` of each edge >= 0), avoiding ``blocked`` edges; None when there is none."""
    tie = itertools.count()
    best = {None: (0, 0.0)}
    back: dict = {}
    heap = [(0, 0.0, next(tie), None)]
    done = set()
    while heap:
        r, d, _, a = heapq.heappop(heap)
        if a in done:
            continue
        done.add(a)
        if a == GOAL:
            path, n = [], GOAL
            while n is not None:
                e = back[n]
                path.append(e)
                n = e.a
            return path[::-1]
        for e in out(a):
            if e in blocked:
                continue
            b = GOAL if e.b is None else e.b
            cost = (r + e.kind.regrasps, d + length(e))
            if b not in done and cost < best.get(b, (float("inf"), 0.0)):
                best[b], back[b] = cost, e
                heapq.heappush(heap, (*cost, next(tie), b))
    return None


def fewest_regrasps(nodes: Iterable[Node], out, feasible: Callable[[Edge], bool], limit: int = 10,
                    witness: bool = False):
    """The least number of regrasps of any path from the robot's start to its goal over
    the ``feasible`` edges, by a plain fix point (the nodes reached with r regrasps,
    closed under the edges that change no grasp, then one more regrasp); None when no path
    has ``limit`` or fewer.  Independent of :func:`search`, to check it.  With
    ``witness``, (count, one such path as a list of edges, or None)."""
    parent: dict = {}

    def close(reached: set) -> set:
        todo = list(reached)
        while todo:
            for e in out(todo.pop()):
                if e.kind.regrasps == 0 and feasible(e):
                    b = GOAL if e.b is None else e.b
                    if b not in reached:
                        reached.add(b)
                        parent[b] = e
                        if b != GOAL:
                            todo.append(b)
        return reached

    def found(r: int):
        if not witness:
            return r
        path, n = [], GOAL
        while n is not None:
            path.append(parent[n])
            n = parent[n].a
        return r, path[::-1]

    reached = close({None})
    for r in range(limit + 1):
        if GOAL in reached:
            return found(r)
        more = {}
        for a in reached - {GOAL}:
            for e in out(a):
                if e.kind.regrasps and e.b not in reached and e.b not in more and feasible(e):
                    more[e.b] = e
        if not more:
            break
        parent.update(more)
        reached = close(reached | set(more))
    return (None, None) if witness else None


def type2(a: Node, b: Node) -> tuple[list[Edge], list[Edge]]:
    """The two Type-2 paths a Type-1 edge a -> b (§III-D, Fig. 4: another grasp at another
    placement, not physically realizable as such) expands to: Type-2a, a transfer to
    (g_a, p_b) then a regrasp there; Type-2b, a regrasp to (g_b, p_a) then a transfer.
    A piece between equal nodes is left out (a == b gives two empty paths)."""
    via_a, via_b = Node(a.hand, a.grasp, b.placement), Node(b.hand, b.grasp, a.placement)
    t2a = [Edge(EdgeKind.TRANSFER, a, via_a), Edge(EdgeKind.REGRASP, via_a, b)]
    t2b = [Edge(EdgeKind.REGRASP, a, via_b), Edge(EdgeKind.TRANSFER, via_b, b)]
    return ([e for e in t2a if e.a != e.b], [e for e in t2b if e.a != e.b])


def optimise(path: list[Edge], connect: Callable[[list[Edge]], bool], rounds: int = 10) -> list[Edge]:
    """Harada et al. 2014 §V, Fig. 6, iterated until nothing changes: two transfers in a
    row become one transfer (transfer-transfer), two regrasps at one placement one regrasp
    (transit-transit), and two Type-2 pairs (transfer + regrasp, twice) one Type-2 pair
    from the first node to the last (Type2-Type2), when ``connect(edges)`` says the
    replacement's motions exist (it solves them; an empty replacement, a move there and
    back, always does).  Fewer regrasps or placements, never more."""
    path = list(path)
    for _ in range(rounds):
        changed = False
        i = 0
        while i < len(path) - 1:
            e, f = path[i], path[i + 1]
            new = None
            if e.kind == f.kind and e.kind in (EdgeKind.TRANSFER, EdgeKind.REGRASP):
                new = [] if e.a == f.b else [Edge(e.kind, e.a, f.b)]  # there and back: nothing
            elif (i + 3 < len(path) and [x.kind for x in path[i:i + 4]] == [EdgeKind.TRANSFER, EdgeKind.REGRASP] * 2
                  and e.a.placement != path[i + 3].b.placement):
                new = next((t for t in type2(e.a, path[i + 3].b) if len(t) == 2 and connect(t)), None)
                if new is not None:
                    path[i:i + 4] = new
                    changed = True
                    continue
            if new is not None and connect(new):
                path[i:i + 2] = new
                changed = True
                continue
            i += 1
        if not changed:
            break
    return path
