"""Local planner and distance metric of the roadmaps (Saut et al. 2010, §V-A).

The local path between two configurations is the straight segment in joint space.  It is
checked at configurations spaced by at most ``resolution`` (rad or m, the largest change
of any joint between two checked configurations) *and* by at most ``2 * margin`` of
Cartesian displacement of any point of the robot, with every pair whose relative pose
changes along the segment kept ``margin`` apart (a coal security margin).  Every point of
the path is then within ``margin`` of a checked configuration, so the whole segment is
collision-free, not only the samples: a check at any finer resolution agrees.  In a world
that keeps clearances, a certified check first steps ``coarse`` times farther with
``coarse`` times the clearance, and checks at the fine step only around the coarse samples
that lack the larger clearance (:func:`tiered_free`): the same certificate, with a
fraction of the checks where the path keeps away from everything.  (A plain
joint-step check at 0.03 rad let 1.3 % of the Super Graph edges through that a check at
0.015 rad found colliding.)  The displacement bound is ``sum_j reach_j |dq_j|``, with
``reach_j`` an upper bound of the distance from joint j to any point it carries (the sum
of the link offsets on the way plus the geometry's bounding radius), 1 for prismatic
joints.  Checks run coarse to fine with early exit (:meth:`CollisionWorld.segment_free`).

The distance is a weighted Euclidean norm over the joints.  A joint's weight is the reach
of the chain it moves: the largest distance, at the rest configuration, from its axis to
the origin of any link it carries, so a radian of torso yaw (which swings both arms) costs
more than a radian of wrist roll.  Weights are divided by the largest one.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from regrasp_cli.model.collision import bisection_order, segment_samples
from regrasp_cli.model.robot import Robot
from regrasp_cli.motion.blend import bezier_points, bezier_steps


def joint_weights(robot: Robot, q_ref: np.ndarray | None = None, floor: float = 0.05) -> np.ndarray:
    """Weights (nq,) in [floor, 1] for :func:`distance` (see the module docstring)."""
    model, data = robot.model, robot.model.createData()
    pin.forwardKinematics(model, data, robot.to_pin(robot.q_rest if q_ref is None else q_ref))
    pin.updateFramePlacements(model, data)
    w = np.empty(robot.nq)
    for i, name in enumerate(robot.joint_names):
        j = model.getJointId(name)
        axis_point = data.oMi[j].translation
        subtree = set(model.subtrees[j])
        reach = 0.0
        for f, frame in enumerate(model.frames):
            if frame.parentJoint in subtree:
                reach = max(reach, float(np.linalg.norm(data.oMf[f].translation - axis_point)))
        w[i] = reach
    w /= max(float(w.max()), 1e-12)
    return np.maximum(w, floor)


def joint_reach(robot: Robot) -> np.ndarray:
    """Upper bound (nq,), metres per radian (1 for prismatic joints), of how far a point
    carried by each joint moves per unit of that joint, whatever the configuration."""
    model, geoms = robot.model, robot.collision_model.geometryObjects
    reach = np.zeros(robot.nq)
    for i, name in enumerate(robot.joint_names):
        j = model.getJointId(name)
        if model.joints[j].shortname().startswith("JointModelP"):
            reach[i] = 1.0
            continue
        for go in geoms:
            if go.parentJoint not in model.subtrees[j]:
                continue
            length, k = 0.0, go.parentJoint
            while k != j:  # offsets of the joints between j and the geometry's joint
                length += float(np.linalg.norm(model.jointPlacements[k].translation))
                k = model.parents[k]
            go.geometry.computeLocalAABB()
            length += float(np.linalg.norm(go.placement.translation)) + float(go.geometry.aabb_radius)
            reach[i] = max(reach[i], length)
    return reach


def held_reach(robot: Robot, reach: np.ndarray, hand: str, vertices_O: np.ndarray, X_GO: np.ndarray) -> np.ndarray:
    """``reach`` (nq,) grown for an object held in ``hand`` at X_GO (4, 4): a point of the
    object lies at most the grasp frame's offset from its joint plus the object's radius
    about G from a point the joint carries, farther than any robot geometry may reach.
    Conservatively added to every joint.  ``vertices_O`` (k, 3): the object's vertices."""
    X_JG = robot.model.frames[robot.hands[hand].grasp_frame].placement.homogeneous
    radius = float(np.max(np.linalg.norm(vertices_O @ X_GO[:3, :3].T + X_GO[:3, 3], axis=1)))
    return reach + float(np.linalg.norm(X_JG[:3, 3])) + radius


def arm_chains(robot: Robot) -> tuple[np.ndarray, ...] | None:
    """Joint sets for :meth:`LocalPlanner.steps` in a world that checks every pair: a pair
    moves relative to itself through the torso and one side (that arm, its hand and what
    it holds), or through both sides (one against the other: both hang from one joint),
    never through all three; joints of no group or hand are in every set.  None (the sum
    over every joint) when the arms do not hang from the same joint."""
    model = robot.model
    parents = {model.parents[model.getJointId(robot.joint_names[robot.groups[f"{s}_arm"][0]])]
               for s in ("right", "left")}
    if len(parents) != 1:
        return None
    side = {s: np.r_[robot.groups[f"{s}_arm"], robot.hands[s].idx if s in robot.hands else []].astype(int)
            for s in ("right", "left")}
    torso = robot.groups["torso"]
    others = np.setdiff1d(np.arange(robot.nq), np.r_[torso, side["right"], side["left"]])
    return (np.r_[torso, side["right"], others], np.r_[torso, side["left"], others],
            np.r_[side["right"], side["left"], others])


@dataclass(frozen=True)
class LocalPlanner:
    """Certified straight-line local planner (see the module docstring)."""

    resolution: float  # rad (or m): largest joint step between two checked configurations
    margin: float  # m: clearance kept by every pair that moves; half the Cartesian step
    reach: np.ndarray  # (nq,) from :func:`joint_reach`
    coarse: int = 1  # > 1: tiered checks in worlds that keep clearances (:func:`tiered_free`)

    def steps(self, q0: np.ndarray, q1: np.ndarray, chains: tuple[np.ndarray, ...] | None = None) -> int:
        """Number of intervals the segment is cut into.

        ``chains``, when given, lists index sets of joints such that every checked pair
        moves relative to itself only through the joints of one set (e.g. the left arm
        against the obstacles: torso + left arm; against the right arm: both arms, not the
        torso that carries both); the Cartesian bound is then the largest over the sets,
        not the sum over every joint.
        """
        d = np.abs(q1 - q0)
        w = d * self.reach
        cart = w.sum() if chains is None else max(float(w[c].sum()) for c in chains)
        return max(1, int(np.ceil(d.max() / self.resolution)), int(np.ceil(cart / (2 * self.margin))))

    def segment_free(self, world, q0: np.ndarray, q1: np.ndarray,
                     chains: tuple[np.ndarray, ...] | None = None, limit: int | None = None) -> bool:
        """Certified check; with ``limit``, only the first (coarsest) ``limit`` samples: a
        cheap test whose False is a proof of collision."""
        n = self.steps(q0, q1, chains)
        if limit is None and self.coarse > 1 and world.certified:
            return tiered_free(world, lambda u: q0 + u[:, None] * (q1 - q0), n, self.coarse)
        return world.segment_free(q0, q1, self.resolution, n, limit)

    def probe_free(self, world, q0: np.ndarray, q1: np.ndarray, every: int,
                   chains: tuple[np.ndarray, ...] | None = None) -> bool:
        """A cheap test of the segment: a sample every ``every`` fine intervals, coarse to
        fine, each checked at the plain clearance.  False proves a collision or a lacking
        clearance; True is no certificate."""
        m = -(-self.steps(q0, q1, chains) // max(every, 1))
        return all(world.is_free(q0 + t * (q1 - q0)) for t in bisection_order(m))

    def blend_free(self, world, A: np.ndarray, C: np.ndarray, B: np.ndarray,
                   chains: tuple[np.ndarray, ...] | None = None) -> bool:
        """Certified check of the blend curve A, C, B (nq,) of :mod:`motion.blend`, sampled
        by the same bounds as a segment, coarse to fine."""
        k = bezier_steps(A, C, B, self.reach, self.resolution, 2 * self.margin, chains)
        if self.coarse > 1 and world.certified:
            return tiered_free(world, lambda u: bezier_points(A, C, B, u), k, self.coarse)
        u = segment_samples(np.zeros(1), np.ones(1), 1.0, k)
        return all(world.is_free(q) for q in bezier_points(A, C, B, u))


def tiered_free(world, points, n: int, coarse: int) -> bool:
    """Certified check of a curve cut into ``n`` intervals that each keep within the
    clearance bound (``points(u)``: configurations (k, nq) at parameters u (k,) in [0, 1]).

    The curve is first cut into m = ceil(n / coarse) intervals, each at most ``coarse``
    fine ones long, and their ends are checked keeping ``coarse`` times the world's
    clearance: an interval whose two ends keep it is free.  A coarse end that lacks it is
    checked at the plain clearance (a collision there ends the check) and the intervals on
    both sides of it are checked at the fine step, m * coarse >= n intervals in all.
    Coarse samples run coarse to fine, so a colliding curve is usually refused early."""
    m = -(-n // coarse)
    u = segment_samples(np.zeros(1), np.ones(1), 1.0, m)
    near = []
    for i, q in zip(np.rint(u * m).astype(int), points(u)):
        if not world.is_free(q, float(coarse)):
            if not world.is_free(q):
                return False
            near.append(int(i))
    if not near:
        return True
    fine = np.unique(np.concatenate([np.arange(max(i - 1, 0) * coarse, min(i + 1, m) * coarse + 1) for i in near]))
    fine = np.setdiff1d(fine, np.asarray(near) * coarse)  # checked already
    return all(world.is_free(q) for q in points(fine / (m * coarse)))


def distance(q0: np.ndarray, q1: np.ndarray, weights: np.ndarray) -> float | np.ndarray:
    """Weighted joint-space distance; ``q1`` may be a stack (n, nq) of configurations."""
    d = np.asarray(q1) - q0
    return np.sqrt(np.sum(weights * d * d, axis=-1))
