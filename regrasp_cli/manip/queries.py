"""The four queries of §V-B through the Super Graph, with lazy revalidation and repair.

"First the query is executed in the precomputed roadmap disregarding the collisions of
the existing nodes and edges in the graph.  Once a path is found, each local path
composing it is checked for collision against the manipulated object ... If a collision
is detected ... an alternative path ... is then searched in the precomputed graph.  If no
solution is found, local reconnections are computed using RRT-like planners."
(Saut et al. 2010, §V-B; the lazy scheme of their reference [22].)

Here a query runs between two configurations of one phase: the Super Graph's nodes get
the phase's finger values (a holding hand is closed on the object; roadmaps were built
with open hands), the two ends are joined to their nearest free nodes, and the shortest
path is revalidated edge by edge against what the roadmap did not check: the object
(static, or attached to the holding hand) and the links of a hand whose fingers are not
open.  Invalid nodes and edges are hidden in a per-query memo and the graph is searched
again; after ``repairs`` searches, or when the ends lie in different components, the
broken portion is bridged by RRT-Connect between the free configurations bounding it.
The result is shortcut and returned with the Table I statistics of the query.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import connected_components

from regrasp_cli.manip.context import Placed, Scratch
from regrasp_cli.manip.keyconf import approach_axis, cartesian_line, shoulder
from regrasp_cli.roadmap.build import RoadmapArtefact
from regrasp_cli.motion.local import distance
from regrasp_cli.roadmap.query import QueryMemo, shortest_path
from regrasp_cli.motion.rrt import partial_shortcut, prune, rrt_connect, shortcut


@dataclass
class QueryStats:
    """Table I per phase: nodes (roadmap nodes on the path + RRT tree nodes), planning
    time (search, connections, repairs, smoothing) and validation time (lazy checks)."""

    nodes: int = 0
    planning: float = 0.0
    validation: float = 0.0
    searches: int = 0
    invalid_edges: int = 0
    rrt_calls: int = 0


class QueryFailed(Exception):
    """A query found no path within its budget."""


@dataclass(frozen=True)
class Roadmap:
    """The Super Graph ready for queries (built once per run)."""

    nodes: np.ndarray  # (m, nq) with open hands
    edges: np.ndarray  # (k, 2) node indices
    lengths: np.ndarray  # (k,) weighted joint-space lengths
    weights: np.ndarray  # (nq,)
    giant: np.ndarray  # (g,) indices of the nodes of the largest connected component
    unchecked: tuple[str, ...] = ()  # obstacles it was not built with: their pairs are checked lazily

    @classmethod
    def of(cls, art: RoadmapArtefact) -> "Roadmap":
        g = art.graph
        return cls.from_arrays(g.nodes, g.edges, g.lengths, art.weights, art.unchecked)

    @classmethod
    def from_arrays(cls, nodes: np.ndarray, edges, lengths, weights: np.ndarray,
                    unchecked: tuple[str, ...] = ()) -> "Roadmap":
        edges = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
        m = len(nodes)
        adjacency = csr_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(m, m))
        _, label = connected_components(adjacency, directed=False)
        giant = np.flatnonzero(label == np.bincount(label).argmax()) if m else np.zeros(0, dtype=np.int64)
        return cls(np.asarray(nodes, float), edges, np.asarray(lengths, float), np.asarray(weights, float), giant,
                   tuple(unchecked))

    def shortest_path(self, sources: list[tuple[int, float]], targets: list[tuple[int, float]],
                      memo: QueryMemo) -> list[int] | None:
        return shortest_path(self.edges, self.lengths, len(self.nodes), sources, targets, memo)


@dataclass(frozen=True)
class PhaseWorlds:
    """Collision worlds of a phase: ``full`` checks everything (uncertified segments),
    ``lazy`` only what the roadmap did not (its nodes and edges)."""

    full: Placed
    lazy: Placed
    fingers: dict  # hand -> finger values during the phase


def set_fingers(scratch: Scratch, q: np.ndarray, fingers: dict) -> np.ndarray:
    q = q.copy()
    for hand, values in fingers.items():
        q[scratch.problem.robot.hands[hand].idx] = values
    return q


def _rrt(scratch: Scratch, rng: np.random.Generator, a: np.ndarray, b: np.ndarray, world: Placed, fingers: dict,
         weights: np.ndarray) -> tuple[np.ndarray | None, int]:
    robot = scratch.problem.robot
    moving = np.concatenate([robot.groups["torso"], robot.groups["right_arm"], robot.groups["left_arm"]])

    def sample():
        return set_fingers(scratch, robot.sample(rng, moving, base=a), fingers)

    res = rrt_connect(a, b, sample, lambda x, y: scratch.segment_free(world, x, y),
                      lambda x, ys: distance(x, ys, weights), rng, scratch.options.rrt)
    return res.path, res.nodes


def _detours(scratch: Scratch, q: np.ndarray) -> list[np.ndarray]:
    """q with one arm, then both arms, then the torso too, moved back to rest."""
    robot = scratch.problem.robot
    out = []
    for groups in (("right_arm",), ("left_arm",), ("right_arm", "left_arm"), ("torso", "right_arm", "left_arm")):
        m = q.copy()
        for g in groups:
            m[robot.groups[g]] = robot.q_rest[robot.groups[g]]
        if not np.array_equal(m, q):
            out.append(m)
    return out


LEVEL = np.array([1.0, 1.0, 0.0])  # a direction's horizontal part


def _retreats(scratch: Scratch, rng: np.random.Generator, q: np.ndarray, world: Placed) -> Iterator[np.ndarray]:
    """For each hand in turn, the waypoints (k, nq) after q that move its grasp frame
    straight by ``retreat_distance`` (its arm alone moving), back along its approach axis
    or towards its shoulder (each level first), the first such line free in ``world``:
    a hand at the back of a cage or shelf is seen by the roadmap from outside.  When no
    such line is free, the same lines after rising ``retreat_lift`` straight up: an open
    jaw round a block it let go, front and back, cannot back out level (its far finger
    hits the block) nor up (the cage's roof), but can rise clear of the block's top and
    then back out (baxter_cage); ``retreat_lift`` 0: no rise.  Lazily: the next hand's
    lines are solved only when asked for."""
    robot, o = scratch.problem.robot, scratch.options
    for hand in robot.hands:
        X_WG = scratch.kin.fk(q, robot.hands[hand].grasp_frame)
        back, home = -(X_WG[:3, :3] @ approach_axis(scratch, hand)), shoulder(scratch, hand, q) - X_WG[:3, 3]
        directions = _directions(back, home)
        line = _straight_out(scratch, rng, hand, q, X_WG, directions, world)
        if line is None and o.retreat_lift > 0:
            X_up = X_WG.copy()
            X_up[2, 3] += o.retreat_lift
            rise = _line(scratch, rng, hand, q, X_up, world, 2)
            out = None if rise is None else _straight_out(scratch, rng, hand, rise[-1], X_up, directions, world)
            line = None if out is None else np.vstack([rise, out])
        if line is not None:
            yield line


def _straight_out(scratch: Scratch, rng: np.random.Generator, hand: str, q: np.ndarray, X_WG: np.ndarray,
                  directions: list[np.ndarray], world: Placed) -> np.ndarray | None:
    """The waypoints (k, nq) after q of the first free line moving the hand's grasp frame
    from X_WG (4, 4) by ``retreat_distance`` along one of ``directions`` (unit, (3,)), or None."""
    for d in directions:
        far = X_WG.copy()
        far[:3, 3] += scratch.options.retreat_distance * d
        line = _line(scratch, rng, hand, q, far, world, scratch.options.line_steps)
        if line is not None:
            return line
    return None


def _line(scratch: Scratch, rng: np.random.Generator, hand: str, q: np.ndarray, X_far: np.ndarray, world: Placed,
          steps: int) -> np.ndarray | None:
    """The waypoints (k, nq) after q of the hand's straight line to X_far (4, 4), its arm
    alone moving (:func:`cartesian_line`), when it is free in ``world``; else None."""
    line = cartesian_line(scratch, rng, hand, q, X_far, steps)
    if line is None or not scratch.path_free(world, line[::-1]):
        return None
    return line[::-1][1:]


def _directions(*ds: np.ndarray) -> list[np.ndarray]:
    """Unit vectors (3,): each of ``ds`` level (its horizontal part, where that is at least
    a fifth of it and not the whole), then as it is; none of a vanishing one."""
    out = []
    for d in ds:
        n = np.linalg.norm(d)
        if n < 1e-9:
            continue
        level = d * LEVEL
        if 0.2 * n <= np.linalg.norm(level) < n * (1 - 1e-9):
            out.append(level / np.linalg.norm(level))
        out.append(d / n)
    return out


def _escape(scratch: Scratch, rng: np.random.Generator, rm: Roadmap, q: np.ndarray, world: Placed, fingers: dict, node_free, q_of,
            stats: QueryStats) -> tuple[list[np.ndarray], list[tuple[int, float]]]:
    """Grow a random tree from q until one of its nodes joins a free Super Graph node:
    the RRT-like local reconnection of §V-B for a configuration in a pocket of the free
    space that no roadmap node sees.  Returns the tree branch (without q) and the node."""
    o, robot = scratch.options, scratch.problem.robot
    moving = np.concatenate([robot.groups["torso"], robot.groups["right_arm"], robot.groups["left_arm"]])
    nodes, parent = [q], [-1]
    for _ in range(o.escape_iterations):
        if rng.random() < 0.3:  # towards a random roadmap node
            target = q_of(int(rm.giant[rng.integers(len(rm.giant))]))
        else:
            target = set_fingers(scratch, robot.sample(rng, moving, base=q), fingers)
        d = distance(target, np.asarray(nodes), rm.weights)
        i = int(np.argmin(d))
        step = o.rrt.step / max(float(d[i]), 1e-12)
        new = target if step >= 1 else nodes[i] + (target - nodes[i]) * step
        if not scratch.segment_free(world, nodes[i], new):
            continue
        nodes.append(new)
        parent.append(i)
        dn = distance(new, rm.nodes[rm.giant], rm.weights)
        for j in rm.giant[np.argsort(dn, kind="stable")[:3]]:
            j = int(j)
            if node_free(j) and scratch.segment_free(world, new, q_of(j)):
                branch, k = [], len(nodes) - 1
                while k > 0:
                    branch.append(nodes[k])
                    k = parent[k]
                stats.nodes += len(nodes)
                return branch[::-1], [(j, float(distance(new, rm.nodes[j], rm.weights)))]
    stats.nodes += len(nodes)
    return [], []


def smooth(scratch: Scratch, rng: np.random.Generator, path: np.ndarray, world: Placed, weights: np.ndarray) -> np.ndarray:
    """Random shortcuts, then partial shortcuts one joint group at a time (the detours of
    one arm while the other needs its waypoints), random shortcuts again (the partial ones
    open new straight lines), then (``options.prune``) the waypoints their neighbours see
    past dropped: fewer, straighter corners to blend and time (default suite: median
    motion 16.9 s instead of 34.5 s; docs/BENCHMARKS.md).

    Most candidate segments are superseded by later shortcuts, so the shortcuts are first
    decided with the cheap probe (:meth:`Scratch.probe_free`) and only the result is
    certified; when one of its segments is not, the smoothing is done again with certified
    checks and the same random draws (the probe never made the path worse, only the work)."""
    seed = int(rng.integers(2**63))
    free = lambda x, y: scratch.segment_free(world, x, y)  # noqa: E731
    probed = _smooth(scratch, np.random.default_rng(seed), path, lambda x, y: scratch.probe_free(world, x, y), weights)
    if all(free(a, b) for a, b in zip(probed[:-1], probed[1:])):
        return probed
    return _smooth(scratch, np.random.default_rng(seed), path, free, weights)


def _smooth(scratch: Scratch, rng: np.random.Generator, path: np.ndarray, free, weights: np.ndarray) -> np.ndarray:
    """:func:`smooth`'s passes with the segment check ``free(q0, q1)``."""
    o = scratch.options
    metric = lambda x, y: distance(x, y, weights)  # noqa: E731
    path = shortcut(path, free, metric, rng, o.shortcut_iterations)
    groups = tuple(scratch.problem.robot.groups.values())
    path = partial_shortcut(path, free, groups, o.partial_shortcuts)
    path = shortcut(path, free, metric, rng, o.final_shortcuts)
    return prune(path, free) if o.prune else path


def rrt_query(scratch: Scratch, rng: np.random.Generator, a: np.ndarray, b: np.ndarray, worlds: PhaseWorlds, weights: np.ndarray,
              stats: QueryStats) -> np.ndarray:
    """The single-query baseline: RRT-Connect from a to b, then shortcut."""
    t0 = time.perf_counter()
    path, n = _rrt(scratch, rng, a, b, worlds.full, worlds.fingers, weights)
    stats.rrt_calls += 1
    stats.nodes += n
    if path is None:
        stats.planning += time.perf_counter() - t0
        raise QueryFailed(f"RRT-Connect found no path within its budget of {scratch.options.rrt.max_iterations} "
                          "iterations")
    path = smooth(scratch, rng, path, worlds.full, weights)
    stats.planning += time.perf_counter() - t0
    return path


class _LazyView:
    """One query's view of the Super Graph: its nodes with the phase's finger values, and
    the memo of what the lazy checks found, kept beside the graph (never in it)."""

    def __init__(self, scratch: Scratch, rm: Roadmap, worlds: PhaseWorlds):
        self.scratch, self.rm, self.worlds = scratch, rm, worlds
        self.memo, self.node, self.validation = QueryMemo(), {}, 0.0

    def q_of(self, i: int) -> np.ndarray:
        if i not in self.node:
            self.node[i] = set_fingers(self.scratch, self.rm.nodes[i], self.worlds.fingers)
        return self.node[i]

    def node_free(self, i: int) -> bool:
        if i in self.memo.invalid_nodes:
            return False
        t = time.perf_counter()
        ok = self.worlds.lazy.is_free(self.q_of(i))
        self.validation += time.perf_counter() - t
        if not ok:
            self.memo.invalid_nodes.add(i)
        return ok

    def ends(self, q: np.ndarray) -> list[tuple[int, float]]:
        """Free nodes q joins with a free segment, nearest first, ``connections`` at most.
        Nodes of the largest component only: ends joined to two different components
        have no path between them (the Super Graph has ~170 components, one of ~86 %)."""
        rm, o = self.rm, self.scratch.options
        d = np.full(len(rm.nodes), np.inf)
        d[rm.giant] = distance(q, rm.nodes[rm.giant], rm.weights)
        out = []
        for i in np.argsort(d, kind="stable")[:min(o.k_connect, len(rm.giant))]:
            i = int(i)
            if self.node_free(i) and self.scratch.segment_free(self.worlds.full, q, self.q_of(i)):
                out.append((i, float(d[i])))
                if len(out) >= o.connections:
                    break
        return out

    def attach(self, rng: np.random.Generator, q: np.ndarray,
               stats: QueryStats) -> tuple[list[np.ndarray], list[tuple[int, float]]]:
        """Configurations leading from q to the graph, and the nodes they join."""
        full = self.worlds.full
        e = self.ends(q)
        if e:
            return [], e
        for mid in _detours(self.scratch, q):  # e.g. the hand that just let go back at rest
            if full.is_free(mid) and self.scratch.segment_free(full, q, mid):
                e = self.ends(mid)
                if e:
                    return [mid], e
        for line in _retreats(self.scratch, rng, q, full):
            e = self.ends(line[-1])
            if e:
                return list(line), e
        return _escape(self.scratch, rng, self.rm, q, full, self.worlds.fingers, self.node_free, self.q_of, stats)

    def first_invalid_edge(self, ids: list[int], stats: QueryStats) -> tuple[int, int] | None:
        """Check the path's edges in order against what the roadmap did not; the first
        invalid one is hidden (memo) and returned."""
        for u, v in zip(ids[:-1], ids[1:]):
            e = frozenset((u, v))
            if e in self.memo.valid_edges:
                continue
            t = time.perf_counter()
            ok = self.node_free(u) and self.node_free(v) and self.scratch.segment_free(
                self.worlds.lazy, self.q_of(u), self.q_of(v))
            self.validation += time.perf_counter() - t
            if ok:
                self.memo.valid_edges.add(e)
            else:
                self.memo.invalid_edges.add(e)
                stats.invalid_edges += 1
                return u, v
        return None


def roadmap_query(scratch: Scratch, rng: np.random.Generator, rm: Roadmap, a: np.ndarray, b: np.ndarray,
                  worlds: PhaseWorlds, stats: QueryStats) -> np.ndarray:
    """A collision-free path (k, nq) from a to b (both free in ``worlds.full``)."""
    o = scratch.options
    t_start = time.perf_counter()
    if scratch.segment_free(worlds.full, a, b):
        stats.planning += time.perf_counter() - t_start
        return np.array([a, b])
    view = _LazyView(scratch, rm, worlds)
    (pre_a, src), (pre_b, dst) = view.attach(rng, a, stats), view.attach(rng, b, stats)
    path = None
    for _ in range(o.repairs):
        stats.searches += 1
        ids = rm.shortest_path(src, dst, view.memo) if src and dst else None
        if ids is None:
            break
        if view.first_invalid_edge(ids, stats) is None:
            path = np.array([a, *pre_a] + [view.q_of(i) for i in ids] + [*pre_b[::-1], b])
            stats.nodes += len(ids)
            break
    if path is None:  # bridge with RRT-Connect between the ends (different components)
        path, n = _rrt(scratch, rng, a, b, worlds.full, worlds.fingers, rm.weights)
        stats.rrt_calls += 1
        stats.nodes += n
        if path is None:
            stats.planning += time.perf_counter() - t_start - view.validation
            stats.validation += view.validation
            raise QueryFailed(f"no path in the roadmap after {stats.searches} searches, and RRT-Connect found none "
                              f"within its budget of {o.rrt.max_iterations} iterations")
    path = smooth(scratch, rng, path, worlds.full, rm.weights)
    stats.planning += time.perf_counter() - t_start - view.validation
    stats.validation += view.validation
    return path
