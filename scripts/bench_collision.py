#!/usr/bin/env python
"""Benchmark full-robot collision checks per second, back-end against back-end.

Usage (from the repository root)::

    .venv/bin/python scripts/bench_collision.py [--n 2000] [--repeats 7] [--seed 0]

World: the default robot and scene (``configs/scenes/desk_handover.yaml``) with the object
resting at its start pose, i.e. ``problem.world(problem.object_at(X_WO_start))``: robot
self-collision, the static obstacles and the object.  ``--no-object`` leaves the object out.

Back-ends, all on the SAME configurations and the SAME active pair set (the world's
``geometry_model.collisionPairs`` with its per-pair security margins):

* ``broadphase``   -- :meth:`CollisionWorld.is_free`: pinocchio + coal's dynamic AABB tree
  broadphase manager, early exit (the production path);
* ``pin-pairs``    -- ``pin.computeCollisions(model, data, geometry_model, geometry_data, q,
  True)``: every pair of the list in order, early exit, no broadphase;
* ``python-fcl``   -- python-fcl objects built from the world's coal shapes; each check
  runs pinocchio FK + ``updateGeometryPlacements`` and copies ``oMg`` into the moving fcl
  objects (Python loop), then ``DynamicAABBTreeCollisionManager.update()`` and
  ``collide`` with a Python callback that keeps only the active pairs and stops at the
  first collision;
* ``python-fcl-pairs`` -- same objects and transform updates, then a Python loop of
  ``fcl.collide`` over the active pairs with early exit.

Configuration sets: ``free`` (arm and torso joints = rest + N(0, 0.3 rad), clipped to the
limits, kept when ``broadphase`` says free: every pair must be checked, the worst case) and
``random`` (all joints uniform in their limits: mostly colliding, early exit).  All
back-ends must agree on every verdict: the disagreements (against ``broadphase``, in any
repeat) are counted, each is re-checked pair by pair with a standalone ``coal.collide``
(fresh GJK solver, contacts enabled) to tell which side is right, and the exit status is
1 when there is any.  ``pin-pairs`` gets a copy of the world's per-pair requests (margins
and GJK settings), so (a) and (b) run the same narrow phase and differ only in how pairs
are selected.

Each measurement is repeated ``--repeats`` times (back-ends interleaved within a repeat);
the table gives the median checks/s and the ratio to ``broadphase``.
"""

from __future__ import annotations

import argparse
import ctypes
import gc
import os
import platform
import statistics
import sys
import time
import warnings
from pathlib import Path

import coal
import fcl
import numpy as np
import pinocchio as pin

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from regrasp_cli.model.collision import CollisionWorld  # noqa: E402
from regrasp_cli.scene import Problem, load_problem  # noqa: E402

DEFAULT_SCENE = ROOT / "configs" / "scenes" / "desk_handover.yaml"
SIGMA = 0.3  # rad, Gaussian noise of the free set around rest


# ---------------------------------------------------------------------- machine

def machine_description() -> list[str]:
    cpu = "unknown"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    try:
        affinity = len(os.sched_getaffinity(0))
    except AttributeError:
        affinity = os.cpu_count()
    return [
        f"CPU: {cpu}",
        f"logical CPUs: {os.cpu_count()} (usable by this process: {affinity})",
        f"OS: {platform.system()} {platform.release()} ({platform.machine()})",
        f"Python {platform.python_version()} ({platform.python_implementation()})",
        f"pin {pin.__version__}, coal {coal.__version__}, python-fcl {fcl.__version__}, numpy {np.__version__}",
    ]


def loadavg() -> str:
    try:
        return " ".join(Path("/proc/loadavg").read_text().split()[:3])
    except OSError:
        return "n/a"


# ---------------------------------------------------------------------- world and configurations

def build_world(problem: Problem, with_object: bool) -> CollisionWorld:
    if with_object:
        return problem.world(problem.object_at(problem.spec.task.X_WO_start))
    return problem.world()


def free_set(problem: Problem, world: CollisionWorld, n: int, rng: np.random.Generator) -> tuple[np.ndarray, int]:
    """n collision-free configurations: arm/torso joints around rest with N(0, SIGMA)."""
    robot = problem.robot
    idx = np.concatenate([robot.groups["torso"], robot.groups["right_arm"], robot.groups["left_arm"]])
    out, tried = [], 0
    while len(out) < n:
        tried += 1
        if tried > 1000 * n:
            raise SystemExit(f"could only find {len(out)} free configurations in {tried - 1} samples")
        q = robot.q_rest.copy()
        q[idx] = np.clip(q[idx] + rng.normal(0.0, SIGMA, len(idx)), robot.lower[idx], robot.upper[idx])
        if world.is_free(q):
            out.append(q)
    return np.array(out), tried


def random_set(problem: Problem, n: int, rng: np.random.Generator) -> np.ndarray:
    """n configurations uniform in the joint limits (all joints)."""
    return np.array([problem.robot.sample(rng) for _ in range(n)])


# ---------------------------------------------------------------------- back-ends
# Each factory returns check(q) -> bool (True = collision-free).

def backend_broadphase(world: CollisionWorld):
    return world.is_free


REQUEST_FIELDS = ("security_margin", "break_distance", "enable_contact", "num_max_contacts", "gjk_initial_guess",
                  "enable_cached_gjk_guess", "gjk_variant", "gjk_convergence_criterion",
                  "gjk_convergence_criterion_type", "gjk_tolerance", "gjk_max_iterations")


def copy_requests(src: pin.GeometryData, dst: pin.GeometryData) -> None:
    """Give ``dst`` the per-pair collision requests (margins, GJK settings) of ``src``."""
    with warnings.catch_warnings():  # enable_cached_gjk_guess is deprecated in coal
        warnings.simplefilter("ignore", DeprecationWarning)
        for a, b in zip(src.collisionRequests, dst.collisionRequests):
            for f in REQUEST_FIELDS:
                setattr(b, f, getattr(a, f))


def backend_pin_pairs(world: CollisionWorld):
    model, gm, to_pin = world.robot.model, world.geometry_model, world.robot.to_pin
    data = model.createData()
    gdata = gm.createData()
    copy_requests(world.geometry_data, gdata)  # same margins and narrow-phase settings as (a)
    compute = pin.computeCollisions

    def check(q):
        return not compute(model, data, gm, gdata, to_pin(q), True)

    return check


def fcl_geometry(geom) -> fcl.CollisionGeometry:
    """The python-fcl twin of a coal shape (same dimensions and conventions)."""
    if float(getattr(geom, "getSweptSphereRadius", lambda: 0.0)()) != 0.0:
        raise SystemExit("coal shape with a swept-sphere radius: no python-fcl equivalent")
    if isinstance(geom, coal.Box):
        return fcl.Box(*(2.0 * np.asarray(geom.halfSide, dtype=float)))
    if isinstance(geom, coal.Cylinder):
        return fcl.Cylinder(float(geom.radius), 2.0 * float(geom.halfLength))
    if isinstance(geom, coal.Sphere):
        return fcl.Sphere(float(geom.radius))
    if isinstance(geom, coal.BVHModelBase):
        verts = np.asarray(geom.vertices(), dtype=float)
        tris = np.array([[t[0], t[1], t[2]] for t in (geom.tri_indices(i) for i in range(geom.num_tris))],
                        dtype=np.int64)
        m = fcl.BVHModel()
        m.beginModel(len(verts), len(tris))
        m.addSubModel(verts, tris)
        m.endModel()
        return m
    raise SystemExit(f"no python-fcl equivalent for {type(geom).__name__}")


class FclScene:
    """python-fcl objects mirroring the world's geometries, updated from pinocchio's oMg."""

    def __init__(self, world: CollisionWorld, gjk_solver: int):
        self.world = world
        model, gm = world.robot.model, world.geometry_model
        self.model, self.gm, self.to_pin = model, gm, world.robot.to_pin
        self.data, self.gdata = model.createData(), gm.createData()
        self.geoms = [fcl_geometry(go.geometry) for go in gm.geometryObjects]
        pin.updateGeometryPlacements(model, self.data, gm, self.gdata, world.robot.to_pin(world.robot.q_rest))
        self.objs = []
        for g, geom in enumerate(self.geoms):
            M = self.gdata.oMg[g]
            self.objs.append(fcl.CollisionObject(geom, fcl.Transform(M.rotation.copy(), M.translation.copy())))
        # geometries attached to the root (obstacles, resting object, robot base) never move
        self.moving = [g for g, go in enumerate(gm.geometryObjects) if go.parentJoint != 0]
        self.moving_objs = [(g, self.objs[g]) for g in self.moving]
        margins = [world.geometry_data.collisionRequests[k].security_margin for k in range(len(gm.collisionPairs))]
        if any(m > 0 for m in margins):
            raise SystemExit("positive security margins have no python-fcl equivalent")
        # pair (i, j) with i < j -> penetration tolerance (0 for plain collision)
        self.pairs = []
        self.pair_tol: dict[tuple[int, int], float] = {}
        for k, cp in enumerate(gm.collisionPairs):
            i, j = sorted((cp.first, cp.second))
            self.pairs.append((self.objs[cp.first], self.objs[cp.second], -margins[k]))
            self.pair_tol[(i, j)] = -margins[k]
        self.n_margin_pairs = sum(1 for m in margins if m != 0.0)
        self.request = fcl.CollisionRequest(gjk_solver_type=gjk_solver)
        self.request_depth = fcl.CollisionRequest(num_max_contacts=100000, enable_contact=True,
                                                  gjk_solver_type=gjk_solver)

    def update(self, q) -> None:
        pin.updateGeometryPlacements(self.model, self.data, self.gm, self.gdata, self.to_pin(q))
        oMg, Transform = self.gdata.oMg, fcl.Transform
        for g, obj in self.moving_objs:
            M = oMg[g]
            obj.setTransform(Transform(M.rotation, M.translation))

    def pair_collides(self, o1, o2, tol: float) -> bool:
        """fcl.collide of one pair; a pair with a negative security margin (tolerance tol > 0)
        collides only when some contact penetrates deeper than tol (coal's semantics)."""
        if tol == 0.0:
            return fcl.collide(o1, o2, self.request) > 0
        result = fcl.CollisionResult()
        if fcl.collide(o1, o2, self.request_depth, result) == 0:
            return False
        return any(c.penetration_depth > tol for c in result.contacts)


def _geom_pointer_offset(objs, geoms) -> int:
    """Byte offset, inside a python-fcl CollisionObject, of its Python geometry pointer.

    python-fcl's callback gets fresh CollisionObject wrappers that share the registered
    object's geometry (a cdef attribute, not visible from Python); reading that pointer is
    how the callback knows which geometries it was handed.  The offset is found and
    validated here on every registered object, so a different layout fails loudly."""
    for off in range(16, 80, 8):
        if all(ctypes.c_void_p.from_address(id(o) + off).value == id(g) for o, g in zip(objs, geoms)):
            return off
    raise SystemExit("cannot locate the geometry pointer in python-fcl's CollisionObject")


def backend_fcl_manager(scene: FclScene, stats: dict | None = None):
    manager = fcl.DynamicAABBTreeCollisionManager()
    manager.registerObjects(scene.objs)
    manager.setup()
    off = _geom_pointer_offset(scene.objs, scene.geoms)
    gid = {id(g): i for i, g in enumerate(scene.geoms)}
    pair_tol = scene.pair_tol
    from_address = ctypes.c_void_p.from_address
    pair_collides = scene.pair_collides
    update = scene.update

    class State:
        hit = False

    state = State()

    def callback(o1, o2, st):
        i = gid[from_address(id(o1) + off).value]
        j = gid[from_address(id(o2) + off).value]
        tol = pair_tol.get((i, j) if i < j else (j, i))
        if tol is None:
            return False
        if pair_collides(o1, o2, tol):
            st.hit = True
            return True
        return False

    def counting_callback(o1, o2, st):
        stats["candidates"] += 1
        i = gid[from_address(id(o1) + off).value]
        j = gid[from_address(id(o2) + off).value]
        tol = pair_tol.get((i, j) if i < j else (j, i))
        if tol is None:
            return False
        stats["active"] += 1
        if pair_collides(o1, o2, tol):
            st.hit = True
            return True
        return False

    cb = counting_callback if stats is not None else callback

    def check(q):
        update(q)
        manager.update()
        state.hit = False
        manager.collide(state, cb)
        return not state.hit

    return check


def backend_fcl_pairs(scene: FclScene):
    pairs, update, collide, request = scene.pairs, scene.update, fcl.collide, scene.request
    pair_collides = scene.pair_collides

    def check(q):
        update(q)
        for o1, o2, tol in pairs:
            if tol == 0.0:
                if collide(o1, o2, request) > 0:
                    return False
            elif pair_collides(o1, o2, tol):
                return False
        return True

    return check


def fresh_check(world: CollisionWorld, q) -> tuple[bool, list[tuple[str, str, float]]]:
    """Independent verdict: every active pair through a standalone ``coal.collide`` (a fresh
    GJK solver per call, contacts enabled, the pair's security margin), then the colliding
    pairs with their signed distances (``coal.distance``)."""
    model, gm = world.robot.model, world.geometry_model
    data, gdata = model.createData(), gm.createData()
    pin.updateGeometryPlacements(model, data, gm, gdata, world.robot.to_pin(q))
    tf = [coal.Transform3s(M.rotation.copy(), M.translation.copy()) for M in gdata.oMg]
    pairs = []
    for k, cp in enumerate(gm.collisionPairs):
        g1, g2 = gm.geometryObjects[cp.first].geometry, gm.geometryObjects[cp.second].geometry
        req = coal.CollisionRequest()
        req.enable_contact = True
        req.security_margin = world.geometry_data.collisionRequests[k].security_margin
        if coal.collide(g1, tf[cp.first], g2, tf[cp.second], req, coal.CollisionResult()):
            d = coal.distance(g1, tf[cp.first], g2, tf[cp.second], coal.DistanceRequest(), coal.DistanceResult())
            pairs.append((world.geometry_name(cp.first), world.geometry_name(cp.second), d))
    return not pairs, pairs


# ---------------------------------------------------------------------- measurement

def time_backend(check, Q) -> tuple[float, list[bool]]:
    gc_was = gc.isenabled()
    gc.disable()
    try:
        t0 = time.perf_counter()
        verdicts = [check(q) for q in Q]
        dt = time.perf_counter() - t0
    finally:
        if gc_was:
            gc.enable()
    return dt, verdicts


def fmt_rate(x: float) -> str:
    return f"{x:,.0f}"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n", type=int, default=2000, help="configurations per set (default 2000)")
    ap.add_argument("--repeats", type=int, default=7, help="repeats of each measurement (default 7)")
    ap.add_argument("--seed", type=int, default=0, help="seed of the configuration sets (default 0)")
    ap.add_argument("--scene", type=Path, default=DEFAULT_SCENE, help="scene.yaml (default: the desk handover)")
    ap.add_argument("--no-object", action="store_true", help="leave the object out of the world")
    ap.add_argument("--gjk", choices=("indep", "libccd"), default=None,
                    help="python-fcl GJK solver (default: whichever is faster, measured)")
    args = ap.parse_args(argv)

    print("## Machine\n")
    for line in machine_description():
        print(f"- {line}")
    print(f"- load average at start: {loadavg()}")
    print()

    problem = load_problem(args.scene, cache_dir=Path("cache"))
    world = build_world(problem, not args.no_object)
    gm = world.geometry_model
    n_robot, n_obst = len(world.robot_geoms), len(world.obstacle_geoms)
    n_obj = 0 if world.object_geom is None else 1
    kinds: dict[str, int] = {}
    for cp in gm.collisionPairs:
        a = "robot" if cp.first < n_robot else ("object" if cp.first == world.object_geom else "obstacle")
        b = "robot" if cp.second < n_robot else ("object" if cp.second == world.object_geom else "obstacle")
        key = "-".join(sorted((a, b)))
        kinds[key] = kinds.get(key, 0) + 1
    shapes: dict[str, int] = {}
    for go in gm.geometryObjects:
        shapes[type(go.geometry).__name__] = shapes.get(type(go.geometry).__name__, 0) + 1

    rng = np.random.default_rng(args.seed)
    t0 = time.perf_counter()
    Q_free, tried = free_set(problem, world, args.n, rng)
    Q_random = random_set(problem, args.n, rng)
    sets = {"free": Q_free, "random": Q_random}
    t_sets = time.perf_counter() - t0

    # python-fcl: choose the GJK solver (the default libccd or fcl's own "indep") by speed
    solvers = {"indep": fcl.GJKSolverType.GST_INDEP, "libccd": fcl.GJKSolverType.GST_LIBCCD}
    if args.gjk is None:
        probe = Q_free[: min(200, len(Q_free))]
        best = None
        for name, s in solvers.items():
            chk = backend_fcl_manager(FclScene(world, s))
            time_backend(chk, probe[:20])  # warm-up
            dt, _ = time_backend(chk, probe)
            if best is None or dt < best[1]:
                best = (name, dt)
        gjk = best[0]
    else:
        gjk = args.gjk
    scene = FclScene(world, solvers[gjk])

    backends = {
        "broadphase": backend_broadphase(world),
        "pin-pairs": backend_pin_pairs(world),
        "python-fcl": backend_fcl_manager(scene),
        "python-fcl-pairs": backend_fcl_pairs(scene),
    }
    names = list(backends)

    print("## World\n")
    print(f"- scene: {args.scene.relative_to(ROOT) if args.scene.is_relative_to(ROOT) else args.scene}"
          f" ({'object resting at its start pose' if n_obj else 'no object'})")
    print(f"- robot: {problem.robot.spec.urdf.name} sha256 {problem.robot.urdf_sha256[:12]}, robot.yaml sha256 "
          f"{problem.robot.robot_yaml_sha256[:12]}")
    print(f"- robot: {problem.robot.nq} joints; geometries: {gm.ngeoms} ({n_robot} robot, {n_obst} obstacles, "
          f"{n_obj} object; moving: {len(scene.moving)}); shapes: "
          + ", ".join(f"{v} {k}" for k, v in sorted(shapes.items())))
    print(f"- active pairs: {world.n_pairs} (" + ", ".join(f"{k} {v}" for k, v in sorted(kinds.items()))
          + f"); pairs with a non-zero security margin: {scene.n_margin_pairs}")
    print(f"- free set: {len(Q_free)} configurations kept of {tried} sampled "
          f"({100 * len(Q_free) / tried:.1f} % free; torso + arms = rest + N(0, {SIGMA} rad), clipped)")
    print(f"- random set: {len(Q_random)} configurations uniform in the joint limits (all joints)")
    print(f"- seed {args.seed}; sets built in {t_sets:.1f} s; python-fcl GJK solver: {gjk}"
          + (" (faster of indep/libccd on 200 free configurations)" if args.gjk is None else ""))
    print()

    # warm-up (allocations, caches) on a few configurations of each set
    for check in backends.values():
        for Q in sets.values():
            time_backend(check, Q[:20])

    rates = {s: {b: [] for b in names} for s in sets}
    verdicts: dict[str, dict[str, list[list[bool]]]] = {s: {b: [] for b in names} for s in sets}
    for r in range(args.repeats):
        order = names[r % len(names):] + names[: r % len(names)]  # rotate to spread drifts
        for s, Q in sets.items():
            for b in order:
                dt, v = time_backend(backends[b], Q)
                rates[s][b].append(len(Q) / dt)
                verdicts[s][b].append(v)
        print(f"repeat {r + 1}/{args.repeats} done (load average {loadavg()})", file=sys.stderr)

    print("## Agreement\n")
    print("Reference: broadphase's verdicts in the first timed pass.  A configuration counts as a "
          "disagreement when a back-end's verdict differs in any of the repeats.\n")
    total_dis = 0
    examples = []
    for s, Q in sets.items():
        ref = verdicts[s]["broadphase"][0]
        parts = []
        for b in names:
            runs = verdicts[s][b]
            bad = [i for i in range(len(Q)) if any(v[i] != ref[i] for v in runs)]
            first = sum(x != y for x, y in zip(runs[0], ref))
            total_dis += len(bad)
            parts.append(f"{b} {len(bad)} (first pass {first})")
            examples += [(s, b, i, [v[i] for v in runs]) for i in bad]
        print(f"- {s}: {sum(ref)}/{len(ref)} free according to broadphase; disagreements: " + ", ".join(parts))
    print(f"- total disagreements: {total_dis}")
    if examples:
        print("\nDisagreements, checked again pair by pair with standalone coal.collide (fresh GJK "
              "solver, contacts enabled) and coal.distance:\n")
        for s, b, i, vs in examples[:12]:
            q = sets[s][i]
            fresh, pairs = fresh_check(world, q)
            print(f"  - {s}[{i}]: {b} says {'free' if vs[0] else 'colliding'} (per repeat: "
                  f"{''.join('F' if x else 'C' for x in vs)}), broadphase {'free' if verdicts[s]['broadphase'][0][i] else 'colliding'}, "
                  f"coal.collide {'free' if fresh else 'colliding'}: "
                  + (", ".join(f"{a}/{c} {d * 1000:+.1f} mm" for a, c, d in pairs) or "no pair"))
        if len(examples) > 12:
            print(f"  - ... and {len(examples) - 12} more")
    print()

    # python-fcl broadphase statistics (untimed pass)
    stats = {"candidates": 0, "active": 0}
    counting = backend_fcl_manager(FclScene(world, solvers[gjk]), stats)
    print("## python-fcl broadphase (untimed pass)\n")
    for s, Q in sets.items():
        stats["candidates"] = stats["active"] = 0
        for q in Q:
            counting(q)
        print(f"- {s}: {stats['candidates'] / len(Q):.1f} AABB-overlapping pairs handed to the Python "
              f"callback per check, {stats['active'] / len(Q):.1f} of them active pairs (narrow phase run)")
    print()

    print(f"## Full-robot collision checks per second (median of {args.repeats} repeats, "
          f"{args.n} configurations per set)\n")
    header = "| back-end | " + " | ".join(f"{s}: checks/s | {s}: × broadphase" for s in sets) + " |"
    print(header)
    print("|" + "---|" * (1 + 2 * len(sets)))
    med = {s: {b: statistics.median(rates[s][b]) for b in names} for s in sets}
    for b in names:
        cells = []
        for s in sets:
            cells += [fmt_rate(med[s][b]), f"{med[s][b] / med[s]['broadphase']:.3f}"]
        print(f"| {b} | " + " | ".join(cells) + " |")
    print()
    print("Spread over the repeats (min – max checks/s):\n")
    print("| back-end | " + " | ".join(sets) + " |")
    print("|" + "---|" * (1 + len(sets)))
    for b in names:
        print(f"| {b} | " + " | ".join(f"{fmt_rate(min(rates[s][b]))} – {fmt_rate(max(rates[s][b]))}"
                                        for s in sets) + " |")
    print()
    # floor: what every back-end pays before any collision test (FK + geometry placements)
    model, gdat, fdat = world.robot.model, gm.createData(), world.robot.model.createData()
    to_pin = world.robot.to_pin

    def placements_only(q):
        pin.updateGeometryPlacements(model, fdat, gm, gdat, to_pin(q))
        return True

    floor = {s: statistics.median(len(Q) / time_backend(placements_only, Q)[0] for _ in range(args.repeats))
             for s, Q in sets.items()}
    print("For reference, pinocchio FK + updateGeometryPlacements alone (no collision test): "
          + ", ".join(f"{s} {fmt_rate(v)}/s" for s, v in floor.items()) + ".\n")
    fast = max(("python-fcl", "python-fcl-pairs"), key=lambda b: med["free"][b])
    print(f"Faster python-fcl variant on the free set: {fast}.")
    print(f"Load average at the end: {loadavg()}")
    return 1 if total_dis else 0


if __name__ == "__main__":
    sys.exit(main())
