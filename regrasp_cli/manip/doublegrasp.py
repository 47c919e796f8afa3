"""Double grasps: Saut et al. 2010, §IV-B, scored with the robot-configuration score of §V-C.

1. Each hand's grasp list is filtered against the environment at the object pose where
   that hand works (the picking hand at the start pose, the placing hand at the goal): a
   grasp from below collides with the support.  The test places the hand alone
   (:mod:`model.handshape`), no IK needed.
2. The survivors that the torso and the arm together reach (one batched IK for the whole
   list, :func:`~regrasp_cli.model.ik.arm_reachable`) are ranked by a cheap score
   (normalised quality + approach cosine) and turned into single-grasp configurations
   (:func:`keyconf.single_configuration`) until ``single_per_hand`` are found: the
   paper's "collision-free single grasps configurations" (4 right and 7 left in its
   scenario); the arm alone first, then, when that leaves too few, with the torso
   leaning for the grasps the arm could not reach.  Each next grasp tried is the best
   whose hand overlaps none of those found: spread over the object, they leave the
   other hand partners (on the default scene, 11 free pairs of 6 x 6 instead of 1).
3. Every pair of them is tested for hand-hand collision with both hands on the object;
   a pair's score is the normalised min of the two grasp qualities plus the normalised
   min of the two robot-configuration scores (approach cosine minus free-arm terms).
4. When few pairs are free (fewer than ``double_grasps_wanted``: a small object, where
   both hands' best grasps take the same side), the taking hand's configurations are
   searched again among the grasps that can share the object with one of the giver's
   (:func:`partners`, hand shapes only), the giver's among the taker's partners, and
   the new pairs among all configurations found come after the first ones.  When that
   still leaves few, pairs first: the grasps the two arms reach are paired by hand shapes
   (:func:`pairable`), and configurations are searched for the giver's grasps with a
   partner, then for their partners (``manip.tasks.handover``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from regrasp_cli.grasp.build import GraspList
from regrasp_cli.manip.context import Scratch
from regrasp_cli.model.handshape import HandShape, StaticGeometry, hand_hits_static, hands_collide
from regrasp_cli.model.ik import arm_reachable
from regrasp_cli.manip.keyconf import SingleConfig, approach_axis, reach_candidates, shoulder, single_configuration


@dataclass(frozen=True)
class SingleStats:
    listed: int  # grasps in the list
    environment_free: int  # after the environment filter
    reachable: int  # of those, reached by the torso and arm together (model.ik.arm_reachable)
    tried: int  # turned into configurations (IK + collision)
    kept: int  # configurations found


@dataclass(frozen=True)
class DoubleGrasp:
    giver: SingleConfig  # the picking hand's configuration at the start pose
    taker: SingleConfig  # the placing hand's configuration at the goal pose
    quality: float  # min of the two grasp qualities
    config: float  # min of the two robot-configuration scores
    score: float  # normalised quality + normalised config, in [0, 2]


def _normalise(x: np.ndarray) -> np.ndarray:
    span = float(x.max() - x.min()) if len(x) else 0.0
    return (x - x.min()) / span if span > 1e-12 else np.ones_like(x)


def empty_list_reason(hand: str) -> str:
    """Why a planner got no grasp of ``hand``: a stored list is never empty (its build fails
    instead), so the scene's filter (:func:`~regrasp_cli.grasp.usable.usable_at_ends`)
    left none: the hand alone hits an obstacle at the start and at the goal with each."""
    return (f"the {hand} hand's grasp list is empty for this scene: none of its grasps is usable at the object's "
            f"start or goal pose (the hand alone hits the support or an obstacle there; `regrasp grasps show` "
            f"lists them)")


def environment_free(grasps: GraspList, shapes: list[HandShape], X_WO: np.ndarray, env: StaticGeometry) -> np.ndarray:
    """Indices of the grasps whose hand at X_WO @ X_OG touches no obstacle (but with its
    fingertips, as it touches the object)."""
    return np.array([k for k in range(len(grasps))
                     if not hand_hits_static(shapes[k], X_WO @ grasps.X_OG[k], env, touching=True)], dtype=int)


def workable(scratch: Scratch, grasps: GraspList, shapes: list[HandShape], X_WO: np.ndarray,
             env: StaticGeometry) -> tuple[np.ndarray, np.ndarray]:
    """The indices of the grasps whose hand clears the obstacles at X_WO
    (:func:`environment_free`), and of those, the ones the torso and the arm together reach
    (:func:`~regrasp_cli.model.ik.arm_reachable`, all at once): the rest would fail every
    IK of :func:`keyconf.single_configuration`, at about 20-60 ms each.  Memoised in the
    run's scratch by hand and pose, the reachability from a stream of its own, so that the
    answer does not depend on the order of the calls."""
    key = (grasps.hand, len(grasps), X_WO.tobytes())
    if key not in scratch.workable:
        free = environment_free(grasps, shapes, X_WO, env)
        rng = np.random.default_rng([len(grasps), 38])
        reach = arm_reachable(scratch.problem.robot, grasps.hand, X_WO @ grasps.X_OG[free], rng) if len(free) \
            else np.zeros(0, dtype=bool)
        scratch.workable[key] = (free, free[reach])
    return scratch.workable[key]


def cheap_order(scratch: Scratch, grasps: GraspList, ks: np.ndarray, X_WO: np.ndarray) -> np.ndarray:
    """``ks`` ordered by normalised grasp quality + cosine between the hand's approach and
    the shoulder->object direction (the rest posture's shoulder)."""
    if not len(ks):
        return ks
    a_G = approach_axis(scratch, grasps.hand)
    to_obj = X_WO[:3, 3] - shoulder(scratch, grasps.hand, scratch.problem.robot.q_rest)
    to_obj /= max(np.linalg.norm(to_obj), 1e-9)
    cos = np.array([(X_WO[:3, :3] @ grasps.X_OG[k, :3, :3] @ a_G) @ to_obj for k in ks])
    score = _normalise(grasps.scores[ks, 4]) + _normalise(cos)
    return ks[np.argsort(-score, kind="stable")]


def single_configurations(scratch: Scratch, rng: np.random.Generator, grasps: GraspList, shapes: list[HandShape], X_WO: np.ndarray,
                          env: StaticGeometry, only: np.ndarray | None = None, wanted: int | None = None,
                          attempts: int | None = None, lean: bool = True) -> tuple[list[SingleConfig], SingleStats]:
    """Up to ``wanted`` (default ``single_per_hand``) single-grasp configurations at X_WO,
    from the first ``attempts`` (default ``grasp_attempts``) of the grasps (all, or the
    indices ``only``) that clear the obstacles and that the arm reaches (:func:`workable`),
    best cheap score first among those whose hand overlaps none of the configurations
    found so far; without ``lean`` the arm alone reaches."""
    o = scratch.options
    wanted = o.single_per_hand if wanted is None else wanted
    attempts = o.grasp_attempts if attempts is None else attempts
    free, reached = workable(scratch, grasps, shapes, X_WO, env)
    if only is not None:
        free, reached = free[np.isin(free, only)], reached[np.isin(reached, only)]
    ks = cheap_order(scratch, grasps, reached, X_WO)
    found, tried = [], 0
    overlap = _overlaps(grasps, shapes)
    # the arm alone first, as the paper; only when that leaves too few, the torso helps
    # with the grasps it could not reach (its postures are farther from the roadmap's)
    for leaning in (False, True)[:1 + lean]:
        pending = [int(k) for k in ks[:attempts] if not any(c.grasp == k for c in found)]
        if not pending or len(found) >= wanted:
            break
        reach = reach_candidates(scratch, rng, grasps, pending, X_WO, leaning)  # every grasp's IK at once
        while pending and len(found) < wanted:
            # spread: the best grasp whose hand overlaps none found so far, else the best
            # (a list's best grasps crowd one side, the top of a statuette: configurations
            # all there leave the other hand no partner, §IV-B's pairs)
            k = next((k for k in pending if not any(overlap(k, c.grasp) for c in found)), pending[0])
            pending.remove(k)
            tried += not leaning
            c = single_configuration(scratch, rng, grasps, k, X_WO, leaning, reach[k])
            if c is not None:
                found.append(c)
    return found, SingleStats(len(grasps), len(free), len(reached), tried, len(found))


def _overlaps(grasps: GraspList, shapes: list[HandShape]):
    """``overlap(k, j)``: would the hands of grasps k and j of one list, both on the
    object, collide (they take the same part of it)?  Memoised."""
    memo: dict[tuple[int, int], bool] = {}

    def overlap(k: int, j: int) -> bool:
        key = (min(k, j), max(k, j))
        if key not in memo:
            memo[key] = k == j or hands_collide(shapes[k], grasps.X_OG[k], shapes[j], grasps.X_OG[j])
        return memo[key]

    return overlap


def pairable(grasps_a: GraspList, shapes_a: list[HandShape], ks_a: np.ndarray, grasps_b: GraspList,
             shapes_b: list[HandShape], ks_b: np.ndarray) -> np.ndarray:
    """(len(ks_a), len(ks_b)) bool: which grasps ``ks_a`` of one hand's list and ``ks_b`` of
    the other's hold the object together without the hands colliding (hand shapes only,
    no IK)."""
    return np.array([[not hands_collide(shapes_a[a], grasps_a.X_OG[a], shapes_b[b], grasps_b.X_OG[b]) for b in ks_b]
                     for a in ks_a], dtype=bool).reshape(len(ks_a), len(ks_b))


def partners(configs: list[SingleConfig], config_list: GraspList, config_shapes: list[HandShape],
             other_list: GraspList, other_shapes: list[HandShape]) -> np.ndarray:
    """Indices of the other hand's grasps that hold the object together with at least one
    of ``configs`` without the hands colliding (:func:`pairable`)."""
    ks = np.arange(len(other_list))
    return ks[pairable(config_list, config_shapes, np.array([c.grasp for c in configs], dtype=int), other_list,
                       other_shapes, ks).any(axis=0)]


def double_grasps(giver: list[SingleConfig], giver_list: GraspList, giver_shapes: list[HandShape],
                  taker: list[SingleConfig], taker_list: GraspList, taker_shapes: list[HandShape]) -> list[DoubleGrasp]:
    """Pairs without hand-hand collision, best score first."""
    pairs = [(a, b) for a in giver for b in taker
             if not hands_collide(giver_shapes[a.grasp], giver_list.X_OG[a.grasp],
                                  taker_shapes[b.grasp], taker_list.X_OG[b.grasp])]
    if not pairs:
        return []
    quality = np.array([min(giver_list.scores[a.grasp, 4], taker_list.scores[b.grasp, 4]) for a, b in pairs])
    config = np.array([min(a.score, b.score) for a, b in pairs])
    score = _normalise(quality) + _normalise(config)
    order = np.argsort(-score, kind="stable")
    return [DoubleGrasp(pairs[i][0], pairs[i][1], float(quality[i]), float(config[i]), float(score[i])) for i in order]
