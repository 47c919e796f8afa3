"""The checks of the in-hand kinds (seed 003): a hand turns the object held in its
fingertips with ``inhand-transfer`` and ``inhand-regrasp`` phases.  :func:`.validate.validate_plan`
gives every phase of any plan the checks of its kind; those of these two are here.

Like :mod:`regrasp_cli.validate` it trusts nothing the planner computed (it never imports
it); from the phases' kinds, per-waypoint object poses and contacts it checks:

* **kind**: the phase touches one hand and holds none; every waypoint a stop (no blend:
  the motion between two is checked straight); only the touching hand's finger joints
  move (the arm holds still); in a transfer every finger touches and each fingertip
  rolls on the object without slipping (:meth:`InHandChecks.slips`); in a regrasp the
  object stays still, one finger
  leaves its contact (it is missing from the waypoints between the first and the last),
  the others keep theirs, and all touch at both ends;
* **object**: the object's pose never jumps between waypoints (at most ``STEP_M`` and
  ``STEP_RAD``; between phases and from the start, :func:`.validate.object_pose_issues`);
* **contacts**, at every waypoint: on the object's surface, the normal along the
  surface's, the fingertip sphere's centre at ``p + r n`` (within :data:`TIP_TOL`), and
  force closure of the fingers in contact (n-1 while one steps; point contacts with the
  plan's friction, the linearised cone of the grasp search); a lifted finger clear of the
  object;
* **collision**: every segment sampled (the object's pose interpolated with the joints)
  against the hand itself and the object, fingertips touching it eroded by the plan's
  contact tolerance; the lifted fingertip of a regrasp gets none: leaving its contact it
  goes no deeper than it was there, between waypoints it stays out, arriving it goes no
  deeper than it will be.
"""

from __future__ import annotations

import numpy as np
import trimesh
from scipy.spatial.transform import Rotation

from regrasp_cli.errors import shown
from regrasp_cli.grasp.quality import force_closure, primitive_wrenches
from regrasp_cli.manip.modes import Kind
from regrasp_cli.model.collision import ObjectPlacement, collision_world
from regrasp_cli.model.robot import Kinematics
from regrasp_cli.replay import Inputs
from regrasp_cli.spatial import segment_poses
from regrasp_cli.trajectory import Phase, Plan
from regrasp_cli.checks import CONE_EDGES, NORMAL_TOL, SURFACE_TOL, TIP_TOL, Issue, pose_differs, surface_distance

STEP_M, STEP_RAD = 0.01, 0.1  # the object's largest move between two waypoints: more is a jump
LIFT_TOL = 1e-5  # m: rounding of a lifted fingertip's distance to the object
SLIP_TOL = 0.001  # m: a transfer's fingertip slips at most this much on the object, summed over the phase
FINGER_TOL = 1e-9  # rad: joints that must not move


def _contact_set(phase: Phase, i: int) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    return {c["finger"]: (np.asarray(c["point"], float), np.asarray(c["normal"], float)) for c in phase.contacts[i]}


class InHandChecks:
    """The checks of the in-hand phases of one plan (module docstring), with the force
    closure and surface tests memoised by contact."""

    def __init__(self, plan: Plan, inputs: Inputs):
        self.plan, self.inputs = plan, inputs
        self.robot, self.kin, self.mesh = inputs.robot, Kinematics(inputs.robot), inputs.mesh
        self.centre = np.asarray(self.mesh.center_mass if self.mesh.is_watertight else self.mesh.centroid, float)
        self.rho = float(np.linalg.norm(self.mesh.vertices - self.centre, axis=1).max())
        self.closure: dict[bytes, bool] = {}
        self.surface: dict[bytes, str | None] = {}

    def fingers(self, hand: str) -> dict[str, int]:
        return {f.name: j for j, f in enumerate(self.robot.hands[hand].spec.fingers)}

    def holds(self, contacts: dict) -> bool:
        p = np.array([v[0] for v in contacts.values()])
        n = np.array([v[1] / np.linalg.norm(v[1]) for v in contacts.values()])
        key = p.tobytes() + n.tobytes()
        if key not in self.closure:
            W = primitive_wrenches(p, n, self.inputs.friction, self.centre, self.rho, n_edges=CONE_EDGES)
            self.closure[key] = len(p) >= 2 and bool(force_closure(W)[0])
        return self.closure[key]

    def on_surface(self, f: str, p: np.ndarray, n: np.ndarray) -> str | None:
        key = p.tobytes() + n.tobytes()
        if key not in self.surface:
            d, normals = surface_distance(self.mesh, p)
            u = float(np.linalg.norm(n))
            msg = None
            if d > SURFACE_TOL:
                msg = f"the {f} contact is {d * 1000:.3g} mm off the object's surface"
            elif abs(u - 1) > 1e-3:
                msg = f"the {f} contact normal has norm {u:.4g}, not 1"
            elif np.arccos(np.clip((normals @ (n / u)).max(), -1, 1)) > NORMAL_TOL:
                msg = f"the {f} contact normal is off the surface normal"
            self.surface[key] = msg
        return self.surface[key]

    def phase_issues(self, phase: Phase) -> list[Issue]:
        """The kind, object and contact checks of the in-hand phase ``phase``."""
        out: list[Issue] = []
        if len(phase.touching) != 1 or phase.holding:
            return [Issue(phase.name, None, "kind", f"a {phase.kind.value} phase touches one hand and holds none "
                                                    f"(the fingers hold the object); found touching "
                                                    f"{list(phase.touching)}, holding {dict(phase.holding)}")]
        if phase.blends is not None and (cut := np.flatnonzero(phase.blends > 0)).size:
            out.append(Issue(phase.name, int(cut[0]), "kind", f"a blend of radius {phase.blends[cut[0]]:.3g}: an "
                                                              "in-hand phase stops at every waypoint (its motion is "
                                                              "checked on straight segments)"))
        hand = self.robot.hands[phase.touching[0]]
        names = self.fingers(phase.touching[0])
        q, X = phase.waypoints, phase.object_poses
        fixed = np.setdiff1d(np.arange(self.robot.nq), hand.idx)
        if np.abs(q[:, fixed] - q[0, fixed]).max(initial=0.0) > FINGER_TOL:
            out.append(Issue(phase.name, None, "kind", f"joints other than the hand's fingers move (the arm holds "
                                                       f"still in a {phase.kind.value} phase)"))
        for i in range(1, len(X)):
            dp = float(np.linalg.norm(X[i, :3, 3] - X[i - 1, :3, 3]))
            dr = float(Rotation.from_matrix(X[i - 1, :3, :3].T @ X[i, :3, :3]).magnitude())
            if dp > STEP_M or dr > STEP_RAD:
                out.append(Issue(phase.name, i, "continuity", f"the object jumps by {dp * 1000:.3g} mm, {dr:.3g} rad "
                                                              f"from waypoint {i - 1}"))
                break
        sets = [_contact_set(phase, i) for i in range(len(q))]
        out += self._kind_contacts(phase, sets, names, q, hand)
        out += self._contacts(phase, sets, names, q, X, hand)
        return out

    def _kind_contacts(self, phase: Phase, sets: list[dict], names: dict, q: np.ndarray, hand) -> list[Issue]:
        out = []
        everyone = set(names)
        if phase.kind is Kind.INHAND_TRANSFER:
            for i, c in enumerate(sets):
                if set(c) != everyone:
                    out.append(Issue(phase.name, i, "kind", f"in a transfer every finger touches; missing "
                                                            f"{', '.join(sorted(everyone - set(c)))}"))
                    return out
            return self.slips(phase, names, q, hand)
        if pose_differs(phase.object_poses[0], phase.object_poses[-1]) or any(
                pose_differs(phase.object_poses[0], x) for x in phase.object_poses):
            out.append(Issue(phase.name, None, "kind", "the object moves during a regrasp"))
        if set(sets[0]) != everyone or set(sets[-1]) != everyone:
            out.append(Issue(phase.name, 0, "kind", "a regrasp starts and ends with every finger touching"))
            return out
        lifted = {f for c in sets[1:-1] for f in everyone - set(c)}
        if len(lifted) != 1 or any(set(c) != everyone - lifted for c in sets[1:-1]):
            out.append(Issue(phase.name, None, "kind", "in a regrasp exactly one finger leaves the object between "
                                                       "the first and the last waypoints"))
            return out
        f = lifted.pop()
        stay = everyone - {f}
        for i, c in enumerate(sets[1:], 1):
            if any(not np.allclose(c[g][0], sets[0][g][0], atol=1e-9) for g in stay):
                out.append(Issue(phase.name, i, "kind", f"a finger other than {f} changes its contact in its regrasp"))
                break
        others = np.setdiff1d(hand.idx, hand.finger_idx[names[f]])
        if np.abs(q[:, others] - q[0, others]).max(initial=0.0) > FINGER_TOL:
            out.append(Issue(phase.name, None, "kind", f"fingers other than {f} move during its regrasp"))
        return out

    def slips(self, phase: Phase, names: dict, q: np.ndarray, hand) -> list[Issue]:
        """A transfer's fingertips roll without slipping: a sphere of radius r that turns by
        the rotation vector phi relative to the object moves its centre by r phi x n on
        it (n the contact's outward normal); summed over the phase, each fingertip's
        centre may stray from that by :data:`SLIP_TOL` (a contact held fixed while the
        finger turns slips r times the turn)."""
        X = phase.object_poses
        sets = [_contact_set(phase, i) for i in range(len(q))]
        for f, j in names.items():
            frame, r = hand.tip_frames[j], hand.spec.fingers[j].tip_radius
            tips = [self.kin.fk(qi, frame) for qi in q]
            c_O = np.array([Xi[:3, :3].T @ (T[:3, 3] - Xi[:3, 3]) for Xi, T in zip(X, tips)])
            R_O = np.array([Xi[:3, :3].T @ T[:3, :3] for Xi, T in zip(X, tips)])
            phi = Rotation.from_matrix(R_O[1:] @ R_O[:-1].transpose(0, 2, 1)).as_rotvec()
            n = np.array([sets[i][f][1] / np.linalg.norm(sets[i][f][1]) for i in range(len(q))])
            mid = n[1:] + n[:-1]
            mid /= np.maximum(np.linalg.norm(mid, axis=1, keepdims=True), 1e-12)
            slip = np.cumsum(np.linalg.norm(np.diff(c_O, axis=0) - r * np.cross(phi, mid), axis=1))
            if len(slip) and slip[-1] > SLIP_TOL:
                i = int(np.argmax(slip > SLIP_TOL)) + 1
                return [Issue(phase.name, i, "grasp", f"the {f} fingertip slips on the object "
                                                      f"({slip[i - 1] * 1000:.3g} mm by waypoint {i}): it must roll")]
        return []

    def _contacts(self, phase: Phase, sets: list[dict], names: dict, q: np.ndarray, X: np.ndarray,
                  hand) -> list[Issue]:
        out = []
        for i, c in enumerate(sets):
            for f, (p, n) in c.items():
                if f not in names:
                    return [Issue(phase.name, i, "grasp", f"contact of unknown finger {shown(f)}")]
                if msg := self.on_surface(f, p, n):
                    return [Issue(phase.name, i, "grasp", msg)]
                j = names[f]
                target = X[i, :3, :3] @ (p + hand.spec.fingers[j].tip_radius * n / np.linalg.norm(n)) + X[i, :3, 3]
                d = float(np.linalg.norm(self.kin.fk(q[i], hand.tip_frames[j])[:3, 3] - target))
                if d > TIP_TOL:
                    return [Issue(phase.name, i, "grasp", f"the {f} fingertip is {d * 1000:.3g} mm from its contact")]
            if not self.holds(c):
                return [Issue(phase.name, i, "grasp", f"the contacts of {', '.join(sorted(c))} are not force closure "
                                                      f"(friction {self.inputs.friction:g})")]
            for f in set(names) - set(c):  # a lifted finger touches nothing
                j = names[f]
                centre = self.kin.fk(q[i], hand.tip_frames[j])[:3, 3]
                c_O = (np.linalg.inv(X[i]) @ np.r_[centre, 1.0])[:3]
                clear = -float(trimesh.proximity.signed_distance(self.mesh, c_O[None])[0])
                if clear < hand.spec.fingers[j].tip_radius - LIFT_TOL:
                    return [Issue(phase.name, i, "grasp", f"the lifted {f} fingertip touches the object")]
        return out

    def tip_clearance(self, phase: Phase, j: int, qs: np.ndarray, Xs: np.ndarray) -> np.ndarray:
        """Distance (k,) from fingertip ``j``'s sphere of the touching hand to the object's
        surface at the configurations ``qs`` (k, nq), the object at ``Xs`` (k, 4, 4):
        negative inside (m)."""
        hand = self.robot.hands[phase.touching[0]]
        c_W = np.array([self.kin.fk(q, hand.tip_frames[j])[:3, 3] for q in qs])
        c_O = np.einsum("kji,kj->ki", Xs[:, :3, :3], c_W - Xs[:, :3, 3])
        return -trimesh.proximity.signed_distance(self.mesh, c_O) - hand.spec.fingers[j].tip_radius

    def lifted(self, phase: Phase) -> int | None:
        """The finger (index in its hand) that a regrasp phase lifts, or None."""
        if phase.kind is not Kind.INHAND_REGRASP or phase.contacts is None or len(phase.waypoints) < 3:
            return None
        names = self.fingers(phase.touching[0])
        away = set(names) - {c["finger"] for c in phase.contacts[1]}
        return names[away.pop()] if len(away) == 1 else None

    def collisions(self, phase: Phase, resolution: float) -> tuple[list[Issue], int]:
        q, X = phase.waypoints, phase.object_poses
        obj = ObjectPlacement(self.mesh, X[0], None, tuple(phase.touching))
        world = collision_world(self.robot, self.inputs.obstacles, self.inputs.disabled, obj, self.inputs.options)
        n = 0
        f = self.lifted(phase)
        if f is not None:  # where it lets go and where it touches again
            ends = self.tip_clearance(phase, f, q[[0, -1]], X[[0, -1]])
        for i in range(len(q)):
            steps = 1 if i == 0 else max(1, int(np.ceil(np.abs(q[i] - q[i - 1]).max() / resolution)))
            ts = np.arange(1, steps + 1) / steps
            Xs = segment_poses(X[max(i - 1, 0)], X[i], ts)
            if f is not None and i > 0 and (issue := self._lifted_clear(phase, f, ends, i, ts, Xs)):
                return [issue], n
            for s, X_s in zip(ts, Xs):
                qs = q[i] if i == 0 else q[i - 1] + s * (q[i] - q[i - 1])
                world.set_object_pose(X_s)
                n += 1
                if not world.is_free(qs):
                    pairs = ", ".join(f"{a}-{b}" for a, b in world.colliding_pairs(qs)[:3])
                    return [Issue(phase.name, i, "collision", f"collision ({pairs}) between waypoints {max(i - 1, 0)} "
                                                              f"and {i}")], n
        return [], n

    def _lifted_clear(self, phase: Phase, f: int, ends: np.ndarray, i: int, ts: np.ndarray,
                      Xs: np.ndarray) -> Issue | None:
        """The lifted fingertip ``f`` on the segment to waypoint ``i`` (samples ``ts``, object
        poses ``Xs``): the contact tolerance lets a touching fingertip into the object, a
        lifted one gets none.  Leaving its contact it goes no deeper than it was there
        (``ends[0]``), between, not in at all, arriving, no deeper than it will be
        (``ends[1]``); :data:`LIFT_TOL` for rounding."""
        q, last = phase.waypoints, len(phase.waypoints) - 1
        keep = ts < 1.0 if i == last else np.ones(len(ts), dtype=bool)  # the contact itself is a grasp
        if not keep.any():
            return None
        floor = min(0.0, ends[0] if i == 1 else 0.0, ends[1] if i == last else 0.0) - LIFT_TOL
        qs = q[i - 1] + ts[keep, None] * (q[i] - q[i - 1])
        depth = self.tip_clearance(phase, f, qs, Xs[keep])
        if depth.min() < floor:
            name = self.robot.hands[phase.touching[0]].spec.fingers[f].name
            return Issue(phase.name, i, "collision", f"the lifted {name} fingertip goes {-depth.min() * 1000:.3g} mm "
                                                     f"into the object between waypoints {i - 1} and {i}")
        return None
