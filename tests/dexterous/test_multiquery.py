"""The multi-query GS_n roadmap (seed 003 §V) on `builtin:hand4` holding a 7 cm sphere:
the learning joins grasps at random orientations into one graph whose every edge is a
feasible chain of transfers and regrasps from its node to the other; a query joins a start
and a goal grasp to it and its pieces run from the start to the goal pose; the roadmap
survives its storage as arrays; the cached artefact is reused when fresh and rebuilt,
never read, when its bytes changed; a bad planning.mode is refused with the field."""

from __future__ import annotations

from dataclasses import replace

import h5py
import networkx as nx
import numpy as np
import pytest
import yaml

from conftest import ROOT
from tests.dexterous.test_roadmap import _assert_feasible, _goal, gs  # noqa: F401 (the fixture)

from regrasp_cli.config import load_inhand_spec
from regrasp_cli.dexterous.gait import GaitOptions
from regrasp_cli.dexterous.multiquery import LearnOptions, from_arrays, learn, query, to_arrays
from regrasp_cli.dexterous.roadmap import GaitTreeOptions, start_config
from regrasp_cli.dexterous.task import inhand_roadmap, load_inhand_problem, roadmap_path, roadmap_provenance
from regrasp_cli.errors import InputError

SMALL = LearnOptions(roots=3, round_expansions=150, query_expansions=300, shortcuts=10)


@pytest.fixture(scope="module")
def learned(gs):  # noqa: F811
    return learn(gs, np.zeros(3), np.random.default_rng(3), SMALL)


def test_every_edge_is_a_feasible_chain_from_its_node_to_the_other(gs, learned):  # noqa: F811
    rm, st = learned
    assert st.joined >= 1 and len(rm.nodes) >= 2
    assert nx.is_connected(rm.graph())  # one component: a grasp that did not join is dropped
    for (a, b), pieces in rm.edges.items():
        X = _assert_feasible(gs, pieces, rm.nodes[a])
        end = pieces[-1].end
        assert np.allclose(end.q, rm.nodes[b].q, atol=1e-9) and np.allclose(X, rm.nodes[b].X_GO, atol=1e-9)
        assert np.allclose(end.p, rm.nodes[b].p, atol=1e-9)
        back = rm.pieces(b, a)  # run backwards it starts at b
        assert np.allclose(back[0].q[0], rm.nodes[b].q, atol=1e-9)


def test_the_roadmap_survives_its_storage_as_arrays(learned):
    rm, _ = learned
    again = from_arrays(to_arrays(rm))
    assert set(again.edges) == set(rm.edges) and len(again.nodes) == len(rm.nodes)
    for e, pieces in rm.edges.items():
        for p, q in zip(pieces, again.edges[e], strict=True):
            assert type(p) is type(q) and np.array_equal(p.q, q.q) and np.array_equal(p.end.X_GO, q.end.X_GO)
            assert np.array_equal(p.end.p, q.end.p) and np.array_equal(p.end.n, q.end.n)


def test_a_query_runs_from_the_start_grasp_to_the_goal_pose(gs, learned):  # noqa: F811
    rm, _ = learned
    rng = np.random.default_rng(5)
    start = start_config(gs, np.eye(4), rng, GaitTreeOptions(start_samples=20))
    goal = start_config(gs, _goal(2.0, [1, 1, 0]), rng, GaitTreeOptions(start_samples=20))
    pieces, st, why = query(gs, rm, start, goal, rng, SMALL)
    assert pieces is not None, why
    X = _assert_feasible(gs, pieces, start)
    assert np.allclose(X, goal.X_GO, atol=1e-9)
    assert len(rm.nodes) == len(from_arrays(to_arrays(rm)).nodes)  # the query left the roadmap as it was


def _scene(tmp_path, **planning):
    d = yaml.safe_load((ROOT / "regrasp_cli" / "data" / "scenes" / "inhand_ball.yaml").read_text())
    d["robot"] = "builtin:hand4"
    d["planning"] = {**d.get("planning", {}), **planning}
    path = tmp_path / "scene.yaml"
    path.write_text(yaml.safe_dump(d))
    return path


def test_the_cached_roadmap_is_reused_and_rebuilt_when_its_bytes_change(tmp_path, cache_dir):
    cache = tmp_path / "cache"
    problem = replace(load_inhand_problem(_scene(tmp_path), cache_dir), cache_dir=cache)  # its own roadmap folder
    opts = LearnOptions(roots=2)
    rm, _, built = inhand_roadmap(problem, opts)
    assert built
    again, _, built = inhand_roadmap(problem, opts)
    assert not built and len(again.nodes) == len(rm.nodes)
    r = replace(GaitTreeOptions(), step_rad=problem.spec.planning.step_rad)
    g = GaitOptions(gait_m=problem.spec.planning.gait_m)
    path = roadmap_path(cache, problem, roadmap_provenance(problem, opts, r, g))
    with h5py.File(path, "r+") as f:
        f["nodes/q"][0, 0] += 0.1  # one joint value changed on disk
    _, _, built = inhand_roadmap(problem, opts)
    assert built  # refused as damaged and learned again, not read


def test_two_objects_get_two_roadmap_files(tmp_path, cache_dir):
    ball = load_inhand_problem(_scene(tmp_path), cache_dir)
    d = yaml.safe_load((tmp_path / "scene.yaml").read_text())
    d["object"]["mesh"] = "builtin:cube"
    (tmp_path / "cube.yaml").write_text(yaml.safe_dump(d))
    cube = load_inhand_problem(tmp_path / "cube.yaml", cache_dir)
    o, r, g = LearnOptions(), GaitTreeOptions(), GaitOptions()
    paths = {roadmap_path(tmp_path, p, roadmap_provenance(p, o, r, g)) for p in (ball, cube)}
    assert len(paths) == 2  # else each would find the other's file stale and learn over it


def test_a_bad_mode_is_refused_with_its_field(tmp_path):
    with pytest.raises(InputError) as e:
        load_inhand_spec(_scene(tmp_path, mode="any"))
    assert "planning.mode" in str(e.value) and "multi-query" in str(e.value)


def test_a_query_option_keeps_the_learned_roadmap_and_a_learning_option_does_not(tmp_path, cache_dir):
    problem = load_inhand_problem(_scene(tmp_path), cache_dir)
    o, r, g = LearnOptions(), GaitTreeOptions(), GaitOptions()
    key = lambda o, r: roadmap_provenance(problem, o, r, g).inputs["params"]  # noqa: E731
    base = key(o, r)
    # the query's budget and aim, and how many detours it cuts: the same roadmap
    assert key(replace(o, query_expansions=600, shortcuts=5), replace(r, nodes=100, goal_bias=0.9)) == base
    # what the learning reads: another roadmap
    assert key(replace(o, roots=10), r) != base
    assert key(o, replace(r, step_rad=0.2)) != base
    assert key(o, replace(r, connect_rad=0.5)) != base
