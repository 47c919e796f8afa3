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
from regrasp_cli.errors import RegraspError


class RegraspGroup(click.Group):
    """Turns domain errors into one clear line and an exit code."""

    def invoke(self, ctx: click.Context):
        try:
            return super().invoke(ctx)
        except RegraspError as exc:
            if ctx.obj and ctx.obj.get("debug"):
                raise
            click.echo(f"error: {exc}", err=True)
            sys.exit(exc.exit_code)


@click.group(cls=RegraspGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="regrasp")
@click.option("--debug", is_flag=True, help="Show tracebacks instead of one-line errors.")
@click.option("--cache-dir", type=click.Path(file_okay=False, path_type=Path), default=Path("cache"),
              show_default=True, envvar="REGRASP_CACHE", help="Where cached artefacts are kept.")
@click.pass_context
def main(ctx: click.Context, debug: bool, cache_dir: Path) -> None:
    """Plan pick-and-place tasks with two-hand regrasping for dual-arm robots
    (Saut et al., IROS 2010)."""
    ctx.obj = {"debug": debug, "cache_dir": cache_dir}
    if not debug:
        warnings.showwarning = _warning_line


def _warning_line(message, category, filename, lineno, file=None, line=None) -> None:
    click.echo(f"warning: {message}", err=True)


@main.command()
@click.argument("scene", type=click.Path(path_type=Path))
@click.option("--seed", type=int, default=None, help="Random seed (default: the scene's planning.seed).")
@click.pass_context
def info(ctx: click.Context, scene: Path, seed: int | None) -> None:
    """Summarise a scene: robot, collision pairs, obstacles, object, reachability."""
    from regrasp_cli.report import print_info

    print_info(scene, ctx.obj["cache_dir"], seed)


@main.group()
def grasps() -> None:
    """Grasp lists: single grasps of each hand for the scene's object (§IV-A)."""


@grasps.command("build")
@click.argument("scene", type=click.Path(path_type=Path))
@click.option("--hand", type=click.Choice(["right", "left", "both"]), default="both", show_default=True)
@click.option("--seed", type=int, default=None, help="Seed of the surface sampling (default: planning.seed).")
@click.option("--jobs", type=int, default=2, show_default=True, help="Parallel worker processes.")
@click.option("--positions", type=int, default=None, help="Grasp-frame positions in the bounding box.")
@click.option("--orientations", type=int, default=None, help="Grasp-frame orientations (SO(3) grid).")
@click.option("--target", type=int, default=None,
              help="Stop once this many distinct grasps are found (0: try every frame; default 120).")
@click.option("--weights", type=str, default=None, metavar="FC,CENTROID,ELLIPSOID,CURVATURE",
              help="Weights of the quality terms (default 1,1,1,6 as in the paper).")
@click.pass_context
def grasps_build(ctx: click.Context, scene: Path, hand: str, seed: int | None, jobs: int,
                 positions: int | None, orientations: int | None, target: int | None, weights: str | None) -> None:
    """Compute the grasp list of each hand and store it in the cache (HDF5)."""
    from regrasp_cli.report import run_grasps_build

    run_grasps_build(scene, ctx.obj["cache_dir"], hand, seed, jobs, positions, orientations, target, weights)


@grasps.command("show")
@click.argument("file", type=click.Path(path_type=Path))
@click.option("--best", type=int, default=10, show_default=True, help="How many grasps to list.")
@click.option("--scene", type=click.Path(path_type=Path), default=None,
              help="Check the file against this scene's robot, object and options; refuse it if stale.")
@click.pass_context
def grasps_show(ctx: click.Context, file: Path, best: int, scene: Path | None) -> None:
    """Print the stored provenance and the best grasps of a grasp list."""
    from regrasp_cli.report import show_grasps

    show_grasps(file, best, scene, ctx.obj["cache_dir"])


@main.group()
def roadmap() -> None:
    """Offline roadmap: elementary Vis-PRM roadmaps composed into the Super Graph (§V-A)."""


@roadmap.command("build")
@click.argument("scene", type=click.Path(path_type=Path))
@click.option("--nodes", type=int, default=50, show_default=True, help="Nodes of each elementary roadmap.")
@click.option("--tree", is_flag=True, help="Super Graph edges only between different components (a forest).")
@click.option("--seed", type=int, default=None, help="Random seed (default: the scene's planning.seed).")
@click.option("--jobs", type=int, default=2, show_default=True, help="Parallel worker processes.")
@click.pass_context
def roadmap_build(ctx: click.Context, scene: Path, nodes: int, tree: bool, seed: int | None, jobs: int) -> None:
    """Build the elementary roadmaps and the Super Graph; store them in the cache (HDF5)."""
    from regrasp_cli.report import run_roadmap_build

    run_roadmap_build(scene, ctx.obj["cache_dir"], nodes, tree, seed, jobs)


@roadmap.command("show")
@click.argument("file", type=click.Path(path_type=Path))
@click.option("--scene", type=click.Path(path_type=Path), default=None,
              help="Check the file against this scene's robot and obstacles; refuse it if stale.")
@click.pass_context
def roadmap_show(ctx: click.Context, file: Path, scene: Path | None) -> None:
    """Print the stored provenance and summary of a roadmap."""
    from regrasp_cli.report import show_roadmap

    show_roadmap(file, scene, ctx.obj["cache_dir"])


if __name__ == "__main__":  # pragma: no cover
    main()
