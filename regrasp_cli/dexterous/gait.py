"""Transfer and regrasping paths, and the reduction of a GS_n path to them (seed 003 §IV).

A *transfer* moves the object with every fingertip rolling on it without slipping (the
fingers follow by IK, :func:`roll`); a *regrasping path* keeps the object still while one
finger lets go and moves to a new contact, the other n-1 holding it in force closure.
Only these two are physically feasible; a path in GS_n, where contacts slide while the
object moves, is not, but when every n-1 fingers' grasp along it is force closure it can
be replaced by alternating transfers and regrasps that stay near it (the reduction
property, §IV-§V).  Seed 003 keeps each contact fixed on the object during a transfer,
which a fingertip sphere does only by slipping on it whenever the finger turns relative
to the object (0.3-0.6 rad in a 0.27 rad turn of the ball): in MuJoCo those slips, not the
plan, turned the ball (docs/DESIGN-NOTES.md, "Rolling fingertips").  A rolling fingertip's
contact moves on the object a little (2-3.5 mm in that turn), so a transfer's contacts
are per waypoint.

:func:`reduce_path` does this greedily: it carries the object along the GS_n path, the
fingertips rolling, as long as the fingers can follow and no contact has drifted more
than ``gait_m`` from the path's; then each drifted finger in turn steps to the path's
contact (a regrasp), and the carrying goes on from there.

A finger's regrasping path (:func:`finger_step`) lifts the fingertip off by opening the
finger (its joints towards the hand's open values) until the tip is clear of the contact's
tangent plane, moves to where the finger, opened the same way, is as clear over the new
contact, and closes on it: three
straight joint-space segments, each checked for collisions of that finger (with the
object, the palm and the other fingers) every ``check_rad``; higher lifts are tried when
a lower one collides.  The collision checks let fingertips into the object by the contact
tolerance; the lifted fingertip gets none (:func:`lifts_clear`): opening a finger can
drag its tip through the surface before it rises.

Frames: the grasp frame G (fixed), the object frame O; metres, radians.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np
import trimesh
from scipy.spatial.transform import Rotation

from regrasp_cli.dexterous.gsn import GsConfig, GsScratch
from regrasp_cli.dexterous.hand import reach, tip_targets
from regrasp_cli.dexterous.transfer import interpolate


LIFT_TOL = 1e-5  # m: rounding of a lifted fingertip's distance to the object (lifts_clear)
ROLL_TOL = 2e-5  # m: a rolling fingertip's centre where its turn puts it (:func:`roll`; a slip per step
# at most this; passes on a mesh converge to under a micron, or stall at an edge between two faces)
ROLL_PASSES = 5  # ... found in at most this many passes (two or three as a rule)
EDGE_RAD = 0.3  # rad: a rolling contact's normal this far off its face's is on an edge (the validator's 0.35)
OFF_M = 0.001  # m: a stepping fingertip first moves this far straight off its contact, and last onto the new one


@dataclass(frozen=True)
class GaitOptions:
    gait_m: float = 0.012  # contact drift from the GS_n path before a finger steps
    lifts_m: tuple[float, ...] = (0.004, 0.008, 0.016, 0.03)  # fingertip lift heights tried
    check_rad: float = 0.04  # joint step between collision checks of a moving finger
    confirm_rad: float = 0.01  # the same, for the finger step kept (`regrasp validate`'s resolution)
    max_joint_step: float = 0.2  # rad per step of a transfer: more is an IK branch jump


@dataclass(frozen=True)
class Transfer:
    """The object moves, the fingertips roll on it: poses (k, 4, 4) in G, configurations
    (k, nq) and contacts per waypoint, the first the state it starts from."""

    X_GO: np.ndarray
    q: np.ndarray
    p: np.ndarray  # (k, n, 3) contacts, object frame
    n: np.ndarray  # (k, n, 3) outward normals

    @property
    def end(self) -> GsConfig:
        return GsConfig(self.X_GO[-1], self.p[-1], self.n[-1], self.q[-1])


@dataclass(frozen=True)
class Regrasp:
    """Finger ``finger`` moves from contact ``before.p[finger]`` to ``after.p[finger]``
    with the object still: configurations (k, nq), lifted from the second to the last but
    one."""

    finger: int
    q: np.ndarray
    before: GsConfig
    after: GsConfig

    @property
    def end(self) -> GsConfig:
        return self.after


Piece = Transfer | Regrasp


def reversed_piece(piece: Piece) -> Piece:
    """The same motion backwards: quasi-static transfers and regrasps are reversible (a
    finger that lifted off a contact and closed on another lifts off the second and
    closes on the first, the others holding the object all along; rolling back without
    slipping retraces the contacts)."""
    if isinstance(piece, Regrasp):
        return Regrasp(piece.finger, piece.q[::-1].copy(), piece.after, piece.before)
    return Transfer(piece.X_GO[::-1].copy(), piece.q[::-1].copy(), piece.p[::-1].copy(), piece.n[::-1].copy())


def reversed_path(pieces: list[Piece]) -> list[Piece]:
    """The pieces from the last one's end back to the first one's start."""
    return [reversed_piece(p) for p in reversed(pieces)]


def _segment_free(s: GsScratch, q_a: np.ndarray, q_b: np.ndarray, finger: int, check_rad: float) -> bool:
    k = max(1, int(np.ceil(np.abs(q_b - q_a).max() / check_rad)))
    for t in np.linspace(0.0, 1.0, k + 1)[1:]:
        if s.finger_collides(q_a + t * (q_b - q_a), finger):
            return False
    return True


def tip_clearance(s: GsScratch, qs: np.ndarray, f: int, X_WO: np.ndarray) -> np.ndarray:
    """Distance (k,) from finger ``f``'s fingertip sphere to the object's surface at the
    configurations ``qs`` (k, nq), the object at ``X_WO`` (4, 4): negative inside (m):
    to the mesh's closest point, signed by the side of its face (the validator measures
    the mesh's signed distance: the same near the surface; an approximation by the
    tangent plane of the nearest surface sample let 0.1 mm through on a ball)."""
    tip = s.hm.hand.tip_frames[f]
    c_W = np.array([s.kin.fk(q, tip)[:3, 3] for q in qs])
    c_O = (c_W - X_WO[:3, 3]) @ X_WO[:3, :3]
    mesh = s.surface.mesh
    closest, d, tri = trimesh.proximity.closest_point(mesh, c_O)  # signed by the nearest face's side
    return np.where(np.einsum("ij,ij->i", c_O - closest, mesh.face_normals[tri]) < 0, -d, d) - s.hand.radii[f]


def lifts_clear(s: GsScratch, qs: list[np.ndarray], f: int, X_WO: np.ndarray, step_rad: float) -> bool:
    """Does finger ``f`` stay off the object from where it lets go (``qs[0]``) to where it
    touches again (``qs[-1]``), along the straight segments between ``qs``, sampled every
    ``step_rad``?  The contact tolerance lets a touching fingertip into the object; a
    lifted one gets none: leaving, it goes no deeper than it was at its contact, between,
    not in at all, arriving, no deeper than it will be (:data:`LIFT_TOL` for rounding)."""
    last = len(qs) - 2
    samples, segment = [qs[0], qs[-1]], []  # the ends first: they set the floors
    for i, (a, b) in enumerate(zip(qs, qs[1:])):
        k = max(1, int(np.ceil(np.abs(b - a).max() / step_rad)))
        t = np.linspace(0.0, 1.0, k + 1)[1:-1] if i == last else np.linspace(0.0, 1.0, k + 1)[1:]
        samples += list(a + t[:, None] * (b - a))
        segment += [i] * len(t)
    d = tip_clearance(s, np.array(samples), f, X_WO)  # one call: its cost is mostly per call
    seg = np.array(segment, dtype=int)
    floor = np.minimum(0.0, np.minimum(np.where(seg == 0, d[0], 0.0), np.where(seg == last, d[1], 0.0))) - LIFT_TOL
    return bool(np.all(d[2:] >= floor))


def _off(s: GsScratch, q: np.ndarray, f: int, X_WO: np.ndarray, p_O: np.ndarray, n_O: np.ndarray,
         rng: np.random.Generator) -> np.ndarray | None:
    """Finger ``f`` moved from ``q`` so that its fingertip is :data:`OFF_M` straight off its
    contact (``p_O``, ``n_O``, object frame) along the normal, by IK; None when it cannot."""
    centre = X_WO[:3, :3] @ (p_O + (s.hand.radii[f] + OFF_M) * n_O) + X_WO[:3, 3]
    targets = np.zeros((len(s.hand.fingers), 3))
    targets[f] = centre
    return reach(s.hand, q, targets, rng, fingers=(f,), restarts=0, tol=0.1 * OFF_M, kin=s.kin)


def _lifted(s: GsScratch, q: np.ndarray, f: int, X_WO: np.ndarray, p_O: np.ndarray, n_O: np.ndarray,
            h: float, rng: np.random.Generator, opened: bool = True) -> np.ndarray | None:
    """Finger ``f`` moved from ``q`` so that its fingertip is ``h`` off the contact's
    tangent plane (``p_O``, ``n_O``, object frame): opened (its joints towards the hand's
    open values; not tried without ``opened``), or by IK straight off along the normal, or
    off and back towards the finger's base (a stretched finger cannot go straight); None
    when none clears."""
    idx, tip = s.hm.hand.finger_idx[f], s.hm.hand.tip_frames[f]
    p_W, n_W = X_WO[:3, :3] @ p_O + X_WO[:3, 3], X_WO[:3, :3] @ n_O
    r = s.hand.radii[f]
    centre = p_W + r * n_W
    root = s.X_WG[:3, :3] @ s.workspaces[f].root + s.X_WG[:3, 3]
    back = (root - centre) / max(np.linalg.norm(root - centre), 1e-9)
    for t in np.linspace(0.05, 1.0, 20) if opened else ():  # opened: forward kinematics only, the cheapest
        q_t = q.copy()
        q_t[idx] = (1 - t) * q[idx] + t * s.hm.q[idx]
        if (s.kin.fk(q_t, tip)[:3, 3] - p_W) @ n_W - r >= h:
            return q_t
    targets = np.zeros((len(s.hand.fingers), 3))
    for d in (n_W, n_W + back, n_W + 2 * back):
        targets[f] = centre + h * d / np.linalg.norm(d)
        # loosely: any clear point
        up = reach(s.hand, q, targets, rng, fingers=(f,), restarts=0, tol=0.1 * h, kin=s.kin)
        if up is not None and (s.kin.fk(up, tip)[:3, 3] - p_W) @ n_W - r >= 0.9 * h:
            return up
    return None


def finger_step(s: GsScratch, c: GsConfig, f: int, p_new: np.ndarray, n_new: np.ndarray, rng: np.random.Generator,
                o: GaitOptions = GaitOptions(), q_hint: np.ndarray | None = None,
                q_down: np.ndarray | None = None) -> Regrasp | None:
    """The regrasping path of finger ``f`` from its contact in ``c`` to ``p_new`` (3,) with
    outward normal ``n_new`` (object frame), or None: the others must hold the object, the
    new grasp be force closure, the finger reach it and move there without collision.
    ``q_hint``: joint values near the new contact's (an IK seed); ``q_down``: finger
    ``f``'s joints there, known (checked, not solved for)."""
    if f not in s.liftable(c):  # then the new grasp holds too: it has one contact more
        return None
    p, n = c.p.copy(), c.n.copy()
    p[f], n[f] = p_new, n_new
    X_WO = s.X_WG @ c.X_GO
    s.place(c.X_GO)
    seed = c.q.copy()  # the other fingers stay; finger f from the hint
    if q_hint is not None:
        idx = s.hm.hand.finger_idx[f]
        seed[idx] = q_hint[idx]
    targets = tip_targets(X_WO, p, n, s.hand.radii)
    if q_down is None:
        down = reach(s.hand, seed, targets, rng, fingers=(f,), restarts=1, tol=s.options.tol, kin=s.kin)
    else:
        down = c.q.copy()
        down[s.hm.hand.finger_idx[f]] = q_down[s.hm.hand.finger_idx[f]]
        if np.linalg.norm(s.hand.tips(s.kin, down)[f] - targets[f]) > s.options.tol:
            return None
    if down is None:
        return None
    if s.finger_collides(down, f):  # every lift's last segment ends there
        return None
    # straight off each contact first: a joint-space line from a touching tip curves and
    # can graze the surface; a millimetre-long one off along the normal does not
    off_a = s.memoised(("off", c.q.tobytes(), c.X_GO.tobytes(), c.p[f].tobytes(), c.n[f].tobytes(), f),
                       lambda: _off(s, c.q, f, X_WO, c.p[f], c.n[f], rng))
    off_b = ...  # solved when first needed
    for h in o.lifts_m:
        for opened in (True, False):  # opening can drag the tip through the surface: then off along the normal
            # a node's finger is lifted at each step it tries
            up_a = s.memoised(("lifted", c.q.tobytes(), c.X_GO.tobytes(), c.p[f].tobytes(), c.n[f].tobytes(), f, h,
                               opened), lambda: _lifted(s, c.q, f, X_WO, c.p[f], c.n[f], h, rng, opened))
            up_b = _lifted(s, down, f, X_WO, p[f], n[f], h, rng, opened)
            if up_a is None or up_b is None:
                break
            if off_b is ...:
                off_b = _off(s, down, f, X_WO, p[f], n[f], rng)
            qs = [c.q] + [x for x in (off_a, up_a, up_b, off_b) if x is not None] + [down]
            segments = list(zip(qs, qs[1:]))
            # coarse first (most tries fail), then as finely as the validator: a distal link
            # can graze a face between coarse checks
            if not (all(_segment_free(s, a, b, f, o.check_rad) for a, b in segments) and
                    all(_segment_free(s, a, b, f, o.confirm_rad) for a, b in segments)):
                break
            if lifts_clear(s, qs, f, X_WO, o.confirm_rad):
                # the quick gate above lets through grasps at the very boundary of closure,
                # which the validator (epsilon over its margin) refuses: the step kept is exact
                return Regrasp(f, np.array(qs), c, GsConfig(c.X_GO, p, n, down)) if s.closed(c.p, c.n, f) else None
    return None


def _tip_frames(s: GsScratch, q: np.ndarray) -> list[np.ndarray]:
    """The fingertip frames (4, 4) in W at ``q``, finger by finger."""
    return [s.kin.fk(q, s.hm.hand.tip_frames[f]) for f in range(len(s.hand.fingers))]


def _tip_rotations(tips: list[np.ndarray], X_WO: np.ndarray) -> np.ndarray:
    """(n, 3, 3) the orientations of the fingertip frames ``tips`` (4, 4 each, W) in the
    object frame at X_WO."""
    return np.array([X_WO[:3, :3].T @ T[:3, :3] for T in tips])


def _touch(s: GsScratch, c_O: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Contacts, outward normals (n, 3) and the normals' angles to their faces' (n,) of
    fingertips centred at ``c_O`` (n, 3), object frame: the surface points nearest, the
    normals towards the centres (between faces' at an edge or a vertex; the face's where a
    centre is inside)."""
    p, tri = s.surface.nearest(c_O)
    away = c_O - p
    d = np.linalg.norm(away, axis=1, keepdims=True)
    face = s.surface.normals[tri]
    n = np.where((d > 1e-9) & ((away * face).sum(axis=1, keepdims=True) > 0), away / np.maximum(d, 1e-12), face)
    return p, n, np.arccos(np.clip((n * face).sum(axis=1), -1.0, 1.0))


def roll(s: GsScratch, state: GsConfig, X_GO: np.ndarray,
         rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray] | str:
    """The fingers' joints (nq,), contacts and outward normals (n, 3), object frame, when
    the object moves from ``state``'s pose to ``X_GO`` (4, 4) one small step, every
    fingertip rolling on it without slipping; or why not: "transfer ik" (a finger cannot
    follow), "transfer roll" (no fixed point) or "transfer edge" (a fingertip rolls over
    an edge: its contact normal more than :data:`EDGE_RAD` off the face's, which the grasp
    model and the validator refuse).

    Point contacts (seed 003 §II): no slip at a contact, the spin about the normal free.
    A sphere of radius r that turns by the rotation vector phi relative to the object
    (object frame) moves its centre by r phi x n on it, n the outward normal (taken
    halfway through the step), and stays r off the surface.  First each fingertip's point
    at its contact is sent where the object's point there goes (IK of that point of the
    tip frame: right to first order in the step); then the centres are put where phi
    says, on the surface's offset, until they move less than :data:`ROLL_TOL` (a fixed
    point that shrinks the error five- to tenfold a pass)."""
    X_a, X_b = s.X_WG @ state.X_GO, s.X_WG @ X_GO
    r = s.hand.radii[:, None]
    tips = _tip_frames(s, state.q)
    p_W = state.p @ X_a[:3, :3].T + X_a[:3, 3]
    points = np.array([T[:3, :3].T @ (p - T[:3, 3]) for T, p in zip(tips, p_W)])  # in the tip frames
    q = reach(s.hand, state.q, state.p @ X_b[:3, :3].T + X_b[:3, 3], rng, restarts=0, tol=ROLL_TOL / 4, kin=s.kin,
              points=points)
    if q is None:
        return "transfer ik"
    R_a = _tip_rotations(tips, X_a)
    c0 = state.p + r * state.n
    c = (s.hand.tips(s.kin, q) - X_b[:3, 3]) @ X_b[:3, :3]
    p, n, _ = _touch(s, c)
    for _ in range(ROLL_PASSES):
        phi = Rotation.from_matrix(_tip_rotations(_tip_frames(s, q), X_b) @ R_a.transpose(0, 2, 1)).as_rotvec()
        mid = (state.n + n) / np.linalg.norm(state.n + n, axis=1, keepdims=True)
        p, n, off = _touch(s, c0 + r * np.cross(phi, mid))
        if off.max() > EDGE_RAD:
            return "transfer edge"
        want = p + r * n
        if np.abs(want - c).max() < ROLL_TOL:
            return q, p, n
        q = reach(s.hand, q, want @ X_b[:3, :3].T + X_b[:3, 3], rng, restarts=0, tol=ROLL_TOL / 4, kin=s.kin)
        if q is None:
            return "transfer ik"
        c = want
    return "transfer roll"


def _transfer_step(s: GsScratch, state: GsConfig, X_GO: np.ndarray, rng: np.random.Generator,
                   o: GaitOptions) -> GsConfig | None:
    rolled = roll(s, state, X_GO, rng)
    q, p, n = rolled if not isinstance(rolled, str) else (None, state.p, state.n)
    why = (rolled if q is None else "transfer joint step" if np.abs(q - state.q).max() > o.max_joint_step
           else "transfer collision" if s.collides(X_GO, q) else "transfer closure" if not s.closed(p, n) else None)
    if why is not None:
        s.failures[why] = s.failures.get(why, 0) + 1
        return None
    return GsConfig(X_GO, p, n, q)


def reduce_path(s: GsScratch, path: list[GsConfig], rng: np.random.Generator,
                o: GaitOptions = GaitOptions()) -> list[Piece] | None:
    """Transfers and regrasps that follow the GS_n path (``path[0]`` the state it starts
    from, consecutive configurations one step apart), or None when they cannot.  They end
    at ``path[-1]``'s pose and contacts (within a quarter of ``gait_m``)."""
    pieces: list[Piece] = []
    state, synced, end = path[0], 0, len(path) - 1  # synced: where the contacts were last the path's
    while True:
        carried = [state]  # carry, the fingertips rolling, as far as the fingers follow
        while synced + len(carried) <= end:
            i = synced + len(carried)
            nxt = _transfer_step(s, carried[-1], path[i].X_GO, rng, o)
            if nxt is None or np.linalg.norm(path[i].p - nxt.p, axis=1).max() > o.gait_m:
                break
            carried.append(nxt)
        # the drifted fingers step to the path's contacts where the carrying stopped, or
        # earlier (less drift, the fingers less stretched) when they cannot there
        for j in _backoff(synced, synced + len(carried) - 1):
            steps = _step_fingers(s, carried[j - synced], path[j], rng, o)
            if steps is not None:
                break
        else:
            return None
        if j > synced:
            pieces.append(_transfer(carried[:j - synced + 1]))
        pieces += steps
        state, synced = (steps[-1].after if steps else carried[j - synced]), j
        if j == end:
            return pieces


def regrasp_to(s: GsScratch, c: GsConfig, end: GsConfig, rng: np.random.Generator, o: GaitOptions = GaitOptions(),
               first: list[int] | None = None, orders: int = 24) -> list[Regrasp] | None:
    """Regrasps from ``c`` to ``end``'s contacts and joints, the object still at their
    (common) pose: one step per finger whose joints differ, straight to its contact in
    ``end``, in the first order that is feasible (``first``, then the fingers' other
    orders, ``orders`` at most); None when none is.  Orders that begin alike share their
    first steps (each step is a pure function of the fingers moved before it)."""
    idx = s.hm.hand.finger_idx
    moved = [f for f in range(len(c.p)) if not np.array_equal(c.q[idx[f]], end.q[idx[f]])]
    tried: dict[tuple[int, ...], Regrasp | None] = {}  # by the fingers moved, in order
    for order in itertools.islice(itertools.chain([first or moved], itertools.permutations(moved)), orders + 1):
        state, steps = c, []
        for k, f in enumerate(order):
            key = tuple(order[:k + 1])
            if key not in tried:
                tried[key] = finger_step(s, state, f, end.p[f], end.n[f], rng, o, q_down=end.q)
            step = tried[key]
            if step is None:
                break
            steps.append(step)
            state = step.after
        else:
            return steps
    return None


def _backoff(synced: int, last: int) -> list[int]:
    """Path indices to try a gait at, from ``last`` back towards ``synced`` (excluded)."""
    out, j = [], last
    while j > synced:
        out.append(j)
        j = synced + (j - synced) // 2
    return out


def _step_fingers(s: GsScratch, state: GsConfig, target: GsConfig, rng: np.random.Generator,
                  o: GaitOptions) -> list[Regrasp] | None:
    """Each finger drifted from ``target``'s contacts steps to it, the farthest first."""
    steps: list[Regrasp] = []
    drift = np.linalg.norm(target.p - state.p, axis=1)
    for k, f in enumerate(np.argsort(-drift)):
        if drift[f] <= (1e-4 if k == 0 else 0.25 * o.gait_m):  # at least the farthest
            break
        step = finger_step(s, state, int(f), target.p[f], target.n[f], rng, o, q_hint=target.q)
        if step is None:
            return None
        steps.append(step)
        state = step.after
    return steps


def _transfer(states: list[GsConfig]) -> Transfer:
    return Transfer(*(np.array([getattr(x, k) for x in states]) for k in ("X_GO", "q", "p", "n")))


def carry(s: GsScratch, a: GsConfig, X_GO: np.ndarray, rng: np.random.Generator, step_m: float, step_rad: float,
          o: GaitOptions = GaitOptions()) -> Transfer | None:
    """The transfer of the object from ``a`` to ``X_GO`` (4, 4) with ``a``'s contacts, every
    step checked (IK, joint step, collisions), or None.  (Keeping the part that goes, an
    RRT's extend, filled the tree with stretched fingers near the goal: docs/DESIGN-NOTES.md.)"""
    states = [a]
    for X in interpolate(a.X_GO, X_GO, step_m, step_rad)[1:]:
        nxt = _transfer_step(s, states[-1], X, rng, o)
        if nxt is None:
            return None
        states.append(nxt)
    return _transfer(states)
