"""The multi-query GS_n roadmap (seed 003 §V): a learning phase builds, once per hand,
object and placement, "a graph composed of components in GS_n linked by regrasping-
transfer and transfer-regrasping paths"; each query then joins its start and goal grasps
to the graph and follows it.

Learning (:func:`learn`): the roadmap starts from an RLG sample at a random orientation
(the object's centre where the scene holds it), and ``roots`` more such grasps are joined
to it in turn, each by the single-query planner's two-tree growth
(:func:`roadmap.join_trees`: the roadmap is one tree, the new grasp the other; their
edges are GS_n paths reduced to transfers and regrasps, their join §V's
transfer-regrasp link), every expansion aimed at the other tree.  The roadmap's growth is
kept either way; a grasp that does not join is dropped, so the graph is one connected
component.

A query (:func:`query`) joins the start grasp and a grasp at the goal pose the same way,
but exploring as the single-query trees do (``GaitTreeOptions.goal_bias`` of the
expansions aimed, the rest towards random poses: aimed joins failed on the cube), and
follows the shortest route (the object's turn), each edge forwards or backwards
(transfers and regrasps are reversible), cutting detours where a direct link goes.
Every edge ends exactly on its node's configuration, so the pieces chain.  The graph is
a tree (each join adds one edge), so routes are long: docs/DESIGN-NOTES.md, "Multi-query roadmap".

Frames: the grasp frame G (fixed), the object frame O; metres, radians.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import networkx as nx
import numpy as np
from scipy.spatial.transform import Rotation

from regrasp_cli.dexterous.gait import GaitOptions, Piece, Regrasp, Transfer, reversed_path
from regrasp_cli.dexterous.gsn import GsConfig, GsScratch
from regrasp_cli.dexterous.roadmap import GaitTreeOptions, RoadmapStats, Tree, pose_distances, random_pose, connect, \
    join_trees, rlg_sample


@dataclass(frozen=True)
class LearnOptions:
    roots: int = 40  # grasps at random orientations joined to the roadmap, in turn
    round_expansions: int = 150  # expansions a join may take before its grasp is dropped
    query_expansions: int = 300  # the same, for a query's start or goal grasp
    root_tries: int = 20  # RLG samples tried for each grasp
    aim: float = 1.0  # probability that a learning join's expansion aims at the other tree, not at a random pose
    # (the single-query planner's 0.5 explores; here the wandering became the routes' detours: 0.5 gave
    # hand4 ball routes of 272 phases, 0.9 166 and 1.0 155, docs/BENCHMARKS.md)
    shortcuts: int = 40  # links a query tries to cut the route's detours (:func:`_shortcut`)
    seed: int = 0  # the learning's random generator (not the query's: one roadmap serves every query)


@dataclass
class GsRoadmap:
    """Nodes (GS_n configurations) and edges ``(a, b) -> pieces from a to b``; one
    connected component."""

    nodes: list[GsConfig] = field(default_factory=list)
    edges: dict[tuple[int, int], list[Piece]] = field(default_factory=dict)

    def graph(self) -> nx.Graph:
        g = nx.Graph()
        g.add_nodes_from(range(len(self.nodes)))
        for (a, b), pieces in self.edges.items():
            g.add_edge(a, b, weight=turn(pieces))
        return g

    def pieces(self, a: int, b: int) -> list[Piece]:
        """The edge's pieces from node ``a`` to node ``b``, whichever way it was stored."""
        return self.edges[(a, b)] if (a, b) in self.edges else reversed_path(self.edges[(b, a)])

    def add(self, c: GsConfig, parent: int | None = None, pieces: list[Piece] | None = None) -> int:
        self.nodes.append(c)
        if parent is not None:
            self.edges[(parent, len(self.nodes) - 1)] = pieces
        return len(self.nodes) - 1


@dataclass
class LearnStats:
    roots: int = 0  # grasps sampled at random orientations
    joined: int = 0  # of them, joined to the roadmap
    expansions: int = 0


def turn(pieces: list[Piece]) -> float:
    """The object's rotation along the pieces, radians (a path's length in the graph),
    plus a thousandth per piece (fewer pieces, all else equal)."""
    out = 0.0
    for p in pieces:
        if isinstance(p, Transfer) and len(p.X_GO) > 1:
            R = p.X_GO[:, :3, :3]
            out += float(Rotation.from_matrix(np.einsum("kji,kjl->kil", R[:-1], R[1:])).magnitude().sum())
    return out + 1e-3 * len(pieces)


def _random_grasp(s: GsScratch, p_GO: np.ndarray, rng: np.random.Generator, o: LearnOptions,
                  r: GaitTreeOptions) -> GsConfig | None:
    X = np.eye(4)
    X[:3, 3] = p_GO
    for _ in range(o.root_tries):
        c = rlg_sample(s, random_pose(X, 0.0, rng), rng, r.candidates)
        if c is not None:
            return c
    return None


def _join(s: GsScratch, rm: GsRoadmap, main: Tree, ids: list[int], c: GsConfig, budget: int, aim: float,
          rng: np.random.Generator, r: GaitTreeOptions, g: GaitOptions, stats: RoadmapStats) -> int | None:
    """Join the grasp ``c`` to the roadmap: a tree from ``c`` and the roadmap's ``main``
    tree (``ids``: the roadmap node of each of its nodes) grown towards each other
    (:func:`roadmap.join_trees`).  The new nodes and edges go into ``rm`` and ``main``;
    ``c``'s roadmap node, or None (then nothing of ``c``'s tree is kept)."""
    side = Tree()
    side.add(c, -1, [])
    first = len(main.nodes)
    joined = join_trees(s, (main, side), rng, replace(r, nodes=budget, goal_bias=aim), g, stats)
    for j in range(first, len(main.nodes)):  # the roadmap's own growth is kept either way
        ids.append(rm.add(main.nodes[j], ids[main.parent[j]], main.edge[j]))
    if joined is None:
        return None
    a, b, link = joined
    side_ids = [rm.add(c)]
    for j in range(1, len(side.nodes)):
        side_ids.append(rm.add(side.nodes[j], side_ids[side.parent[j]], side.edge[j]))
    rm.edges[(ids[a], side_ids[b])] = link
    for j, i in enumerate(side_ids):  # one tree now, for the next joins' nearest nodes
        main.add(side.nodes[j], -1, [])
        ids.append(i)
    return side_ids[0]


def learn(s: GsScratch, p_GO: np.ndarray, rng: np.random.Generator, o: LearnOptions = LearnOptions(),
          r: GaitTreeOptions = GaitTreeOptions(), g: GaitOptions = GaitOptions(),
          progress=None) -> tuple[GsRoadmap, LearnStats]:
    """The learning phase with the object's centre at ``p_GO`` (3,), grasp frame: a
    roadmap from a grasp at a random orientation, to which ``o.roots`` more are joined in
    turn, each with its tree of transfers and regrasps; the roadmap and its counts.
    ``progress(done, total)`` is called after each grasp."""
    st, rm = LearnStats(), GsRoadmap()
    first = _random_grasp(s, p_GO, rng, o, r)
    if first is None:
        return rm, st
    main = Tree()
    main.add(first, -1, [])
    ids = [rm.add(first)]
    rs = RoadmapStats()
    for k in range(o.roots):
        c = _random_grasp(s, p_GO, rng, o, r)
        if c is not None:
            st.roots += 1
            st.joined += _join(s, rm, main, ids, c, o.round_expansions, o.aim, rng, r, g, rs) is not None
        if progress is not None:
            progress(k + 1, o.roots)
    st.expansions = rs.iterations
    return rm, st


def query(s: GsScratch, rm: GsRoadmap, start: GsConfig, goal: GsConfig, rng: np.random.Generator,
          o: LearnOptions = LearnOptions(), r: GaitTreeOptions = GaitTreeOptions(),
          g: GaitOptions = GaitOptions()) -> tuple[list[Piece] | None, RoadmapStats, str]:
    """The pieces from ``start`` to ``goal`` over the roadmap (left as it is), or None and
    why not: each is joined to it as :func:`learn` joins a grasp (exploring: the aim is
    ``r.goal_bias``, not ``o.aim``), then the shortest path
    (the object's turn) is followed, each edge forwards or backwards."""
    stats = RoadmapStats(start_liftable=len(s.liftable(start)))
    if not rm.nodes:
        return None, stats, "the roadmap has no nodes"
    work = GsRoadmap(list(rm.nodes), dict(rm.edges))
    main = Tree()
    for c in rm.nodes:
        main.add(c, -1, [])
    ids = list(range(len(rm.nodes)))
    ends = []
    for name, c in (("start", start), ("goal", goal)):
        i = _join(s, work, main, ids, c, o.query_expansions, r.goal_bias, rng, r, g, stats)
        if i is None:
            stats.kept = len(work.nodes)
            return None, stats, f"the {name} grasp did not join the roadmap in {o.query_expansions} expansions"
        ends.append(i)
    stats.kept = len(work.nodes)
    route = nx.shortest_path(work.graph(), ends[0], ends[1], weight="weight")
    return _shortcut(s, work, route, rng, o, r, g), stats, ""


def _shortcut(s: GsScratch, rm: GsRoadmap, route: list[int], rng: np.random.Generator, o: LearnOptions,
              r: GaitTreeOptions, g: GaitOptions) -> list[Piece]:
    """The route's pieces, with detours cut: from each node, the farthest later node of
    the route within ``r.connect_rad`` is tried with :func:`roadmap.connect` (at most
    ``o.shortcuts`` tries in all).  A roadmap grown as trees joins two grasps through
    their common ancestor, a long way round when they are near each other."""
    poses = np.array([rm.nodes[i].X_GO for i in route])
    pieces, i, tries = [], 0, 0
    while i < len(route) - 1:
        d = pose_distances(poses[i + 2:], poses[i], s.rho)
        near = np.nonzero(d <= r.connect_rad)[0]
        j = i + 1
        if near.size and tries < o.shortcuts:
            tries += 1
            s.generated += 1
            link = connect(s, rm.nodes[route[i]], rm.nodes[route[i + 2 + near[-1]]], rng, r, g)
            if link is not None:
                pieces += link
                i = i + 2 + int(near[-1])
                continue
        pieces += rm.pieces(route[i], route[j])
        i = j
    return pieces


# ------------------------------------------------------------------ storage as arrays


def to_arrays(rm: GsRoadmap) -> dict[str, np.ndarray]:
    """The roadmap as flat arrays (an HDF5 artefact's datasets)."""
    nodes = rm.nodes
    edges = list(rm.edges.items())
    pieces = [(e, p) for e, (_, ps) in enumerate(edges) for p in ps]
    n_f, nq = nodes[0].p.shape[0], nodes[0].q.shape[0]
    lengths = np.array([len(p.q) for _, p in pieces], int)
    X = [p.X_GO if isinstance(p, Transfer) else np.repeat(p.before.X_GO[None], len(p.q), 0) for _, p in pieces]
    return {
        "nodes/X_GO": np.array([c.X_GO for c in nodes]), "nodes/p": np.array([c.p for c in nodes]),
        "nodes/n": np.array([c.n for c in nodes]), "nodes/q": np.array([c.q for c in nodes]),
        "edges/ab": np.array([e for e, _ in edges], int).reshape(-1, 2),
        "pieces/edge": np.array([e for e, _ in pieces], int),
        "pieces/finger": np.array([p.finger if isinstance(p, Regrasp) else -1 for _, p in pieces], int),
        "pieces/length": lengths,
        "waypoints/X_GO": np.concatenate(X) if X else np.zeros((0, 4, 4)),
        "waypoints/q": np.concatenate([p.q for _, p in pieces]) if pieces else np.zeros((0, nq)),
        "waypoints/p": np.concatenate([_contacts(p, "p") for _, p in pieces]) if pieces else np.zeros((0, n_f, 3)),
        "waypoints/n": np.concatenate([_contacts(p, "n") for _, p in pieces]) if pieces else np.zeros((0, n_f, 3)),
    }


def _contacts(p: Piece, which: str) -> np.ndarray:
    """(k, n, 3): a piece's contacts (``which`` "p") or normals ("n") per waypoint (a
    regrasp's before it but at its last, where they are those after it)."""
    if isinstance(p, Transfer):
        return getattr(p, which)
    return np.stack([getattr(p.before, which)] * (len(p.q) - 1) + [getattr(p.after, which)])


def from_arrays(d: dict[str, np.ndarray]) -> GsRoadmap:
    """The roadmap :func:`to_arrays` stored."""
    nodes = [GsConfig(*(d[f"nodes/{k}"][i] for k in ("X_GO", "p", "n", "q"))) for i in range(len(d["nodes/q"]))]
    rm = GsRoadmap(nodes)
    ab = d["edges/ab"]
    for a, b in ab:
        rm.edges[(int(a), int(b))] = []
    keys = [(int(a), int(b)) for a, b in ab]
    starts = np.concatenate([[0], np.cumsum(d["pieces/length"])])
    for k, (e, f) in enumerate(zip(d["pieces/edge"], d["pieces/finger"])):
        X, q, p, n = (d[f"waypoints/{w}"][starts[k]:starts[k + 1]] for w in ("X_GO", "q", "p", "n"))
        if f < 0:
            piece: Piece = Transfer(X, q, p, n)
        else:
            piece = Regrasp(int(f), q, GsConfig(X[0], p[0], n[0], q[0]), GsConfig(X[0], p[-1], n[-1], q[-1]))
        rm.edges[keys[int(e)]].append(piece)
    return rm
