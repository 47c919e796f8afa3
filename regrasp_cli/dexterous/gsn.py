"""GS_n: configurations where all n fingers touch the object with force closure, and the
paths between them (seed 003 §IV-§VI).

A configuration (:class:`GsConfig`) is the object's pose in the hand's grasp frame G
(the wrist is fixed), one contact per finger on the object's surface, and the finger
joints that put each fingertip sphere on its contact.  Sampling is the RLG way (§V): the
object pose and the contacts are the free parameters and the joints follow by IK; the
contacts come from the grasp search of :func:`grasp.fingertips.grasp_for_frame` (per finger,
surface points inside its workspace whose normal faces it, thumb first), so a sample is a
grasp of our grasp lists with every finger in contact.  Collisions other than at the
fingertips are rejected there (finger-finger, finger-object, object-palm).

A path in GS_n (:func:`gs_path`) moves the object along a linear path (position linear,
orientation slerp) while each contact that changes follows the surface geodesic between
its two contacts (§VI), fingers by IK at each step.  Every step is checked: IK, the joint
step, collisions, force closure of the n fingers, and force closure without each finger
whose contact moves.  The paper asks the latter for *every* finger (§IV: "the
force-closure property is tested for each n-1 fingers grasp"), so that the path reduces
to regrasping and transfer paths; we ask it of the fingers that must let go, which is
what the reduction uses.  The difference matters for hands with one opposing thumb (ours,
the Allegro): without the thumb the other fingers push from one side and seldom hold the
object, so the paper's condition leaves GS_n nearly empty (our hand on a 7 cm sphere: 1 of
392 samples; the thumb may let go in 2); here the thumb mostly keeps its contact and the
other fingers gait.

Frames: the grasp frame G of the hand (fixed), the object frame O; metres, radians.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
import pinocchio as pin
import trimesh

from regrasp_cli.dexterous.contacts import closed, closure, holds, normals_meet
from regrasp_cli.dexterous.hand import InHand, reach, tip_targets
from regrasp_cli.dexterous.surface import MeshSurface, along, geodesic
from regrasp_cli.dexterous.transfer import interpolate, poses_between
from regrasp_cli.grasp.fingertips import grasp_for_frame
from regrasp_cli.grasp.single import GraspOptions, HandModel
from regrasp_cli.grasp.surface import Surface as SampledSurface
from regrasp_cli.grasp.workspace import FingerWorkspace
from regrasp_cli.model.collision import CollisionWorld, cold_start
from regrasp_cli.model.robot import Kinematics
from regrasp_cli.spatial import inverse


MEMO_ENTRIES = 20_000  # results of each kind :meth:`GsScratch.memoised` keeps (contact candidates: ~3 kB each)


@dataclass(frozen=True)
class GsOptions:
    friction: float = 0.8
    step_m: float = 0.002  # object translation and contact travel per step of a path
    step_rad: float = 0.05  # object rotation per step
    max_joint_step: float = 0.2  # rad per step: more is an IK branch jump
    tol: float = 1e-4  # m, fingertip centre on its target
    link_room: float | None = None  # m beyond a fingertip where the surface must not turn sharply (GsScratch.clear)
    # The fingers that hold while one steps (GsScratch.liftable), when their normals nearly
    # meet in a point (within meet_ratio times the object's radius: on a sphere they all
    # do), must reach this Ferrari-Canny epsilon: in MuJoCo the ball's regrasps held at
    # 0.09 and more and turned it 0.12-1.6 rad at 0.056 and less, while the cube's (normals
    # 0.24-0.44 radii apart) held down to 0.011 (docs/DESIGN-NOTES.md, "Rolling fingertips")
    lift_epsilon: float = 0.075
    meet_ratio: float = 0.15


@dataclass(frozen=True)
class GsConfig:
    X_GO: np.ndarray  # (4, 4) object pose in the grasp frame
    p: np.ndarray  # (n, 3) contacts, object frame
    n: np.ndarray  # (n, 3) outward normals there
    q: np.ndarray  # (nq,) robot configuration (fingers set)


class GsScratch:
    """What checking GS_n needs for one object and hand: the hand model with the object
    attached, the fingers' workspaces, the sampled surface (contact candidates) and the
    triangulated one (geodesics)."""

    def __init__(self, hm: HandModel, workspaces: tuple[FingerWorkspace, ...], sampled: SampledSurface,
                 surface: MeshSurface, rho: float, options: GsOptions = GsOptions(),
                 grasp: GraspOptions = GraspOptions(candidates_per_finger=6), world: CollisionWorld | None = None):
        self.hm, self.workspaces, self.sampled, self.surface = hm, workspaces, sampled, surface
        self.world = world  # the scene's obstacles with the robot and the object (W), if any
        self.X_GO = np.eye(4)  # where the object is (:meth:`place`)
        self.rho, self.options, self.grasp = rho, options, grasp
        self.hand = InHand(hm.robot, hm.hand.side, hm.q.copy(), tuple(range(len(hm.hand.finger_idx))))
        self.X_WG = hm.X_WG
        self.centre = sampled.mass_centre
        self.kin = Kinematics(hm.robot)
        self.checks = 0  # collision checks
        self.generated = 0  # configurations generated (samples and edge ends)
        self.failures: dict[str, int] = {}  # why GS_n paths failed, per check
        self._liftable: dict[bytes, tuple[int, ...]] = {}
        self._memo: dict[object, dict[tuple, object]] = {}  # :meth:`memoised`, per kind
        # collision pairs of each finger (and of all, None): with the object (the eroded
        # fingertips' model), with the palm and the other fingers (the exact one's)
        pairs = hm.pair_fingers
        fingers = range(len(hm.hand.finger_idx))
        objects = [k for k, (_, fb) in enumerate(pairs) if fb is None]
        self._object_pairs = {None: objects} | {f: [k for k in objects if pairs[k][0] == f] for f in fingers}
        hand = [k for k, (_, fb) in enumerate(pairs) if fb is not None]
        self._hand_pairs = {None: hand} | {f: [k for k in hand if f in pairs[k]] for f in fingers}

    def closure(self, p: np.ndarray, n: np.ndarray, without: int | None = None) -> float:
        if without is not None:
            p, n = np.delete(p, without, axis=0), np.delete(n, without, axis=0)
        return closure(p, n, self.options.friction, self.centre, self.rho)

    def memoised(self, key: tuple, make):
        """``make()``, remembered under ``key`` (a helper's name, then its arguments;
        ``make`` pure) for this query.  Each helper's results are forgotten all at once
        past ``MEMO_ENTRIES`` (tens of MB): samples at random poses, whose candidates are
        never asked again, must not push out the lifts a tree's nodes reuse."""
        memo = self._memo.setdefault(key[0], {})
        if key not in memo:
            if len(memo) >= MEMO_ENTRIES:
                memo.clear()
            memo[key] = make()
        return memo[key]

    def closed(self, p: np.ndarray, n: np.ndarray, without: int | None = None) -> bool:
        """Force closure with the validator's margin (:meth:`closure` > 0) of the contacts
        but finger ``without``'s; memoised: a node's finger is asked at each step it tries."""
        def test() -> bool:
            q, m = (p, n) if without is None else (np.delete(p, without, axis=0), np.delete(n, without, axis=0))
            return closed(q, m, self.options.friction, self.centre, self.rho)
        return self.memoised(("closed", p.tobytes(), n.tobytes(), without), test)

    def holds(self, p: np.ndarray, n: np.ndarray, without: int | None = None) -> bool:
        """Do the contacts (but finger ``without``'s) hold the object (force closure)?"""
        if without is not None:
            p, n = np.delete(p, without, axis=0), np.delete(n, without, axis=0)
        return holds(p, n, self.options.friction, self.centre, self.rho)

    def liftable(self, c: GsConfig) -> tuple[int, ...]:
        """The fingers that may let go: the others still hold the object (memoised per set
        of contacts: a tree node is asked at each of its expansions), firmly (:meth:`firm`)."""
        key = c.p.tobytes() + c.n.tobytes()
        if key not in self._liftable:
            self._liftable[key] = tuple(f for f in range(len(c.p)) if self.holds(c.p, c.n, f) and
                                        self.firm(c.p, c.n, f))
        return self._liftable[key]

    def firm(self, p: np.ndarray, n: np.ndarray, without: int) -> bool:
        """Do the contacts but finger ``without``'s, force closure, hold the object firmly
        enough for it to let go?  Where their normals nearly meet in a point
        (:func:`contacts.normals_meet` within ``meet_ratio`` radii) only friction keeps the
        object from turning about it, and they must reach a Ferrari-Canny epsilon of
        ``lift_epsilon``; elsewhere the normal forces resist the turn."""
        o = self.options
        keep = np.delete(np.arange(len(p)), without)
        apart = normals_meet(p[keep], n[keep]) > o.meet_ratio * self.rho
        return apart or self.closure(p, n, without) >= o.lift_epsilon

    @cached_property
    def clear(self) -> np.ndarray:
        """(m,) bool per sampled surface point: a fingertip touching the surface there
        touches it there only (its sphere, of the largest tip radius, clear of the rest of
        the mesh to 0.5 mm): not across an edge or inside a crease, where the object's
        least turn would push into the fingertip; with ``options.link_room``, also the
        surface within that of the sphere turns less than 45 degrees from the contact's
        normal: not within a fingertip of an edge, where the finger's links lean over the
        next face (tried on the cube: docs/DESIGN-NOTES.md)."""
        r = float(self.hand.radii.max())
        c = self.sampled.points + r * self.sampled.normals
        _, d, _ = trimesh.proximity.closest_point(self.surface.mesh, c)
        clear = d >= r - 5e-4
        if self.options.link_room is None:
            return clear
        n = self.sampled.normals
        near = self.sampled.tree.query_ball_point(c, r + self.options.link_room)
        return clear & np.array([bool(np.all(n[nb] @ n[i] >= np.cos(np.pi / 4))) for i, nb in enumerate(near)])

    @cached_property
    def _exact(self) -> HandModel:
        """The hand with fingertips not eroded: the hand model's fingertips are shrunk by
        the contact tolerance so that they may touch the object, which must not let two
        fingers overlap."""
        hm = self.hm
        return HandModel(hm.robot, hm.hand.side, self.surface.mesh, set(hm.disabled_links), 0.0)

    def _touches(self, q: np.ndarray, finger: int | None) -> bool:
        """Does ``finger`` (or any finger, or the palm, when None) go into the object
        beyond the contact tolerance, or overlap another finger or the palm, at ``q``?
        The fingers' own pairs are checked with exact fingertips only: the eroded ones
        overlap only where these do."""
        hm, ex = self.hm, self._exact
        objects, hand = self._pair_sets[finger]
        pin.updateGeometryPlacements(hm.robot.model, hm.data, hm.gm, objects, hm.robot.to_pin(q))
        if pin.computeCollisions(hm.gm, objects, True):
            return True
        pin.updateGeometryPlacements(ex.robot.model, hm.data, ex.gm, hand)  # the joints just placed
        return pin.computeCollisions(ex.gm, hand, True)

    @cached_property
    def _pair_sets(self) -> dict[int | None, tuple[pin.GeometryData, pin.GeometryData]]:
        """Per finger (None: all), scratch of the eroded model with only the finger's
        object pairs active, and of the exact one with only its hand pairs: one call into
        coal checks each set (pair by pair from Python cost as much again)."""
        out = {}
        for f in self._object_pairs:
            sets = []
            for gm, pairs in ((self.hm.gm, self._object_pairs[f]), (self._exact.gm, self._hand_pairs[f])):
                gd = gm.createData()
                cold_start(gd)
                gd.deactivateAllCollisionPairs()
                for k in pairs:
                    gd.activateCollisionPair(k)
                sets.append(gd)
            out[f] = tuple(sets)
        return out

    def place(self, X_GO: np.ndarray) -> None:
        """Put the object at ``X_GO`` (4, 4) for the collision checks that follow."""
        self.X_GO = X_GO
        self.hm.set_object(inverse(X_GO))

    def _hits_obstacle(self, q: np.ndarray) -> bool:
        if self.world is None:
            return False
        self.world.set_object_pose(self.X_WG @ self.X_GO)
        return not self.world.is_free(q)

    def collides(self, X_GO: np.ndarray, q: np.ndarray) -> bool:
        """The hand with the object at ``X_GO``: fingers or palm inside the object (beyond
        the contact tolerance at the fingertips) or overlapping each other, or the hand or
        the object against an obstacle."""
        self.checks += 1
        self.place(X_GO)
        return self._touches(q, None) or self._hits_obstacle(q)

    def finger_collides(self, q: np.ndarray, finger: int) -> bool:
        """Finger ``finger`` (moving, the object where :meth:`place` put it) against the
        object, the palm, the other fingers and the obstacles."""
        self.checks += 1
        return self._touches(q, finger) or self._hits_obstacle(q)


def sample_config(s: GsScratch, X_GO: np.ndarray) -> GsConfig | None:
    """A configuration of GS_n with the object at ``X_GO``, or None (RLG sampling: the
    contacts from the fingers' workspaces, the joints by IK, through the grasp search,
    whose fingertips may touch each other: that is checked here)."""
    g, _ = grasp_for_frame(s.hm, s.workspaces, s.sampled, inverse(X_GO), 0, s.options.friction, s.rho, s.grasp)
    if g is None or not g.in_contact.all():
        return None
    q = s.hm.q.copy()
    q[s.hm.hand.idx] = g.finger_q
    ok = s.holds(g.points, g.normals) and not s.collides(X_GO, q)
    return GsConfig(X_GO.copy(), g.points.copy(), g.normals.copy(), q) if ok else None


def gs_path(s: GsScratch, a: GsConfig, b_pose: np.ndarray, b_p: np.ndarray, rng: np.random.Generator,
            fixed: tuple[int, ...] = ()) -> list[GsConfig] | None:
    """The linear path in GS_n from ``a`` to the object at ``b_pose`` with contacts ``b_p``
    (n, 3), object frame (on the surface; those of the ``fixed`` fingers must equal a's),
    every step checked (see the module); the configurations after ``a``, or None."""
    o = s.options
    moving = [f for f in range(len(a.p)) if f not in fixed and np.linalg.norm(b_p[f] - a.p[f]) > 1e-9]
    paths = {}
    for f in moving:
        tri, uv = s.surface.locate(np.stack([a.p[f], b_p[f]]))
        paths[f] = geodesic(s.surface, (int(tri[0]), int(tri[1])), (uv[0], uv[1]))
        if paths[f] is None:
            s.failures["geodesic"] = s.failures.get("geodesic", 0) + 1
            return None
    travel = max([float(np.linalg.norm(np.diff(pth, axis=0), axis=1).sum()) for pth in paths.values()] + [0.0])
    poses = interpolate(a.X_GO, b_pose, o.step_m, o.step_rad)
    k = max(len(poses) - 1, int(np.ceil(travel / o.step_m)))
    if k != len(poses) - 1:
        poses = poses_between(a.X_GO, b_pose, k)
    out, last = [], a
    radii = s.hand.radii
    for i in range(1, k + 1):
        t = i / k
        p, n = last.p.copy(), last.n.copy()
        if moving:
            pts = np.stack([along(paths[f], np.array([t]))[0] for f in moving])
            tri, _ = s.surface.locate(pts)
            p[moving], n[moving] = pts, s.surface.normals[tri]
        X_GO = poses[i]
        q = reach(s.hand, last.q, tip_targets(s.X_WG @ X_GO, p, n, radii), rng, restarts=0, tol=o.tol, kin=s.kin)
        why = ("ik" if q is None else "joint step" if np.abs(q - last.q).max() > o.max_joint_step
               else "collision" if s.collides(X_GO, q) else None)
        if why is None:  # closure without a finger implies it with all (more contacts)
            why = "n-1 closure" if not all(s.holds(p, n, f) for f in moving) else None
        if why is not None:
            s.failures[why] = s.failures.get(why, 0) + 1
            return None
        last = GsConfig(X_GO, p, n, q)
        out.append(last)
    return out

