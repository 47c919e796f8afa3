"""`regrasp inhand plan SCENE`: in-hand reorientation by finger gaiting (seed 003), plan
JSON out, a summary printed; the plan is checked by the independent validator before
the command reports success."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

from rich.console import Console

from regrasp_cli.commands.report import CliBuilder
from regrasp_cli.config import load_inhand_spec, scene_files
from regrasp_cli.dexterous.record import make_inhand_plan
from regrasp_cli.dexterous.task import load_inhand_problem, plan_inhand
from regrasp_cli.store import check_writable
from regrasp_cli.trajectory import write_plan


def run_inhand_plan(scene: Path, cache_dir: Path, out_file: Path, seed: int | None, timings: bool, check: bool,
                    console: Console | None = None, mode: str | None = None) -> int:
    """The `inhand plan` command; returns 0 when solved, raises the outcome's
    PlanningFailed (exit 1) when not."""
    from regrasp_cli.commands.validate import check_written

    console = console or Console()
    check_writable(out_file, "--output", inputs=scene_files(load_inhand_spec(scene)))
    problem = load_inhand_problem(scene, cache_dir)
    if mode is not None:
        problem = replace(problem, spec=replace(problem.spec, planning=replace(problem.spec.planning, mode=mode)))
    seed = problem.spec.planning.seed if seed is None else seed
    what = "planning the finger gaits" + (" (building the roadmap if missing)"
                                          if problem.spec.planning.mode == "multi-query" else "")
    with console.status(what) as status:
        def progress(done: int, budget: int) -> None:
            if done % 25 == 0:  # a redraw costs more than an expansion's bookkeeping
                status.update(f"{what}: {done} of {budget} expansions")
        out = plan_inhand(problem, cache_dir, seed, progress, CliBuilder(console))
    plan = make_inhand_plan(problem, out, seed, out_file, cache_dir, timings)
    write_plan(out_file, plan)
    st = out.stats
    if out.failure is not None:
        console.print(f"[red]not solved[/red]: stage {out.failure.stage.value}: {out.failure.reason}")
        console.print(f"plan (status failed): {out_file}")
        raise out.failure
    stages = ", ".join(f"{k} {v:.2f} s" for k, v in st["stages_s"].items())
    console.print(f"in-hand ({problem.robot.spec.file.parent.name}, {problem.hand} hand, seed {seed}): "
                  f"{stages}; total {st['planning_s']:.2f} s")
    console.print(f"GS_n tree: {st['nodes_generated']} configurations generated, {st['nodes_kept']} nodes kept "
                  f"({st['iterations']} expansions, {st['trees']} tree(s)); the start grasp lets "
                  f"{st['start_liftable']} fingers go")
    console.print(f"motion of {plan.duration:.1f} s: {st['transfers']} transfers, {st['regrasps']} finger regrasps "
                  f"(gaits), {sum(len(p.waypoints) for p in plan.phases)} waypoints; before smoothing "
                  f"{st['transfers_unsmoothed']} transfers, {st['regrasps_unsmoothed']} regrasps")
    if check:
        check_written(out_file, console)
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
        rm, st, built = inhand_roadmap(problem, cache_dir, progress=lambda k, n: bar.update(task, completed=k, total=n),
                                       builder=CliBuilder(console))
    edges = len(rm.edges)
    if not built:
        console.print(f"roadmap fresh in the cache: {len(rm.nodes)} nodes, {edges} edges")
        return 0
    console.print(f"roadmap learned in {perf_counter() - t:.1f} s: {st.joined} of {st.roots} grasps at random "
                  f"orientations joined, {len(rm.nodes)} nodes, {edges} edges ({st.expansions} expansions)")
    return 0
