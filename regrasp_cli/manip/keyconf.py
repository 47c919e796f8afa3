"""Key configurations: grasp q_g, exchange q_e and place q_p (Saut et al. 2010, §V-C).

"All robot joints are sampled except the arm(s) grasping the object ... computed using the
inverse kinematics characterized by the grasps and the object position.  Then, a
collision test is performed."  The non-grasping joints (torso, free arm) are drawn around
the rest configuration (the rest itself first, so the most natural posture wins when it
is free), the grasping arm(s) by IK to the grasp frame.

A robot executing the plan also needs to get its fingers onto the object without
sweeping through it, so each key configuration comes with:

* a *pre-shape*: the fingers opened from the grasp values towards ``open`` by the largest
  fraction (``OnlineOptions.preshape``) at which the hand at the grasp pose is free of the
  object, and from which closing is collision-free;
* an *approach line*: the hand moves straight (IK waypoints) from ``approach_distance``
  away to the grasp pose with its fingers pre-shaped; directions tried in order: away from
  the object's centre, up, back along the wrist;
* a *lift line* for the pick and place: the object rises ``lift_height`` straight up from
  its support (and is lowered the same way at the goal).

Every configuration and segment is checked with the object where it is at that moment:
static in the world, or attached to the holding hand, with the fingertips of the hands
in contact allowed to touch it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from regrasp_cli.grasp.build import GraspList
from regrasp_cli.model.ik import IKOptions, arm_ik, solve_pose
from regrasp_cli.manip.context import Scratch
from regrasp_cli.spatial import inverse

OTHER = {"right": "left", "left": "right"}


@dataclass(frozen=True)
class SingleConfig:
    """A one-hand grasp of the object resting at X_WO, with the motions around it.

    ``approach`` runs from the pre-grasp pose (fingers open) to the grasp pose (fingers
    pre-shaped), ``q_closed`` is the grasp itself, ``lift`` runs from ``q_closed`` to the
    object lifted (fingers closed).  A place uses the same pieces in reverse."""

    hand: str
    grasp: int
    X_WO: np.ndarray  # (4, 4)
    approach: np.ndarray  # (k, nq)
    q_closed: np.ndarray  # (nq,)
    lift: np.ndarray  # (k, nq)
    cos_approach: float  # cosine between the approach and the shoulder->object direction
    free_arm_cost: float  # §V-C "natural" posture terms of the free arm, >= 0

    @property
    def score(self) -> float:
        return self.cos_approach - self.free_arm_cost


@dataclass(frozen=True)
class ExchangeConfig:
    """Both hands on the object at X_WO: the taking hand approaches the object held by the
    giving hand (``approach``, ending with its fingers pre-shaped), closes (``q_both``),
    the giving hand opens (``q_release``) and retreats (``retreat``, ending with its
    fingers open)."""

    X_WO: np.ndarray
    approach: np.ndarray  # (k, nq)
    q_both: np.ndarray  # (nq,)
    q_release: np.ndarray  # (nq,)
    retreat: np.ndarray  # (k, nq)


# ------------------------------------------------------------------ geometry helpers


def approach_axis(scratch: Scratch, hand: str) -> np.ndarray:
    """Unit vector (3,) in the grasp frame G from the wrist (the joint carrying G) to G."""
    robot = scratch.problem.robot
    X_JG = robot.model.frames[robot.hands[hand].grasp_frame].placement.homogeneous
    a = X_JG[:3, :3].T @ X_JG[:3, 3]
    n = np.linalg.norm(a)
    return a / n if n > 1e-9 else np.array([0.0, 0.0, 1.0])


def shoulder(scratch: Scratch, hand: str, q: np.ndarray) -> np.ndarray:
    """Position (3,) of the first joint of the hand's arm at q."""
    robot = scratch.problem.robot
    return scratch.kin.fk(q, robot.joint_names[robot.hands[hand].arm_idx[0]])[:3, 3]


def wrist(scratch: Scratch, hand: str, q: np.ndarray) -> np.ndarray:
    robot = scratch.problem.robot
    X_WG = scratch.kin.fk(q, robot.hands[hand].grasp_frame)
    X_JG = robot.model.frames[robot.hands[hand].grasp_frame].placement.homogeneous
    return (X_WG @ inverse(X_JG))[:3, 3]


def free_arm_cost(scratch: Scratch, hand: str, q: np.ndarray) -> float:
    """§V-C's free-arm terms for the arm that does not hold at q: joint distance to rest
    (rad, RMS), wrist height difference to rest (m) and wrist distance to the plane of the
    torso and shoulders (m, beyond its value at rest); about 0 at rest, ~1 when far."""
    robot = scratch.problem.robot
    free = OTHER[hand]
    idx = robot.hands[free].arm_idx
    dq = float(np.sqrt(np.mean((q[idx] - robot.q_rest[idx]) ** 2)))
    w, w0 = wrist(scratch, free, q), wrist(scratch, free, robot.q_rest)

    def plane_distance(qc, p):
        s_r, s_l = shoulder(scratch, "right", qc), shoulder(scratch, "left", qc)
        if len(robot.groups["torso"]):
            torso = scratch.kin.fk(qc, robot.joint_names[robot.groups["torso"][0]])[:3, 3]
        else:  # no torso joint (Baxter): the vertical plane through the shoulders
            torso = (s_r + s_l) / 2 - np.array([0.0, 0.0, 0.3])
        n = np.cross(s_r - torso, s_l - torso)
        n /= max(np.linalg.norm(n), 1e-9)
        return abs(float(n @ (p - torso)))

    dz = abs(float(w[2] - w0[2]))
    dplane = max(0.0, plane_distance(q, w) - plane_distance(robot.q_rest, w0))
    return (dq / np.pi + dz / 0.5 + dplane / 0.5) / 3


def _translated(X: np.ndarray, d: np.ndarray) -> np.ndarray:
    Y = X.copy()
    Y[:3, 3] += d
    return Y


def cartesian_line(scratch: Scratch, rng: np.random.Generator, hand: str, q_end: np.ndarray, X_far: np.ndarray, steps: int) -> np.ndarray | None:
    """Waypoints (steps + 1, nq) moving the hand's grasp frame on a straight line from
    X_far (orientation kept) to where it is at ``q_end``; only the arm moves.  None when
    IK fails or the arm would jump (a branch change)."""
    robot = scratch.problem.robot
    h = robot.hands[hand]
    X_end = scratch.kin.fk(q_end, h.grasp_frame)
    qs, q = [q_end], q_end
    opts = IKOptions(restarts=0, max_iters=60)
    for i in range(1, steps + 1):
        X = X_end.copy()
        X[:3, 3] = X_end[:3, 3] + (X_far[:3, 3] - X_end[:3, 3]) * (i / steps)
        res = solve_pose(robot, h.grasp_frame, X, q, h.arm_idx, rng, opts)
        if not res.success or np.max(np.abs(res.q - q)) > 0.6:
            return None
        q = res.q
        qs.append(q)
    return np.array(qs[::-1])


def with_fingers(scratch: Scratch, q: np.ndarray, hand: str, values: np.ndarray) -> np.ndarray:
    out = q.copy()
    out[scratch.problem.robot.hands[hand].idx] = values
    return out


def preshapes(scratch: Scratch, hand: str, closed: np.ndarray) -> list[np.ndarray]:
    """Finger values opened from ``closed`` towards open, most open first."""
    open_ = scratch.problem.robot.hands[hand].open
    return [closed + a * (open_ - closed) for a in scratch.options.preshape]


def _approach(scratch: Scratch, rng: np.random.Generator, hand: str, q_pre: np.ndarray, centre_W: np.ndarray, world,
              directions_extra: tuple[np.ndarray, ...] = ()) -> np.ndarray | None:
    """Approach waypoints ending at ``q_pre`` (hand at the grasp pose, fingers pre-shaped),
    starting with the fingers open ``approach_distance`` away; checked in ``world``, the
    start (a query's end) with the queries' clearance."""
    robot, o = scratch.problem.robot, scratch.options
    h = robot.hands[hand]
    certified = scratch.certified(world)
    X_WG = scratch.kin.fk(q_pre, h.grasp_frame)
    away = X_WG[:3, 3] - centre_W
    back = -(X_WG[:3, :3] @ approach_axis(scratch, hand))
    for d in (away, *directions_extra, back):
        n = np.linalg.norm(d)
        if n < 1e-9:
            continue
        line = cartesian_line(scratch, rng, hand, q_pre, _translated(X_WG, o.approach_distance * d / n), o.line_steps)
        if line is None or not scratch.path_free(world, line):
            continue
        q_open = with_fingers(scratch, line[0], hand, h.open)
        if np.array_equal(q_open, line[0]):
            if certified.is_free(line[0]):
                return line
            continue
        if certified.is_free(q_open) and scratch.segment_free(world, q_open, line[0]):
            return np.vstack([q_open[None], line])
    return None


def _sample_base(scratch: Scratch, rng: np.random.Generator, s: int, moving: np.ndarray) -> np.ndarray:
    """Rest configuration with open hands (s == 0), else with the joints ``moving`` drawn
    around rest (Gaussian, clipped to the limits)."""
    robot = scratch.problem.robot
    q = robot.q_rest.copy()
    for h in robot.hands.values():
        q[h.idx] = h.open
    if s:
        q[moving] = np.clip(q[moving] + rng.normal(0.0, scratch.options.sample_sigma, len(moving)),
                            robot.lower[moving], robot.upper[moving])
    return q


# ------------------------------------------------------------------ single grasps


def single_configuration(scratch: Scratch, rng: np.random.Generator, grasps: GraspList, k: int, X_WO: np.ndarray) -> SingleConfig | None:
    """A collision-free configuration grasping the object at X_WO (resting on its support)
    with grasp ``k`` of the hand's list, with its approach and lift lines; None when the
    samples are exhausted."""
    p, o = scratch.problem, scratch.options
    robot, hand = p.robot, grasps.hand
    X_OG = grasps.X_OG[k]
    X_WG = X_WO @ X_OG
    w_free = scratch.world(X_WO)
    w_touch = scratch.world(X_WO, touching=(hand,))
    centre = X_WO[:3, :3] @ p.object.mesh.centroid + X_WO[:3, 3]
    moving = np.concatenate([robot.groups["torso"], robot.hands[OTHER[hand]].arm_idx])
    for s in range(o.key_samples):
        base = _sample_base(scratch, rng, s, moving)
        if not w_free.is_free(base):
            continue
        ik = arm_ik(robot, hand, X_WG, base, rng, options=o.ik)
        if not ik.success:
            continue
        q_closed = with_fingers(scratch, ik.q, hand, grasps.finger_q[k])
        if not w_touch.is_free(q_closed):
            continue
        q_pre = next((q for q in (with_fingers(scratch, ik.q, hand, f) for f in preshapes(scratch, hand, grasps.finger_q[k]))
                      if w_free.is_free(q) and scratch.segment_free(w_touch, q, q_closed)), None)
        if q_pre is None:
            continue
        lift = cartesian_line(scratch, rng, hand, q_closed, _translated(X_WG, np.array([0, 0, o.lift_height])), o.line_steps)
        if lift is None:
            continue
        lift = lift[::-1]
        w_held = scratch.world(inverse(X_OG), attached=hand, touching=(hand,))
        if not scratch.path_free(w_held, lift) or not scratch.certified(w_held).is_free(lift[-1]):
            continue  # the top of the lift is a query's end: it keeps the queries' clearance
        approach = _approach(scratch, rng, hand, q_pre, centre, w_free, (np.array([0.0, 0.0, 1.0]),))
        if approach is None:
            continue
        a_W = X_WG[:3, :3] @ approach_axis(scratch, hand)
        to_obj = X_WO[:3, 3] - shoulder(scratch, hand, q_closed)
        cos = float(a_W @ to_obj / max(np.linalg.norm(to_obj), 1e-9))
        return SingleConfig(hand, k, X_WO, approach, q_closed, lift, cos, free_arm_cost(scratch, hand, q_closed))
    return None


# ------------------------------------------------------------------ exchange


def exchange_configuration(scratch: Scratch, rng: np.random.Generator, giver: GraspList, kg: int, taker: GraspList, kt: int,
                           X_WO: np.ndarray) -> ExchangeConfig | None:
    """Both hands on the object at X_WO (grasp ``kg`` of the giving hand, which holds it,
    ``kt`` of the taking hand): the hand-over of §V-B with its approach and retreat; None
    when the samples are exhausted."""
    p, o = scratch.problem, scratch.options
    robot = p.robot
    g, t = giver.hand, taker.hand
    X_OGg, X_OGt = giver.X_OG[kg], taker.X_OG[kt]
    fg, ft = giver.finger_q[kg], taker.finger_q[kt]
    w_g = scratch.world(inverse(X_OGg), attached=g, touching=(g,))
    w_gt = scratch.world(inverse(X_OGg), attached=g, touching=(g, t))
    w_t = scratch.world(inverse(X_OGt), attached=t, touching=(t,))
    w_tg = scratch.world(inverse(X_OGt), attached=t, touching=(t, g))
    centre = X_WO[:3, :3] @ p.object.mesh.centroid + X_WO[:3, 3]
    torso = robot.groups["torso"]
    for s in range(o.key_samples):
        base = _sample_base(scratch, rng, s, torso)
        ik_g = arm_ik(robot, g, X_WO @ X_OGg, base, rng, options=o.ik)
        if not ik_g.success:
            continue
        ik_t = arm_ik(robot, t, X_WO @ X_OGt, ik_g.q, rng, options=o.ik)
        if not ik_t.success:
            continue
        q_both = with_fingers(scratch, with_fingers(scratch, ik_t.q, g, fg), t, ft)
        if not w_gt.is_free(q_both):
            continue
        q_tpre = next((q for q in (with_fingers(scratch, q_both, t, f) for f in preshapes(scratch, t, ft))
                       if w_g.is_free(q) and scratch.segment_free(w_gt, q, q_both)), None)
        if q_tpre is None:
            continue
        q_gpre = next((q for q in (with_fingers(scratch, q_both, g, f) for f in preshapes(scratch, g, fg))
                       if w_t.is_free(q) and scratch.segment_free(w_tg, q_both, q)), None)
        if q_gpre is None:
            continue
        approach = _approach(scratch, rng, t, q_tpre, centre, w_g)
        if approach is None:
            continue
        retreat = _approach(scratch, rng, g, q_gpre, centre, w_t)
        if retreat is None:
            continue
        return ExchangeConfig(X_WO, approach, q_both, q_gpre, retreat[::-1])
    return None
