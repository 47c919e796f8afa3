"""`regrasp plan SCENE`: cached artefacts in, plan JSON out, a Table I summary printed.

Missing or stale artefacts (grasp lists, roadmap) are built first with their progress
bars, or refused with ``--no-build``.  The plan is then checked by the independent
validator (:mod:`regrasp_cli.validate`) before the command reports success.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

from regrasp_cli import __version__
from regrasp_cli.grasp.build import GraspList
from regrasp_cli.plan.context import OnlineOptions
from regrasp_cli.plan.ompl_peer import ompl_version
from regrasp_cli.plan.planner import Outcome, PlanningFailed, run
from regrasp_cli.plan.queries import Roadmap
from regrasp_cli.scene import Problem, load_problem
from regrasp_cli.store import atomic_write_bytes, sha256_bytes, sha256_file
from regrasp_cli.trajectory import Phase, Plan, PlanGrasp, write_plan

QUERIES = ("grasp", "carry", "place", "rest")


def load_artefacts(scene: Path, cache_dir: Path, problem: Problem, build: bool, jobs: int, need_roadmap: bool,
                   console: Console, roadmap_nodes: int = 50, grasp_target: int | None = None) -> tuple[dict[str, GraspList], object | None, dict[str, str]]:
    """The grasp lists of both hands and the roadmap, built when missing or stale unless
    ``build`` is False (then a missing or stale one raises an InputError naming it)."""
    from regrasp_cli.grasp import build as gb
    from regrasp_cli.report import build_options, roadmap_options, run_grasps_build, run_roadmap_build
    from regrasp_cli.roadmap import build as rb
    from regrasp_cli.store import is_fresh

    spec = problem.spec
    options = build_options(spec.planning.seed, None, jobs, None, None, grasp_target)
    lists, hashes = {}, {}
    for hand in ("right", "left"):
        prov = gb.provenance(problem, hand, options)
        path = gb.artefact_path(cache_dir, problem, hand, options)
        if build and not (path.is_file() and is_fresh(path, prov)):
            run_grasps_build(scene, cache_dir, hand, None, jobs, None, None, grasp_target, console=console)
        lists[hand] = gb.read_grasp_list(path, prov)
        hashes[f"grasps_{hand}"] = sha256_file(path)
    art = None
    if need_roadmap:
        r_opts = roadmap_options(spec, roadmap_nodes, False, None)
        prov = rb.provenance(problem, r_opts)
        path = rb.artefact_path(cache_dir, problem, r_opts)
        if build and not (path.is_file() and is_fresh(path, prov)):
            run_roadmap_build(scene, cache_dir, roadmap_nodes, False, None, jobs, console=console)
        art = rb.read_roadmap(path, prov)
        hashes["roadmap"] = sha256_file(path)
    return lists, art, hashes


def _rel(path: Path, base: Path) -> str:
    try:
        return os.path.relpath(Path(path).resolve(), base.resolve())
    except ValueError:  # another drive (Windows)
        return str(Path(path).resolve())


def export_object(problem: Problem, cache_dir: Path) -> Path:
    """The object mesh as used (scaled), as an STL in the cache; the bytes are deterministic."""
    data = problem.object.to_stl_bytes()
    name = problem.object.name.replace("builtin:", "builtin_").replace("/", "_")
    path = Path(cache_dir) / "objects" / f"{Path(name).stem}-{sha256_bytes(data)[:12]}.stl"
    if not path.is_file() or sha256_file(path) != sha256_bytes(data):
        path.parent.mkdir(parents=True, exist_ok=True)
        atomic_write_bytes(path, data)
    return path


def _grasp(lists: dict[str, GraspList], hand: str, k: int, robot) -> PlanGrasp:
    g = lists[hand]
    h = robot.hands[hand]
    contacts = tuple({"finger": g.finger_names[f], "point": g.points[k, f], "normal": g.normals[k, f]}
                     for f in range(len(g.finger_names)) if g.in_contact[k, f])
    return PlanGrasp(hand, k, g.X_OG[k], tuple(robot.joint_names[i] for i in h.idx), g.finger_q[k], contacts,
                     float(g.scores[k, 4]))


def make_plan(problem: Problem, lists: dict[str, GraspList], outcome: Outcome, options: OnlineOptions, seed: int,
              out_file: Path, cache_dir: Path, hashes: dict[str, str], timings: bool) -> Plan:
    robot, spec = problem.robot, problem.spec
    base = Path(out_file).resolve().parent
    mesh = export_object(problem, cache_dir)
    obstacles = tuple({"name": o.name, "shape": o.shape, "size": list(o.size), "pose": o.X_WO,
                       "mesh": None if o.mesh is None else _rel(o.mesh, base)} for o in spec.obstacles)
    grasps, poses = (), {"start": spec.task.X_WO_start, "goal": spec.task.X_WO_goal}
    if outcome.failure is None:
        dg = outcome.double
        grasps = (_grasp(lists, dg.giver.hand, dg.giver.grasp, robot), _grasp(lists, dg.taker.hand, dg.taker.grasp, robot))
        poses["exchange"] = outcome.exchange.X_WO
    stats = {"software_version": __version__, "artefacts": hashes, "counts": outcome.stats}
    if options.planner == "ompl-rrtconnect":
        stats["ompl_version"] = ompl_version()
    if timings:
        table = {q: {"nodes": outcome.stats.get("queries", {}).get(q, {}).get("nodes", 0),
                     "planning_s": outcome.timing.get(f"{q} planning", 0.0),
                     "validation_s": outcome.timing.get(f"{q} validation", 0.0)} for q in QUERIES}
        stats["phases"] = table
        stats["stages_s"] = {k: outcome.timing.get(k, 0.0) for k in ("double grasps", "exchange", "queries", "timing")}
        stats["total_s"] = float(sum(v for k, v in outcome.timing.items() if k in
                                     ("double grasps", "exchange", "queries", "timing")))
    return Plan(
        status="failed" if outcome.failure else "solved",
        failure=None if outcome.failure is None else {"stage": outcome.failure.stage, "reason": outcome.failure.reason},
        scene={"file": _rel(spec.file, base), "sha256": sha256_file(spec.file)},
        robot={"urdf": _rel(robot.spec.urdf, base), "urdf_sha256": robot.urdf_sha256,
               "robot_yaml": _rel(robot.spec.file, base), "robot_yaml_sha256": robot.robot_yaml_sha256},
        joint_names=robot.joint_names,
        limits={"lower": robot.lower, "upper": robot.upper, "velocity": robot.velocity,
                "acceleration": np.full(robot.nq, options.acceleration)},
        object={"name": problem.object.name, "mesh": _rel(mesh, base), "sha256": sha256_file(mesh),
                "friction": spec.object.friction},
        obstacles=obstacles,
        collision={"contact_tolerance": problem.collision_options.contact_tolerance,
                   "support_tolerance": problem.collision_options.support_tolerance,
                   "disabled_pairs": sorted(list(p) for p in problem.disabled.links())},
        grasps=grasps, object_poses=poses,
        phases=tuple(Phase(m.name, m.holding, m.touching, m.waypoints, m.times) for m in outcome.phases),
        stats=stats, seed=seed, planner=options.planner)


def print_summary(plan: Plan, outcome: Outcome, console: Console) -> None:
    """Table I of the paper, one row per query: nodes and seconds of the online planning
    (search, connections, repairs, smoothing) and of the lazy path validation."""
    ompl = f" {plan.stats['ompl_version']}" if "ompl_version" in plan.stats else ""
    t = Table(title=f"Online planning ({plan.planner}{ompl}, seed {plan.seed}): n nodes, T seconds",
              caption="planning: search, connections, repairs, smoothing; validation: lazy checks "
                      "(n: invalid edges found)")
    for c in ("query", "planning n", "planning T", "validation n", "validation T", "total T"):
        t.add_column(c, justify="right")
    qs, tm = outcome.stats.get("queries", {}), outcome.timing
    for q in QUERIES:
        p, v = tm.get(f"{q} planning", 0.0), tm.get(f"{q} validation", 0.0)
        t.add_row(q, str(qs.get(q, {}).get("nodes", 0)), f"{p:.2f}", str(qs.get(q, {}).get("invalid_edges", 0)),
                  f"{v:.2f}", f"{p + v:.2f}")
    console.print(t)
    total = sum(tm.get(k, 0.0) for k in ("double grasps", "exchange", "queries", "timing"))
    console.print(f"double grasps {tm.get('double grasps', 0):.2f} s, exchange {tm.get('exchange', 0):.2f} s, "
                  f"queries {tm.get('queries', 0):.2f} s: total {total:.2f} s; motion of {plan.duration:.1f} s in "
                  f"{sum(len(p.waypoints) for p in plan.phases)} waypoints over {len(plan.phases)} phases")


def run_plan(scene: Path, cache_dir: Path, out_file: Path, seed: int | None, planner: str, build: bool, jobs: int,
             timings: bool, check: bool, roadmap_nodes: int = 50, grasp_target: int | None = None,
             console: Console | None = None) -> int:
    """The `plan` command; returns the exit code (0 solved, 1 not)."""
    from regrasp_cli.validate import print_validation, validate_plan

    console = console or Console()
    if planner == "ompl-rrtconnect":
        ompl_version()  # InputError naming the extra before anything is loaded
    problem = load_problem(scene, cache_dir)
    lists, art, hashes = load_artefacts(scene, cache_dir, problem, build, jobs, planner == "roadmap", console,
                                        roadmap_nodes, grasp_target)
    seed = problem.spec.planning.seed if seed is None else seed
    options = OnlineOptions(planner=planner)
    outcome = run(problem, lists, Roadmap.of(art) if art is not None else None, options, seed)
    plan = make_plan(problem, lists, outcome, options, seed, out_file, cache_dir, hashes, timings)
    write_plan(out_file, plan)
    if outcome.failure is not None:
        console.print(f"[red]not solved[/red]: stage {outcome.failure.stage}: {outcome.failure.reason}")
        console.print(f"plan (status failed): {out_file}")
        raise outcome.failure
    print_summary(plan, outcome, console)
    if check:
        report = validate_plan(out_file)
        print_validation(report, console)
        if not report.valid:
            raise PlanningFailed("validation", f"the written plan fails {len(report.issues)} check(s); first: "
                                 f"{report.issues[0]}")
    console.print(f"plan: {out_file}")
    return 0
