"""Elementary roadmaps composed into the Super Graph: Saut et al. 2010, §V-A (Fig. 4, 5),
after Gharbi, Cortés & Siméon 2009 (their reference [4]).

The robot is split into the *common* part T (everything the torso carries that is not an
arm: base, torso, chest, head) and two *independent* parts R and L (each arm with its
hand).  The elementary roadmaps R_r (torso + right arm) and R_l (torso + left arm) are
built for the subsystems T+R and T+L alone: self-collisions within the subsystem and
collisions with the static obstacles; the other arm is left out, the hands are open.

Super Graph nodes: for every pair (x_r, x_l) of elementary nodes, two candidates: the arms
of both with the torso of x_r, and with the torso of x_l.  With the torso of x_r, R_r has
already checked everything but the pairs involving L with another part (L against T, R and
the obstacles; L against L does not depend on the torso and R_l checked it), so only
those are checked; symmetrically with the torso of x_l.

Super Graph edges: only between nodes X, Y whose right parts are equal or adjacent in R_r
and whose left parts are equal or adjacent in R_l (the paper's filter), both taking their
torso from the same roadmap, plus the torso swaps (see :func:`candidate_edges`).  When
both take their torso from the right roadmap, the right part moves exactly along an R_r
edge, so only the pairs involving L (but not L with L) are checked along the segment; from
the left, symmetrically; a swap moves the torso in a way no elementary edge covered, and
every pair is checked except L with L and R with R.  Which candidates are checked, and
in which order, is the builder's (:mod:`regrasp_cli.roadmap.build`): only useful
ones, a forest in tree mode.

Composition is a pure function of the two roadmaps: they are not modified.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import Callable

import coal
import numpy as np
import pinocchio as pin

from regrasp_cli.model.robot import Robot, carries

COMMON, RIGHT, LEFT, OBSTACLE = "T", "R", "L", "O"


def link_parts(robot: Robot) -> dict[str, str]:
    """Part of every link: 'R' or 'L' if an arm joint of that side moves it, else 'T'."""
    model = robot.model
    arm_joints = {side: {model.getJointId(robot.joint_names[i]) for i in robot.groups[f"{side}_arm"]}
                  for side in ("right", "left")}
    parts = {}
    for frame in model.frames:
        chain, j = set(), frame.parentJoint
        while j != 0:
            chain.add(j)
            j = model.parents[j]
        if chain & arm_joints["right"]:
            parts[frame.name] = RIGHT
        elif chain & arm_joints["left"]:
            parts[frame.name] = LEFT
        else:
            parts[frame.name] = COMMON
    return parts


def hand_links(robot: Robot) -> set[str]:
    """Links carried by the last joint of an arm (flange, palm, fingers): rigid with each
    other while the hands stay open, as they do in the roadmaps."""
    model = robot.model
    out = set()
    for side in ("right", "left"):
        last = model.getJointId(robot.joint_names[robot.groups[f"{side}_arm"][-1]])
        out |= {f.name for f in model.frames if f.parentJoint in model.subtrees[last]}
    return out


def margin_rule(robot: Robot, margin: float) -> Callable[[str, str], float]:
    """Clearance of a pair in the roadmap worlds: ``margin`` unless both links belong to
    the same open hand (they do not move relative to each other) or are links of one
    chain closer than ``margin`` already at rest (:func:`close_at_rest`): those are still
    checked for collision, without a clearance they could never keep."""
    hands = hand_links(robot)
    parts = link_parts(robot)
    close = close_at_rest(robot, margin)
    return lambda a, b: 0.0 if ((a in hands and b in hands and parts.get(a) == parts.get(b))
                                or frozenset((a, b)) in close) else margin


@lru_cache(maxsize=8)
def close_at_rest(robot: Robot, margin: float) -> frozenset[frozenset[str]]:
    """Link pairs on one kinematic chain (one link's joint carries the other) whose
    collision geometries are closer than ``margin`` (m) at the rest configuration: on a
    robot with tightly packed scanned links (Unitree G1's elbow and wrist) they are
    always that close, so a clearance there would reject every configuration."""
    model, gm = robot.model, robot.collision_model
    data, gd = model.createData(), pin.GeometryData(gm)
    pin.updateGeometryPlacements(model, data, gm, gd, robot.to_pin(robot.q_rest))
    out = set()
    objs = gm.geometryObjects
    for a in range(len(objs)):
        for b in range(a + 1, len(objs)):
            ja, jb = objs[a].parentJoint, objs[b].parentJoint
            if ja == jb or not (carries(model, ja, jb) or carries(model, jb, ja)):
                continue
            la, lb = (model.frames[objs[k].parentFrame].name for k in (a, b))
            X, Y = gd.oMg[a], gd.oMg[b]
            d = coal.distance(objs[a].geometry, coal.Transform3s(X.rotation, X.translation), objs[b].geometry,
                              coal.Transform3s(Y.rotation, Y.translation), coal.DistanceRequest(),
                              coal.DistanceResult())
            if d < margin:
                out.add(frozenset((la, lb)))
    return frozenset(out)


def part_filter(parts: dict[str, str], accept: Callable[[str, str], bool]) -> Callable[[str, str], bool]:
    """A CollisionWorld pair filter from a rule over parts ('T', 'R', 'L', 'O')."""

    def part(name: str) -> str:
        return OBSTACLE if name.startswith("obstacle:") else parts.get(name, COMMON)

    return lambda a, b: accept(part(a), part(b))


def subsystem(side: str) -> Callable[[str, str], bool]:
    """Elementary roadmap of T + side: nothing that involves the other arm."""
    other = LEFT if side == RIGHT else RIGHT
    return lambda a, b: other not in (a, b)


def involving(side: str) -> Callable[[str, str], bool]:
    """Pairs of ``side`` with any other part (not with itself)."""
    return lambda a, b: (a == side) != (b == side)


def mixed(a: str, b: str) -> bool:
    """Every pair but those within one arm."""
    return not (a == b and a in (LEFT, RIGHT))


@dataclass(frozen=True)
class SuperGraph:
    """Nodes (m, nq) full configurations; ``source`` (m, 3): index in R_r, index in R_l,
    and 0/1 for a torso taken from R_r/R_l; edges (k, 2) with lengths (k,)."""

    nodes: np.ndarray
    source: np.ndarray
    edges: np.ndarray
    lengths: np.ndarray
    candidates_nodes: int  # node candidates tested
    candidates_edges: int  # edge candidates tested


def compose_nodes(robot: Robot, q_base: np.ndarray, r_nodes: np.ndarray, l_nodes: np.ndarray,
                  free_with_right_torso: Callable[[np.ndarray], bool],
                  free_with_left_torso: Callable[[np.ndarray], bool]) -> tuple[np.ndarray, np.ndarray, int]:
    """Super Graph nodes from the elementary nodes (torso + arm values, in group order)."""
    t, ra, la = robot.groups["torso"], robot.groups["right_arm"], robot.groups["left_arm"]
    nt = len(t)
    nodes, source, tested = [], [], 0
    for i, xr in enumerate(r_nodes):
        for j, xl in enumerate(l_nodes):
            for s, torso, check in ((0, xr[:nt], free_with_right_torso), (1, xl[:nt], free_with_left_torso)):
                if s == 1 and np.array_equal(xr[:nt], xl[:nt]):
                    continue  # the same node twice
                q = q_base.copy()
                q[t], q[ra], q[la] = torso, xr[nt:], xl[nt:]
                tested += 1
                if check(q):
                    nodes.append(q)
                    source.append((i, j, s))
    return np.array(nodes).reshape(-1, robot.nq), np.array(source, dtype=np.int64).reshape(-1, 3), tested


def candidate_edges(source: np.ndarray, r_adj: list[set[int]], l_adj: list[set[int]]) -> np.ndarray:
    """Pairs (a, b), a < b, of Super Graph nodes whose right parts are equal or adjacent in
    R_r and left parts equal or adjacent in R_l, in a deterministic order (k, 2).

    Both ends take their torso from the same elementary roadmap, except for the *torso
    swaps* (same elementary nodes, the torso of one and then of the other).  An edge from
    one roadmap's torso to the other's for different elementary nodes would move the torso
    along no elementary edge and need every pair checked; it is replaced by a swap and an
    edge of one kind (X(r) -> X(l) -> Y(l)): such edges were 46 % of the candidates and
    more than half of the build time."""
    index = {tuple(map(int, s)): k for k, s in enumerate(source)}
    out = []
    for a, (i, j, s) in enumerate(source):
        for i2 in sorted(r_adj[i] | {int(i)}):
            for j2 in sorted(l_adj[j] | {int(j)}):
                swap = i2 == i and j2 == j
                for s2 in (0, 1) if swap else (int(s),):
                    b = index.get((i2, j2, s2))
                    if b is not None and b > a:
                        out.append((a, b))
    return np.array(out, dtype=np.int64).reshape(-1, 2)


def edge_kind(source: np.ndarray, a: int, b: int) -> int:
    """0: both torsos from R_r; 1: both from R_l; 2: mixed."""
    sa, sb = int(source[a, 2]), int(source[b, 2])
    return sa if sa == sb else 2


class UnionFind:
    def __init__(self, n: int):
        self.parent = list(range(n))

    def find(self, x: int) -> int:
        while self.parent[x] != x:
            self.parent[x] = self.parent[self.parent[x]]
            x = self.parent[x]
        return x

    def union(self, a: int, b: int) -> bool:
        ra, rb = self.find(a), self.find(b)
        if ra == rb:
            return False
        self.parent[max(ra, rb)] = min(ra, rb)
        return True
