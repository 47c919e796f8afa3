"""RRT-Connect and shortcut smoothing, as functions of callables.

RRT-Connect (Kuffner & LaValle 2000; reference [12] of Saut et al. 2010) grows a tree from
each end and, at every iteration, extends one tree towards a random sample and then
*connects* the other tree greedily towards the new node, swapping roles each time.  The
online stage uses it to repair the portions of a roadmap path that the object blocks
(§V-B) and, alone, as the single-query baseline of the paper's comparison.

Like caelan/motion-planners, the planner knows nothing of robots: ``sample() -> q``,
``segment_free(q0, q1)`` (the local planner), ``distance(q, qs)`` and a step size; the
random generator comes from the caller.  Trees are per-call scratch.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np


@dataclass(frozen=True)
class RRTOptions:
    step: float = 0.3  # largest extension, in the units of ``distance``
    max_iterations: int = 2000
    goal_bias: float = 0.05  # probability of sampling the other tree's root


@dataclass(frozen=True)
class RRTResult:
    path: np.ndarray | None  # (k, d) from start to goal, or None when the budget ran out
    iterations: int
    nodes: int  # nodes in both trees


class _Tree:
    def __init__(self, root: np.ndarray):
        self.nodes = [root]
        self.parent = [-1]

    def nearest(self, q: np.ndarray, distance) -> int:
        return int(np.argmin(distance(q, np.asarray(self.nodes))))

    def add(self, q: np.ndarray, parent: int) -> int:
        self.nodes.append(q)
        self.parent.append(parent)
        return len(self.nodes) - 1

    def branch(self, i: int) -> list[np.ndarray]:
        out = []
        while i != -1:
            out.append(self.nodes[i])
            i = self.parent[i]
        return out  # from node i back to the root


def _steer(q_from: np.ndarray, q_to: np.ndarray, step: float, distance) -> np.ndarray:
    d = float(distance(q_from, q_to))
    return q_to if d <= step else q_from + (q_to - q_from) * (step / d)


def rrt_connect(start: np.ndarray, goal: np.ndarray, sample: Callable[[], np.ndarray],
                segment_free: Callable[[np.ndarray, np.ndarray], bool],
                distance: Callable[[np.ndarray, np.ndarray], np.ndarray], rng: np.random.Generator,
                options: RRTOptions = RRTOptions()) -> RRTResult:
    """A collision-free path from ``start`` to ``goal`` (both assumed valid), or None."""
    if segment_free(start, goal):
        return RRTResult(np.array([start, goal]), 0, 2)
    a, b = _Tree(np.asarray(start, float)), _Tree(np.asarray(goal, float))
    a_is_start = True
    for it in range(1, options.max_iterations + 1):
        target = b.nodes[0] if rng.random() < options.goal_bias else sample()
        i = a.nearest(target, distance)
        q_new = _steer(a.nodes[i], target, options.step, distance)
        if segment_free(a.nodes[i], q_new):
            k = a.add(q_new, i)
            # connect: extend b towards q_new until it gets there or is blocked
            j = b.nearest(q_new, distance)
            while True:
                q = _steer(b.nodes[j], q_new, options.step, distance)
                if not segment_free(b.nodes[j], q):
                    break
                j = b.add(q, j)
                if float(distance(q, q_new)) == 0.0:
                    branch_a, branch_b = a.branch(k), b.branch(j)
                    path = branch_a[::-1] + branch_b[1:]
                    if not a_is_start:
                        path = path[::-1]
                    return RRTResult(np.array(path), it, len(a.nodes) + len(b.nodes))
        a, b, a_is_start = b, a, not a_is_start
    return RRTResult(None, options.max_iterations, len(a.nodes) + len(b.nodes))


def path_length(path: np.ndarray, distance) -> float:
    return float(sum(distance(path[i], path[i + 1]) for i in range(len(path) - 1)))


def prune(path: np.ndarray, segment_free: Callable[[np.ndarray, np.ndarray], bool]) -> np.ndarray:
    """Drop every interior waypoint whose neighbours see each other (one pass, first to
    last): each waypoint is a stop of the timed motion (:mod:`motion.timing`), and the
    random shortcuts add two per cut.  The ends stay; the path never gets longer (the
    triangle inequality).  Returns a new array (k, d), k >= 2."""
    path = [np.asarray(q, float) for q in path]
    out = [path[0]]
    for k in range(1, len(path) - 1):
        if not segment_free(out[-1], path[k + 1]):
            out.append(path[k])
    out.append(path[-1])
    return np.array(out)


def partial_shortcut(path: np.ndarray, segment_free: Callable[[np.ndarray, np.ndarray], bool],
                     groups: tuple[np.ndarray, ...], attempts: int = 30) -> np.ndarray:
    """Partial shortcuts (after Geraerts & Overmars 2007): for one joint group (an index
    array of ``groups``) and a span of waypoints i0 < i1, move only that group's joints
    along the straight line joining its values at the span's ends, at the pace of the
    original path (its cumulative joint-space length), while the other joints keep their
    motion.  Kept when every new segment is free and the group travels less (L1 over its
    joints).  Spans are tried longest first, per group: the whole path, then its halves,
    recursively, ``attempts`` checks in all.

    A full shortcut must move every joint at once, so one arm's detour survives whenever
    the other arm needs its waypoints; roadmap paths (Super Graph nodes sample every joint)
    are full of such detours: a free arm swinging 2 rad out and back while the other
    carries the object.  The ends stay fixed.  Returns a new array (k, d), same k.
    """
    path = np.array(path, dtype=float)
    for g in groups:
        spans = [(0, len(path) - 1)]
        while spans and attempts > 0:
            i0, i1 = spans.pop(0)
            if i1 - i0 < 2:
                continue
            part = path[i0:i1 + 1]
            lengths = np.linalg.norm(np.diff(part, axis=0), axis=1)
            if np.abs(np.diff(part[:, g], axis=0)).sum() <= np.abs(part[-1, g] - part[0, g]).sum() + 1e-9:
                continue  # the group goes straight already (or only monotonically per joint)
            f = np.concatenate([[0.0], np.cumsum(lengths)]) / lengths.sum()
            new = part.copy()
            new[1:-1, g] = part[0, g] + f[1:-1, None] * (part[-1, g] - part[0, g])  # the ends exactly
            attempts -= 1
            pairs = list(zip(new[:-1], new[1:]))
            if all(segment_free(a, b) for a, b in pairs):
                path[i0:i1 + 1] = new
            else:
                m = (i0 + i1) // 2
                spans += [(i0, m), (m, i1)]
    return path


def shortcut(path: np.ndarray, segment_free: Callable[[np.ndarray, np.ndarray], bool], distance,
             rng: np.random.Generator, iterations: int = 100) -> np.ndarray:
    """Random shortcuts: pick two points on the path (on its segments, not only at its
    waypoints) and join them directly when the local planner allows; the ends stay fixed
    and the length never grows.  Returns a new array (k, d)."""
    path = [np.asarray(q, float) for q in path]
    for _ in range(iterations):
        if len(path) < 3:
            break
        cum = np.concatenate([[0.0], np.cumsum([distance(path[i], path[i + 1]) for i in range(len(path) - 1)])])
        if cum[-1] <= 0:
            break
        s0, s1 = np.sort(rng.uniform(0.0, cum[-1], 2))
        i0, i1 = int(np.searchsorted(cum, s0, side="right") - 1), int(np.searchsorted(cum, s1, side="right") - 1)
        i0, i1 = min(i0, len(path) - 2), min(i1, len(path) - 2)
        if i0 == i1:
            continue

        def point(i, s):
            seg = cum[i + 1] - cum[i]
            return path[i] if seg <= 0 else path[i] + (path[i + 1] - path[i]) * ((s - cum[i]) / seg)

        p0, p1 = point(i0, s0), point(i1, s1)
        if float(distance(p0, p1)) < (s1 - s0) - 1e-12 and segment_free(p0, p1):  # s: arc length
            path = path[:i0 + 1] + [p0, p1] + path[i1 + 1:]
    # drop repeated points produced when a cut lands on a waypoint
    out = [path[0]]
    for q in path[1:]:
        if float(distance(out[-1], q)) > 1e-12:
            out.append(q)
    if len(out) == 1:
        out.append(path[-1])
    return np.array(out)
