"""`regrasp roadmap build` as a library (regrasp_cli.roadmap.build): small roadmaps of
the default scene are built once per module and checked independently: validity of every
stored node and edge (the Super Graph with the plain world, the elementary roadmaps with
their subsystem world, edges re-checked at half the resolution), the paper's edge filter,
tree mode, determinism (seed and number of jobs) and the refusal of a roadmap built for
another robot or obstacle set."""

from __future__ import annotations

import shutil
from dataclasses import replace
from pathlib import Path

import networkx as nx
import numpy as np
import pytest
import yaml

from cli_helpers import copy_artefacts

from regrasp_cli.errors import InputError, StaleArtefactError
from regrasp_cli.model.collision import CollisionWorld, collision_world
from regrasp_cli.model.robot import load_robot
from regrasp_cli.roadmap import compose
from regrasp_cli.roadmap.build import (RoadmapArtefact, RoadmapOptions, artefact_path, build_roadmap, load_or_build,
                                       nearest_roadmap,
                                       provenance, q_base, read_roadmap, summary)
from regrasp_cli.motion.local import distance
from regrasp_cli.scene import load_problem

ROOT = Path(__file__).resolve().parents[2]
ROBOT_DIR = ROOT / "configs" / "robots" / "humanoid43"
SCENE_YAML = ROOT / "configs" / "scenes" / "desk_handover.yaml"

OPTS = RoadmapOptions(nodes=10)  # shared with tests/roadmap/test_compose.py through the run's cache
TREE = replace(OPTS, tree=True)
FULL = replace(OPTS, stretch=0.0)  # every candidate edge checked
SMALL = RoadmapOptions(nodes=8)  # the determinism builds


def fresh_cache(tmp_path_factory, cache_dir: Path) -> Path:
    """An empty cache holding only the (slow to compute) self-collision pairs."""
    d = tmp_path_factory.mktemp("fresh")
    src = Path(cache_dir) / "self_collision"
    if src.is_dir():
        copy_artefacts(src, d / "self_collision")
    return d


@pytest.fixture(scope="module")
def graph(problem, cache_dir) -> RoadmapArtefact:
    return load_or_build(SCENE_YAML, cache_dir, OPTS, jobs=2)


@pytest.fixture(scope="module")
def graph_path(graph, problem, cache_dir) -> Path:
    return artefact_path(cache_dir, problem, OPTS)


@pytest.fixture(scope="module")
def tree(problem, cache_dir) -> RoadmapArtefact:
    return load_or_build(SCENE_YAML, cache_dir, TREE, jobs=1)


@pytest.fixture(scope="module")
def full(problem, cache_dir) -> RoadmapArtefact:
    return load_or_build(SCENE_YAML, cache_dir, FULL, jobs=2)


@pytest.fixture(scope="module")
def plain_world(problem) -> CollisionWorld:
    return problem.world()


def subsystem_world(problem, side: str) -> CollisionWorld:
    robot = problem.robot
    filt = compose.part_filter(compose.link_parts(robot), compose.subsystem(side))
    return collision_world(robot, problem.spec.obstacles, problem.disabled.links(), pair_filter=filt)


def arrays(art: RoadmapArtefact) -> dict[str, np.ndarray]:
    out = {"weights": art.weights, "joint_names": np.array(art.joint_names)}
    for side, rm in (("right", art.right), ("left", art.left)):
        for k in ("nodes", "edges", "lengths", "guard"):
            out[f"{side}/{k}"] = getattr(rm, k)
        out[f"{side}/samples"] = np.array(rm.samples)
    for k in ("nodes", "source", "edges", "lengths"):
        out[f"sg/{k}"] = getattr(art.graph, k)
    out["sg/candidates"] = np.array([art.graph.candidates_nodes, art.graph.candidates_edges])
    return out


def assert_same_roadmap(a: RoadmapArtefact, b: RoadmapArtefact) -> None:
    xa, xb = arrays(a), arrays(b)
    assert xa.keys() == xb.keys()
    for k in xa:
        assert xa[k].shape == xb[k].shape, k
        assert np.array_equal(xa[k], xb[k]), k


# --------------------------------------------------------------------------- structure


def test_the_roadmap_is_not_trivial(graph):
    assert len(graph.right.nodes) == OPTS.nodes and len(graph.left.nodes) == OPTS.nodes
    assert len(graph.graph.nodes) > 0 and len(graph.graph.edges) > 0


def test_super_graph_nodes_match_their_elementary_sources(graph, problem):
    robot = problem.robot
    t, ra, la = robot.groups["torso"], robot.groups["right_arm"], robot.groups["left_arm"]
    nt = len(t)
    sg = graph.graph
    assert sg.nodes.shape == (len(sg.source), robot.nq)
    base = q_base(problem)
    other = np.setdiff1d(np.arange(robot.nq), np.concatenate([t, ra, la]))
    for q, (i, j, s) in zip(sg.nodes, sg.source):
        xr, xl = graph.right.nodes[i], graph.left.nodes[j]
        assert s in (0, 1)
        assert np.array_equal(q[t], (xr if s == 0 else xl)[:nt])
        assert np.array_equal(q[ra], xr[nt:]) and np.array_equal(q[la], xl[nt:])
        assert np.array_equal(q[other], base[other])
    assert len({tuple(s) for s in sg.source.tolist()}) == len(sg.source)  # no duplicate node
    assert sg.candidates_nodes >= len(sg.nodes)
    assert sg.candidates_edges >= len(sg.edges)


def test_super_graph_edges_are_ordered_with_their_lengths(graph):
    sg = graph.graph
    assert np.all(sg.edges[:, 0] < sg.edges[:, 1])
    assert len({tuple(e) for e in sg.edges.tolist()}) == len(sg.edges)
    expected = distance(sg.nodes[sg.edges[:, 0]], sg.nodes[sg.edges[:, 1]], graph.weights)
    assert np.allclose(sg.lengths, expected)


def test_super_graph_edges_have_their_elementary_parts(graph):
    """The paper's filter: a Super Graph edge only joins nodes whose right parts are equal
    or adjacent in R_r and whose left parts are equal or adjacent in R_l."""
    r_edges = {frozenset(map(int, e)) for e in graph.right.edges}
    l_edges = {frozenset(map(int, e)) for e in graph.left.edges}
    src = graph.graph.source
    for a, b in graph.graph.edges:
        (i, j, _), (i2, j2, _) = src[a], src[b]
        assert i == i2 or frozenset((int(i), int(i2))) in r_edges, (a, b, src[a], src[b])
        assert j == j2 or frozenset((int(j), int(j2))) in l_edges, (a, b, src[a], src[b])


# --------------------------------------------------------------------------- validity


def test_super_graph_nodes_are_collision_free(graph, plain_world):
    bad = [k for k, q in enumerate(graph.graph.nodes) if not plain_world.is_free(q)]
    assert not bad, [(k, plain_world.colliding_pairs(graph.graph.nodes[k])) for k in bad[:5]]


def test_super_graph_edges_pass_at_half_resolution(graph, plain_world):
    res = OPTS.resolution / 2
    sg = graph.graph
    bad = [(int(a), int(b)) for a, b in sg.edges if not plain_world.segment_free(sg.nodes[a], sg.nodes[b], res)]
    assert not bad, f"{len(bad)} of {len(sg.edges)} edges collide at resolution {res}: {bad[:10]}"


@pytest.mark.parametrize("side", ["right", "left"])
def test_elementary_nodes_and_edges_are_valid(graph, problem, side):
    robot = problem.robot
    idx = np.concatenate([robot.groups["torso"], robot.groups[f"{side}_arm"]])
    base = q_base(problem)
    world = subsystem_world(problem, compose.RIGHT if side == "right" else compose.LEFT)
    rm = getattr(graph, side)
    assert rm.nodes.shape == (len(rm.guard), len(idx))

    def full(x):
        q = base.copy()
        q[idx] = x
        return q

    for k, x in enumerate(rm.nodes):
        assert world.is_free(full(x)), (side, k, world.colliding_pairs(full(x)))
        assert robot.within_limits(full(x))
    res = OPTS.resolution / 2
    bad = [(int(a), int(b)) for a, b in rm.edges if not world.segment_free(full(rm.nodes[a]), full(rm.nodes[b]), res)]
    assert not bad, (side, bad)


# --------------------------------------------------------------------------- tree mode


def test_tree_mode_yields_a_forest(tree):
    g = tree.networkx()
    assert g.number_of_edges() > 0
    assert nx.is_forest(g)


def test_tree_mode_spans_the_components_of_graph_mode(tree, graph):
    """Same seed, same elementary roadmaps and Super Graph nodes; the tree keeps a subset
    of the graph's edges with exactly the same connected components."""
    for side in ("right", "left"):
        assert np.array_equal(getattr(tree, side).nodes, getattr(graph, side).nodes)
    assert np.array_equal(tree.graph.nodes, graph.graph.nodes)
    assert np.array_equal(tree.graph.source, graph.graph.source)
    t_edges = {tuple(e) for e in tree.graph.edges.tolist()}
    g_edges = {tuple(e) for e in graph.graph.edges.tolist()}
    assert t_edges <= g_edges
    comps = lambda g: sorted(sorted(c) for c in nx.connected_components(g))  # noqa: E731
    assert comps(tree.networkx()) == comps(graph.networkx())


def test_graph_mode_skips_only_edges_it_can_do_without(graph, full):
    """Useful cycles: the graph keeps a subset of the edges of the graph with every valid
    candidate, with the same components, and joins the ends of every edge it left out
    by a path at most ``stretch`` times that edge's length."""
    assert np.array_equal(graph.graph.nodes, full.graph.nodes)
    g_edges = {tuple(e) for e in graph.graph.edges.tolist()}
    f_edges = {tuple(e) for e in full.graph.edges.tolist()}
    assert g_edges < f_edges
    comps = lambda g: sorted(sorted(c) for c in nx.connected_components(g))  # noqa: E731
    g = graph.networkx()
    assert comps(g) == comps(full.networkx())
    for (a, b), length in zip(full.graph.edges.tolist(), full.graph.lengths):
        if (a, b) not in g_edges:
            assert nx.dijkstra_path_length(g, a, b, weight="length") <= OPTS.stretch * length + 1e-9


# --------------------------------------------------------------------------- determinism


@pytest.fixture(scope="module")
def fresh_builds(problem, cache_dir, tmp_path_factory):
    """Two builds with the same seed in fresh caches, one with 1 job, one with 2."""
    out = {}
    for jobs in (1, 2):
        d = fresh_cache(tmp_path_factory, cache_dir)
        art, rep = build_roadmap(SCENE_YAML, d, SMALL, jobs=jobs)
        out[jobs] = (art, rep, d)
    return out


def test_same_seed_and_any_jobs_give_the_same_roadmap(fresh_builds):
    (a1, r1, d1), (a2, r2, d2) = fresh_builds[1], fresh_builds[2]
    assert d1 != d2 and r1.path.parent.parent == d1 and r2.path.parent.parent == d2
    assert r1.path.name == r2.path.name
    assert_same_roadmap(a1, a2)
    # and what was stored on disk too
    assert_same_roadmap(read_roadmap(r1.path), read_roadmap(r2.path))
    assert r1.rows == r2.rows | {"collision checks / s": r1.rows["collision checks / s"]}


def test_stored_roadmap_reads_back_identical(fresh_builds, problem):
    art, rep, _ = fresh_builds[2]
    assert rep.path.is_file() and rep.path.suffix == ".h5"
    assert_same_roadmap(read_roadmap(rep.path, provenance(problem, SMALL)), art)


def test_build_report(fresh_builds):
    art, rep, _ = fresh_builds[1]
    for k in ("R_r (torso + right arm)", "R_l (torso + left arm)", "Super Graph", "collision checks"):
        assert k in rep.rows
    assert set(rep.seconds) == {"elementary roadmaps", "Super Graph nodes", "Super Graph edges", "write"}
    assert all(v >= 0 for v in rep.seconds.values())
    assert rep.rows["Super Graph"].startswith(f"{len(art.graph.nodes)} nodes")
    assert summary(art).items() <= rep.rows.items()


def test_a_cached_roadmap_is_reused(graph, graph_path, problem, cache_dir):
    mtime = graph_path.stat().st_mtime_ns
    again = load_or_build(SCENE_YAML, cache_dir, OPTS, jobs=1, build=False)
    assert_same_roadmap(again, graph)
    assert graph_path.stat().st_mtime_ns == mtime


def test_a_missing_roadmap_is_refused_without_build(tmp_path, problem, cache_dir):
    d = tmp_path / "empty"
    copy_artefacts(Path(cache_dir) / "self_collision", d / "self_collision")
    with pytest.raises(InputError):
        load_or_build(SCENE_YAML, d, OPTS, build=False)
    assert not (d / "roadmap").exists()


@pytest.mark.parametrize("nodes,jobs,field", [(0, 1, "--nodes"), (-3, 1, "--nodes"), (4, 0, "--jobs")])
def test_bad_numbers_are_input_errors(tmp_path, nodes, jobs, field):
    with pytest.raises(InputError, match=field):
        build_roadmap(SCENE_YAML, tmp_path, RoadmapOptions(nodes=nodes), jobs=jobs)
    assert not (tmp_path / "roadmap").exists()


# --------------------------------------------------------------------------- provenance


def scene_copy(tmp_path: Path, robot_yaml: Path | None = None, move: str | None = None) -> Path:
    d = yaml.safe_load(SCENE_YAML.read_text())
    d["robot"] = str(robot_yaml or ROBOT_DIR / "robot.yaml")
    if move is not None:
        ob = next(o for o in d["obstacles"] if o["name"] == move)
        ob["pose"]["xyz"][2] += 0.05
    path = tmp_path / "scene.yaml"
    path.write_text(yaml.safe_dump(d, sort_keys=False))
    return path


def robot_copy(tmp_path: Path, rest: float | None = None, urdf_suffix: str = "") -> Path:
    d = yaml.safe_load((ROBOT_DIR / "robot.yaml").read_text())
    if rest is not None:
        d["rest"]["r_arm_j1"] = rest
    (tmp_path / "robot.urdf").write_text((ROBOT_DIR / "robot.urdf").read_text() + urdf_suffix)
    path = tmp_path / "robot.yaml"
    path.write_text(yaml.safe_dump(d, sort_keys=False))
    return path


def test_own_provenance_is_accepted(graph, graph_path, problem):
    assert_same_roadmap(read_roadmap(graph_path, provenance(problem, OPTS)), graph)


def test_refused_for_moved_obstacle(graph_path, tmp_path, cache_dir):
    other = load_problem(scene_copy(tmp_path, move="vase_body"), cache_dir)
    with pytest.raises(StaleArtefactError) as exc:
        read_roadmap(graph_path, provenance(other, OPTS))
    msg = str(exc.value)
    assert "obstacles" in msg and "urdf" not in msg and "robot_yaml" not in msg


def test_refused_for_another_robot_yaml(graph_path, tmp_path, cache_dir):
    robot_yaml = robot_copy(tmp_path, rest=0.25)
    other = load_problem(scene_copy(tmp_path, robot_yaml=robot_yaml), cache_dir)
    with pytest.raises(StaleArtefactError) as exc:
        read_roadmap(graph_path, provenance(other, OPTS))
    msg = str(exc.value)
    assert "robot_yaml" in msg and "obstacles" not in msg


def test_refused_for_another_urdf(graph_path, problem, tmp_path):
    robot = load_robot(robot_copy(tmp_path, urdf_suffix="\n<!-- edited -->\n"))
    other = replace(problem, robot=robot)  # provenance depends on the robot and obstacles only
    with pytest.raises(StaleArtefactError) as exc:
        read_roadmap(graph_path, provenance(other, OPTS))
    assert "urdf" in str(exc.value) and "obstacles" not in str(exc.value)


def test_refused_for_other_options(graph_path, problem):
    with pytest.raises(StaleArtefactError, match="params"):
        read_roadmap(graph_path, provenance(problem, replace(OPTS, seed=OPTS.seed + 1)))


# --------------------------------------------------------------------------- reuse for moved obstacles


def _variant(tmp_path: Path, name: str, edit) -> Path:
    d = yaml.safe_load(SCENE_YAML.read_text())
    edit(d["obstacles"])
    path = tmp_path / f"{name}.yaml"
    path.write_text(yaml.safe_dump(d, sort_keys=False))
    return path


def _moved(names):
    def edit(obstacles):
        for ob in obstacles:
            if ob["name"] in names:
                ob["pose"]["xyz"][1] += 0.05
    return edit


def test_a_roadmap_is_reused_when_a_few_obstacles_moved_and_not_when_many(graph, graph_path, cache_dir, tmp_path):
    """Thirteen obstacles: one or two moved (or one removed) reuse the roadmap, the moved
    ones to be checked online; one added where it blocks many nodes, five moved (more
    than a third), or other options do not."""
    d = tmp_path / "cache"
    copy_artefacts(Path(cache_dir) / "self_collision", d / "self_collision")
    (d / "roadmap").mkdir(parents=True)
    shutil.copy(graph_path, d / "roadmap" / graph_path.name)
    vase = load_problem(_variant(tmp_path, "vase", _moved({"vase_body", "vase_neck"})), cache_dir)
    reuse = nearest_roadmap(d, vase, OPTS)
    assert reuse is not None and reuse.path.name == graph_path.name
    assert reuse.unchecked == ("vase_body", "vase_neck") and reuse.removed == 0 and reuse.blocked <= 0.05
    # one obstacle added, but where the arms work: it blocks too many of the nodes
    wall = {"name": "wall", "box": {"size": [0.1, 1.6, 0.5]}, "pose": {"xyz": [0.45, 0.0, 1.15]}}
    walled = load_problem(_variant(tmp_path, "wall", lambda obs: obs.append(wall)), cache_dir)
    assert nearest_roadmap(d, walled, OPTS) is None
    gone = load_problem(_variant(tmp_path, "gone", lambda obs: obs.pop()), cache_dir)
    reuse = nearest_roadmap(d, gone, OPTS)
    assert reuse is not None and reuse.unchecked == () and reuse.removed == 1
    legs = {"desk_leg_fr", "desk_leg_fl", "desk_leg_br", "desk_leg_bl", "vase_body"}
    assert nearest_roadmap(d, load_problem(_variant(tmp_path, "many", _moved(legs)), cache_dir), OPTS) is None
    assert nearest_roadmap(d, vase, replace(OPTS, seed=OPTS.seed + 1)) is None


def test_the_queries_check_the_moved_obstacles_lazily(problem):
    """The lazy world of a phase holds the pairs of the obstacles the roadmap was not
    built with, and those of no other obstacle."""
    from regrasp_cli.manip.context import OnlineOptions, Scratch
    from regrasp_cli.manip.tasks.handover import phase_worlds

    robot = problem.robot
    fingers = {h: robot.hands[h].open for h in ("right", "left")}
    for unchecked in ((), ("vase_body",)):
        scratch = Scratch(problem, OnlineOptions(), unchecked)
        lazy = phase_worlds(scratch, problem.spec.task.X_WO_start, None, fingers).lazy.world
        pairs = lazy.model.geometry_model.collisionPairs
        names = {lazy.geometry_name(g) for cp in pairs for g in (cp.first, cp.second)}
        obstacles = {n for n in names if n.startswith("obstacle:")}
        assert obstacles == {f"obstacle:{n}" for n in unchecked}
