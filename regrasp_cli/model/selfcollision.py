"""Automatic disabling of self-collision link pairs, as MoveIt's setup assistant does.

A link pair is disabled when it is *adjacent* (one link's joint is the parent of the
other's, possibly through links without geometry, or both links ride the same joint),
*always* in collision (in every sampled configuration: e.g. overlapping shoulder
geometry) or *never* close: farther apart than ``never_margin`` in all of ``samples``
configurations drawn uniformly within the joint limits.

"Never" is a statistical verdict.  MoveIt applies it to every pair; we measured that on
a dual-arm robot it then disables pairs that plainly can collide (a right fingertip
against the left wrist: both arms must move to the same place, which uniform samples
almost never do), and those are exactly the pairs a hand-over needs.  So "never" is only
applied to pairs on one kinematic chain (one link is an ancestor of the other), with a
distance margin rather than a bare collision test; pairs on different branches (left vs
right arm) stay checked, at little cost since the broadphase culls far pairs.  Pairs
listed in robot.yaml's ``disabled_collisions`` or in the SRDF it names are added.

Computing it: a verdict needs one predicate per geometry pair and sample (distance
``<= 0``, distance ``<= never_margin``), and it is settled by the first sample that
breaks it (one free sample: not "always"; one close sample: not "never").  So each
geometry is covered by a few spheres (:func:`sphere_cover`), whose distances give a
lower bound of coal's distance for all samples at once (numpy), and coal's exact
distance is asked only where that bound does not decide, most promising samples first.
The verdicts are those of computing every distance in every sample (same samples, same
coal queries, cold-started).  Unitree G1 with Dex3 hands (43 joints, 38 meshes, 1000
samples): 3.8 s instead of ~12.5 min, same pairs; humanoid43 (primitives, 3000 samples):
0.5 s instead of 1.6 s.

The result depends only on the URDF, the collision meshes it names and the sampling
options (not on the rest of robot.yaml), so it is cached under ``cache/`` keyed by their
hashes (:func:`cache_key`) and never has to be invalidated by hand.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import coal
import numpy as np
import pinocchio as pin

from regrasp_cli.errors import InputError
from regrasp_cli.model.collision import cold_start
from regrasp_cli.model.robot import Robot
from regrasp_cli.store import atomic_write_text, sha256_file, sha256_params

PairProgress = Callable[[int, int], None]  # (link pairs classified, link pairs to classify)

CACHE_VERSION = 4  # 4: keyed by URDF + collision meshes + options, not robot.yaml's bytes
_SPHERES = 8  # spheres per geometry: 64 sphere pairs per geometry pair and sample
_TOL = 1e-9  # m: a bound decides only by more than this (coal and numpy round differently)


@dataclass(frozen=True)
class DisabledPairs:
    """Disabled link pairs (sorted names) with the reason of each."""

    pairs: dict[tuple[str, str], str]  # (link_a, link_b) -> adjacent | always | never | user
    samples: int
    never_margin: float = 0.02

    def links(self) -> set[tuple[str, str]]:
        return set(self.pairs)

    def count(self, reason: str) -> int:
        return sum(1 for r in self.pairs.values() if r == reason)


# --------------------------------------------------------------------------- sphere covers


def sphere_cover(geom: coal.CollisionGeometry, k: int = _SPHERES) -> tuple[np.ndarray, np.ndarray]:
    """Spheres whose union holds ``geom``: centres (m, 3) in the geometry's frame (m) and
    radii (m,), with m <= k.

    For a mesh the spheres hold its triangles (coal's mesh distances are between
    triangles), split in k groups by median cuts of their centroids; primitives are cut
    along their longest axis.  A shape without known bounds gets its local AABB's sphere
    (infinite for a half-space: its pairs then always go to coal).
    """
    swept = geom.getSweptSphereRadius() if hasattr(geom, "getSweptSphereRadius") else 0.0
    if isinstance(geom, coal.Sphere):
        c, r = np.zeros((1, 3)), np.array([geom.radius])
    elif isinstance(geom, (coal.Cylinder, coal.Cone, coal.Capsule)):
        h = geom.halfLength / k  # half length of each slice along z
        c = np.zeros((k, 3))
        c[:, 2] = -geom.halfLength + (2 * np.arange(k) + 1) * h
        rad = geom.radius + h if isinstance(geom, coal.Capsule) else np.hypot(geom.radius, h)
        r = np.full(k, rad)
    elif isinstance(geom, coal.Box):
        half = np.array(geom.halfSide, dtype=float)
        axis = int(np.argmax(half))
        c = np.zeros((k, 3))
        c[:, axis] = -half[axis] + (2 * np.arange(k) + 1) * half[axis] / k
        slab = half.copy()
        slab[axis] /= k
        r = np.full(k, np.linalg.norm(slab))
    elif isinstance(geom, coal.BVHModelBase) and geom.num_tris > 0 and k > 1:
        V = np.asarray(geom.vertices(), dtype=float)
        T = np.array([[t[0], t[1], t[2]] for t in (geom.tri_indices(i) for i in range(geom.num_tris))])
        groups = _median_split(V[T].mean(axis=1), k)
        c, r = np.empty((len(groups), 3)), np.empty(len(groups))
        for i, g in enumerate(groups):
            P = V[np.unique(T[g])]
            c[i] = 0.5 * (P.min(axis=0) + P.max(axis=0))
            r[i] = np.sqrt(((P - c[i]) ** 2).sum(axis=1).max())
    elif isinstance(geom, (coal.ConvexBase, coal.BVHModelBase)):
        # one sphere around all the points holds their hull, hence any triangles on them
        P = np.asarray(geom.points() if isinstance(geom, coal.ConvexBase) else geom.vertices(), dtype=float)
        P = P.reshape(-1, 3) if P.size else np.zeros((1, 3))
        c = 0.5 * (P.min(axis=0) + P.max(axis=0))[None]
        r = np.array([np.sqrt(((P - c) ** 2).sum(axis=1).max())])
    else:
        geom.computeLocalAABB()
        c = np.asarray(geom.aabb_center, dtype=float).reshape(1, 3)
        r = np.array([geom.aabb_radius])
        if not (np.isfinite(c).all() and np.isfinite(r).all() and np.abs(c).max() < 1e6):
            c, r = np.zeros((1, 3)), np.array([np.inf])  # unbounded: a bound of -inf (no NaN)
    return c, r + swept


def _median_split(p: np.ndarray, k: int) -> list[np.ndarray]:
    """Indices of the points ``p`` (n, 3) in at most k groups: the group of most points is
    cut at the median of its longest extent until there are k."""
    groups = [np.arange(len(p))]
    while len(groups) < k:
        i = max(range(len(groups)), key=lambda j: len(groups[j]))
        g = groups[i]
        if len(g) < 2:
            break
        axis = int(np.argmax(np.ptp(p[g], axis=0)))
        order = g[np.argsort(p[g, axis], kind="stable")]
        groups[i:i + 1] = [order[:len(g) // 2], order[len(g) // 2:]]
    return groups


def cover_distance(p_a: np.ndarray, r_a: np.ndarray, p_b: np.ndarray, r_b: np.ndarray) -> np.ndarray:
    """Lower bound (S,) of the distance between two covered shapes in S placements.

    ``p_a`` (S, ma, 3) and ``p_b`` (S, mb, 3) are the sphere centres in one frame (m),
    ``r_a`` (ma,) and ``r_b`` (mb,) their radii (m); negative when spheres overlap.
    """
    d2 = ((p_a[:, :, None, :] - p_b[:, None, :, :]) ** 2).sum(axis=-1)
    return (np.sqrt(d2) - r_a[:, None] - r_b[None, :]).min(axis=(1, 2), initial=np.inf)


# --------------------------------------------------------------------------- classification


def _geometric_parent(robot: Robot, joint: int, has_geometry: set[int]) -> int:
    """Nearest ancestor joint carrying collision geometry (0 = the root)."""
    j = robot.model.parents[joint]
    while j != 0 and j not in has_geometry:
        j = robot.model.parents[j]
    return j


def _ancestors(robot: Robot, joint: int) -> set[int]:
    out = set()
    while joint != 0:
        joint = robot.model.parents[joint]
        out.add(joint)
    return out


def compute_disabled_pairs(robot: Robot, samples: int, rng: np.random.Generator,
                           never_margin: float = 0.02, progress: PairProgress | None = None) -> DisabledPairs:
    """Classify every link pair of the robot's collision model (see the module docstring).

    ``samples`` configurations are drawn from ``rng`` (uniform within the joint limits).
    ``progress(done, total)``, if given, is called with the number of non-adjacent link
    pairs classified so far, from 0 up to the total.
    """
    gm = robot.collision_model.copy()
    n = gm.ngeoms
    joint_of = [gm.geometryObjects[g].parentJoint for g in range(n)]
    link_of = [robot.link_of_geometry(g) for g in range(n)]
    has_geometry = set(joint_of)
    gparent = {j: _geometric_parent(robot, j, has_geometry) for j in has_geometry}
    ancestors = {j: _ancestors(robot, j) for j in has_geometry}

    reasons: dict[tuple[str, str], str] = {}
    by_link: dict[tuple[str, str], list[int]] = {}  # link pair -> its geometry pair ids in gm
    chain: dict[tuple[str, str], bool] = {}
    for a in range(n):
        for b in range(a + 1, n):
            key = tuple(sorted((link_of[a], link_of[b])))
            if key[0] == key[1]:
                continue
            ja, jb = joint_of[a], joint_of[b]
            if ja == jb or gparent[ja] == jb or gparent[jb] == ja:
                reasons[key] = "adjacent"
                continue
            gm.addCollisionPair(pin.CollisionPair(a, b))
            by_link.setdefault(key, []).append(len(gm.collisionPairs) - 1)
            chain[key] = ja in ancestors[jb] or jb in ancestors[ja]
    todo = [key for key in by_link if key not in reasons]
    if progress is not None:
        progress(0, len(todo))

    # every sample's geometry placements X_WG, kept to put back before an exact query
    gd, data = gm.createData(), robot.model.createData()
    cold_start(gd)
    X_WG = np.empty((samples, n, 4, 4))
    for s in range(samples):
        pin.updateGeometryPlacements(robot.model, data, gm, gd, robot.to_pin(robot.sample(rng)))
        for g in range(n):
            X_WG[s, g] = gd.oMg[g].homogeneous
    # two levels of bounds: one sphere per geometry for all samples, then its cover where
    # that one does not decide (made on demand: reading a mesh's triangles takes ~20 ms)
    balls = [sphere_cover(gm.geometryObjects[g].geometry, 1) for g in range(n)]
    ball_W = np.einsum("sgij,gj->sgi", X_WG[:, :, :3, :3], np.concatenate([c for c, _ in balls])) + X_WG[:, :, :3, 3]
    ball_r = np.concatenate([r for _, r in balls])
    covers: dict[int, tuple[np.ndarray, np.ndarray]] = {}  # geometry -> centres (samples, m, 3) in W, radii (m,)

    def cover(g: int) -> tuple[np.ndarray, np.ndarray]:
        if g not in covers:
            c, r = sphere_cover(gm.geometryObjects[g].geometry)
            covers[g] = np.einsum("sij,mj->smi", X_WG[:, g, :3, :3], c) + X_WG[:, g, None, :3, 3], r
        return covers[g]

    exact: dict[tuple[int, int], float] = {}  # (pair id, sample) -> coal's distance (m)

    def distance(k: int, s: int) -> float:
        if (k, s) not in exact:
            p = gm.collisionPairs[k]
            gd.oMg[p.first] = pin.SE3(X_WG[s, p.first])
            gd.oMg[p.second] = pin.SE3(X_WG[s, p.second])
            exact[k, s] = pin.computeDistance(gm, gd, k).min_distance
        return exact[k, s]

    def bound(k: int, idx: np.ndarray) -> np.ndarray:
        """Lower bound (len(idx),) of the distance of pair k in the samples idx."""
        (p_a, r_a), (p_b, r_b) = cover(gm.collisionPairs[k].first), cover(gm.collisionPairs[k].second)
        return cover_distance(p_a[idx], r_a, p_b[idx], r_b)

    def always(k: int, lb0: np.ndarray) -> bool:
        """In collision (distance <= 0) in every sample; the likeliest free samples first."""
        if (lb0 > _TOL).any():
            return False
        lb = bound(k, np.arange(samples))
        if (lb > _TOL).any():
            return False
        return not any(distance(k, int(s)) > 0.0 for s in np.argsort(-lb, kind="stable"))

    def near(k: int, lb0: np.ndarray) -> bool:
        """Within the margin in some sample; the likeliest close samples first."""
        if any(d <= never_margin for (kk, _), d in exact.items() if kk == k):
            return True
        cand = np.flatnonzero(lb0 <= never_margin + _TOL)
        lb = bound(k, cand)
        cand, lb = cand[lb <= never_margin + _TOL], lb[lb <= never_margin + _TOL]
        return any(distance(k, int(s)) <= never_margin for s in cand[np.argsort(lb, kind="stable")])

    for done, key in enumerate(todo, 1):
        bounds = {}  # geometry pair -> one-sphere bound (samples,)
        for k in by_link[key]:
            a, b = gm.collisionPairs[k].first, gm.collisionPairs[k].second
            bounds[k] = np.linalg.norm(ball_W[:, a] - ball_W[:, b], axis=-1) - ball_r[a] - ball_r[b]
        if any(always(k, lb) for k, lb in bounds.items()):
            reasons[key] = "always"
        elif chain[key] and not any(near(k, lb) for k, lb in bounds.items()):
            reasons[key] = "never"
        exact.clear()
        if progress is not None:
            progress(done, len(todo))
    return DisabledPairs(reasons, samples, never_margin)


# --------------------------------------------------------------------------- cache


def collision_meshes_sha256(robot: Robot) -> str:
    """Hash of the mesh files the collision geometry was read from (their bytes, in the
    order of the collision model; the URDF's own hash covers primitives, scales, poses)."""
    files = []
    for g in robot.collision_model.geometryObjects:
        if isinstance(g.geometry, (coal.BVHModelBase, coal.ConvexBase)):  # primitives: meshPath "BOX", ...
            path = Path(g.meshPath)
            files.append(sha256_file(path) if path.is_file() else f"unreadable {g.meshPath}")
    return sha256_params(files)


def cache_key(robot: Robot) -> dict:
    """What the computed pairs depend on: the URDF, its collision meshes (and whether they
    are replaced by convex hulls, the links that take their visual geometry) and the
    ``self_collision`` options.  Not the rest of robot.yaml (rest pose, hands, groups: the
    samples cover every joint within its URDF limits) nor the user's and SRDF pairs, which
    are added after the cache is read."""
    opts = robot.spec.self_collision
    key = {"urdf": robot.urdf_sha256, "meshes": collision_meshes_sha256(robot), "samples": opts.samples,
           "seed": opts.seed, "margin": opts.never_margin, "convex_hulls": robot.spec.convex_hulls,
           "version": CACHE_VERSION}
    if robot.spec.collision_from_visual:  # absent otherwise: the keys of robots without it unchanged
        key["from_visual"] = list(robot.spec.collision_from_visual)
    if robot.spec.exact_meshes and robot.spec.convex_hulls:  # likewise
        key["exact_meshes"] = sorted(robot.spec.exact_meshes)
    return key


def disabled_pairs(robot: Robot, cache_dir: Path | None, progress: PairProgress | None = None) -> DisabledPairs:
    """The robot's disabled link pairs: computed once, then read from ``cache_dir``.

    The user's ``disabled_collisions`` are added (and checked to name real links).  A
    computation reports to ``progress(done, total)`` (link pairs settled), if given.
    """
    opts = robot.spec.self_collision
    key = cache_key(robot)
    stem = sha256_params(key)[:20]
    path = None if cache_dir is None else Path(cache_dir) / "self_collision" / f"{stem}.json"
    result = None
    if path is not None and path.is_file():
        try:
            raw = json.loads(path.read_text())
            result = DisabledPairs({tuple(p[:2]): p[2] for p in raw["pairs"]}, raw["samples"], raw["never_margin"])
        except (ValueError, KeyError, TypeError, IndexError):
            result = None  # unreadable cache: recompute and overwrite
    if result is None:
        rng = np.random.default_rng(opts.seed)
        # no progress argument unless asked (tests replace the function by a four-argument stand-in)
        result = (compute_disabled_pairs(robot, opts.samples, rng, opts.never_margin) if progress is None else
                  compute_disabled_pairs(robot, opts.samples, rng, opts.never_margin, progress=progress))
        if path is not None:
            # robot_yaml_sha256: the robot.yaml first computed with (provenance, not a key)
            body = {"urdf_sha256": robot.urdf_sha256, "meshes_sha256": key["meshes"],
                    "robot_yaml_sha256": robot.robot_yaml_sha256, "samples": result.samples, "seed": opts.seed,
                    "never_margin": result.never_margin, "version": CACHE_VERSION,
                    "pairs": sorted([a, b, r] for (a, b), r in result.pairs.items())}
            atomic_write_text(path, json.dumps(body, indent=1) + "\n")
    pairs = dict(result.pairs)
    listed = [(f"disabled_collisions[{i}]", p) for i, p in enumerate(robot.spec.disabled_collisions)]
    listed += [(f"srdf ({robot.spec.srdf.name})", p) for p in robot.spec.srdf_disabled]
    for where, (a, b) in listed:
        for name in (a, b):
            if not robot.model.existFrame(name):
                raise InputError(robot.spec.file, where, f"unknown link {name!r}")
        pairs.setdefault(tuple(sorted((a, b))), "user")
    return DisabledPairs(pairs, result.samples, result.never_margin)
