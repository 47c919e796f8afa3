"""A planning run's :class:`~regrasp_cli.manip.solve.Outcome` as a plan/2
(:mod:`regrasp_cli.trajectory`): the motion with the kinds, holdings and placements of
its transitions, and everything an independent checker needs to replay it."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from regrasp_cli import __version__
from regrasp_cli.grasp.build import GraspList
from regrasp_cli.manip.context import OnlineOptions
from regrasp_cli.manip.ompl_peer import ompl_version
from regrasp_cli.manip.solve import Outcome
from regrasp_cli.scene import Problem
from regrasp_cli.store import atomic_write_bytes, sha256_bytes, sha256_file
from regrasp_cli.trajectory import Phase, Placement, Plan, PlanGrasp


def relative_path(path: Path, base: Path) -> str:
    """``path`` relative to ``base`` (absolute when on another drive)."""
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


def plan_grasp(lists: dict[str, GraspList], gid: str, hand: str, k: int, robot) -> PlanGrasp:
    """Grasp ``k`` of ``hand``'s list, as the plan records it under id ``gid`` (with its
    index in the cached list)."""
    g, h = lists[hand], robot.hands[hand]
    contacts = tuple({"finger": g.finger_names[f], "point": g.points[k, f], "normal": g.normals[k, f]}
                     for f in range(len(g.finger_names)) if g.in_contact[k, f])
    return PlanGrasp(gid, hand, g.X_OG[k], tuple(robot.joint_names[i] for i in h.idx), g.finger_q[k], contacts,
                     float(g.scores[k, 4]), g.stored_index(k))


def _phase(m) -> Phase:
    tr = m.transition
    return Phase(tr.label, tr.kind, dict(tr.holding), tr.touching, tr.placement, m.waypoints, m.times,
                 object_poses=m.object_poses, contacts=m.contacts, blends=m.radii, timing=m.timing)


def _stats(outcome: Outcome, options: OnlineOptions, hashes: dict[str, str], timings: bool) -> dict:
    counts = dict(outcome.counts)
    counts["transitions"] = {k: v.counts() for k, v in outcome.transitions.items()}
    stats = {"software_version": __version__, "artefacts": hashes, "counts": counts}
    if options.planner == "ompl-rrtconnect":
        stats["ompl_version"] = ompl_version()
    if timings:
        stats["transitions"] = {k: {"nodes": v.nodes, "planning_s": v.planning_s, "validation_s": v.validation_s}
                                for k, v in outcome.transitions.items()}
        stats["stages_s"] = dict(outcome.stages)
        stats["total_s"] = outcome.planning_s
    return stats


def obstacle_records(obstacles, base: Path) -> tuple[dict, ...]:
    """The plan's ``obstacles``: each ObstacleSpec (posed in W) as a dict, mesh paths
    relative to ``base``."""
    return tuple({"name": o.name, "shape": o.shape, "size": list(o.size), "pose": o.X_WO,
                  "mesh": None if o.mesh is None else relative_path(o.mesh, base)} for o in obstacles)


def make_plan(problem: Problem, lists: dict[str, GraspList], outcome: Outcome, options: OnlineOptions, seed: int,
              out_file: Path, cache_dir: Path, hashes: dict[str, str], timings: bool) -> Plan:
    """The plan of ``outcome``; paths in it are relative to ``out_file``'s folder.  With
    ``timings`` False it holds no wall-clock time (the same seed gives the same bytes)."""
    robot, spec = problem.robot, problem.spec
    base = Path(out_file).resolve().parent
    mesh = export_object(problem, cache_dir)
    obstacles = obstacle_records(spec.obstacles, base)
    return Plan(
        status="failed" if outcome.failure else "solved",
        failure=None if outcome.failure is None else outcome.failure.as_dict(),
        scene={"file": relative_path(spec.file, base), "sha256": sha256_file(spec.file)},
        robot={"urdf": relative_path(robot.spec.urdf, base), "urdf_sha256": robot.urdf_sha256,
               "robot_yaml": relative_path(robot.spec.file, base), "robot_yaml_sha256": robot.robot_yaml_sha256},
        joint_names=robot.joint_names,
        limits={"lower": robot.lower, "upper": robot.upper, "velocity": robot.velocity,
                "acceleration": np.full(robot.nq, options.acceleration)},
        object={"name": problem.object.name, "mesh": relative_path(mesh, base), "sha256": sha256_file(mesh),
                "friction": spec.object.friction},
        obstacles=obstacles,
        collision={"contact_tolerance": problem.collision_options.contact_tolerance,
                   "support_tolerance": problem.collision_options.support_tolerance,
                   "disabled_pairs": sorted(list(p) for p in problem.disabled.links())},
        grasps=tuple(plan_grasp(lists, gid, hand, k, robot) for gid, hand, k in outcome.grasps),
        placements=tuple(Placement(pid, X) for pid, X in outcome.placements.items()),
        phases=tuple(_phase(m) for m in outcome.phases),
        stats=_stats(outcome, options, hashes, timings), seed=seed, planner=options.planner, task=outcome.task)
