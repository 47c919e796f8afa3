"""The `regrasp` command: a thin click layer that parses, calls the library and prints.

Domain errors (:class:`~regrasp_cli.errors.RegraspError`) become one line on stderr and
their exit code (2 for bad input); ``--debug`` shows the traceback instead.  Heavy
imports (pinocchio, trimesh) happen inside the subcommands so ``--help`` is instant.
"""

from __future__ import annotations

import sys
import warnings
from pathlib import Path

import click

from regrasp_cli import __version__
from regrasp_cli.errors import RegraspError, one_line


class RegraspGroup(click.Group):
    """Turns domain errors into one clear line and an exit code."""

    def invoke(self, ctx: click.Context):
        try:
            return super().invoke(ctx)
        except RegraspError as exc:
            if ctx.obj and ctx.obj.get("debug"):
                raise
            click.echo(f"error: {one_line(str(exc))}", err=True)
            sys.exit(exc.exit_code)


@click.group(cls=RegraspGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="regrasp")
@click.option("--debug", is_flag=True, help="Show tracebacks instead of one-line errors.")
@click.option("--cache-dir", type=click.Path(file_okay=False, path_type=Path), default=Path("cache"),
              show_default=True, envvar="REGRASP_CACHE", help="Where cached artefacts are kept.")
@click.pass_context
def main(ctx: click.Context, debug: bool, cache_dir: Path) -> None:
    """Plan pick-and-place tasks for dual-arm robots with the fewest regrasps: one arm,
    a hand-over (Saut et al., IROS 2010) or intermediate placements (Harada et al., ICRA 2014)."""
    ctx.obj = {"debug": debug, "cache_dir": cache_dir}
    if not debug:
        warnings.showwarning = _warning_line


def _roadmap_nodes() -> int:
    """The roadmap's default size, from its options (imported when a command needs it)."""
    from regrasp_cli.roadmap.build import RoadmapOptions

    return RoadmapOptions.nodes


def _warning_line(message, category, filename, lineno, file=None, line=None) -> None:
    click.echo(f"warning: {one_line(str(message))}", err=True)


def _check_seed(ctx: click.Context, param: click.Parameter, value: int | None) -> int | None:
    if value is not None and value < 0:
        from regrasp_cli.errors import InputError

        raise InputError(None, "--seed", f"expected an integer >= 0, found {value}")
    return value


def seed_option(help: str = "Random seed (default: the scene's planning.seed)."):
    return click.option("--seed", type=int, default=None, callback=_check_seed, help=help)


def _set_cache_dir(ctx: click.Context, param: click.Parameter, value: Path | None) -> None:
    if value is not None:
        ctx.obj["cache_dir"] = value


def cache_option(f):
    """--cache-dir after the subcommand too (``regrasp plan S --cache-dir D``)."""
    return click.option("--cache-dir", type=click.Path(file_okay=False, path_type=Path), default=None,
                        expose_value=False, callback=_set_cache_dir,
                        help="Where cached artefacts are kept (as before the command; default: cache).")(f)


def cluster_options(what: str, paths: str):
    """--backend and --scheduler: where ``what`` go (the workers must see ``paths``)."""
    def decorate(f):
        f = click.option("--scheduler", default=None, metavar="ADDRESS",
                         help="The Dask scheduler's address (e.g. tcp://host:8786), for --backend dask; the workers "
                              f"must see {paths} at the same paths (a shared file system).")(f)
        return click.option("--backend", type=click.Choice(["loky", "dask"]), default="loky", show_default=True,
                            help=f"{what} go to local loky processes (--jobs at once), or to the workers of an "
                                 "existing Dask cluster (all its threads; needs --scheduler and pip install "
                                 "'regrasp[dask]').")(f)
    return decorate


@main.command()
@click.argument("scene", type=click.Path(path_type=Path))
@seed_option()
@cache_option
@click.pass_context
def info(ctx: click.Context, scene: Path, seed: int | None) -> None:
    """Summarise a scene: robot, collision pairs, obstacles, object, reachability."""
    from regrasp_cli.commands.report import print_info

    print_info(scene, ctx.obj["cache_dir"], seed)


@main.group()
def grasps() -> None:
    """Grasp lists: single grasps of each hand for the scene's object (§IV-A)."""


@grasps.command("build")
@click.argument("scene", type=click.Path(path_type=Path))
@click.option("--hand", type=click.Choice(["right", "left", "both"]), default="both", show_default=True)
@seed_option("Seed of the surface sampling (default: planning.seed).")
@click.option("--jobs", type=int, default=2, show_default=True, help="Parallel worker processes.")
@click.option("--positions", type=int, default=None, help="Grasp-frame positions in the bounding box.")
@click.option("--orientations", type=int, default=None, help="Grasp-frame orientations (SO(3) grid).")
@click.option("--target", type=int, default=None,
              help="Stop once this many distinct grasps are found (0: try every frame; default 120).")
@click.option("--pinch-frames", type=int, default=None,
              help="Fingertip hands: samples of the pinch pass run when the grid leaves the list short "
                   "(0: none).")
@click.option("--weights", type=str, default=None, metavar="FC,CENTROID,ELLIPSOID,CURVATURE",
              help="Weights of the quality terms (default 1,1,1,6 as in the paper).")
@click.option("--meshes", type=click.Path(path_type=Path), default=None, metavar="DIR",
              help="A dataset: build for each mesh file in DIR (.obj .stl .ply .off .glb, sorted by name; not "
                   "its subfolders) in place of the scene's object, one task per mesh x hand, each with one job.")
@cluster_options("With --meshes, the tasks", "the scene, the meshes and the cache folder")
@cache_option
@click.pass_context
def grasps_build(ctx: click.Context, scene: Path, hand: str, seed: int | None, jobs: int,
                 positions: int | None, orientations: int | None, target: int | None, pinch_frames: int | None,
                 weights: str | None, meshes: Path | None, backend: str, scheduler: str | None) -> None:
    """Compute the grasp list of each hand and store it in the cache (HDF5).

    With --meshes DIR, the lists of every mesh in DIR, in the cache as the one-scene build
    names them; a table says how each went, and the command exits 1 if any failed."""
    if meshes is not None:
        from regrasp_cli.commands.dataset import run_dataset_build

        run_dataset_build(scene, ctx.obj["cache_dir"], meshes, hand, seed, jobs, positions, orientations, target,
                          weights, pinch_frames, backend=backend, scheduler=scheduler)
        return
    if backend != "loky" or scheduler is not None:
        from regrasp_cli.errors import InputError

        raise InputError(None, "--backend" if backend != "loky" else "--scheduler", "only with --meshes DIR")
    from regrasp_cli.commands.report import run_grasps_build

    run_grasps_build(scene, ctx.obj["cache_dir"], hand, seed, jobs, positions, orientations, target, weights,
                     pinch_frames=pinch_frames)


@grasps.command("show")
@click.argument("file", type=click.Path(path_type=Path))
@click.option("--best", type=int, default=10, show_default=True, help="How many grasps to list (and to draw).")
@click.option("--scene", type=click.Path(path_type=Path), default=None,
              help="Check the file against this scene's robot, object and options; refuse it if stale.")
@click.option("--png", type=click.Path(path_type=Path), default=None, metavar="FILE",
              help="Also draw the best grasps on the object (hand, grasp frame, contacts and normals) into this "
                   "PNG; needs --scene.")
@cache_option
@click.pass_context
def grasps_show(ctx: click.Context, file: Path, best: int, scene: Path | None, png: Path | None) -> None:
    """Print the stored provenance and the best grasps of a grasp list; draw them with --png."""
    from regrasp_cli.commands.report import show_grasps
    from regrasp_cli.commands.show import check_grasps_png

    check_grasps_png(png, scene, best, file)
    show_grasps(file, best, scene, ctx.obj["cache_dir"])
    if png is not None:
        from regrasp_cli.commands.show import run_grasps_png

        click.echo(f"png: {run_grasps_png(file, best, scene, ctx.obj['cache_dir'], png)}")


@main.group()
def placements() -> None:
    """Stable placements of the object and where they fit on the scene's supports (Harada et al. 2014)."""


@placements.command("build")
@click.argument("scene", type=click.Path(path_type=Path))
@cache_option
@click.pass_context
def placements_build(ctx: click.Context, scene: Path) -> None:
    """Compute the object's stable placements, store them in the cache (HDF5) and list
    how many fit on each support of the scene."""
    from regrasp_cli.commands.placements import run_placements_build

    run_placements_build(scene, ctx.obj["cache_dir"])


@placements.command("show")
@click.argument("file", type=click.Path(path_type=Path))
@click.option("--scene", type=click.Path(path_type=Path), default=None,
              help="Check the file against this scene's object (refuse it if stale) and count the fits on its "
                   "supports.")
@click.option("--png", type=click.Path(path_type=Path), default=None, metavar="FILE",
              help="Also draw the placements into this PNG; needs --scene.")
@cache_option
def placements_show(file: Path, scene: Path | None, png: Path | None) -> None:
    """Print the stored provenance and the placements of a placements file; draw them with --png."""
    from regrasp_cli.commands.placements import show_placements

    show_placements(file, scene, png)


@main.group()
def roadmap() -> None:
    """Offline roadmap: elementary Vis-PRM roadmaps composed into the Super Graph (§V-A)."""


@roadmap.command("build")
@click.argument("scene", type=click.Path(path_type=Path))
@click.option("--nodes", type=int, default=lambda: _roadmap_nodes(), show_default=True,
              help="Nodes of each elementary roadmap.")
@click.option("--tree", is_flag=True, help="Super Graph edges only between different components (a forest).")
@seed_option()
@click.option("--jobs", type=int, default=2, show_default=True, help="Parallel worker processes.")
@cache_option
@click.pass_context
def roadmap_build(ctx: click.Context, scene: Path, nodes: int, tree: bool, seed: int | None, jobs: int) -> None:
    """Build the elementary roadmaps and the Super Graph; store them in the cache (HDF5)."""
    from regrasp_cli.commands.report import run_roadmap_build

    run_roadmap_build(scene, ctx.obj["cache_dir"], nodes, tree, seed, jobs)


@roadmap.command("show")
@click.argument("file", type=click.Path(path_type=Path))
@click.option("--scene", type=click.Path(path_type=Path), default=None,
              help="Check the file against this scene's robot and obstacles; refuse it if stale.")
@cache_option
@click.pass_context
def roadmap_show(ctx: click.Context, file: Path, scene: Path | None) -> None:
    """Print the stored provenance and summary of a roadmap."""
    from regrasp_cli.commands.report import show_roadmap

    show_roadmap(file, scene, ctx.obj["cache_dir"])


@main.command()
@click.argument("scene", type=click.Path(path_type=Path))
@click.option("-o", "--output", type=click.Path(path_type=Path), default=Path("plan.json"),
              show_default=True, help="Where to write the plan JSON.")
@seed_option()
@click.option("--planner", type=click.Choice(["roadmap", "rrt-connect", "ompl-rrtconnect"]), default="roadmap",
              show_default=True,
              help="Queries through the cached Super Graph, single-query RRT-Connect (the paper's baseline) or "
                   "OMPL's RRT-Connect (extra 'ompl').")
@click.option("--no-build", is_flag=True, help="Refuse missing or stale artefacts instead of building them.")
@click.option("--jobs", type=int, default=2, show_default=True,
              help="Worker processes for artefact builds and the online stages (the plan does not depend on it).")
@click.option("--no-timings", is_flag=True,
              help="Leave wall-clock times out of the plan, so that the same seed writes the same bytes.")
@click.option("--no-check", is_flag=True, help="Skip the independent validation of the written plan.")
@click.option("--roadmap-nodes", type=int, default=lambda: _roadmap_nodes(), show_default=True,
              help="Nodes per elementary roadmap of the roadmap to use (built if missing).")
@click.option("--grasp-target", type=int, default=None,
              help="Target size of the grasp lists to use (built if missing; default 120).")
@click.option("--style", type=click.Choice(["auto", "one-arm", "handover", "inhand", "place-regrasp", "seed000"]),
              default="auto", show_default=True,
              help="auto: the manipulation with the fewest regrasps (one arm, hand-overs, intermediate placements); "
                   "or only one arm, only hand-overs, only turning the object in one hand's fingers (inhand, tried "
                   "last by auto), only intermediate placements; seed000: the fixed hand-over task of Saut et al. "
                   "2010.")
@click.option("--sampler", type=click.Choice(["faces", "vis-prm"]), default="faces", show_default=True,
              help="Where intermediate placements come from: one fit per resting face of the object, or a "
                   "Visibility-PRM over the hands' grasps at placements on the supports (Harada et al. 2014 §IV-B-2).")
@click.option("--held-speed", type=float, default=None,
              help="Share of the arms' speed at which a held object moves (velocity limits times it, "
                   "accelerations times its square; default 0.5: fingertip grasps slip at full speed).")
@cache_option
@click.pass_context
def plan(ctx: click.Context, scene: Path, output: Path, seed: int | None, planner: str, no_build: bool, jobs: int,
         no_timings: bool, no_check: bool, roadmap_nodes: int, grasp_target: int | None, style: str,
         sampler: str, held_speed: float | None) -> None:
    """Plan how the robot moves the scene's object from its start to its goal pose with
    the fewest regrasps; write the plan JSON.

    Exits 0 when solved, 1 with the failing stage and reason when not."""
    from regrasp_cli.commands.plan import run_plan

    run_plan(scene, ctx.obj["cache_dir"], output, seed, planner, not no_build, jobs, not no_timings, not no_check,
             roadmap_nodes, grasp_target, style=style, sampler=sampler, held_speed=held_speed)


@main.group()
def inhand() -> None:
    """In-hand manipulation: a hand reorients the object in its fingers (Saut et al., seed 003)."""


@inhand.command("plan")
@click.argument("scene", type=click.Path(path_type=Path))
@click.option("-o", "--output", type=click.Path(path_type=Path), default=Path("plan.json"),
              show_default=True, help="Where to write the plan JSON.")
@seed_option()
@click.option("--no-timings", is_flag=True,
              help="Leave wall-clock times out of the plan, so that the same seed writes the same bytes.")
@click.option("--no-check", is_flag=True, help="Skip the independent validation of the written plan.")
@click.option("--mode", type=click.Choice(["single-query", "multi-query"]), default=None,
              help="Override the scene's planning.mode: trees from the start and goal, or the learned roadmap "
                   "(`regrasp inhand roadmap`, built first when missing).")
@cache_option
@click.pass_context
def inhand_plan(ctx: click.Context, scene: Path, output: Path, seed: int | None, no_timings: bool,
                no_check: bool, mode: str | None) -> None:
    """Plan the finger gaits that turn the object held in the hand's fingertips from its
    start to its goal pose (format regrasp.inhand/1); write the plan JSON.

    Exits 0 when solved, 1 with the failing stage and reason when not."""
    from regrasp_cli.commands.inhand import run_inhand_plan

    run_inhand_plan(scene, ctx.obj["cache_dir"], output, seed, not no_timings, not no_check, mode=mode)


@inhand.command("roadmap")
@click.argument("scene", type=click.Path(path_type=Path))
@cache_option
@click.pass_context
def inhand_roadmap(ctx: click.Context, scene: Path) -> None:
    """Learn the multi-query GS_n roadmap (seed 003 §V) for the scene's hand, object,
    friction and placement, and cache it; queries with `--mode multi-query` (or
    planning.mode: multi-query) use it.  Exits 1 when no grasp joined the roadmap."""
    from regrasp_cli.commands.inhand import run_inhand_roadmap

    run_inhand_roadmap(scene, ctx.obj["cache_dir"])


@main.command()
@click.argument("plan_file", metavar="PLAN", type=click.Path(path_type=Path))
@click.option("--resolution", type=float, default=0.01, show_default=True,
              help="Largest joint step (rad) between two checked configurations.")
@click.option("--cartesian-step", type=float, default=0.005, show_default=True,
              help="Largest displacement (m) of any robot point between two checked configurations.")
def validate(plan_file: Path, resolution: float, cartesian_step: float) -> None:
    """Replay a plan with independent checks; exit 0 when valid, 1 when not."""
    from rich.console import Console

    from regrasp_cli.errors import InputError
    from regrasp_cli.commands.validate import print_validation
    from regrasp_cli.validate import validate_plan

    for value, name in ((resolution, "--resolution"), (cartesian_step, "--cartesian-step")):
        if not value > 0:
            raise InputError(None, name, f"expected a number > 0, found {value}")
    report = validate_plan(plan_file, resolution, cartesian_step)
    print_validation(report, Console())
    if not report.valid:
        sys.exit(1)


@main.command()
@click.argument("plan_file", metavar="PLAN", type=click.Path(path_type=Path))
@click.option("--html", "html_file", type=click.Path(path_type=Path), default=None, metavar="FILE",
              help="Write an animated 3D view of the plan: one self-contained HTML file (no server, no network).")
@click.option("--png", "png_dir", type=click.Path(path_type=Path), default=None, metavar="DIR",
              help="Write the key frames (01_start, 02_pick, 03_exchange, 04_place, 05_end) as PNG into DIR.")
@click.option("--fps", type=int, default=25, show_default=True, help="Samples per second of the animation.")
@click.option("--size", default="960x720", show_default=True, metavar="WxH", help="Size of the PNG pictures (pixels).")
@click.option("--geometry", type=click.Choice(["visual", "collision"]), default="visual", show_default=True,
              help="Draw the robot's visual geometry, or the collision geometry the planner checked.")
def show(plan_file: Path, html_file: Path | None, png_dir: Path | None, fps: int, size: str, geometry: str) -> None:
    """Look at a plan: an animated 3D page and key-frame pictures.  Give --html, --png or both."""
    from regrasp_cli.commands.show import run_show

    run_show(plan_file, html_file, png_dir, fps, size, geometry)


@main.command()
@click.argument("plan_file", metavar="PLAN", type=click.Path(path_type=Path))
@click.option("-o", "--output", "outputs", type=click.Path(path_type=Path), multiple=True, metavar="FILE",
              help="Write the samples to FILE, in the format its name asks for: .csv, .npz, .json, or "
                   ".joint_trajectory.json (shaped like ROS trajectory_msgs/JointTrajectory).  Repeatable.")
@click.option("--rate", type=float, default=100.0, show_default=True, help="Samples per second (Hz).")
def export(plan_file: Path, outputs: tuple[Path, ...], rate: float) -> None:
    """Sample a solved plan for a controller: every joint's position, velocity and
    acceleration at a fixed rate, with the phase, the holding hands and grasps, the
    object's pose and the gripper events."""
    from regrasp_cli.commands.export import run_export

    for path in run_export(plan_file, outputs, rate):
        click.echo(f"samples: {path}")


@main.command()
@click.argument("plan_file", metavar="PLAN", type=click.Path(path_type=Path))
@click.option("-o", "--output", "report_file", type=click.Path(path_type=Path), default=None, metavar="FILE",
              help="Also write the report as JSON to FILE.")
@click.option("--squeeze", type=float, default=None,
              help="Newtons each contact of a holding hand pushes with, along the surface's inward normal "
                   "[default: 20].")
@click.option("--position-tol", type=float, default=None,
              help="Metres the object may drift from where the plan says it is, in any phase [default: 0.01].")
@click.option("--angle-tol", type=float, default=None,
              help="Radians the object may turn from the plan's orientation, in any phase [default: 0.1].")
@cache_option
@click.pass_context
def simulate(ctx: click.Context, plan_file: Path, report_file: Path | None, squeeze: float | None,
             position_tol: float | None, angle_tol: float | None) -> None:
    """Check a solved plan in physics (MuJoCo, `pip install 'regrasp[sim]'`): the robot
    tracks the plan under gravity, the fingers squeeze with a bounded force, and the object
    is a free body with the plan's friction.  Exit 0 when the object stays within the
    tolerances of the plan in every phase, 1 when it does not (naming the phase)."""
    from rich.console import Console

    from regrasp_cli.commands.simulate import print_report, run_simulate

    report = run_simulate(plan_file, report_file, ctx.obj["cache_dir"], squeeze, position_tol, angle_tol)
    print_report(report, Console())
    if not report.ok:
        sys.exit(1)


@main.command()
@click.argument("folder", metavar="DIR", type=click.Path(path_type=Path), required=False)
@click.option("--force", is_flag=True, help="Overwrite files already in DIR.")
def examples(folder: Path | None, force: bool) -> None:
    """List the shipped robots and example scenes; with DIR, copy them there to edit.

    A scene names a shipped robot as `robot: builtin:NAME`."""
    from regrasp_cli.commands.report import run_examples

    run_examples(folder, force)


@main.command()
@click.argument("suite_file", metavar="SUITE", type=click.Path(path_type=Path))
@click.option("-o", "--output", type=click.Path(path_type=Path), default=None, metavar="DIR",
              help="Results folder (default: bench-results/<suite name>/).")
@click.option("--jobs", type=int, default=2, show_default=True,
              help="Runs at once, each in its own process (also the processes of missing artefact builds).")
@click.option("--seeds", type=int, default=None, help="Override the suite's seeds with 0 .. N-1.")
@click.option("--planners", default=None, metavar="A,B", help="Override the suite's planners.")
@click.option("--budget-s", type=float, default=None, help="Override the suite's wall-clock budget per run (s).")
@click.option("--iterations", type=int, default=None,
              help="Override the suite's RRT-Connect iterations per query (every planner's).")
@cluster_options("The runs", "the cache and results folders")
@cache_option
@click.pass_context
def bench(ctx: click.Context, suite_file: Path, output: Path | None, jobs: int, seeds: int | None,
          planners: str | None, budget_s: float | None, backend: str, scheduler: str | None,
          iterations: int | None) -> None:
    """Run a benchmark suite: every scene x planner x seed, each run in its own process
    with a time budget; write runs.jsonl, summary.md and times.png and print the tables.
    An in-hand suite (format regrasp.inhand-bench/1) runs every hand x object x goal.

    A failed run (no plan, invalid plan, crash, over budget) is recorded with its reason."""
    from regrasp_cli.commands.bench import run_bench

    run_bench(suite_file, ctx.obj["cache_dir"], output, jobs, seeds, planners, budget_s,
              backend=backend, scheduler=scheduler, iterations=iterations)


if __name__ == "__main__":  # pragma: no cover
    main()
