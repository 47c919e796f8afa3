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
from regrasp_cli.model.ik import IKOptions, arm_ik, arm_ik_batch, finger_ik, solve_pose, two_arm_ik
from regrasp_cli.manip.context import Scratch
from regrasp_cli.model.reachmap import approach_axis as reach_approach_axis
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
    return reach_approach_axis(scratch.problem.robot, hand)


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


def cartesian_line(scratch: Scratch, rng: np.random.Generator, hand: str, q_end: np.ndarray, X_far: np.ndarray, steps: int,
                   lean: bool = False) -> np.ndarray | None:
    """Waypoints (steps + 1, nq) moving the hand's grasp frame on a straight line from
    X_far (orientation kept) to where it is at ``q_end``; only the arm moves.  None when
    IK fails or the arm would jump (a branch change).  With ``lean``, the torso helps
    where the arm alone cannot follow the line (stretched out)."""
    robot = scratch.problem.robot
    h = robot.hands[hand]
    X_end = scratch.kin.fk(q_end, h.grasp_frame)
    qs, q = [q_end], q_end
    opts = IKOptions(restarts=0, max_iters=60)
    with_torso = np.concatenate([robot.groups["torso"], h.arm_idx])
    for i in range(1, steps + 1):
        X = X_end.copy()
        X[:3, 3] = X_end[:3, 3] + (X_far[:3, 3] - X_end[:3, 3]) * (i / steps)
        res = solve_pose(robot, h.grasp_frame, X, q, h.arm_idx, rng, opts)
        if not res.success and lean and len(robot.groups["torso"]):
            res = solve_pose(robot, h.grasp_frame, X, q, with_torso, rng, opts)
        if not res.success or np.max(np.abs(res.q - q)) > 0.6:
            return None
        q = res.q
        qs.append(q)
    return np.array(qs[::-1])


def with_fingers(scratch: Scratch, q: np.ndarray, hand: str, values: np.ndarray) -> np.ndarray:
    out = q.copy()
    out[scratch.problem.robot.hands[hand].idx] = values
    return out


def preshapes(scratch: Scratch, grasps: GraspList, k: int, up_O: np.ndarray | None = None):
    """Pre-shapes of grasp ``k``, lazily (finger values, (n_hand_joints,)): opened from
    closed towards open, most open first; for a fingertip hand, then every fingertip
    backed off its contact along the surface normal (finger IK), farthest first: opening
    a low pinch towards the open hand can swing a finger into the support, backing off
    moves each tip straight out of its contact.  With ``up_O`` (3,), the object resting on
    a support whose upward direction is that (frame O), the backed-off tips then also rise
    :data:`PRESHAPE_LIFT` off it: a pinch on a flat object rests its tips on the support
    (within the contact tolerance), where backing off along a level normal leaves them."""
    h = scratch.problem.robot.hands[grasps.hand]
    closed = grasps.finger_q[k]
    for a in scratch.options.preshape:
        yield closed + a * (h.open - closed)
    ups = (None,) if up_O is None else (None, np.asarray(up_O, dtype=float))
    for up in ups if h.kind == "fingertips" else ():
        for d in scratch.options.backoff:
            # computed once per run, and only when the openings above collide
            key = (grasps.hand, k, d, None if up is None else up.tobytes())
            if key not in scratch.backed_off:
                scratch.backed_off[key] = _backed_off(scratch, grasps, k, d, None if up is None else PRESHAPE_LIFT * up)
            if scratch.backed_off[key] is not None:
                yield scratch.backed_off[key]


_BACK_OFF_IK = IKOptions(restarts=0, max_iters=30)  # from the closed values only: no random restart
PRESHAPE_LIFT = 0.005  # m: backed-off fingertips rise this far off a support (more than the contact tolerance)


def _backed_off(scratch: Scratch, grasps: GraspList, k: int, distance: float,
                lift_O: np.ndarray | None = None) -> np.ndarray | None:
    """Finger values (n_hand_joints,) of grasp ``k`` with every fingertip in contact moved
    out of its contact along the surface normal, towards ``distance`` (m) out and at least
    half of it, and by ``lift_O`` (3,) (m, frame O) (finger IK from the closed values, no
    restart: a joint limit may stop a finger short of the exact target), or None when a
    finger cannot back off that far."""
    robot = scratch.problem.robot
    h = robot.hands[grasps.hand]
    q = with_fingers(scratch, robot.q_rest, grasps.hand, grasps.finger_q[k])
    X_WO = scratch.kin.fk(q, h.grasp_frame) @ inverse(grasps.X_OG[k])  # the hand where it is at rest
    lift_W = np.zeros(3) if lift_O is None else X_WO[:3, :3] @ lift_O
    for f in np.nonzero(grasps.in_contact[k])[0]:
        r = h.spec.fingers[f].tip_radius
        p_W, n_W = X_WO[:3, :3] @ grasps.points[k, f] + X_WO[:3, 3], X_WO[:3, :3] @ grasps.normals[k, f]
        q = finger_ik(robot, grasps.hand, int(f), p_W + (r + distance) * n_W + lift_W, q, None, _BACK_OFF_IK).q
        if (scratch.kin.fk(q, h.tip_frames[f])[:3, 3] - p_W) @ n_W < r + distance / 2:
            return None
    return q[h.idx]


def _approach(scratch: Scratch, rng: np.random.Generator, hand: str, q_pre: np.ndarray, centre_W: np.ndarray, world,
              directions_extra: tuple[np.ndarray, ...] = (), last: tuple[np.ndarray, ...] = (),
              lean: bool = False) -> np.ndarray | None:
    """Approach waypoints ending at ``q_pre`` (hand at the grasp pose, fingers pre-shaped),
    starting with the fingers open ``approach_distance`` away; checked in ``world``, the
    start (a query's end) with the queries' clearance.  Directions tried: away from the
    object's centre, ``directions_extra``, back along the hand's approach, ``last``; the
    torso helps with ``lean`` (:func:`cartesian_line`)."""
    robot, o = scratch.problem.robot, scratch.options
    h = robot.hands[hand]
    certified = scratch.certified(world)
    X_WG = scratch.kin.fk(q_pre, h.grasp_frame)
    away = X_WG[:3, 3] - centre_W
    back = -(X_WG[:3, :3] @ approach_axis(scratch, hand))
    for d in (away, *directions_extra, back, *last):
        n = np.linalg.norm(d)
        if n < 1e-9:
            continue
        line = cartesian_line(scratch, rng, hand, q_pre, _translated(X_WG, o.approach_distance * d / n), o.line_steps,
                              lean)
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
        q[moving] = _around_rest(scratch, rng, moving)
    return q


def _around_rest(scratch: Scratch, rng: np.random.Generator, idx: np.ndarray) -> np.ndarray:
    """Values (len(idx),) of the joints ``idx`` drawn around rest: Gaussian of
    ``sample_sigma``, clipped to the limits."""
    robot = scratch.problem.robot
    return np.clip(robot.q_rest[idx] + rng.normal(0.0, scratch.options.sample_sigma, len(idx)), robot.lower[idx],
                   robot.upper[idx])


def reach_candidates(scratch: Scratch, rng: np.random.Generator, grasps: GraspList, ks, X_WO: np.ndarray,
                     lean: bool) -> dict[int, list[np.ndarray]]:
    """For each grasp k of ``ks``, the configurations (nq,) with the hand's grasp frame at
    X_WO @ X_OG[k], in the order :func:`single_configuration` tries them: for each of
    ``key_samples`` samples of the non-grasping joints around rest (§V-C: the torso and
    the free arm; the rest itself first; one in collision drawn again, up to
    ``base_draws`` times when leaning; the same samples for every grasp), the arm alone
    reaching from it (the torso as sampled); or, with ``lean``, the torso and the arm
    together from it, then from ``ik_seeds`` random postures of both (an object low on
    the desk at arm's length: a humanoid leans to pick it up).  Every IK of every grasp
    at once (:func:`~regrasp_cli.model.ik.arm_ik_batch`): one at a time, the IKs of the
    grasps that fail were most of the time of the nodes."""
    robot, o, hand = scratch.problem.robot, scratch.options, grasps.hand
    w_free = scratch.world(X_WO)
    torso = bool(len(robot.groups["torso"]))
    moving = np.concatenate([robot.groups["torso"], robot.hands[OTHER[hand]].arm_idx])
    posture = np.concatenate([robot.groups["torso"], robot.hands[hand].arm_idx])
    draws = o.base_draws if lean else 1
    bases = [next((b for b in (_sample_base(scratch, rng, s, moving) for _ in range(draws)) if w_free.is_free(b)), None)
             for s in range(o.key_samples)]  # shared by the grasps: where the object is, not how it is held
    rows, seeds = [], []
    for k in ks:
        for base in (b for b in bases if b is not None):
            starts = [base] if not lean or torso else []
            for _ in range(o.ik_seeds if lean else 0):  # other postures (lean, elbow, wrist) for the same hand pose
                seed = base.copy()
                seed[posture] = rng.uniform(robot.lower[posture], robot.upper[posture])
                starts.append(seed)
            rows += [int(k)] * len(starts)
            seeds += starts
    out: dict[int, list[np.ndarray]] = {int(k): [] for k in ks}
    if not rows:
        return out
    X_WG = X_WO @ grasps.X_OG[np.array(rows)]
    Q, ok = arm_ik_batch(robot, hand, X_WG, np.array(seeds), rng, with_torso=lean and torso, options=o.ik)
    for k, q, good in zip(rows, Q, ok):
        if good:
            out[k].append(q)
    return out


def _reach_both(scratch: Scratch, rng: np.random.Generator, hands: tuple[str, str],
                X_WGs: tuple[np.ndarray, np.ndarray], base: np.ndarray, lean: bool) -> np.ndarray | None:
    """A configuration (nq,) from ``base`` with both hands' grasp frames at ``X_WGs``:
    each arm alone (the torso as sampled); or, with ``lean``, the torso and both arms
    solved together (the torso cannot lean towards one hand without moving the other's
    shoulder); None when it does not converge."""
    robot, o = scratch.problem.robot, scratch.options
    if lean:
        ik = two_arm_ik(robot, hands, X_WGs, base, rng, options=o.ik)
    else:
        ik = arm_ik(robot, hands[0], X_WGs[0], base, rng, options=o.ik)
        if ik.success:
            ik = arm_ik(robot, hands[1], X_WGs[1], ik.q, rng, options=o.ik)
    return ik.q if ik.success else None


def _reach_both_batch(scratch: Scratch, rng: np.random.Generator, hands: tuple[str, str],
                      X_WGs: tuple[np.ndarray, np.ndarray], bases: np.ndarray) -> list[np.ndarray | None]:
    """:func:`_reach_both` without leaning for every configuration of ``bases`` (B, nq) at
    once: each arm alone, the first hand's from each base, then the second's from those
    (batched DLS, :func:`~regrasp_cli.model.ik.arm_ik_batch`); None where either did not
    converge.  A failing exchange pose cost PR2 1,254 one-at-a-time solves (5.4 s)."""
    robot, o = scratch.problem.robot, scratch.options
    B = len(bases)
    Q1, ok1 = arm_ik_batch(robot, hands[0], np.repeat(X_WGs[0][None], B, axis=0), bases, rng, options=o.ik)
    Q2, ok2 = arm_ik_batch(robot, hands[1], np.repeat(X_WGs[1][None], B, axis=0), Q1, rng, options=o.ik)
    return [q if a and b else None for q, a, b in zip(Q2, ok1, ok2)]


# ------------------------------------------------------------------ single grasps


def single_configuration(scratch: Scratch, rng: np.random.Generator, grasps: GraspList, k: int, X_WO: np.ndarray,
                         lean: bool = False, candidates: list[np.ndarray] | None = None) -> SingleConfig | None:
    """A collision-free configuration grasping the object at X_WO (resting on its support)
    with grasp ``k`` of the hand's list, with its approach and lift lines; None when the
    samples are exhausted.  The arm alone reaches the grasp, or with ``lean`` the torso
    helps; ``candidates``: the configurations reaching it, when the caller solved them
    (:func:`reach_candidates`, for many grasps at once)."""
    if candidates is None:
        candidates = reach_candidates(scratch, rng, grasps, [k], X_WO, lean)[k]
    for q in candidates:
        c = _grasp_at(scratch, rng, grasps, k, X_WO, q, lean)
        if c is not None:
            return c
    return None


def _free_arm_clear(scratch: Scratch, rng: np.random.Generator, hand: str, q: np.ndarray, world,
                    draws: int) -> np.ndarray | None:
    """``q`` when it is free in ``world``, else ``q`` with the free arm (the other hand's)
    drawn again around rest until it is (a torso that leans to reach can put that arm
    through the desk), up to ``draws`` times; None when no draw is free."""
    arm = scratch.problem.robot.hands[OTHER[hand]].arm_idx
    if world.is_free(q):
        return q
    for _ in range(draws):
        r = q.copy()
        r[arm] = _around_rest(scratch, rng, arm)
        if world.is_free(r):
            return r
    return None


def _grasp_at(scratch: Scratch, rng: np.random.Generator, grasps: GraspList, k: int, X_WO: np.ndarray,
              q: np.ndarray, lean: bool) -> SingleConfig | None:
    """The single-grasp configuration with the arm at ``q`` (grasp ``k`` reached), when the
    closed hand, the pre-shape, the lift and the approach (the torso helping with
    ``lean``) are free."""
    p, o = scratch.problem, scratch.options
    robot, hand = p.robot, grasps.hand
    X_OG = grasps.X_OG[k]
    X_WG = X_WO @ X_OG
    w_free = scratch.world(X_WO)
    w_touch = scratch.world(X_WO, touching=(hand,))
    q_closed = _free_arm_clear(scratch, rng, hand, with_fingers(scratch, q, hand, grasps.finger_q[k]), w_touch,
                               o.base_draws if lean else 0)
    if q_closed is None:
        return None
    q = with_fingers(scratch, q_closed, hand, robot.hands[hand].open)
    up_O = X_WO[2, :3]  # the world's vertical in O: the support is below the object
    q_pre = next((qp for qp in (with_fingers(scratch, q, hand, f) for f in preshapes(scratch, grasps, k, up_O))
                  if w_free.is_free(qp) and scratch.segment_free(w_touch, qp, q_closed)), None)
    if q_pre is None:
        return None
    lift = cartesian_line(scratch, rng, hand, q_closed, _translated(X_WG, np.array([0, 0, o.lift_height])), o.line_steps,
                          lean)
    if lift is None:
        return None
    lift = lift[::-1]
    w_held = scratch.world(inverse(X_OG), attached=hand, touching=(hand,))
    if not scratch.path_free(w_held, lift) or not scratch.certified(w_held).is_free(lift[-1]):
        return None  # the top of the lift is a query's end: it keeps the queries' clearance
    centre = X_WO[:3, :3] @ p.object.mesh.centroid + X_WO[:3, 3]
    approach = _approach(scratch, rng, hand, q_pre, centre, w_free, (np.array([0.0, 0.0, 1.0]),), lean=lean)
    if approach is None:
        return None
    a_W = X_WG[:3, :3] @ approach_axis(scratch, hand)
    to_obj = X_WO[:3, 3] - shoulder(scratch, hand, q_closed)
    cos = float(a_W @ to_obj / max(np.linalg.norm(to_obj), 1e-9))
    return SingleConfig(hand, k, X_WO, approach, q_closed, lift, cos, free_arm_cost(scratch, hand, q_closed))


# ------------------------------------------------------------------ exchange


def exchange_configuration(scratch: Scratch, rng: np.random.Generator, giver: GraspList, kg: int, taker: GraspList, kt: int,
                           X_WO: np.ndarray, lean: bool = False) -> ExchangeConfig | None:
    """Both hands on the object at X_WO (grasp ``kg`` of the giving hand, which holds it,
    ``kt`` of the taking hand): the hand-over of §V-B with its approach and retreat; None
    when the samples are exhausted.  Each arm alone reaches its grasp (the torso
    sampled), or with ``lean`` the torso and both arms are solved together
    (:func:`_reach_both`)."""
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
    X_WGs = (X_WO @ X_OGg, X_WO @ X_OGt)
    if lean:  # one sample at a time: the torso and both arms solved together
        reached = (_reach_both(scratch, rng, (g, t), X_WGs, _sample_base(scratch, rng, s, torso), True)
                   for s in range(o.key_samples))
    else:  # every sample's arms at once
        reached = _reach_both_batch(scratch, rng, (g, t), X_WGs,
                                    np.array([_sample_base(scratch, rng, s, torso) for s in range(o.key_samples)]))
    for q in reached:
        if q is None:
            continue
        q_both = with_fingers(scratch, with_fingers(scratch, q, g, fg), t, ft)
        if not w_gt.is_free(q_both):
            continue
        q_tpre = next((q for q in (with_fingers(scratch, q_both, t, f) for f in preshapes(scratch, taker, kt))
                       if w_g.is_free(q) and scratch.segment_free(w_gt, q, q_both)), None)
        if q_tpre is None:
            continue
        q_gpre = next((q for q in (with_fingers(scratch, q_both, g, f) for f in preshapes(scratch, giver, kg))
                       if w_t.is_free(q) and scratch.segment_free(w_tg, q_both, q)), None)
        if q_gpre is None:
            continue
        up = (np.array([0.0, 0.0, 1.0]),)  # straight up, as a single grasp may, when the other ways are blocked
        approach = _approach(scratch, rng, t, q_tpre, centre, w_g, last=up, lean=lean)
        if approach is None:
            continue
        retreat = _approach(scratch, rng, g, q_gpre, centre, w_t, last=up, lean=lean)
        if retreat is None:
            continue
        return ExchangeConfig(X_WO, approach, q_both, q_gpre, retreat[::-1])
    return None
