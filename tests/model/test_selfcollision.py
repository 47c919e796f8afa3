"""Tests of regrasp_cli.model.selfcollision: verdicts known on paper on a tiny robot, the
fast classification against every distance in every sample, the sphere-cover bounds, the
progress callback and what the cache key depends on."""

from __future__ import annotations

import io
import json
from pathlib import Path

import coal
import numpy as np
import pinocchio as pin
import pytest
import yaml

from regrasp_cli.model import selfcollision
from regrasp_cli.model.collision import cold_start
from regrasp_cli.model.robot import load_robot
from regrasp_cli.model.selfcollision import (cache_key, compute_disabled_pairs, cover_distance, disabled_pairs,
                                             sphere_cover)

HUMANOID = Path(__file__).resolve().parents[2] / "regrasp_cli" / "data" / "robots" / "humanoid43" / "robot.yaml"

# A planar robot around the z axis: arm a reaches out along +x (a2 bends at most 0.5 rad,
# so it stays > 0.43 m from the base sphere), arm b along -x, and b2 is a sphere on b's
# second joint axis, at the base's centre, overlapping the base in every configuration.
TINY_URDF = """<robot name="tiny">
  <link name="base"><collision><geometry><sphere radius="0.1"/></geometry></collision></link>
  <joint name="ja1" type="revolute"><parent link="base"/><child link="a1"/><axis xyz="0 0 1"/>
    <limit lower="-0.3" upper="0.3" effort="1" velocity="1"/></joint>
  <link name="a1"><collision><origin xyz="0.3 0 0"/><geometry><sphere radius="0.05"/></geometry></collision></link>
  <joint name="ja2" type="revolute"><parent link="a1"/><child link="a2"/><origin xyz="0.3 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-0.5" upper="0.5" effort="1" velocity="1"/></joint>
  <link name="a2"><collision><origin xyz="0.3 0 0"/><geometry>GEOMETRY</geometry></collision></link>
  <joint name="jb1" type="revolute"><parent link="base"/><child link="b1"/><origin rpy="0 0 3.14159265"/>
    <axis xyz="0 0 1"/><limit lower="-0.3" upper="0.3" effort="1" velocity="1"/></joint>
  <link name="b1"><collision><origin xyz="0.3 0 0"/><geometry><sphere radius="0.05"/></geometry></collision></link>
  <joint name="jb2" type="revolute"><parent link="b1"/><child link="b2"/><axis xyz="0 0 1"/>
    <limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
  <link name="b2"><collision><geometry><sphere radius="0.12"/></geometry></collision></link>
</robot>
"""

TINY_EXPECTED = {("a1", "base"): "adjacent", ("b1", "base"): "adjacent", ("a1", "a2"): "adjacent",
                 ("b1", "b2"): "adjacent", ("a2", "base"): "never", ("b2", "base"): "always"}

# a tetrahedron with 5 cm edges along x, y, z (triangles of vertices, m)
TET = [((0, 0, 0), (0.05, 0, 0), (0, 0.05, 0)), ((0, 0, 0), (0, 0.05, 0), (0, 0, 0.05)),
       ((0, 0, 0), (0, 0, 0.05), (0.05, 0, 0)), ((0.05, 0, 0), (0, 0, 0.05), (0, 0.05, 0))]


def _stl(triangles) -> str:
    facets = "".join("facet normal 0 0 0\n outer loop\n" + "".join(f"  vertex {x} {y} {z}\n" for x, y, z in t)
                     + " endloop\nendfacet\n" for t in triangles)
    return f"solid tet\n{facets}endsolid tet\n"


def tiny_robot(tmp_path: Path, geometry: str = '<sphere radius="0.05"/>', samples: int = 50, **yaml_changes):
    """The tiny robot of TINY_URDF (a2's geometry given) with a minimal robot.yaml."""
    urdf = tmp_path / "tiny.urdf"
    urdf.write_text(TINY_URDF.replace("GEOMETRY", geometry))
    spec = {"format": "regrasp.robot/1", "urdf": str(urdf),
            "groups": {"torso": [], "right_arm": ["ja1"], "left_arm": ["jb1"]},
            "hands": {"right": {"grasp_frame": "a2", "fingers": [
                {"name": "f", "joints": ["ja2"], "tip_link": "a2", "tip_radius": 0.01, "open": [0.0]}]}},
            "self_collision": {"samples": samples, "seed": 0, "never_margin": 0.02}}
    spec.update(yaml_changes)
    path = tmp_path / "robot.yaml"
    path.write_text(yaml.safe_dump(spec, sort_keys=False))
    return load_robot(path)


def every_distance(robot, samples: int, seed: int, never_margin: float, adjacent: set) -> dict:
    """The classification done plainly: every distance of every geometry pair in every
    sample (the reference the fast version must equal)."""
    gm = robot.collision_model.copy()
    links = [robot.link_of_geometry(g) for g in range(gm.ngeoms)]
    keys, chain = [], []
    for a in range(gm.ngeoms):
        for b in range(a + 1, gm.ngeoms):
            key = tuple(sorted((links[a], links[b])))
            if key[0] != key[1] and key not in adjacent:
                gm.addCollisionPair(pin.CollisionPair(a, b))
                keys.append(key)
                ja, jb = gm.geometryObjects[a].parentJoint, gm.geometryObjects[b].parentJoint
                sub_a, sub_b = robot.model.subtrees[ja], robot.model.subtrees[jb]
                chain.append(jb in sub_a or ja in sub_b)
    gd, data = gm.createData(), robot.model.createData()
    cold_start(gd)
    rng = np.random.default_rng(seed)
    d = np.empty((samples, len(keys)))
    for s in range(samples):
        pin.computeDistances(robot.model, data, gm, gd, robot.to_pin(robot.sample(rng)))
        d[s] = [r.min_distance for r in gd.distanceResults]
    out = {key: "adjacent" for key in adjacent}
    for key in set(keys):
        cols = [i for i, k in enumerate(keys) if k == key]
        if any((d[:, i] <= 0).all() for i in cols):
            out[key] = "always"
        elif chain[cols[0]] and not any((d[:, i] <= never_margin).any() for i in cols):
            out[key] = "never"
    return out


# --------------------------------------------------------------------------- verdicts


def test_tiny_robot_verdicts_known_on_paper(tmp_path):
    """a2 never comes near the base (one chain): never; b2 sits in the base: always; arms
    a and b never meet either, but they are on different branches: kept."""
    result = compute_disabled_pairs(tiny_robot(tmp_path), 50, np.random.default_rng(0))
    assert result.pairs == TINY_EXPECTED
    assert result.samples == 50 and result.never_margin == 0.02


def test_tiny_robot_equals_every_distance(tmp_path):
    robot = tiny_robot(tmp_path)
    adjacent = {k for k, r in TINY_EXPECTED.items() if r == "adjacent"}
    assert every_distance(robot, 50, 0, 0.02, adjacent) == TINY_EXPECTED


@pytest.fixture(scope="module")
def humanoid():
    return load_robot(HUMANOID)


@pytest.mark.parametrize("samples, margin", [(1, 0.02), (40, 0.02), (40, 0.15)])
def test_humanoid_equals_every_distance(humanoid, samples, margin):
    """Same verdicts as computing every distance in every sample (with 1 sample pairs are
    'always' too; a wide margin makes most chain pairs near)."""
    robot = humanoid
    fast = compute_disabled_pairs(robot, samples, np.random.default_rng(3), margin)
    adjacent = {k for k, r in fast.pairs.items() if r == "adjacent"}
    assert fast.pairs == every_distance(robot, samples, 3, margin, adjacent)
    if samples == 1:
        assert fast.count("always") > 0


def test_progress_counts_link_pairs_up_to_the_total(tmp_path):
    calls = []
    compute_disabled_pairs(tiny_robot(tmp_path), 20, np.random.default_rng(0),
                           progress=lambda done, total: calls.append((done, total)))
    total = 10 - 4  # C(5, 2) link pairs, 4 adjacent
    assert calls[0] == (0, total) and calls[-1] == (total, total)
    assert all(t == total for _, t in calls)
    assert [d for d, _ in calls] == list(range(total + 1))


# --------------------------------------------------------------------------- bounds


def _cover_holds(points: np.ndarray, geom) -> bool:
    c, r = sphere_cover(geom)
    d = np.linalg.norm(points[:, None, :] - c[None], axis=-1) - r[None]
    return bool((d.min(axis=1) <= 1e-12).all())


@pytest.mark.parametrize("geom", [coal.Box(0.3, 0.1, 0.05), coal.Cylinder(0.04, 0.3), coal.Capsule(0.03, 0.2),
                                  coal.Cone(0.05, 0.2), coal.Sphere(0.07)], ids=lambda g: type(g).__name__)
def test_sphere_cover_holds_the_primitive(geom):
    geom.computeLocalAABB()
    p = np.random.default_rng(0).uniform(1.2 * geom.aabb_local.min_, 1.2 * geom.aabb_local.max_, (3000, 3))
    d = np.array([coal.distance(geom, coal.Transform3s(), coal.Sphere(1e-9), coal.Transform3s(np.eye(3), q),
                                coal.DistanceRequest(), coal.DistanceResult()) for q in p])
    inside = p[d <= 0.0]
    assert len(inside) > 300
    assert _cover_holds(inside, geom)


def test_sphere_cover_holds_the_mesh_triangles(tmp_path):
    """A bumpy 10 x 10 grid (200 triangles): every point of every triangle is covered."""
    z = np.random.default_rng(2).uniform(0.0, 0.05, (11, 11))
    v = [[(0.02 * i, 0.03 * j, z[i, j]) for j in range(11)] for i in range(11)]
    grid = [t for i in range(10) for j in range(10)
            for t in ((v[i][j], v[i + 1][j], v[i + 1][j + 1]), (v[i][j], v[i + 1][j + 1], v[i][j + 1]))]
    mesh = tmp_path / "grid.stl"
    mesh.write_text(_stl(grid))
    robot = tiny_robot(tmp_path, f'<mesh filename="{mesh}"/>', convex_hulls=False)  # the mesh itself
    geom = next(g.geometry for g in robot.collision_model.geometryObjects if isinstance(g.geometry, coal.BVHModelBase))
    assert geom.num_tris == 200 and len(sphere_cover(geom)[1]) == 8
    rng = np.random.default_rng(0)
    w = rng.dirichlet(np.ones(3), 50)  # barycentric coordinates of 50 points per triangle
    V = np.asarray(geom.vertices())
    T = np.array([[t[0], t[1], t[2]] for t in (geom.tri_indices(i) for i in range(geom.num_tris))])
    pts = np.concatenate([w @ V[t] for t in T])
    assert _cover_holds(pts, geom)


def test_cover_distance_is_below_coal_distance():
    rng = np.random.default_rng(1)
    shapes = [coal.Box(0.3, 0.1, 0.05), coal.Cylinder(0.04, 0.3), coal.Capsule(0.03, 0.2), coal.Sphere(0.07)]
    for _ in range(200):
        ga, gb = rng.choice(len(shapes), 2)
        X = [pin.SE3(pin.rpy.rpyToMatrix(*rng.uniform(-np.pi, np.pi, 3)), rng.uniform(-0.3, 0.3, 3)) for _ in range(2)]
        (ca, ra), (cb, rb) = sphere_cover(shapes[ga]), sphere_cover(shapes[gb])
        pa = (X[0].rotation @ ca.T).T + X[0].translation
        pb = (X[1].rotation @ cb.T).T + X[1].translation
        lb = cover_distance(pa[None], ra, pb[None], rb)[0]
        d = coal.distance(shapes[ga], coal.Transform3s(X[0].rotation, X[0].translation), shapes[gb],
                          coal.Transform3s(X[1].rotation, X[1].translation), coal.DistanceRequest(),
                          coal.DistanceResult())
        assert lb <= d + 1e-9


# --------------------------------------------------------------------------- cache


def test_cache_key_ignores_rest_and_hand_open(tmp_path):
    spec = yaml.safe_load(HUMANOID.read_text())
    spec["urdf"] = str(HUMANOID.parent / "robot.urdf")
    spec["rest"] = {**spec["rest"], "r_arm_j1": 0.1}
    spec["hands"]["right"]["fingers"][1]["open"] = [0.0, 0.1, 0.1]
    spec["disabled_collisions"] = [["r_palm", "l_palm"]]
    other = tmp_path / "robot.yaml"
    other.write_text(yaml.safe_dump(spec, sort_keys=False))
    a, b = load_robot(HUMANOID), load_robot(other)
    assert not np.array_equal(a.q_rest, b.q_rest)
    assert cache_key(a) == cache_key(b)


def test_cache_key_follows_urdf_meshes_and_options(tmp_path):
    mesh = tmp_path / "tet.stl"
    mesh.write_text(_stl(TET))
    geometry = f'<mesh filename="{mesh}"/>'
    key = cache_key(tiny_robot(tmp_path, geometry))
    assert cache_key(tiny_robot(tmp_path, geometry)) == key
    mesh.write_text(_stl([tuple(tuple(2 * x for x in v) for v in t) for t in TET]))  # same URDF, bigger mesh
    assert cache_key(tiny_robot(tmp_path, geometry)) != key
    assert cache_key(tiny_robot(tmp_path, '<sphere radius="0.06"/>')) != cache_key(tiny_robot(tmp_path))
    assert cache_key(tiny_robot(tmp_path, samples=51)) != cache_key(tiny_robot(tmp_path))
    assert cache_key(tiny_robot(tmp_path, geometry, convex_hulls=False)) != key  # the meshes, not their hulls


def test_cache_is_shared_by_robots_differing_in_rest_and_gets_user_pairs(tmp_path, monkeypatch):
    cache = tmp_path / "cache"
    first = disabled_pairs(tiny_robot(tmp_path), cache)
    assert first.pairs == TINY_EXPECTED
    (body,) = [json.loads(f.read_text()) for f in (cache / "self_collision").glob("*.json")]
    assert {(a, b): r for a, b, r in body["pairs"]} == TINY_EXPECTED  # identical fresh and cached

    def boom(*args, **kwargs):
        raise AssertionError("recomputed although cached")

    monkeypatch.setattr(selfcollision, "compute_disabled_pairs", boom)
    robot = tiny_robot(tmp_path, rest={"ja1": 0.2}, disabled_collisions=[["a1", "b1"]])
    again = disabled_pairs(robot, cache)
    assert again.pairs == {**TINY_EXPECTED, ("a1", "b1"): "user"}


def test_progress_bar_drawn_only_while_computing(tmp_path):
    """The CLI's bar (commands.progress) shows while the matrix is computed, not when it
    is read from the cache."""
    from rich.console import Console

    from regrasp_cli.commands.progress import self_collision_bar

    robot, cache = tiny_robot(tmp_path, samples=5), tmp_path / "cache"
    for computes in (True, False):
        stream = io.StringIO()
        with self_collision_bar(Console(file=stream, force_terminal=True)) as progress:
            assert disabled_pairs(robot, cache, progress).pairs["b2", "base"] == "always"
        assert ("self-collision" in stream.getvalue()) == computes
