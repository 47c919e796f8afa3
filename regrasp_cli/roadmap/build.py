"""`regrasp roadmap build`: elementary Vis-PRM roadmaps and their Super Graph, cached in
HDF5 (Saut et al. 2010, §V-A).

Stages: the two elementary roadmaps (in parallel, one process each), the Super Graph
nodes, then its edges: shortest first, each checked only when the edges accepted so far
do not already join its ends within ``stretch`` times its length (:func:`_edges`), in
parallel over forked workers in a fixed protocol, so the result does not depend on the
number of jobs.  The roadmap depends on the robot (URDF,
robot.yaml), the static obstacles and the options, not on the object: its provenance
hashes exactly those, each obstacle on its own.  A scene whose obstacles differ from a
cached roadmap's in a few (moved, added or removed: at most a third of them) reuses it
(:func:`nearest_roadmap`): the online queries then check the pairs with the moved and
added obstacles lazily, with the object's (Saut et al. 2010 §V-B), instead of a rebuild.

No silent emptiness: an elementary roadmap or a Super Graph without a node is an
:class:`~regrasp_cli.errors.EmptyRoadmap` (nothing written) naming the pairs that rejected
most samples (:mod:`.rejections`); one with fewer nodes than asked for (saying which pairs
rejected most samples), or a rest configuration in collision, a warning in the
:class:`BuildReport`.
"""

from __future__ import annotations

import heapq
import json
import time
from collections import deque
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Callable

import networkx as nx
import numpy as np

from regrasp_cli.errors import EmptyRoadmap, InputError
from regrasp_cli.model.collision import CollisionWorld, collision_world
from regrasp_cli.parallel import Workers, ordered_map
from regrasp_cli.roadmap.compose import (LEFT, RIGHT, SuperGraph, UnionFind, candidate_edges, compose_nodes,
                                         edge_kind, involving, link_parts, margin_rule, mixed, part_filter,
                                         subsystem)
from regrasp_cli.motion.local import LocalPlanner, distance, joint_reach, joint_weights
from regrasp_cli.roadmap.rejections import FEW, Rejections, pairs_text, tallied
from regrasp_cli.roadmap.visprm import ElementaryRoadmap, VisPRMOptions, visibility_prm
from regrasp_cli.scene import Problem, load_problem, obstacles_sha256
from regrasp_cli.store import Provenance, canonical_json, read_artefact, read_provenance, robot_identity, \
    sha256_params, write_artefact

FORMAT, FORMAT_VERSION = "regrasp.roadmap", 2  # 2: each obstacle's digest in the provenance
EDGE_CHUNK = 16  # candidate Super Graph edges per task
EDGE_WINDOW = 4  # tasks in flight
PROBE = 16  # samples of a segment in Vis-PRM's cheap visibility test


@dataclass(frozen=True)
class RoadmapOptions:
    nodes: int = 50  # nodes of each elementary roadmap
    max_failures: int = 2000  # Vis-PRM: consecutive dropped samples that end a roadmap early
    tree: bool = False  # Super Graph edges only between different components
    stretch: float = 2.0  # an edge is checked only when the graph does not already join its ends within
    # stretch times its length (0: every candidate edge); see _Joined
    resolution: float = 0.05  # rad: largest joint step between two checked configurations
    margin: float = 0.03  # m: clearance of the moving pairs; half the largest Cartesian step
    seed: int = 0


@dataclass(frozen=True)
class RoadmapArtefact:
    """What is stored: the elementary roadmaps (nodes over torso + arm joints, in group
    order) and the Super Graph (full configurations)."""

    right: ElementaryRoadmap
    left: ElementaryRoadmap
    graph: SuperGraph
    joint_names: tuple[str, ...]
    weights: np.ndarray  # (nq,) of the distance metric
    unchecked: tuple[str, ...] = ()  # the scene's obstacles it was not built with (:func:`nearest_roadmap`)

    def networkx(self) -> nx.Graph:
        """The Super Graph as an undirected networkx graph, edge attribute ``length``."""
        g = nx.Graph()
        g.add_nodes_from(range(len(self.graph.nodes)))
        g.add_weighted_edges_from(((int(a), int(b), float(w)) for (a, b), w in
                                   zip(self.graph.edges, self.graph.lengths)), weight="length")
        return g


@dataclass(frozen=True)
class BuildReport:
    path: Path
    rows: dict[str, str]  # summary table rows
    seconds: dict[str, float]
    warnings: tuple[str, ...] = ()  # few nodes, a rest configuration in collision: one line each


# ------------------------------------------------------------------ provenance


def obstacle_digests(obstacles) -> list[str]:
    """``NAME:DIGEST`` of each obstacle (its shape, size, pose and mesh), sorted."""
    return sorted(f"{o.name}:{obstacles_sha256((o,))[:16]}" for o in obstacles)


def provenance(problem: Problem, options: RoadmapOptions) -> Provenance:
    r = problem.robot
    return Provenance(FORMAT, FORMAT_VERSION, {
        "urdf": r.urdf_sha256, "robot_yaml": r.spec_sha256,
        "obstacles": canonical_json(obstacle_digests(problem.spec.obstacles)),
        "params": sha256_params(asdict(options))})


def artefact_path(cache_dir: Path, problem: Problem, options: RoadmapOptions) -> Path:
    """``roadmap/<robot identity>-<12 hex digits of the provenance inputs>.h5``."""
    key = sha256_params(dict(provenance(problem, options).inputs))[:12]
    return Path(cache_dir) / "roadmap" / f"{robot_identity(problem.robot)}-{key}.h5"


REUSE_BLOCKED = 0.05  # a roadmap is reused when the moved and added obstacles block at most this share of its nodes


@dataclass(frozen=True)
class Reuse:
    """A cached roadmap of the same robot and options built for other obstacles."""

    path: Path
    provenance: Provenance
    unchecked: tuple[str, ...]  # the scene's obstacles (names) it was not built with: moved or added
    removed: int  # obstacles it was built with that the scene does not have
    blocked: float = 0.0  # share of its Super Graph nodes that the unchecked obstacles collide with
    roadmap: RoadmapArtefact | None = None  # as read (with ``unchecked``)


def blocked_share(problem: Problem, nodes: np.ndarray, names: tuple[str, ...]) -> float:
    """The share of the configurations ``nodes`` (m, nq) in collision with the scene's
    obstacles ``names`` (robot-obstacle pairs only)."""
    if not names or not len(nodes):
        return 0.0
    fresh = {f"obstacle:{n}" for n in names}
    world = collision_world(problem.robot, problem.spec.obstacles, problem.disabled.links(),
                            pair_filter=lambda a, b: a in fresh or b in fresh)
    return float(np.mean([not world.is_free(q) for q in nodes]))


def nearest_roadmap(cache_dir: Path, problem: Problem, options: RoadmapOptions) -> Reuse | None:
    """The cached roadmap of this robot and these options whose obstacles differ least
    from the scene's, when at most a third of them differ (moved, added or removed; one
    at least may) and the moved and added ones block at most :data:`REUSE_BLOCKED` of its
    Super Graph nodes; None when none does.  Obstacles only removed leave the roadmap
    valid but sparser where they stood; moved and added ones are revalidated online,
    where a few blocked nodes cost a few repairs but many cost more than a rebuild (a
    box where the hands meet: 40-50 s a plan)."""
    expected = provenance(problem, options)
    want = set(json.loads(expected.inputs["obstacles"]))
    best = None
    for path in sorted((Path(cache_dir) / "roadmap").glob(f"{robot_identity(problem.robot)}-*.h5")):
        try:
            found = read_provenance(path)
            have = set(json.loads(found.inputs.get("obstacles", "null")) or ())
        except (InputError, ValueError, TypeError):
            continue  # damaged or foreign: never reused
        if (found.format, found.format_version) != (FORMAT, FORMAT_VERSION) or any(
                found.inputs.get(k) != expected.inputs[k] for k in ("urdf", "robot_yaml", "params")):
            continue
        added = {d.rsplit(":", 1)[0] for d in want - have}  # moved (the same name elsewhere) or new
        removed = {d.rsplit(":", 1)[0] for d in have - want} - added
        cost = len(added) + len(removed)
        if cost <= max(1, len(want) // 3) and (best is None or cost < best[0]):
            best = (cost, Reuse(path, found, tuple(sorted(added)), len(removed)))
    if best is None:
        return None
    reuse = best[1]
    art = replace(read_roadmap(reuse.path, reuse.provenance), unchecked=reuse.unchecked)
    share = blocked_share(problem, art.graph.nodes, reuse.unchecked)
    return replace(reuse, blocked=share, roadmap=art) if share <= REUSE_BLOCKED else None


# ------------------------------------------------------------------ worlds

@dataclass(frozen=True, eq=False)
class _Build:
    """What the build's workers share, made in the parent before they are forked (the
    collision worlds cannot be pickled); the worlds are the scratch of whoever runs."""

    problem: Problem
    worlds: dict[str, CollisionWorld]
    options: RoadmapOptions
    weights: np.ndarray  # (nq,) path-length weights
    planner: LocalPlanner
    chains: tuple  # per edge kind, see edge_chains
    nodes: np.ndarray | None = None  # (n, nq) Super Graph nodes, once composed
    source: np.ndarray | None = None  # (n, 2) their elementary nodes


def _worlds(problem: Problem, options: RoadmapOptions) -> dict[str, CollisionWorld]:
    parts = link_parts(problem.robot)
    margin = margin_rule(problem.robot, options.margin)

    def world(rule, without: str | None = None):
        keep = None if without is None else (lambda name: parts.get(name) != without)
        return collision_world(problem.robot, problem.spec.obstacles, problem.disabled.links(),
                               pair_filter=part_filter(parts, rule), margin=margin, links=keep)

    # the elementary worlds leave the other arm out altogether (it is in no checked pair)
    return {"right": world(subsystem(RIGHT), LEFT), "left": world(subsystem(LEFT), RIGHT),
            "node_right_torso": world(involving(LEFT)), "node_left_torso": world(involving(RIGHT)),
            "mixed": world(mixed)}


def q_base(problem: Problem) -> np.ndarray:
    """Rest configuration with the hands open: the value of the joints no roadmap moves."""
    q = problem.robot.q_rest.copy()
    for h in problem.robot.hands.values():
        q[h.idx] = h.open
    return q


def edge_chains(robot) -> tuple[tuple[np.ndarray, ...] | None, ...]:
    """Per edge kind, the joint sets through which the checked pairs move relative to each
    other (see :meth:`LocalPlanner.steps`): with the right roadmap's torso, L's pairs with
    the obstacles and the torso move through torso + left arm, with R through both arms;
    symmetrically; a torso swap checks all pairs (every joint)."""
    t, r, l = robot.groups["torso"], robot.groups["right_arm"], robot.groups["left_arm"]
    return ((np.r_[t, l], np.r_[l, r]), (np.r_[t, r], np.r_[l, r]), None)


def _elementary(b: _Build, side: str) -> tuple[ElementaryRoadmap, int, Rejections]:
    """The elementary roadmap of torso + ``side`` arm, its collision checks, and what its
    collision checks rejected."""
    problem, options, planner = b.problem, b.options, b.planner
    robot = problem.robot
    idx = np.concatenate([robot.groups["torso"], robot.groups[f"{side}_arm"]])
    base, w = q_base(problem), b.weights[idx]
    world = b.worlds[side]
    rng = np.random.default_rng([options.seed, 0 if side == "right" else 1])
    lo, hi = robot.lower[idx], robot.upper[idx]

    def full(x):
        q = base.copy()
        q[idx] = x
        return q

    tally = Rejections()
    is_free = tallied(world.is_free, world.colliding_pairs, tally)
    roadmap = visibility_prm(
        sample=lambda: rng.uniform(lo, hi),
        is_free=lambda x: is_free(full(x)),
        segment_free=lambda x0, x1: planner.segment_free(world, full(x0), full(x1)),
        maybe_free=lambda x0, x1: planner.segment_free(world, full(x0), full(x1), limit=PROBE),
        distance=lambda x0, xs: distance(x0, xs, w),
        options=VisPRMOptions(max_nodes=options.nodes, max_failures=options.max_failures))
    return roadmap, world.n_checks, tally


def _edge_worlds(b: _Build) -> tuple[CollisionWorld, ...]:
    """The worlds of the three edge kinds (edge_kind's order)."""
    return b.worlds["node_right_torso"], b.worlds["node_left_torso"], b.worlds["mixed"]


def _check_edges(b: _Build, chunk: np.ndarray) -> tuple[np.ndarray, int]:
    """Validity (c,) of candidate Super Graph edges (c, 2), and the checks made."""
    by_kind = _edge_worlds(b)
    before = sum(w.n_checks for w in by_kind)
    ok = np.array([b.planner.segment_free(by_kind[k], b.nodes[i], b.nodes[j], b.chains[k])
                   for i, j in chunk for k in (edge_kind(b.source, i, j),)], dtype=bool)
    return ok, sum(w.n_checks for w in by_kind) - before


class _Joined:
    """The Super Graph's edges as they are accepted, answering whether a candidate edge
    would still be useful: it joins two components (tree mode), or its ends are not already
    joined by a path at most ``stretch`` times its length (Nieuwenhuisen & Overmars 2004,
    "useful cycles"); with ``stretch`` 0 every edge is."""

    def __init__(self, n: int, tree: bool, stretch: float):
        self.components, self.tree, self.stretch = UnionFind(n), tree, stretch
        self.adjacent: list[dict[int, float]] = [dict() for _ in range(n)]

    def useful(self, a: int, b: int, length: float) -> bool:
        if self.components.find(a) != self.components.find(b):
            return True
        if self.tree:
            return False
        return self.stretch <= 0 or not self._within(a, b, self.stretch * length)

    def _within(self, a: int, b: int, bound: float) -> bool:
        """Is b at most ``bound`` from a along the accepted edges (Dijkstra cut at bound)?"""
        best, frontier = {a: 0.0}, [(0.0, a)]
        while frontier:
            d, u = heapq.heappop(frontier)
            if u == b:
                return True
            if d > best[u]:
                continue
            for v, w in self.adjacent[u].items():
                if d + w <= bound and d + w < best.get(v, np.inf):
                    best[v] = d + w
                    heapq.heappush(frontier, (d + w, v))
        return False

    def add(self, a: int, b: int, length: float) -> None:
        self.components.union(a, b)
        self.adjacent[a][b] = self.adjacent[b][a] = length


def _edges(b: _Build, cand: np.ndarray, jobs: int, progress) -> tuple[np.ndarray, int]:
    """Validity (c,) of the candidate edges (c, 2), and the checks made.

    Candidates are taken shortest first; one is checked only when it is still useful
    (:class:`_Joined`) given the edges accepted so far, and a valid one is kept only if it
    still is when its check returns.  Checks run in chunks of :data:`EDGE_CHUNK` over
    ``jobs`` workers, :data:`EDGE_WINDOW` chunks in flight: a chunk is made from the
    results of all the chunks before the window, so the roadmap does not depend on the
    number of jobs.  Long candidates, the costliest to check, are mostly the ones skipped."""
    lengths = np.asarray(distance(b.nodes[cand[:, 0]], b.nodes[cand[:, 1]], b.weights), dtype=float).reshape(-1)
    order = np.argsort(lengths, kind="stable")
    joined = _Joined(len(b.nodes), b.options.tree, b.options.stretch)
    valid, checks, position, pending = np.zeros(len(cand), dtype=bool), 0, 0, deque()
    with Workers(_check_edges, jobs, b) as workers:
        while True:
            while len(pending) < EDGE_WINDOW and position < len(order):
                chunk = []
                while len(chunk) < EDGE_CHUNK and position < len(order):  # the next useful candidates
                    k = int(order[position])
                    position += 1
                    if joined.useful(int(cand[k, 0]), int(cand[k, 1]), lengths[k]):
                        chunk.append(k)
                if chunk:
                    pending.append((chunk, workers.submit(cand[chunk])))
            if not pending:
                break
            chunk, result = pending.popleft()
            ok, n = result()
            checks += n
            for k in np.asarray(chunk)[ok]:
                a, c = int(cand[k, 0]), int(cand[k, 1])
                if joined.useful(a, c, lengths[k]):
                    joined.add(a, c, lengths[k])
                    valid[k] = True
            if progress:
                progress("Super Graph edges", position - sum(len(c) for c, _ in pending), len(cand))
    return valid, checks


# ------------------------------------------------------------------ build


def build_roadmap(scene: Path, cache_dir: Path, options: RoadmapOptions, jobs: int = 2,
                  progress: Callable[[str, int, int], None] | None = None) -> tuple[RoadmapArtefact, BuildReport]:
    """Build, store and return the roadmap; ``progress(stage, done, total)``."""
    if options.nodes <= 0:
        raise InputError(None, "--nodes", f"expected an integer >= 1, found {options.nodes}")
    if jobs <= 0:
        raise InputError(None, "--jobs", f"expected an integer >= 1, found {jobs}")
    problem = load_problem(scene, cache_dir)
    robot = problem.robot
    for side in ("right", "left"):
        if len(robot.groups[f"{side}_arm"]) == 0:
            raise InputError(robot.spec.file, f"groups.{side}_arm", "expected at least one joint")
    seconds: dict[str, float] = {}
    t0 = time.perf_counter()
    worlds = _worlds(problem, options)
    weights = joint_weights(robot)
    planner = LocalPlanner(options.resolution, options.margin, joint_reach(robot))
    b = _Build(problem, worlds, options, weights, planner, edge_chains(robot))
    rest = problem.world().colliding_pairs(q_base(problem))
    warnings = [f"the robot's rest configuration (hands open) is in collision: {pairs_text(rest)}; the roadmaps "
                "hold the joints they do not sample there"] if rest else []
    if progress:
        progress("elementary roadmaps", 0, 2)
    (right, cr, rej_r), (left, cl, rej_l) = list(ordered_map(_elementary, ["right", "left"], min(jobs, 2), b))
    warnings += _check_elementary(options, {"right": (right, rej_r), "left": (left, rej_l)}, rest)
    checks = cr + cl
    seconds["elementary roadmaps"] = time.perf_counter() - t0
    if progress:
        progress("elementary roadmaps", 2, 2)

    t1 = time.perf_counter()
    nodes, source, tested_nodes, n, few = _super_graph_nodes(b, right, left, rest)
    checks += n
    warnings += few
    seconds["Super Graph nodes"] = time.perf_counter() - t1

    t2 = time.perf_counter()
    cand = candidate_edges(source, right.neighbours(), left.neighbours())
    b = replace(b, nodes=nodes, source=source)
    valid, n = _edges(b, cand, jobs, progress)
    checks += n
    if progress:
        progress("Super Graph edges", len(cand), len(cand))
    edges = cand[valid]
    lengths = distance(nodes[edges[:, 0]], nodes[edges[:, 1]], weights) if len(edges) else np.zeros(0)
    graph = SuperGraph(nodes, source, edges, np.asarray(lengths, dtype=float), tested_nodes, len(cand))
    seconds["Super Graph edges"] = time.perf_counter() - t2

    art = RoadmapArtefact(right, left, graph, robot.joint_names, weights)
    t3 = time.perf_counter()
    path = artefact_path(cache_dir, problem, options)
    write_roadmap(path, provenance(problem, options), art, options)
    seconds["write"] = time.perf_counter() - t3
    rows = summary(art)
    rows["collision checks"] = f"{checks:,}"
    total = sum(seconds.values())
    rows["collision checks / s"] = f"{checks / max(total, 1e-9):,.0f}"
    return art, BuildReport(path, rows, seconds, tuple(warnings))


def _rest_note(rest: list[tuple[str, str]]) -> str:
    return (f"; the rest configuration (hands open), where the roadmaps hold the joints they do not sample, is in "
            f"collision: {pairs_text(rest)}") if rest else ""


def _check_elementary(options: RoadmapOptions, roadmaps: dict[str, tuple[ElementaryRoadmap, Rejections]],
                         rest: list[tuple[str, str]]) -> list[str]:
    """Raises EmptyRoadmap when an elementary roadmap has no node, naming the pairs that
    rejected most samples (and ``rest``, the colliding pairs of the rest configuration);
    returns a warning per roadmap with fewer nodes than asked for."""
    what = f"samples collide or come within {1000 * options.margin:g} mm"
    empty, few = [], []
    for side, (rm, tally) in roadmaps.items():
        name = f"R_{side[0]} (torso + {side} arm)"
        if len(rm.nodes) == 0:
            empty.append(f"{name} has no node: {tally.describe(what)}")
        elif len(rm.nodes) < options.nodes:  # any shortfall is said: a user asked for the nodes
            few.append(f"{name} has {len(rm.nodes)} of the {options.nodes} nodes asked for: {tally.describe(what)}")
    if empty:
        raise EmptyRoadmap("the roadmap is empty: " + "; ".join(empty) + _rest_note(rest))
    return few


def _super_graph_nodes(b: _Build, right: ElementaryRoadmap, left: ElementaryRoadmap, rest: list[tuple[str, str]]):
    """Super Graph nodes (m, nq), their sources (m, 3), the candidates tested, the
    collision checks made, and a warning when fewer than :data:`FEW` of the candidates
    are free; raises EmptyRoadmap when none is."""
    wr, wl = b.worlds["node_right_torso"], b.worlds["node_left_torso"]
    before, tally = wr.n_checks + wl.n_checks, Rejections()
    nodes, source, tested = compose_nodes(b.problem.robot, q_base(b.problem), right.nodes, left.nodes,
                                          tallied(wr.is_free, wr.colliding_pairs, tally),
                                          tallied(wl.is_free, wl.colliding_pairs, tally))
    what = f"combinations of elementary nodes collide or come within {1000 * b.options.margin:g} mm"
    if len(nodes) == 0:
        raise EmptyRoadmap(f"the roadmap is empty: no Super Graph node: {tally.describe(what)}{_rest_note(rest)}")
    few = [f"the Super Graph has only {len(nodes)} nodes: {tally.describe(what)}"] if len(nodes) < FEW * tested else []
    return nodes, source, tested, wr.n_checks + wl.n_checks - before, few


def summary(art: RoadmapArtefact) -> dict[str, str]:
    def comps(rm: ElementaryRoadmap) -> int:
        g = nx.Graph()
        g.add_nodes_from(range(len(rm.nodes)))
        g.add_edges_from(map(tuple, rm.edges))
        return nx.number_connected_components(g)

    g = art.networkx()
    rows = {}
    for name, rm in (("R_r (torso + right arm)", art.right), ("R_l (torso + left arm)", art.left)):
        rows[name] = (f"{len(rm.nodes)} nodes ({int(rm.guard.sum())} guards), {len(rm.edges)} edges, "
                      f"{comps(rm)} components, {rm.samples} samples")
    sg = art.graph
    rows["Super Graph"] = (f"{len(sg.nodes)} nodes (of {sg.candidates_nodes} candidates), {len(sg.edges)} edges "
                           f"(of {sg.candidates_edges} candidates), {nx.number_connected_components(g)} components")
    return rows


# ------------------------------------------------------------------ storage


def write_roadmap(path: Path, prov: Provenance, art: RoadmapArtefact, options: RoadmapOptions) -> None:
    groups = {}
    for side, rm in (("right", art.right), ("left", art.left)):
        groups[side] = {"nodes": rm.nodes, "edges": rm.edges, "lengths": rm.lengths, "guard": rm.guard}
    sg = art.graph
    groups["super_graph"] = {"nodes": sg.nodes, "source": sg.source, "edges": sg.edges, "lengths": sg.lengths}
    write_artefact(path, prov, {"joint_names": np.array(art.joint_names), "weights": art.weights},
                   attrs={"options": canonical_json(asdict(options)),
                          "samples_right": art.right.samples, "samples_left": art.left.samples,
                          "candidate_nodes": sg.candidates_nodes, "candidate_edges": sg.candidates_edges},
                   groups=groups)


def read_roadmap(path: Path, expected: Provenance | None = None) -> RoadmapArtefact:
    """Load a roadmap; with ``expected``, refuse it when the robot, obstacles or options changed."""
    a = read_artefact(path, expected or read_provenance(path), rebuild="regrasp roadmap build")
    rms = {side: ElementaryRoadmap(a[f"{side}/nodes"], a[f"{side}/edges"], a[f"{side}/lengths"], a[f"{side}/guard"].astype(bool),
                         int(a.attrs[f"samples_{side}"])) for side in ("right", "left")}
    sg = SuperGraph(a["super_graph/nodes"], a["super_graph/source"], a["super_graph/edges"], a["super_graph/lengths"],
                    int(a.attrs["candidate_nodes"]), int(a.attrs["candidate_edges"]))
    names = tuple(str(s) for s in a["joint_names"])
    return RoadmapArtefact(rms["right"], rms["left"], sg, names, a["weights"])


def load_or_build(scene: Path, cache_dir: Path, options: RoadmapOptions, jobs: int = 2,
                  build: bool = True) -> RoadmapArtefact:
    """The cached roadmap if fresh; else a new one (or, with ``build=False``, a refusal)."""
    from regrasp_cli.store import artefact_lock, is_fresh

    problem = load_problem(scene, cache_dir)
    prov = provenance(problem, options)
    path = artefact_path(cache_dir, problem, options)
    with artefact_lock(path, create=build):  # another process building it: wait, then read it
        if path.is_file() and is_fresh(path, prov):
            return read_roadmap(path, prov)
        if not build:
            return read_roadmap(path, prov)  # raises: missing or stale, naming what differs
        return build_roadmap(scene, cache_dir, options, jobs)[0]
