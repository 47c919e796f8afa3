"""A physics check of a solved plan (issue 43): what `regrasp simulate PLAN` runs.

Force closure with point or soft contacts (seed 000 §III, seed 003 §II) is a model; this
drives the plan in MuJoCo under gravity and says whether the fingers really keep the
object where the plan says it is.

The world (:func:`build_world`):

- the robot from its URDF through pinocchio: a body per joint at its placement, a hinge
  or slide along the joint's axis with the URDF's inertia, limits and a motor armature;
  its collision geometry (primitives as MuJoCo primitives, hulls as meshes, a link kept
  exact in robot.yaml's ``exact_meshes`` split by coacd); gravity compensated on the
  links (``gravcomp``), as a robot's controller does; a URDF mimic as an equality;
- the obstacles, static; the object a free body of coacd's convex parts with a uniform
  density, the plan's friction and a soft finger's torsional friction
  (:func:`.grasp.quality.default_torsion_mu`; MuJoCo's condim 4); a finger touches it
  with the torsional friction of its hand's fingertip patch (robot.yaml's ``tip_patch``,
  5 mm by default), or none where the tips are rigid (``tip_patch: 0``, condim 3: a
  fingertip that spins on the object as it rolls in an in-hand transfer does not drag it);
- links do not collide with each other (the plan is checked for that by the validator),
  they do with the obstacles and the object.

The controller (:func:`run`): every joint tracks the exported trajectory
(:func:`regrasp_cli.export.sample_plan`, at the simulation's rate) with a position
actuator given the velocity reference (ctrl = q + kv/kp qd) and the acceleration fed
forward (M qdd).  A finger's actuator is force-limited, and the fingers that hold or
close on the object squeeze it: each contact of the grasp pushes with ``squeeze_n``
newtons along the inward normal, applied as the joint torques tau = J^T f of the plan's
configuration (bounded whatever the object does).  The fingers are never written.

The measure: per sample, the object's pose against the plan's (:attr:`Samples.X_WO`),
the distance of the origins (m) and the rotation angle between them (rad); per phase the
largest and the last, and whether the object was dropped (a phase that holds it rigidly
ends with no robot geometry touching it; in-hand phases hold it with their fingers'
contacts and are judged by their drift alone).  A phase passes when its largest drift is
within the tolerances; a simulation that diverged (MuJoCo's warnings) passes nothing.

Units: s, m, rad, kg, N.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pinocchio as pin
from scipy.spatial.transform import Rotation

from regrasp_cli.errors import InputError
from regrasp_cli.export import Samples, sample_plan
from regrasp_cli.grasp.quality import default_torsion_mu
from regrasp_cli.replay import Inputs
from regrasp_cli.store import (Provenance, artefact_lock, is_fresh, read_artefact, sha256_bytes, sha256_params,
                               write_artefact)
from regrasp_cli.trajectory import Plan


@dataclass(frozen=True)
class SimOptions:
    """How the plan is simulated and judged (the defaults in one place)."""

    timestep: float = 0.002  # s
    squeeze_n: float = 20.0  # N per contact of a holding hand, along the inward normal
    density: float = 500.0  # kg/m^3 of the object (wood)
    position_tol: float = 0.01  # m: a phase passes when the object stays this close to the plan ...
    angle_tol: float = 0.1  # rad: ... and turns no more than this from it
    settle: float = 0.3  # s the robot holds its start before the plan runs (the object settles)
    arm_kp: float = 2000.0  # N m/rad (N/m) of the arm joints' position actuators
    arm_kv: float = 100.0  # N m s/rad
    arm_armature: float = 0.1  # kg m^2 reflected motor inertia per arm joint
    finger_kp: float = 20.0
    finger_kv: float = 0.5
    finger_armature: float = 0.005
    finger_force: float = 5.0  # N m (N): the finger actuators' bound, squeeze excluded
    squeeze_ramp: float = 0.1  # s: a closing hand's squeeze ramps up over its closing's last this,
    # an opening hand's down over its first
    coacd_threshold: float = 0.02  # coacd's concavity threshold for the object's parts


@dataclass(frozen=True)
class PhaseDrift:
    """How far the object was from the plan during one phase."""

    name: str
    kind: str
    t0: float
    t1: float
    max_position: float  # m
    max_angle: float  # rad
    end_position: float
    end_angle: float
    dropped: bool  # the phase holds the object and ends with no link touching it
    ok: bool


@dataclass(frozen=True)
class SimReport:
    """The outcome of :func:`run`: per phase drifts, and whether every phase passed."""

    plan: str
    options: SimOptions
    object_mass: float  # kg
    object_parts: int  # convex parts of the object
    tracking_error: float  # rad or m, the largest joint error at the plan's end
    wall_s: float
    phases: tuple[PhaseDrift, ...] = field(default_factory=tuple)
    diverged: bool = False  # MuJoCo's state went bad and was reset: the drifts say nothing of the plan

    @property
    def ok(self) -> bool:
        return not self.diverged and all(p.ok for p in self.phases)

    @property
    def first_failure(self) -> PhaseDrift | None:
        return next((p for p in self.phases if not p.ok), None)


def import_mujoco():
    """The ``mujoco`` and ``coacd`` modules, or an :class:`InputError` saying how to get them."""
    try:
        return importlib.import_module("mujoco"), importlib.import_module("coacd")
    except ImportError as exc:
        raise InputError(None, "simulate", f"needs MuJoCo and coacd ({exc.name} is not installed): "
                                           "pip install 'regrasp[sim]'") from None


def _quat(mujoco, R: np.ndarray) -> np.ndarray:
    q = np.zeros(4)
    mujoco.mju_mat2Quat(q, np.asarray(R, float).reshape(9))
    return q


PARTS_FORMAT = "regrasp.convex_parts"
PARTS_VERSION = 1


def convex_parts(coacd, vertices: np.ndarray, faces: np.ndarray, threshold: float,
                 cache_dir: Path | None = None) -> list[np.ndarray]:
    """coacd's convex decomposition of a mesh (vertices (n, 3) m, faces (f, 3)): each
    part's vertices (k, 3).  Seconds for a scanned object, so kept under
    ``cache_dir/objects/`` by the mesh's bytes and coacd's parameters."""
    v, f = np.ascontiguousarray(vertices, float), np.ascontiguousarray(faces, np.int64)
    params = {"threshold": threshold, "max_convex_hull": 64, "seed": 0, "coacd": _version("coacd")}
    expected = Provenance(PARTS_FORMAT, PARTS_VERSION, {"mesh": sha256_bytes(v.tobytes() + f.tobytes()),
                                                        "params": sha256_params(params)})
    path = None if cache_dir is None else (Path(cache_dir) / "objects" /
                                           f"coacd-{sha256_params(dict(expected.inputs))[:16]}.h5")
    if path is None:
        return _decompose(coacd, v, f, params)
    with artefact_lock(path):
        if path.is_file() and is_fresh(path, expected):
            a = read_artefact(path, expected)
            return np.split(a["vertices"], np.cumsum(a["counts"])[:-1])
        parts = _decompose(coacd, v, f, params)
        write_artefact(path, expected, {"vertices": np.concatenate(parts),
                                        "counts": np.array([len(p) for p in parts], dtype=np.int64)})
        return parts


def _version(dist: str) -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version(dist)
    except PackageNotFoundError:
        return ""


def _decompose(coacd, v: np.ndarray, f: np.ndarray, params: dict) -> list[np.ndarray]:
    coacd.set_log_level("error")
    parts = coacd.run_coacd(coacd.Mesh(v, f), threshold=params["threshold"], max_convex_hull=params["max_convex_hull"],
                            seed=params["seed"])
    return [np.asarray(p, float) for p, _ in parts]


def _add_robot_geom(mujoco, coacd, spec, body, go, exact: bool, threshold: float, name: str,
                    cache_dir: Path | None, contact: dict) -> None:
    """The robot geometry ``go`` (a pinocchio GeometryObject) on ``body``: contype 1
    (links), colliding with obstacles and the object (2), not with links; ``contact``:
    MuJoCo geom attributes of its contacts (empty: the object's)."""
    import coal

    g = go.geometry
    X = go.placement
    kw = dict(pos=X.translation, quat=_quat(mujoco, X.rotation), contype=1, conaffinity=2, density=0.0,
              group=1) | contact
    G = mujoco.mjtGeom
    if isinstance(g, coal.Box):
        body.add_geom(type=G.mjGEOM_BOX, size=np.asarray(g.halfSide), **kw)
    elif isinstance(g, coal.Sphere):
        body.add_geom(type=G.mjGEOM_SPHERE, size=[g.radius, 0, 0], **kw)
    elif isinstance(g, coal.Cylinder):
        body.add_geom(type=G.mjGEOM_CYLINDER, size=[g.radius, g.halfLength, 0], **kw)
    elif isinstance(g, coal.Capsule):
        body.add_geom(type=G.mjGEOM_CAPSULE, size=[g.radius, g.halfLength, 0], **kw)
    elif isinstance(g, (coal.ConvexBase, coal.BVHModelBase)):
        if isinstance(g, coal.ConvexBase):
            parts = [np.asarray(g.points(), float)]
        else:
            v = np.asarray(g.vertices(), float)
            faces = np.array([[t[0], t[1], t[2]] for t in (g.tri_indices(i) for i in range(g.num_tris))])
            parts = convex_parts(coacd, v, faces, threshold, cache_dir) if exact else [v]
        for k, v in enumerate(parts):
            spec.add_mesh(name=f"{name}_{k}", uservert=v.reshape(-1))
            body.add_geom(type=G.mjGEOM_MESH, meshname=f"{name}_{k}", **kw)
    else:
        raise InputError(None, "robot collision geometry", f"cannot simulate a {type(g).__name__} ({go.name})")


SOLREF = [0.005, 1.0]  # MuJoCo's time constant (s) and damping ratio of the object's contacts: stiff (default 0.02)


@dataclass(frozen=True)
class World:
    """A compiled MuJoCo world for one plan, and where our joints are in it."""

    model: object  # mujoco.MjModel
    qpos: np.ndarray  # (nq,) qpos address of each of the plan's joints
    dof: np.ndarray  # (nq,) qvel address of each
    actuated: np.ndarray  # (na,) indices into the plan's joints of the actuated ones (mimic followers are not)
    object_body: int
    object_parts: int
    robot_geoms: np.ndarray  # geom ids of the links


def build_world(inputs: Inputs, X_WO0: np.ndarray, opts: SimOptions, cache_dir: Path | None = None) -> World:
    """The robot, the obstacles and the object (a free body at ``X_WO0`` (4, 4)) as a
    compiled MuJoCo model (module docstring)."""
    mujoco, coacd = import_mujoco()
    from regrasp_cli.model.objects import load_object_mesh

    robot = inputs.robot
    model = robot.model
    spec = mujoco.MjSpec()
    spec.compiler.degree = False
    spec.option.timestep = opts.timestep
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    spec.option.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
    spec.option.impratio = 10.0
    spec.option.noslip_iterations = 5  # no creep: static friction holds (MuJoCo's soft contacts otherwise slide slowly)
    fingers = {int(i) for hand in robot.hands.values() for i in hand.idx}
    q0 = robot.to_pin(robot.q_rest)
    bodies = {0: spec.worldbody}
    for j in range(1, model.njoints):
        jm, i = model.joints[j], j - 1  # pinocchio joint j is our joint j - 1 (Robot checks one dof each)
        X = model.jointPlacements[j]
        b = bodies[model.parents[j]].add_body(name=model.names[j], pos=X.translation, quat=_quat(mujoco, X.rotation))
        inertia = model.inertias[j]
        b.mass = max(inertia.mass, 1e-4)
        b.ipos = inertia.lever
        I = inertia.inertia
        b.fullinertia = [max(I[0, 0], 1e-7), max(I[1, 1], 1e-7), max(I[2, 2], 1e-7), I[0, 1], I[0, 2], I[1, 2]]
        b.gravcomp = 1.0
        jd = jm.createData()
        jm.calc(jd, q0[jm.idx_q:jm.idx_q + jm.nq])
        S = np.asarray(jd.S).reshape(6)
        kind = mujoco.mjtJoint.mjJNT_SLIDE if robot.prismatic[i] else mujoco.mjtJoint.mjJNT_HINGE
        jt = b.add_joint(name=model.names[j], type=kind, axis=S[:3] if robot.prismatic[i] else S[3:])
        if np.isfinite(robot.lower[i]) and jm.nq == 1:
            jt.range = [robot.lower[i], robot.upper[i]]
            jt.limited = mujoco.mjtLimited.mjLIMITED_TRUE
        jt.armature = opts.finger_armature if i in fingers else opts.arm_armature
        bodies[j] = b
    exact = set(robot.spec.exact_meshes)
    mu = inputs.friction
    # a finger's contacts take its hand's tips (priority over the object's), the object's stiffness
    tips = {int(i): dict(priority=2, condim=4 if h.spec.tip_patch > 0 else 3, solref=SOLREF,
                         friction=[mu, default_torsion_mu(mu, h.spec.tip_patch), 0.0])
            for h in robot.hands.values() for i in h.idx}
    for k, go in enumerate(robot.collision_model.geometryObjects):
        _add_robot_geom(mujoco, coacd, spec, bodies[go.parentJoint], go,
                        model.frames[go.parentFrame].name in exact, opts.coacd_threshold, f"link{k}", cache_dir,
                        tips.get(go.parentJoint - 1, {}))
    for f, (lead, m, o) in robot.mimic.items():
        spec.add_equality(type=mujoco.mjtEq.mjEQ_JOINT, name1=robot.joint_names[f], name2=robot.joint_names[lead],
                          data=[o, m, 0, 0, 0] + [0] * 7)
    G = mujoco.mjtGeom
    for n, ob in enumerate(inputs.obstacles):
        kw = dict(pos=ob.X_WO[:3, 3], quat=_quat(mujoco, ob.X_WO[:3, :3]), contype=2, conaffinity=1)
        if ob.shape == "box":
            spec.worldbody.add_geom(type=G.mjGEOM_BOX, size=np.asarray(ob.size) / 2, **kw)
        elif ob.shape == "cylinder":
            spec.worldbody.add_geom(type=G.mjGEOM_CYLINDER, size=[ob.size[0], ob.size[1] / 2, 0], **kw)
        elif ob.shape == "sphere":
            spec.worldbody.add_geom(type=G.mjGEOM_SPHERE, size=[ob.size[0], 0, 0], **kw)
        else:
            mesh = load_object_mesh(str(ob.mesh), base_dir=ob.mesh.parent, scale=ob.size[0],
                                    file=None, field=f"obstacles[{n}].mesh").mesh
            for k, v in enumerate(convex_parts(coacd, mesh.vertices, mesh.faces, opts.coacd_threshold, cache_dir)):
                spec.add_mesh(name=f"obstacle{n}_{k}", uservert=v.reshape(-1))
                spec.worldbody.add_geom(type=G.mjGEOM_MESH, meshname=f"obstacle{n}_{k}", **kw)
    parts = convex_parts(coacd, inputs.mesh.vertices, inputs.mesh.faces, opts.coacd_threshold, cache_dir)
    body = spec.worldbody.add_body(name="object", pos=X_WO0[:3, 3], quat=_quat(mujoco, X_WO0[:3, :3]))
    body.add_freejoint(name="object")
    for k, v in enumerate(parts):
        spec.add_mesh(name=f"object_{k}", uservert=v.reshape(-1))
        # priority 1: the object's friction is the contact's (MuJoCo takes the larger of
        # two equal-priority geoms', and the links' default 1.0 would hide the plan's)
        body.add_geom(type=G.mjGEOM_MESH, meshname=f"object_{k}", contype=2, conaffinity=3, condim=4,
                      friction=[mu, default_torsion_mu(mu), 0.0], density=opts.density, priority=1, solref=SOLREF)
    actuated = np.array([i for i in range(len(robot.joint_names)) if i not in robot.mimic], dtype=int)
    for i in actuated:
        a = spec.add_actuator(name=robot.joint_names[i], target=robot.joint_names[i], trntype=mujoco.mjtTrn.mjTRN_JOINT)
        if i in fingers:
            a.set_to_position(kp=opts.finger_kp, kv=opts.finger_kv)
            a.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE
            a.forcerange = [-opts.finger_force, opts.finger_force]
        else:
            a.set_to_position(kp=opts.arm_kp, kv=opts.arm_kv)
    try:
        m = spec.compile()
    except ValueError as exc:
        raise InputError(None, "simulate", f"MuJoCo cannot compile the world: {str(exc).splitlines()[0]}") from None
    qpos = np.array([m.joint(n).qposadr[0] for n in robot.joint_names], dtype=int)
    dof = np.array([m.joint(n).dofadr[0] for n in robot.joint_names], dtype=int)
    obj = m.body("object").id
    robot_geoms = np.flatnonzero(m.geom_contype == 1)
    return World(m, qpos, dof, actuated, obj, len(parts), robot_geoms)


CONE_EDGES = 8  # tangent directions of the linearised friction cones of :func:`internal_forces`
NORMAL_RATIO = 4.0  # the squeeze's largest normal part at most this times its smallest
SHARE_STEPS = 8  # bisection steps of the squeeze's share of the friction
SHARE_MAX = 8.0  # ... searched up to this many times the friction (a grasp that needs more than mu slips)


def internal_forces(points: np.ndarray, normals: np.ndarray, mu: float, force: float) -> np.ndarray:
    """The squeeze of a grasp: contact forces (k, 3) on the object that sum to no force
    and no torque, with the most friction to spare (the smallest share of mu any contact
    uses, bisected over LPs on ``CONE_EDGES`` tangent directions per contact; grasp force
    optimisation), normal parts between 1 and ``NORMAL_RATIO`` times the smallest, scaled
    so that they average ``force`` N: the fingers together press with k ``force`` N and
    the squeeze alone does not push the object away.

    ``points`` (k, 3) m and outward ``normals`` (k, 3) in one frame.  A grasp whose
    squeeze needs more than mu gets the one that needs the least (it will slip); without
    any (one contact, or two not opposite), each contact pushes ``force`` along its
    normal."""
    P = np.asarray(points, float).reshape(-1, 3)
    N = np.asarray(normals, float).reshape(-1, 3)
    N = N / np.maximum(np.linalg.norm(N, axis=1, keepdims=True), 1e-12)
    plain = -force * N
    if len(P) < 2:
        return plain
    lo, hi = 0.0, mu
    best = _squeeze_within(P, N, hi)
    while best is None and hi < SHARE_MAX * mu:  # more friction than there is: the contacts will slip
        lo, hi = hi, 2 * hi
        best = _squeeze_within(P, N, hi)
    if best is None:
        return plain
    for _ in range(SHARE_STEPS):
        mid = (lo + hi) / 2
        F = _squeeze_within(P, N, mid)
        lo, hi, best = (lo, mid, F) if F is not None else (mid, hi, best)
    lam = -(best * N).sum(axis=1)
    return best * (force / lam.mean())


def _squeeze_within(P: np.ndarray, N: np.ndarray, mu: float) -> np.ndarray | None:
    """Internal contact forces (k, 3), normal parts in [1, NORMAL_RATIO], tangential parts
    within mu (the least in total), or None when there are none (an LP)."""
    from scipy.optimize import linprog

    k, E = len(P), CONE_EDGES
    ang = 2 * np.pi * np.arange(E) / E
    U = np.zeros((k, E, 3))  # unit tangent directions
    for i, n in enumerate(N):
        a = np.cross(n, [1.0, 0.0, 0.0] if abs(n[0]) < 0.9 else [0.0, 1.0, 0.0])
        a /= np.linalg.norm(a)
        U[i] = np.cos(ang)[:, None] * a + np.sin(ang)[:, None] * np.cross(n, a)
    r = P - P.mean(axis=0)
    # variables: lambda (k normal parts), then beta (k E tangential weights)
    cols = np.concatenate([-N, U.reshape(k * E, 3)])  # (k + kE, 3) force per unit variable
    at = np.concatenate([r, np.repeat(r, E, axis=0)])
    A_eq = np.concatenate([cols.T, np.cross(at, cols).T])  # (6, k + kE)
    A_ub = np.zeros((k, k + k * E))  # sum_j beta_ij <= mu lambda_i
    for i in range(k):
        A_ub[i, i] = -mu
        A_ub[i, k + i * E:k + (i + 1) * E] = 1.0
    cost = np.concatenate([np.zeros(k), np.ones(k * E)])
    bounds = [(1.0, NORMAL_RATIO)] * k + [(0.0, None)] * (k * E)
    res = linprog(cost, A_ub=A_ub, b_ub=np.zeros(k), A_eq=A_eq, b_eq=np.zeros(6), bounds=bounds, method="highs")
    if res.status != 0:
        return None
    lam, beta = res.x[:k], res.x[k:].reshape(k, E)
    return -lam[:, None] * N + np.einsum("ke,kex->kx", beta, U)


def _ramp(t: np.ndarray, t0: float, t1: float) -> np.ndarray:
    return np.clip((t - t0) / max(t1 - t0, 1e-9), 0.0, 1.0)


def contact_pushes(plan: Plan, inputs: Inputs, samples: Samples, force: float,
                   ramp: float) -> list[list[tuple[str, str, np.ndarray, float, np.ndarray]]]:
    """Per sample, the contacts that squeeze: (hand, finger, force on the object in O (3,)
    N, weight in [0, 1], the contact point in O (3,) m), the forces :func:`internal_forces` of the contacts held.  A
    holding hand's grasp at full weight; a hand closing on the object (touching now,
    holding next) ramped up over the last ``ramp`` s of its closing (a squeeze that starts
    earlier drives the fingers still in flight ahead of the plan: they arrive one by one and
    push the object along its support), one opening off it ramped down over the first; in-hand, along
    a segment the blend (1 - s) F_a + s F_b of the internal forces of the contacts at its
    two ends (each balanced, so is the sum), s linear in time, but over the segment's first
    ``ramp`` s where a finger leaves and its last where one arrives: the others take the
    leaving finger's load before it lifts (a finger fading out over the whole segment
    left the others pressing for four, and the ball turned 0.22 rad)."""
    robot = inputs.robot
    mu = inputs.friction
    out: list[list[tuple[str, str, np.ndarray, float, np.ndarray]]] = [[] for _ in samples.t]
    squeezes: dict[str, list[tuple[str, str, np.ndarray, np.ndarray]]] = {}
    stances: dict[tuple, dict] = {}  # an in-hand contact set's internal forces

    def squeeze_of(contacts, hand_of: dict) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """finger -> (its force (3,), its point (3,)): the internal forces of these contacts."""
        mine = [c for c in contacts if c["finger"] in hand_of]
        key = tuple((c["finger"], np.asarray(c["point"], float).tobytes()) for c in mine)
        if key not in stances:
            P = np.array([c["point"] for c in mine], float).reshape(-1, 3)
            F = internal_forces(P, np.array([c["normal"] for c in mine], float).reshape(-1, 3), mu, force)
            stances[key] = {c["finger"]: (F_i, p_i) for c, F_i, p_i in zip(mine, F, P)}
        return stances[key]

    def grasp_pushes(hand: str, gid: str, w: float) -> list[tuple[str, str, np.ndarray, float, np.ndarray]]:
        if gid not in squeezes:
            c = inputs.contacts[gid]
            F = internal_forces(c.points, c.normals, mu, force)
            squeezes[gid] = [(hand, f, F_i, p_i) for f, F_i, p_i in zip(c.fingers, F, c.points)]
        return [(h, f, F_i, w, p_i) for h, f, F_i, p_i in squeezes[gid]]

    for k, p in enumerate(plan.phases):
        at = np.flatnonzero(samples.phase == k)
        if not len(at):
            continue
        t = samples.t[at]
        before = plan.phases[k - 1].holding if k else {}
        after = plan.phases[k + 1].holding if k + 1 < len(plan.phases) else {}
        for hand, gid in p.holding.items():
            for i in at:
                out[i] += grasp_pushes(hand, gid, 1.0)
        if p.contacts is not None:
            hand_of = {f.name: h for h in p.touching for f in robot.hands[h].spec.fingers}
            seg = np.clip(np.searchsorted(p.times, t, side="right") - 1, 0, len(p.times) - 2)
            for i, j, tt in zip(at, seg, t):
                ends = [squeeze_of(p.contacts[j], hand_of), squeeze_of(p.contacts[j + 1], hand_of)]
                t0, t1 = p.times[j], p.times[j + 1]
                r = min(ramp, t1 - t0)
                # a finger lets go once the others have taken its load, and takes it back once it touches
                t0, t1 = (t0, t0 + r) if len(ends[1]) < len(ends[0]) else (t1 - r, t1) if len(ends[1]) > len(
                    ends[0]) else (t0, t1)
                s = float(_ramp(np.array(tt), t0, t1))
                for f in sorted(ends[0].keys() | ends[1].keys()):  # (1 - s) F_j + s F_j+1: each balanced
                    F = sum(w * e[f][0] for w, e in ((1.0 - s, ends[0]), (s, ends[1])) if f in e)
                    point = (ends[0].get(f) or ends[1][f])[1]
                    out[i].append((hand_of[f], f, F, 1.0, point))
            continue
        for hand in p.touching:
            if hand in p.holding:
                continue
            if hand in after:
                w, gid = _ramp(t, p.times[-1] - min(ramp, p.times[-1] - p.times[0]), p.times[-1]), after[hand]
            elif hand in before:
                w, gid = 1.0 - _ramp(t, p.times[0], p.times[0] + min(ramp, p.times[-1] - p.times[0])), before[hand]
            else:
                continue
            for i, wi in zip(at, w):
                out[i] += grasp_pushes(hand, gid, float(wi))
    return out


def point_jacobian(model, data, frame: int, p_W: np.ndarray) -> np.ndarray:
    """(3, nv) Jacobian of the point at ``p_W`` (3,) m of frame ``frame``'s link (its
    velocity in W: v + w x r, r from the frame's origin), from ``data`` after
    ``computeJointJacobians`` and ``updateFramePlacements``."""
    J = pin.getFrameJacobian(model, data, frame, pin.LOCAL_WORLD_ALIGNED)
    r = np.asarray(p_W, float) - data.oMf[frame].translation
    return J[:3] - pin.skew(r) @ J[3:]


def squeeze_torques(plan: Plan, inputs: Inputs, samples: Samples, force: float, ramp: float) -> np.ndarray:
    """(m, nq) joint torques (N m or N) per sample: each squeezing contact (:func:`contact_pushes`)
    pushes with its force (``force`` N on average) times its weight, turned into W by the
    plan's object pose, at its contact point, through its finger's joints only:
    tau = J_c^T f at the plan's configuration, J_c the Jacobian of the point of the
    finger's last link at the contact (a pad's contact is not its frame's origin)."""
    robot = inputs.robot
    model = robot.model
    data = model.createData()
    v_of = np.array([model.joints[j].idx_v for j in range(1, model.njoints)], dtype=int)
    pushes = contact_pushes(plan, inputs, samples, force, ramp)
    finger_of = {(hand, x.name): f for hand, h in robot.hands.items() for f, x in enumerate(h.spec.fingers)}
    tau = np.zeros((len(samples.t), len(robot.joint_names)))
    for i, push in enumerate(pushes):
        if not push:
            continue
        qp = robot.to_pin(samples.q[i])
        pin.computeJointJacobians(model, data, qp)
        pin.updateFramePlacements(model, data)
        X_WO = samples.X_WO[i]
        for hand, finger, F_O, w, p_O in push:
            h, f = robot.hands[hand], finger_of[hand, finger]
            J_c = point_jacobian(model, data, h.tip_frames[f], X_WO[:3, :3] @ p_O + X_WO[:3, 3])
            idx = h.finger_idx[f]
            tau[i, idx] += J_c[:, v_of[idx]].T @ (w * X_WO[:3, :3] @ F_O)
    return tau


def run(plan: Plan, file: Path, inputs: Inputs, opts: SimOptions = SimOptions(),
        cache_dir: Path | None = None) -> SimReport:
    """Simulate the solved plan ``plan`` (read from ``file``, its inputs loaded) and
    measure the object's drift from it, phase by phase (module docstring)."""
    import time

    mujoco, _ = import_mujoco()
    wall = time.perf_counter()
    try:
        samples = sample_plan(plan, file, inputs, 1.0 / opts.timestep)
    except ValueError as exc:  # more samples than memory holds
        raise InputError(file, "phases", f"too long to simulate at {1 / opts.timestep:g} Hz: {exc}") from None
    world = build_world(inputs, samples.X_WO[0], opts, cache_dir)
    m = world.model
    d = mujoco.MjData(m)
    tau = squeeze_torques(plan, inputs, samples, opts.squeeze_n, opts.squeeze_ramp)
    fingers = np.zeros(len(inputs.robot.joint_names), dtype=bool)
    for hand in inputs.robot.hands.values():
        fingers[hand.idx] = True
    kv_kp = np.where(fingers, opts.finger_kv / opts.finger_kp, opts.arm_kv / opts.arm_kp)[world.actuated]
    act = world.actuated
    d.qpos[world.qpos] = samples.q[0]
    mujoco.mj_forward(m, d)
    accel = np.zeros(m.nv)
    Ma = np.zeros(m.nv)

    def step(i: int) -> None:
        d.ctrl[:] = samples.q[i, act] + kv_kp * samples.qd[i, act]
        accel[world.dof] = samples.qdd[i]
        mujoco.mj_mulM(m, d, Ma, accel)
        d.qfrc_applied[world.dof] = Ma[world.dof] + tau[i]
        mujoco.mj_step(m, d)

    for _ in range(int(round(opts.settle / opts.timestep))):
        step(0)
    p_WO = np.zeros((len(samples.t), 3))
    R_WO = np.zeros((len(samples.t), 3, 3))
    touching = np.zeros(len(samples.t), dtype=bool)
    obj, links = world.object_body, set(world.robot_geoms.tolist())
    for i in range(len(samples.t)):
        step(i)
        p_WO[i], R_WO[i] = d.xpos[obj], d.xmat[obj].reshape(3, 3)
        ends = i + 1 == len(samples.t) or samples.phase[i + 1] != samples.phase[i]
        if ends:
            touching[i] = any(
                (m.geom_bodyid[c.geom1] == obj and c.geom2 in links) or (m.geom_bodyid[c.geom2] == obj and c.geom1 in links)
                for c in d.contact[:d.ncon])
    pos = np.linalg.norm(p_WO - samples.X_WO[:, :3, 3], axis=1)
    ang = Rotation.from_matrix(np.einsum("mji,mjk->mik", samples.X_WO[:, :3, :3], R_WO)).magnitude()
    phases = []
    for k, p in enumerate(plan.phases):
        at = np.flatnonzero(samples.phase == k)
        if not len(at):  # shorter than a step: judged at the sample where it ends
            at = np.array([min(int(np.searchsorted(samples.t, p.times[-1])), len(samples.t) - 1)])
        dropped = bool(p.holding) and not touching[at[-1]]
        mp, ma = float(pos[at].max()), float(ang[at].max())
        phases.append(PhaseDrift(p.name, p.kind.value, float(p.times[0]), float(p.times[-1]), mp, ma,
                                 float(pos[at[-1]]), float(ang[at[-1]]), dropped,
                                 not dropped and mp <= opts.position_tol and ma <= opts.angle_tol))
    track = float(np.abs(d.qpos[world.qpos] - samples.q[-1]).max())
    W = mujoco.mjtWarning
    diverged = any(d.warning[w].number for w in (W.mjWARN_BADQACC, W.mjWARN_BADQPOS, W.mjWARN_BADQVEL))
    return SimReport(str(file), opts, float(m.body_mass[obj]), world.object_parts, track,
                     time.perf_counter() - wall, tuple(phases), diverged)
