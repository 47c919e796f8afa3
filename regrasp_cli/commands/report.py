"""Human-readable summaries printed by the CLI (rich tables)."""

from __future__ import annotations

from pathlib import Path

import click
import numpy as np
from rich.console import Console
from rich.table import Table

from regrasp_cli.model.reach import Reach, reach
from regrasp_cli.artefacts import check_positive, build_grasp_list, build_options, roadmap_options
from regrasp_cli.commands.progress import load_problem_shown
from regrasp_cli.placement.supports import resting_gap
from regrasp_cli.scene import Problem


def _fmt(v, n=3) -> str:
    return "[" + ", ".join(f"{x:.{n}g}" for x in v) + "]"


def reachability(problem: Problem, rng: np.random.Generator) -> dict[tuple[str, str], Reach]:
    """Reach of each hand at the object's start and goal poses (bounding-box centre)."""
    world = problem.world()
    centre_O = problem.object.mesh.bounds.mean(axis=0)
    out = {}
    for pose_name, X in (("start", problem.spec.task.X_WO_start), ("goal", problem.spec.task.X_WO_goal)):
        p_W = X[:3, :3] @ centre_O + X[:3, 3]
        for hand in problem.robot.hands:
            out[(pose_name, hand)] = reach(problem.robot, world, hand, p_W, rng)
    return out


def print_info(scene: Path, cache_dir: Path, seed: int | None, console: Console | None = None) -> None:
    console = console or Console()
    problem = load_problem_shown(scene, cache_dir)
    robot, spec = problem.robot, problem.spec
    rng = np.random.default_rng(spec.planning.seed if seed is None else seed)

    t = Table(title=f"Robot {robot.model.name} ({robot.spec.urdf.name})", show_header=True)
    t.add_column("group")
    t.add_column("DoF", justify="right")
    t.add_column("joints")
    for g, idx in robot.groups.items():
        t.add_row(g, str(len(idx)), ", ".join(robot.joint_names[i] for i in idx) or "-")
    for side, h in robot.hands.items():
        t.add_row(f"{side} hand", str(len(h.idx)),
                  f"{len(h.spec.fingers)} fingers ({', '.join(f.name for f in h.spec.fingers)}), kind {h.kind}, "
                  f"grasp frame {h.spec.grasp_frame}, {h.spec.contact} contact")
    grouped = set(np.concatenate([*robot.groups.values(), *(h.idx for h in robot.hands.values())]).tolist())
    followers = [f"{robot.joint_names[i]} ({robot.joint_names[robot.mimic[i][0]]})" for i in range(robot.nq)
                 if i not in grouped and i in robot.mimic]
    other = [robot.joint_names[i] for i in range(robot.nq) if i not in grouped and i not in robot.mimic]
    if followers:
        t.add_row("mimic (follows)", str(len(followers)), ", ".join(followers))
    if other:
        t.add_row("other (held at rest)", str(len(other)), ", ".join(other))
    t.add_row("total", str(robot.nq), "")
    console.print(t)

    world = problem.world()
    n_geoms = robot.collision_model.ngeoms
    d = problem.disabled
    t = Table(title="Collision checking (pinocchio + coal broadphase)")
    t.add_column("what")
    t.add_column("count", justify="right")
    t.add_row("robot collision geometries", str(n_geoms))
    t.add_row("link pairs disabled: adjacent / always / never / robot.yaml",
              f"{d.count('adjacent')} / {d.count('always')} / {d.count('never')} / {d.count('user')}")
    t.add_row(f"  ('never' = farther than {d.never_margin} m in {d.samples} random configurations, same chain)", "")
    n_obst = len(world.obstacle_geoms)
    n_self = world.n_pairs - sum(1 for cp in world.geometry_model.collisionPairs if cp.second >= n_geoms)
    t.add_row("robot-robot geometry pairs checked", str(n_self))
    t.add_row("robot-obstacle geometry pairs checked", str(world.n_pairs - n_self))
    t.add_row("total pairs checked", str(world.n_pairs))
    console.print(t)

    t = Table(title=f"Obstacles ({n_obst})")
    for c in ("name", "shape", "size (m)", "position (m)"):
        t.add_column(c)
    for ob in spec.obstacles:
        t.add_row(ob.name, ob.shape, _fmt(ob.size), _fmt(ob.X_WO[:3, 3]))
    console.print(t)

    obj = problem.object
    t = Table(title="Object")
    t.add_column("what")
    t.add_column("value")
    t.add_row("mesh", obj.name)
    t.add_row("triangles", str(obj.n_triangles))
    t.add_row("watertight", f"{'yes' if obj.watertight else 'no'} ({obj.n_shells} shell{'s' * (obj.n_shells != 1)})")
    t.add_row("extents (m)", _fmt(obj.extents))
    t.add_row("friction", f"{spec.object.friction:g}")
    console.print(t)

    reaches = reachability(problem, rng)
    t = Table(title="Reachability of the object poses (grasp frame at the object centre)")
    for c in ("pose", "hand", "reachable", "approach orientations: IK / collision-free / tried"):
        t.add_column(c)
    for (pose, hand), r in reaches.items():
        t.add_row(pose, hand, "[green]yes[/]" if r.reachable else "[red]no[/]",
                  f"{r.ik_solutions} / {r.collision_free} / {r.orientations_tried}")
    console.print(t)

    t = Table(title="Robot configurations")
    t.add_column("configuration")
    t.add_column("collision-free")
    for name, q, X in (("start (object at its start pose)", problem.q_start, spec.task.X_WO_start),
                       ("goal (object at its goal pose)", problem.q_goal, spec.task.X_WO_goal)):
        w = problem.world(problem.object_at(X))
        pairs = w.colliding_pairs(q)
        t.add_row(name, "[green]yes[/]" if not pairs else f"[red]no[/]: {', '.join('-'.join(p) for p in pairs[:3])}")
    console.print(t)

    for pose in ("start", "goal"):
        hands = [h for h in robot.hands if reaches[(pose, h)].reachable]
        if len(hands) == 1:
            verdict = f"reachable by the {hands[0]} arm only"
        elif hands:
            verdict = "reachable by both arms"
        else:
            verdict = "reachable by neither arm"
        console.print(f"The object's {pose} pose is {verdict}.")
    for pose, X in (("start", spec.task.X_WO_start), ("goal", spec.task.X_WO_goal)):
        gap = resting_gap(problem.object.mesh.vertices, X, spec.obstacles)
        if gap is not None and abs(gap) > max(problem.collision_options.support_tolerance, 0.001):
            where = f"{gap * 1000:.1f} mm above" if gap > 0 else f"{-gap * 1000:.1f} mm into"
            console.print(f"[yellow]warning[/]: the object's {pose} pose is {where} the obstacle top under it; it "
                          "would fall or be pushed out on a real robot (the planner has no gravity)")


def provenance_table(file: Path, prov) -> Table:
    """A two-column table (provenance, value) headed by an artefact's stored provenance."""
    t = Table(title=f"{file}")
    t.add_column("provenance")
    t.add_column("value")
    t.add_row("format", f"{prov.format} v{prov.format_version}")
    t.add_row("software", prov.software_version)
    t.add_row("created", prov.created)
    for k, v in prov.inputs.items():
        t.add_row(f"sha256 {k}", v[:16] + "…")
    return t


def run_grasps_build(scene: Path, cache_dir: Path, hand: str, seed: int | None, jobs: int,
                     positions: int | None, orientations: int | None, target: int | None = None,
                     weights: str | None = None, console: Console | None = None,
                     pinch_frames: int | None = None) -> None:
    from regrasp_cli.config import load_scene_spec

    spec = load_scene_spec(scene)
    options = build_options(spec.planning.seed, seed, jobs, positions, orientations, target, weights, pinch_frames)
    hands = ["right", "left"] if hand == "both" else [hand]
    build_grasp_lists(scene, cache_dir, hands, options, console or Console())


def build_grasp_lists(scene: Path, cache_dir: Path, hands: list[str], options, console: Console) -> None:
    """Build the grasp lists of ``hands`` with ``options`` (a BuildOptions), with progress
    bars and the summary tables.  Raises EmptyResultError naming every hand whose list is
    empty (and why), after building the others."""
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    from regrasp_cli.errors import EmptyGraspList, EmptyResultError

    problem = load_problem_shown(scene, cache_dir)  # every input error before the progress bars start
    spec = problem.spec
    reports, empty = [], []
    with Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                  console=console, transient=False) as bar:
        for h in hands:
            task = bar.add_task(f"{h} hand: grasp frames", total=None)

            def show(done, total, kept, t=task, h=h):
                bar.update(t, completed=done, total=total,
                           description=f"{h} hand: grasp frames ({kept} grasps)")

            try:
                reports.append(build_grasp_list(scene, cache_dir, h, options, show, problem))
            except EmptyGraspList as exc:
                empty.append(exc)
    if reports:
        _grasp_tables(spec, reports, console)
    if len(empty) > 1:
        raise EmptyResultError("; ".join(exc.message for exc in empty))
    if empty:
        raise empty[0]


def _grasp_tables(spec, reports: list, console: Console) -> None:
    """The summary and time tables of built grasp lists ((GraspList, BuildReport) each)."""
    t = Table(title=f"Grasp lists ({spec.object.mesh}, friction {spec.object.friction:g})")
    for c in ("hand", "frames tried", "of them pinch", "hand in object", "enough contacts", "force closure",
              "kept (distinct)", "best quality", "time (s)", "grasps/s"):
        t.add_column(c, justify="right")
    for glist, rep in reports:
        total = sum(rep.seconds.values())
        t.add_row(rep.hand, str(rep.frames), str(rep.pinch_frames), str(rep.frames_blocked),
                  str(rep.frames_with_contacts),
                  str(rep.force_closure), str(rep.kept),
                  f"{glist.scores[0, -1]:.3f}" if len(glist) else "-", f"{total:.1f}",
                  f"{rep.kept / total:.1f}" if total > 0 else "-")
    console.print(t)
    t = Table(title="Time per stage (s)")
    t.add_column("stage")
    for _, rep in reports:
        t.add_column(rep.hand, justify="right")
    for stage in reports[0][1].seconds:
        t.add_row(stage, *(f"{rep.seconds[stage]:.2f}" for _, rep in reports))
    console.print(t)
    for _, rep in reports:
        console.print(f"{rep.hand} hand: {rep.path}")


def show_grasps(file: Path, best: int, scene: Path | None, cache_dir: Path, console: Console | None = None) -> None:
    from regrasp_cli.grasp.build import provenance, read_grasp_list, stored_options
    from regrasp_cli.store import read_provenance

    console = console or Console()
    prov = read_provenance(file)
    expected = None
    if scene is not None:
        # the list's own build options, with the scene's robot, object and friction: a list
        # built with other options is not stale, one for another object or robot is
        problem = load_problem_shown(scene, cache_dir)
        expected = provenance(problem, str(_hand_of(file)), stored_options(file))
    glist = read_grasp_list(file, expected)
    t = provenance_table(file, prov)
    t.add_row("hand", glist.hand)
    t.add_row("grasps", str(len(glist)))
    console.print(t)
    t = Table(title=f"Best {min(best, len(glist))} grasps")
    for c in ("#", "fingers in contact", "epsilon", "centroid", "ellipsoid", "curvature", "total",
              "hand position in object (m)"):
        t.add_column(c, justify="right")
    for i in range(min(best, len(glist))):
        fingers = ",".join(n for n, c in zip(glist.finger_names, glist.in_contact[i]) if c)
        t.add_row(str(i), fingers, *(f"{v:.3f}" for v in glist.scores[i]), _fmt(glist.X_OG[i, :3, 3]))
    console.print(t)


def _hand_of(file: Path) -> str:
    import h5py

    with h5py.File(file, "r") as f:
        return f.attrs["hand"]


def run_roadmap_build(scene: Path, cache_dir: Path, nodes: int, tree: bool, seed: int | None, jobs: int,
                      console: Console | None = None) -> None:
    from regrasp_cli.config import load_scene_spec

    options = roadmap_options(load_scene_spec(scene), nodes, tree, seed)
    check_positive(jobs, "--jobs")
    build_roadmap_shown(scene, cache_dir, options, jobs, console or Console())


def build_roadmap_shown(scene: Path, cache_dir: Path, options, jobs: int, console: Console) -> None:
    """Build the roadmap with ``options`` (a RoadmapOptions), with progress bars and the
    summary tables; its warnings go to stderr.  An empty roadmap raises EmptyRoadmap."""
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    from regrasp_cli.roadmap.build import build_roadmap

    load_problem_shown(scene, cache_dir)  # every input error before the progress bars start
    with Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                  console=console) as bar:
        tasks: dict[str, int] = {}

        def show(stage: str, done: int, total: int) -> None:
            if stage not in tasks:
                tasks[stage] = bar.add_task(stage, total=total)
            bar.update(tasks[stage], completed=done, total=total)

        art, rep = build_roadmap(scene, cache_dir, options, jobs, progress=show)
    for line in rep.warnings:  # few nodes, a rest configuration in collision: loud, on stderr
        click.echo(f"warning: {line}", err=True)
    t = Table(title=f"Roadmap ({'tree' if options.tree else 'graph'} mode, {options.nodes} nodes per elementary "
                    "roadmap)")
    t.add_column("what")
    t.add_column("value")
    for k, v in rep.rows.items():
        t.add_row(k, v)
    console.print(t)
    t = Table(title="Time per stage (s)")
    t.add_column("stage")
    t.add_column("seconds", justify="right")
    for k, v in rep.seconds.items():
        t.add_row(k, f"{v:.2f}")
    t.add_row("total", f"{sum(rep.seconds.values()):.2f}")
    console.print(t)
    console.print(f"roadmap: {rep.path}")


def show_roadmap(file: Path, scene: Path | None, cache_dir: Path, console: Console | None = None) -> None:
    import json

    import h5py

    from regrasp_cli.roadmap.build import RoadmapOptions, provenance, read_roadmap, summary
    from regrasp_cli.store import read_provenance

    console = console or Console()
    prov = read_provenance(file)
    expected = None
    if scene is not None:
        problem = load_problem_shown(scene, cache_dir)
        with h5py.File(file, "r") as f:
            options = RoadmapOptions(**json.loads(f.attrs["options"]))
        expected = provenance(problem, options)
    art = read_roadmap(file, expected)
    t = provenance_table(file, prov)
    for k, v in summary(art).items():
        t.add_row(k, v)
    console.print(t)


class CliBuilder:
    """Builds a missing or stale artefact for `regrasp plan` with the progress bars and
    summary tables of `regrasp grasps build` / `regrasp roadmap build`."""

    def __init__(self, console: Console):
        self.console = console

    def notice(self, message: str) -> None:
        self.console.print(message, markup=False, highlight=False, soft_wrap=True)

    def grasps(self, scene: Path, cache_dir: Path, hand: str, options) -> None:
        build_grasp_lists(scene, cache_dir, [hand], options, self.console)

    def roadmap(self, scene: Path, cache_dir: Path, options, jobs: int) -> None:
        build_roadmap_shown(scene, cache_dir, options, jobs, self.console)


def run_examples(folder: Path | None, force: bool, console: Console | None = None) -> None:
    """`regrasp examples [DIR]`: list the shipped robots and scenes, or copy them to DIR."""
    from regrasp_cli.examples import BUILTIN_PREFIX, copy_examples, data_dir, robot_names, scene_files

    console = console or Console()
    if folder is None:
        console.print(f"robots (in a scene: robot: {BUILTIN_PREFIX}NAME): "
                      + ", ".join(BUILTIN_PREFIX + n for n in robot_names()), markup=False)
        for p in scene_files():
            console.print(f"scene: {p.relative_to(data_dir())}", markup=False)
        console.print("copy them with: regrasp examples DIR", markup=False)
        return
    written = copy_examples(folder, force)
    for p in written:
        console.print(f"wrote {p}", markup=False, highlight=False)
    scenes = [p for p in written if p.parent.name == "scenes"]
    if scenes:
        console.print(f"try: regrasp plan {scenes[0]}", markup=False, highlight=False)
