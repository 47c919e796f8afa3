"""`regrasp inhand plan SCENE`: in-hand reorientation by finger gaiting (seed 003), plan
JSON out, a summary printed: the pipeline of every task (:mod:`regrasp_cli.pipeline`),
the plan checked by the independent validator before the command reports success."""

from __future__ import annotations

from pathlib import Path

from rich.console import Console

from regrasp_cli.commands.report import CliBuilder
from regrasp_cli.commands.validate import print_validation
from regrasp_cli.config import load_inhand_spec, scene_files
from regrasp_cli.dexterous.task import load_inhand_problem
from regrasp_cli.pipeline import Request, load_task, run_task
from regrasp_cli.store import check_writable


def run_inhand_plan(scene: Path, cache_dir: Path, out_file: Path, seed: int | None, timings: bool, check: bool,
                    console: Console | None = None, mode: str | None = None) -> int:
    """The `inhand plan` command; returns 0 when solved, raises the outcome's
    PlanningFailed (exit 1) when not."""
    console = console or Console()
    check_writable(out_file, "--output", inputs=scene_files(load_inhand_spec(scene)))
    request = Request(seed=seed, mode=mode)
    loaded = load_task(scene, cache_dir, request)
    what = "planning the finger gaits" + (" (building the roadmap if missing)"
                                          if loaded.problem.spec.planning.mode == "multi-query" else "")
    with console.status(what) as status:
        def progress(done: int, budget: int) -> None:
            if done % 25 == 0:  # a redraw costs more than an expansion's bookkeeping
                status.update(f"{what}: {done} of {budget} expansions")
        run = run_task(loaded, request, out_file, check, timings, progress, CliBuilder(console))
    out = run.outcome
    if out.failure is not None:
        console.print(f"[red]not solved[/red]: stage {out.failure.stage.value}: {out.failure.reason}")
        console.print(f"plan (status failed): {out_file}")
        raise out.failure
    st, problem = out.counts, loaded.problem
    stages = ", ".join(f"{k} {v:.2f} s" for k, v in out.stages.items())
    console.print(f"in-hand ({problem.robot.spec.file.parent.name}, {problem.spec.hand} hand, seed {run.plan.seed}): "
                  f"{stages}; total {out.planning_s:.2f} s")
    console.print(f"GS_n tree: {st['nodes_generated']} configurations generated, {st['nodes_kept']} nodes kept "
                  f"({st['iterations']} expansions, {st['trees']} tree(s)); the start grasp lets "
                  f"{st['start_liftable']} fingers go")
    console.print(f"motion of {run.plan.duration:.1f} s: {st['transfers']} transfers, {st['finger_regrasps']} finger "
                  f"regrasps (gaits), {sum(len(p.waypoints) for p in run.plan.phases)} waypoints; before smoothing "
                  f"{st['transfers_unsmoothed']} transfers, {st['finger_regrasps_unsmoothed']} regrasps")
    if run.report is not None:
        print_validation(run.report, console)
    if run.refused is not None:
        console.print(f"plan (status failed): {out_file}")
        raise run.refused
    console.print(f"plan: {out_file}")
    return 0


def run_inhand_roadmap(scene: Path, cache_dir: Path, console: Console | None = None) -> int:
    """The `inhand roadmap` command: learn (or find fresh in the cache) the roadmap."""
    from time import perf_counter

    from rich.progress import Progress

    from regrasp_cli.dexterous.task import inhand_roadmap

    console = console or Console()
    problem = load_inhand_problem(scene, cache_dir)
    t = perf_counter()
    with Progress(console=console, transient=True) as bar:
        task = bar.add_task("learning the GS_n roadmap (grasps joined)", total=None)
        rm, st, built = inhand_roadmap(problem, progress=lambda k, n: bar.update(task, completed=k, total=n),
                                       builder=CliBuilder(console))
    edges = len(rm.edges)
    if not built:
        console.print(f"roadmap fresh in the cache: {len(rm.nodes)} nodes, {edges} edges")
        return 0
    console.print(f"roadmap learned in {perf_counter() - t:.1f} s: {st.joined} of {st.roots} grasps at random "
                  f"orientations joined, {len(rm.nodes)} nodes, {edges} edges ({st.expansions} expansions)")
    return 0
