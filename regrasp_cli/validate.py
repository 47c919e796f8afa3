"""Independent checker of a plan JSON (``regrasp.plan/2``, :mod:`regrasp_cli.trajectory`).

It trusts nothing the planner computed: it reloads the robot, object and obstacles the plan
names (refusing stale files by their SHA-256, :mod:`regrasp_cli.replay`) and re-checks the
motion from each phase's ``kind``, ``holding``, ``touching`` and ``placement``, never from
its name:

* **continuity**: each phase starts where the previous one ended;
* **timing**: times start at 0, never decrease, join up between phases.  A phase that
  stops at every waypoint gives every straight segment at least its minimal stop-to-stop
  duration (:mod:`motion.timing`).  A phase with blends and a speed grid
  (:mod:`motion.blend`) has a grid whose times follow from its speeds, speed 0 at its
  stops, waypoint times at their knots, and joint velocities and accelerations within the
  limits at every ``dt`` (and at every grid point);
* **limits**: joint position limits at the waypoints (segments are straight in joint
  space and blends stay in the convex hull of their control points, so the waypoints
  bound them);
* **attachment**: the object's world pose X_WO, followed through the phases, is where the
  holding hands' grasps say it is, the holding fingers stay closed, it never jumps between
  phases (a resting phase's placement is where the previous phase left the object), the
  per-waypoint ``object_poses`` (when given) agree, and it ends at the ``goal`` placement;
* **kind**: a grasp, release or hand-over moves only the fingers of its ``touching`` hands;
* **grasp**: contacts on the object surface, normals along the surface normal, force
  closure (Saut et al. 2010, §IV-A-3), fingertip spheres on their contacts when the hand
  takes the object;
* **collision**: every segment (and blend curve) sampled finely enough that no joint moves more than
  ``resolution`` and no robot point more than ``cartesian_step`` between samples (the
  bound of :mod:`motion.local`), against the robot itself, the obstacles and the object.
  Where every joint carried by the holding hand's grasp-frame joint (its fingers) keeps
  its value through a phase, the held object and the links of that hand keep their
  relative pose: those pairs are checked once, at the phase's first waypoint, not at every
  sample (they are the costliest: the object's mesh against fingertips in contact).

The in-hand kinds (``inhand-transfer``, ``inhand-regrasp``: fingers turning the object, seed
003) get their kind, object, contact and collision checks from
:mod:`regrasp_cli.validate_inhand`, whatever else the plan does: one validator for every task.

Malformed, incomplete or stale input raises :class:`~regrasp_cli.errors.InputError`;
everything else wrong with the plan is an :class:`Issue` of the returned report.
"""

from __future__ import annotations

from pathlib import Path
from time import perf_counter

import coal
import numpy as np
import pinocchio as pin

from regrasp_cli.checks import (CONE_EDGES, FINGER_TOL, NORMAL_TOL, SURFACE_TOL, TIP_TOL, Issue, PhaseSummary,
                                ValidationReport, continuity_issues, limit_issues, phase_timing_issues, pose_differs,
                                surface_distance)
from regrasp_cli.errors import shown
from regrasp_cli.grasp.quality import force_closure, primitive_wrenches
from regrasp_cli.manip.modes import Kind
from regrasp_cli.model.collision import CollisionWorld, ObjectPlacement, collision_world
from regrasp_cli.model.robot import Kinematics, Robot
from regrasp_cli.motion.local import held_reach, joint_reach
from regrasp_cli.motion.blend import bezier_points, bezier_steps
from regrasp_cli.parallel import ordered_map
from regrasp_cli.replay import JOINT_TOL, Carry, Inputs, follow, load_inputs
from regrasp_cli.spatial import inverse
from regrasp_cli.trajectory import Phase, Plan, PlanGrasp, read_plan
from regrasp_cli.validate_inhand import InHandChecks

MAX_COLLISIONS = 3  # per phase: then the phase's collision check stops


# ------------------------------------------------------------------ motion checks


def _finger_idx(robot: Robot, grasp: PlanGrasp) -> list[int] | None:
    idx = [robot.joint_names.index(n) for n in grasp.finger_joints if n in robot.joint_names]
    return idx if len(idx) == len(grasp.finger_joints) else None  # else reported by the grasp check


def attachment_issues(plan: Plan, phase: Phase, kin: Kinematics, carry: Carry) -> list[Issue]:
    """Whether the holding hands agree with their grasps (pose, closed fingers) where the
    object is (``carry``); the first holder carries it, so only the others are checked
    at every waypoint."""
    out, q, robot = [], phase.waypoints, kin.robot
    for hand, gid in phase.holding.items():
        grasp = plan.grasp(gid)
        for i in range(1 if hand == carry.hand else len(q)):
            X_WO_grasp = kin.fk(q[i], robot.hands[hand].grasp_frame) @ inverse(grasp.X_OG)
            off = pose_differs(X_WO_grasp, carry.X_WO(kin, q[i]))
            if off:
                out.append(Issue(phase.name, i, "attachment", f"the {hand} hand's grasp {gid} puts the object "
                                                              f"{off} away from where it is"))
                break
        idx = _finger_idx(robot, grasp)
        if idx is None:
            continue
        d = np.abs(q[:, idx] - grasp.finger_values)
        rows = np.flatnonzero(d.max(axis=1) > FINGER_TOL)
        if rows.size:
            j = int(np.argmax(d[rows[0]]))
            out.append(Issue(phase.name, int(rows[0]), "attachment",
                             f"the {hand} hand's {grasp.finger_joints[j]} is {d[rows[0], j]:.4g} off its grasp value "
                             f"(at {rows.size} waypoints)"))
    return out


def kind_issues(phase: Phase, robot: Robot) -> list[Issue]:
    """A grasp, release or hand-over moves only the fingers of the hands in ``touching``:
    an arm moving while fingers close on the object would push it."""
    if phase.kind not in (Kind.GRASP, Kind.RELEASE, Kind.HANDOVER):
        return []
    fingers = np.zeros(robot.nq, dtype=bool)
    for hand in phase.touching:
        fingers[robot.hands[hand].idx] = True
    d = np.abs(phase.waypoints - phase.waypoints[0])[:, ~fingers]
    if not d.size or d.max() <= JOINT_TOL:
        return []
    i, j = np.unravel_index(int(np.argmax(d)), d.shape)
    name = np.array(robot.joint_names)[~fingers][j]
    return [Issue(phase.name, int(i), "kind", f"{name} moves by {d[i, j]:.4g} in a {phase.kind.value} phase, "
                                              f"where only the fingers of the {' and '.join(phase.touching)} "
                                              "hand may move")]


def object_pose_issues(phase: Phase, previous: Phase | None, poses: tuple, previous_poses: tuple | None,
                       carry: Carry, kin: Kinematics) -> list[Issue]:
    """The object does not jump between phases (a resting phase's placement is where the
    previous phase left it), and the per-waypoint ``object_poses``, when given, are where
    the object is."""
    out = []
    if previous_poses is not None and (off := pose_differs(previous_poses[1], poses[0])):
        where = f"placement {shown(phase.placement)}" if phase.placement is not None else "its pose"
        since = "the start placement" if previous is None else f"the end of phase {previous.name}"
        out.append(Issue(phase.name, 0, "attachment", f"the object jumps by {off} between {since} and {where}"))
    if phase.object_poses is not None:
        for i, (q, X) in enumerate(zip(phase.waypoints, phase.object_poses)):
            if off := pose_differs(X, carry.X_WO(kin, q)):
                out.append(Issue(phase.name, i, "attachment", f"object_poses[{i}] is {off} away from where the "
                                                              "object is"))
                break
    return out


def segment_steps(dq: np.ndarray, reach: np.ndarray, resolution: float, cartesian_step: float) -> int:
    """Intervals cutting segment dq (nq,) so that no joint moves more than ``resolution``
    and no robot point more than ``cartesian_step`` (m; ``reach`` (nq,) m/rad) per interval."""
    d = np.abs(dq)
    return max(int(np.ceil(d.max() / resolution)), int(np.ceil(float(reach @ d) / cartesian_step)), 1)


def _where(i: int, s: float) -> tuple[int, str]:
    """(waypoint index, words) of the point at parameter s in (0, 1] of segment i -> i + 1."""
    if s == 1.0:
        return i + 1, f"at waypoint {i + 1}"
    return i, f"between waypoints {i} and {i + 1} (s = {s:.3f})"


def collision_issues(phase: Phase, world: CollisionWorld, reach: np.ndarray, resolution: float,
                     cartesian_step: float) -> tuple[list[Issue], int]:
    """The first waypoint, then the samples of each piece in order (its end included): the
    straight segments, or for a phase with blends its straight pieces and blend curves;
    the first colliding sample of a piece is reported with its colliding pairs, at most
    :data:`MAX_COLLISIONS` per phase.  Returns (issues, configurations checked)."""
    q, out = phase.waypoints, []
    if not world.is_free(q[0]):
        out.append(_collision(phase, world, q[0], 0, "at waypoint 0"))
    n_checked = 1
    for i, (A, C, B), curved in _pieces(phase):
        if len(out) >= MAX_COLLISIONS:
            break
        if curved:
            n = bezier_steps(A, C, B, reach, resolution, cartesian_step)
            samples = bezier_points(A, C, B, np.arange(1, n + 1) / n)
        else:
            n = segment_steps(B - A, reach, resolution, cartesian_step)
            samples = A + (np.arange(1, n + 1) / n)[:, None] * (B - A)
            samples[-1] = B
        for k, qs in enumerate(samples, 1):
            n_checked += 1
            if not world.is_free(qs):
                where = (i, f"on the blend at waypoint {i} (u = {k / n:.3f})") if curved else _where(i, k / n)
                out.append(_collision(phase, world, qs, *where))
                break  # one issue per piece
    return out, n_checked


def _pieces(phase: Phase):
    """(waypoint index, (A, C, B), curved) of each piece: the segments between waypoints,
    or the straight pieces and blends of a phase with blends (a straight piece's A and B
    are its ends); the segments too when the blends do not fit (a timing issue)."""
    try:
        path = phase.path()
    except ValueError:
        path = None
    if path is None:
        for i in range(len(phase.waypoints) - 1):
            a, b = phase.waypoints[i], phase.waypoints[i + 1]
            yield i, (a, 0.5 * (a + b), b), False
        return
    curved = np.abs(path.A - 2 * path.C + path.B).max(axis=1) > 0
    mid = 0.5 * (path.starts[:-1] + path.starts[1:])
    where = np.searchsorted(path.knots, mid, side="right") - 1
    for k in range(len(path.A)):
        i = int(where[k] + 1) if curved[k] else int(where[k])  # a blend is around the knot after mid
        yield min(i, len(phase.waypoints) - 1), (path.A[k], path.C[k], path.B[k]), bool(curved[k])


def _collision(phase: Phase, world: CollisionWorld, q: np.ndarray, waypoint: int, where: str) -> Issue:
    pairs = world.colliding_pairs(q)  # every pair, unlike the early-exit check
    names = ", ".join(f"{a} - {b}" for a, b in pairs[:4]) + (" ..." if len(pairs) > 4 else "")
    return Issue(phase.name, waypoint, "collision", f"{where}: {names or 'collision'}")


def phase_world(inputs: Inputs, phase: Phase, carry: Carry, pair_filter=None) -> CollisionWorld:
    """Robot, obstacles and the object, static or held, for ``phase`` (the pairs
    ``pair_filter(a, b)`` accepts, see :class:`CollisionWorld`)."""
    touching = tuple(dict.fromkeys((*phase.holding, *phase.touching)))
    obj = ObjectPlacement(inputs.mesh, carry.X_PO, carry.hand, touching)
    return collision_world(inputs.robot, inputs.obstacles, inputs.disabled, obj, inputs.options,
                           pair_filter=pair_filter)


def rigid_links(robot: Robot, phase: Phase, carry: Carry) -> frozenset[str]:
    """Links whose pose relative to the held object is the same at every point of the
    phase: those carried by the holding hand's grasp-frame joint, when every joint they
    hang from below it keeps its value at every waypoint (segments are straight, so it
    keeps it between them too); empty when the object is not held or a joint moves."""
    if carry.hand is None:
        return frozenset()
    model = robot.model
    j = model.frames[robot.hands[carry.hand].grasp_frame].parentJoint
    below = [model.names[k] for k in model.subtrees[j] if k != j]
    idx = [robot.joint_names.index(n) for n in below if n in robot.joint_names]
    q = phase.waypoints
    if idx and np.abs(q[:, idx] - q[0, idx]).max() > FINGER_TOL:
        return frozenset()
    return frozenset(f.name for f in model.frames if f.parentJoint in model.subtrees[j])


# ------------------------------------------------------------------ grasp checks


def contact_issues(plan: Plan, inputs: Inputs) -> list[Issue]:
    """Each grasp: contacts on the surface, normals along it, force closure."""
    mesh, robot, out = inputs.mesh, inputs.robot, []
    # a closed, consistently wound mesh defines outward; otherwise only the normal's line is known
    oriented = bool(mesh.is_watertight and mesh.is_winding_consistent)
    centre = np.asarray(mesh.center_mass if oriented else mesh.centroid, dtype=float)
    rho = float(np.linalg.norm(mesh.extents) / 2)  # as the grasp search
    for g in plan.grasps:
        c = inputs.contacts[g.id]
        hand = robot.hands[g.hand]
        name = f"grasp {g.id} ({g.hand} hand)"

        def issue(msg: str) -> None:
            out.append(Issue(None, None, "grasp", f"{name}: {msg}"))

        if sorted(g.finger_joints) != sorted(robot.joint_names[i] for i in hand.idx):
            issue(f"finger_joints {list(g.finger_joints)} are not the {g.hand} hand's finger joints")
        fingers = [f.name for f in hand.spec.fingers]
        for f in c.fingers:
            if f not in fingers:
                issue(f"contact of unknown finger {shown(f)} (the hand has {', '.join(fingers)})")
        if len(set(c.fingers)) != len(c.fingers):
            issue("two contacts of one finger")
        units = np.linalg.norm(c.normals, axis=1)
        for f, p, n, u in zip(c.fingers, c.points, c.normals, units):
            d, face_normals = surface_distance(mesh, p)
            if d > SURFACE_TOL:
                issue(f"{f} contact {d * 1000:.3g} mm off the object surface")
            if abs(u - 1) > 1e-3:
                issue(f"{f} contact normal has norm {u:.4g}, not 1")
            elif d <= SURFACE_TOL:
                cos = face_normals @ (n / u)
                angle = float(np.arccos(np.clip((cos if oriented else np.abs(cos)).max(), -1, 1)))
                if angle > NORMAL_TOL:
                    issue(f"{f} contact normal is {angle:.3g} rad off the surface normal")
        if np.all(units > 1e-12):
            W = primitive_wrenches(c.points, c.normals, inputs.friction, centre, rho,
                                   contact=hand.spec.contact, n_edges=CONE_EDGES)
            if not force_closure(W)[0]:
                issue(f"the {len(c.points)} contacts are not force closure (friction {inputs.friction:g}, "
                      f"{hand.spec.contact} contacts)")
    return out


def fingertip_issues(plan: Plan, inputs: Inputs, poses: list[tuple[np.ndarray, np.ndarray]]) -> list[Issue]:
    """Fingertip sphere centres at ``p + r_tip n`` (as the grasp search puts them) where the
    hand takes the object: the first waypoint of the first phase holding with the grasp.
    ``poses`` holds X_WO at the first and last waypoint of each phase."""
    robot, kin, out = inputs.robot, Kinematics(inputs.robot), []
    for g in plan.grasps:
        c, hand = inputs.contacts[g.id], robot.hands[g.hand]
        k = next((k for k, p in enumerate(plan.phases) if p.holding.get(g.hand) == g.id), None)
        if k is None:
            continue
        phase = plan.phases[k]
        q, X_WO = phase.waypoints[0], poses[k][0]
        fingers = {f.name: j for j, f in enumerate(hand.spec.fingers)}
        for f, p, n in zip(c.fingers, c.points, c.normals):
            if f not in fingers or not np.linalg.norm(n) > 1e-12:
                continue  # reported by contact_issues
            j = fingers[f]
            if hand.kind != "fingertips":  # a pad touches anywhere on the finger's surface
                d = _finger_distance(robot, hand, j, q, X_WO[:3, :3] @ p + X_WO[:3, 3])
                if d > TIP_TOL:
                    out.append(Issue(phase.name, 0, "grasp",
                                     f"grasp {g.id}: the {f} pad is {d * 1000:.3g} mm from its contact"))
                continue
            target_O = p + hand.spec.fingers[j].tip_radius * n / np.linalg.norm(n)
            p_W = X_WO[:3, :3] @ target_O + X_WO[:3, 3]
            d = float(np.linalg.norm(kin.fk(q, hand.tip_frames[j])[:3, 3] - p_W))
            if d > TIP_TOL:
                out.append(Issue(phase.name, 0, "grasp",
                                 f"grasp {g.id}: the {f} fingertip is {d * 1000:.3g} mm from its contact"))
    return out


def _finger_distance(robot: Robot, hand, finger: int, q: np.ndarray, p_W: np.ndarray) -> float:
    """Distance (m) from the point p_W (3,) to the surface of the collision geometries
    that move with the finger at q (its pads, a tip on a mimic joint of its own:
    :meth:`Robot.hand_joints`), by coal: 0 on the surface, the depth when inside."""
    joints = {j for j, f in robot.hand_joints(hand.spec.side).items() if f == finger}
    data = robot.model.createData()
    pin.forwardKinematics(robot.model, data, robot.to_pin(q))
    point, X_point = coal.Sphere(1e-9), coal.Transform3s(np.eye(3), p_W)
    best = np.inf
    for go in robot.collision_model.geometryObjects:
        if go.parentJoint in joints:
            X = data.oMi[go.parentJoint] * go.placement
            r = coal.DistanceResult()
            coal.distance(go.geometry, coal.Transform3s(X.rotation, X.translation), point, X_point,
                          coal.DistanceRequest(), r)
            best = min(best, abs(r.min_distance))
    return float(best)


# ------------------------------------------------------------------ the whole plan


def _phase_collisions(j: dict, k: int) -> tuple[list[Issue], int, float]:
    t0 = perf_counter()
    phase, carry, inputs = j["plan"].phases[k], j["carries"][k], j["inputs"]
    if phase.kind.inhand:
        found, n = InHandChecks(j["plan"], inputs).collisions(phase, j["resolution"])
        return found, n, perf_counter() - t0
    reach = j["reach"]
    if carry.hand is not None:  # the held object reaches farther than the robot
        reach = held_reach(inputs.robot, reach, carry.hand, np.asarray(inputs.mesh.vertices), carry.X_PO)
    rigid = rigid_links(inputs.robot, phase, carry)

    def moving(a: str, b: str) -> bool:  # not the object against a link rigid with it
        return not ("object" in (a, b) and (a in rigid or b in rigid))

    found, n = collision_issues(phase, phase_world(inputs, phase, carry, moving), reach, j["resolution"],
                                j["cartesian_step"])
    if rigid:
        once = phase_world(inputs, phase, carry, lambda a, b: not moving(a, b))
        if not once.is_free(phase.waypoints[0]):
            found.insert(0, _collision(phase, once, phase.waypoints[0], 0,
                                       "the held object against its hand (the same all phase)"))
    return found, n, perf_counter() - t0


def validate_plan(path: str | Path, resolution: float = 0.01, cartesian_step: float = 0.005,
                  jobs: int = 2, dt: float = 0.002) -> ValidationReport:
    """Check the plan file ``path`` (see the module docstring).

    Args:
        path: plan JSON; the files it names are relative to its directory unless absolute.
        resolution: largest joint step (rad or m) between two collision-checked samples.
        cartesian_step: largest displacement (m) of any robot point between two samples.
        jobs: processes for the collision checks of the phases (the report is the same).
        dt: time step (s) at which velocities and accelerations of smooth phases are checked.

    Raises:
        InputError: the plan is malformed or incomplete, a file it names is missing, or
            stale (:class:`~regrasp_cli.errors.StaleArtefactError`: its SHA-256 changed).
    """
    if not (resolution > 0 and cartesian_step > 0 and dt > 0):
        raise ValueError("resolution, cartesian_step and dt must be > 0")
    path = Path(path)
    plan = read_plan(path)
    if plan.status == "failed":
        f = plan.failure if isinstance(plan.failure, dict) else {}
        msg = f"the planner failed at stage {f.get('stage', '?')}: {f.get('reason', 'no reason given')}"
        return ValidationReport((Issue(None, None, "status", msg),), 0, {})

    inputs = load_inputs(plan, path)
    robot, reach, kin = inputs.robot, joint_reach(inputs.robot), Kinematics(inputs.robot)
    issues = [Issue(None, None, "input", note) for note in inputs.notes]
    carries, poses = follow(path, plan, kin)
    inhand = InHandChecks(plan, inputs)
    per_phase, dts = [], []
    for k, phase in enumerate(plan.phases):
        t0 = perf_counter()
        previous = plan.phases[k - 1] if k else None
        found = continuity_issues(phase, previous, robot.joint_names)
        found += phase_timing_issues(phase, previous, inputs.velocity, inputs.acceleration, dt, robot.joint_names)
        found += limit_issues(phase, robot.joint_names, inputs.lower, inputs.upper)
        if phase.kind.inhand:  # the fingers move the object (seed 003)
            found += inhand.phase_issues(phase)
        else:
            found += attachment_issues(plan, phase, kin, carries[k]) + kind_issues(phase, robot)
        before = poses[k - 1] if k else (None, plan.placement("start").X_WO)
        found += object_pose_issues(phase, previous, poses[k], before, carries[k], kin)
        per_phase.append(found)
        dts.append(perf_counter() - t0)
    job = {"plan": plan, "inputs": inputs, "carries": carries, "reach": reach, "resolution": resolution,
           "cartesian_step": cartesian_step}
    # longest phases first, so that two workers finish together; a phase outside the joint
    # limits is not sampled (its segments may be any length: 1e6 rad at 0.01 is 1e8 samples)
    inside = [k for k in range(len(plan.phases)) if not any(i.check == "limits" for i in per_phase[k])]
    order = sorted(inside, key=lambda k: -len(plan.phases[k].waypoints))
    results = dict(zip(order, ordered_map(_phase_collisions, order, jobs, job)))
    results.update({k: ([], 0, 0.0) for k in range(len(plan.phases)) if k not in results})
    summaries, seconds = [], {}
    for k, phase in enumerate(plan.phases):
        found, n, dt = results[k]
        issues += per_phase[k] + found
        seconds[phase.name] = seconds.get(phase.name, 0.0) + dts[k] + dt
        summaries.append(PhaseSummary(phase.name, phase.kind.value, len(phase.waypoints), n, dts[k] + dt))
    X_end = poses[-1][1] if poses else plan.placement("start").X_WO
    if off := pose_differs(X_end, plan.placement("goal").X_WO):
        where = (plan.phases[-1].name, len(plan.phases[-1].waypoints) - 1) if plan.phases else (None, None)
        issues.append(Issue(*where, "attachment", f"the object ends {off} away from its goal placement"))

    if not plan.phases:
        issues.append(Issue(None, None, "status", "a solved plan has at least one phase"))
    t0 = perf_counter()
    issues += contact_issues(plan, inputs) + fingertip_issues(plan, inputs, poses)
    seconds["grasps"] = perf_counter() - t0
    return ValidationReport(tuple(issues), sum(s.configurations for s in summaries), seconds, tuple(summaries))
