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

The result depends only on the URDF, robot.yaml and the sampling options, so it is cached
under ``cache/`` keyed by their hashes and never has to be invalidated by hand.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin

from regrasp_cli.errors import InputError
from regrasp_cli.model.collision import cold_start
from regrasp_cli.model.robot import Robot
from regrasp_cli.store import atomic_write_text, sha256_params


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
                           never_margin: float = 0.02) -> DisabledPairs:
    """Classify every link pair of the robot's collision model (see the module docstring)."""
    gm = robot.collision_model.copy()
    n = gm.ngeoms
    joint_of = [gm.geometryObjects[g].parentJoint for g in range(n)]
    link_of = [robot.link_of_geometry(g) for g in range(n)]
    has_geometry = set(joint_of)
    gparent = {j: _geometric_parent(robot, j, has_geometry) for j in has_geometry}
    ancestors = {j: _ancestors(robot, j) for j in has_geometry}

    reasons: dict[tuple[str, str], str] = {}
    pair_links: list[tuple[str, str]] = []
    same_chain: list[bool] = []
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
            pair_links.append(key)
            same_chain.append(ja in ancestors[jb] or jb in ancestors[ja])

    gd, data = gm.createData(), robot.model.createData()
    cold_start(gd)
    n_pairs = len(pair_links)
    closest = np.full(n_pairs, np.inf)
    always = np.ones(n_pairs, dtype=bool)
    results = gd.distanceResults
    for _ in range(samples):
        q = robot.sample(rng)
        pin.computeDistances(robot.model, data, gm, gd, robot.to_pin(q))
        d = np.fromiter((r.min_distance for r in results), dtype=float, count=n_pairs)
        np.minimum(closest, d, out=closest)
        always &= d <= 0.0
    near = closest <= never_margin

    # Aggregate geometry pairs to link pairs: a link pair is "near" if any of its geometry
    # pairs is; it "always" collides if one of its geometry pairs collides in every sample.
    near_link: dict[tuple[str, str], bool] = {}
    always_link: dict[tuple[str, str], bool] = {}
    chain_link: dict[tuple[str, str], bool] = {}
    for k, key in enumerate(pair_links):
        near_link[key] = near_link.get(key, False) or bool(near[k])
        always_link[key] = always_link.get(key, False) or bool(always[k])
        chain_link[key] = same_chain[k]
    for key in near_link:
        if key in reasons:
            continue
        if always_link[key]:
            reasons[key] = "always"
        elif not near_link[key] and chain_link[key]:
            reasons[key] = "never"
    return DisabledPairs(reasons, samples, never_margin)


def disabled_pairs(robot: Robot, cache_dir: Path | None) -> DisabledPairs:
    """The robot's disabled link pairs: computed once, then read from ``cache_dir``.

    The user's ``disabled_collisions`` are added (and checked to name real links).
    """
    opts = robot.spec.self_collision
    key = sha256_params({"urdf": robot.urdf_sha256, "robot_yaml": robot.robot_yaml_sha256,
                         "samples": opts.samples, "seed": opts.seed, "margin": opts.never_margin,
                         "version": 3})[:20]
    path = None if cache_dir is None else Path(cache_dir) / "self_collision" / f"{key}.json"
    result = None
    if path is not None and path.is_file():
        try:
            raw = json.loads(path.read_text())
            result = DisabledPairs({tuple(p[:2]): p[2] for p in raw["pairs"]}, raw["samples"], raw["never_margin"])
        except (ValueError, KeyError, TypeError, IndexError):
            result = None  # unreadable cache: recompute and overwrite
    if result is None:
        result = compute_disabled_pairs(robot, opts.samples, np.random.default_rng(opts.seed), opts.never_margin)
        if path is not None:
            body = {"urdf_sha256": robot.urdf_sha256, "robot_yaml_sha256": robot.robot_yaml_sha256,
                    "samples": result.samples, "seed": opts.seed, "never_margin": result.never_margin,
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
