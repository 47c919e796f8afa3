"""`regrasp inhand plan SCENE`: in-hand reorientation by finger gaiting (seed 003), plan
JSON out, a summary printed; the plan is checked by the independent validator before
the command reports success."""

from __future__ import annotations

from pathlib import Path

from rich.console import Console

from regrasp_cli.dexterous.record import make_inhand_plan
from regrasp_cli.dexterous.task import load_inhand_problem, plan_inhand
from regrasp_cli.store import check_writable
from regrasp_cli.trajectory import write_plan


def run_inhand_plan(scene: Path, cache_dir: Path, out_file: Path, seed: int | None, timings: bool, check: bool,
                    console: Console | None = None) -> int:
    """The `inhand plan` command; returns 0 when solved, raises the outcome's
    PlanningFailed (exit 1) when not."""
    from regrasp_cli.commands.validate import check_written

    console = console or Console()
    check_writable(out_file, "--output")
    problem = load_inhand_problem(scene, cache_dir)
    seed = problem.spec.planning.seed if seed is None else seed
    with console.status("planning the finger gaits"):
        out = plan_inhand(problem, cache_dir, seed)
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
