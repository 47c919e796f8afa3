"""`regrasp plan SCENE`: cached artefacts in, plan JSON out, a Table I summary printed.

The robot's start and goal configurations are checked first (nothing else matters if
they collide).  Missing or stale artefacts (grasp lists, roadmap) are then built with
their progress bars, or refused with ``--no-build``; an empty one fails the plan at stage
``grasps`` or ``roadmap`` with the build's reason.  The plan is then checked by the
independent validator (:mod:`regrasp_cli.validate`) before the command reports success.
"""

from __future__ import annotations

from pathlib import Path

from rich.console import Console
from rich.table import Table

from regrasp_cli.commands.progress import scene_inputs, self_collision_bar
from regrasp_cli.commands.report import CliBuilder
from regrasp_cli.commands.validate import print_validation
from regrasp_cli.errors import InputError
from regrasp_cli.manip.ompl_peer import ompl_version
from regrasp_cli.manip.solve import Outcome
from regrasp_cli.pipeline import Request, load_task, run_task
from regrasp_cli.roadmap.build import RoadmapOptions
from regrasp_cli.store import check_writable
from regrasp_cli.trajectory import Plan


def print_summary(plan: Plan, outcome: Outcome, console: Console) -> None:
    """Table I of the paper, one row per transit or transfer query: nodes and seconds of
    the online planning (search, connections, repairs, smoothing) and of the lazy path
    validation; then the task's stages."""
    ompl = f" {plan.stats['ompl_version']}" if "ompl_version" in plan.stats else ""
    t = Table(title=f"Online planning ({outcome.task}, {plan.planner}{ompl}, seed {plan.seed}): n nodes, T seconds",
              caption="planning: search, connections, repairs, smoothing; validation: lazy checks "
                      "(n: invalid edges found)")
    for c in ("query", "planning n", "planning T", "validation n", "validation T", "total T"):
        t.add_column(c, justify="right")
    for q, s in outcome.transitions.items():
        t.add_row(q, str(s.nodes), f"{s.planning_s:.2f}", str(s.invalid_edges), f"{s.validation_s:.2f}",
                  f"{s.planning_s + s.validation_s:.2f}")
    console.print(t)
    stages = ", ".join(f"{k} {v:.2f} s" for k, v in outcome.stages.items())
    kinds = " ".join(p.kind.value for p in plan.phases)
    console.print(f"{stages}: total {outcome.planning_s:.2f} s; motion of {plan.duration:.1f} s in "
                  f"{sum(len(p.waypoints) for p in plan.phases)} waypoints over {len(plan.phases)} phases "
                  f"({kinds})")
    styles = outcome.counts.get("styles")
    if styles:
        r, n = outcome.counts.get("regrasps", 0), outcome.counts.get("placements", 0)
        console.print(f"style: {outcome.counts['style']}, {r} regrasp{'s' * (r != 1)}, {n} intermediate "
                      f"placement{'s' * (n != 1)}")
        for name, why in styles.items():
            if why != "chosen":
                console.print(f"  {name} not used: {why}")


def run_plan(scene: Path, cache_dir: Path, out_file: Path, seed: int | None, planner: str, build: bool, jobs: int,
             timings: bool, check: bool, roadmap_nodes: int = RoadmapOptions.nodes, grasp_target: int | None = None,
             console: Console | None = None, style: str = "auto", sampler: str = "faces",
             held_speed: float | None = None) -> int:
    """The `plan` command; returns the exit code (0 solved, 1 not)."""
    console = console or Console()
    for value, name, least in ((roadmap_nodes, "--roadmap-nodes", 1), (grasp_target, "--grasp-target", 0),
                               (jobs, "--jobs", 1)):
        if value is not None and value < least:  # named as this command spells them, not as the builds do
            raise InputError(None, name, f"expected an integer >= {least}, found {value}")
    if held_speed is not None and not 0.0 < held_speed <= 1.0:
        raise InputError(None, "--held-speed", f"expected a number in (0, 1], found {held_speed:g}")
    check_writable(out_file, "--output", inputs=scene_inputs(scene))  # before the work, not after it
    if planner == "ompl-rrtconnect":
        ompl_version()  # InputError naming the extra before anything is loaded
    request = Request(planner=planner, style=style, seed=seed, jobs=jobs, sampler=sampler,
                      roadmap_nodes=roadmap_nodes, grasp_target=grasp_target, held_speed=held_speed)
    with self_collision_bar() as progress:
        loaded = load_task(scene, cache_dir, request, build, CliBuilder(console), progress)
    run = run_task(loaded, request, out_file, check, timings)
    if run.outcome.failure is not None:
        f = run.outcome.failure
        where = f.stage.value + (f" ({f.transition})" if f.transition else "")
        console.print(f"[red]not solved[/red]: stage {where}: {f.reason}")
        console.print(f"plan (status failed): {out_file}")
        raise f
    print_summary(run.plan, run.outcome, console)
    if run.report is not None:
        print_validation(run.report, console)
    if run.refused is not None:
        console.print(f"plan (status failed): {out_file}")
        raise run.refused
    console.print(f"plan: {out_file}")
    return 0
