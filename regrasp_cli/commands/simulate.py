"""`regrasp simulate PLAN`: the plan driven in MuJoCo under gravity, the object's drift
from the plan per phase (:mod:`regrasp_cli.simulate`)."""

from __future__ import annotations

import json
from dataclasses import asdict, replace
from pathlib import Path

from rich.console import Console
from rich.markup import escape
from rich.table import Table

from regrasp_cli.errors import InputError
from regrasp_cli.replay import load_inputs
from regrasp_cli.simulate import SimOptions, SimReport, import_mujoco, run
from regrasp_cli.store import atomic_write_text, check_writable
from regrasp_cli.trajectory import read_plan

MAX_SQUEEZE = 1000.0  # N per contact


def run_simulate(plan_file: Path, report_file: Path | None, cache_dir: Path | None, squeeze: float | None = None,
                 position_tol: float | None = None, angle_tol: float | None = None) -> SimReport:
    """Simulate ``plan_file`` (the options not given as :class:`SimOptions`' defaults;
    the object's convex parts cached in ``cache_dir``); write the report as JSON to
    ``report_file`` when given."""
    opts = SimOptions()
    checks = (("--squeeze", "squeeze_n", squeeze, MAX_SQUEEZE), ("--position-tol", "position_tol", position_tol, 10.0),
              ("--angle-tol", "angle_tol", angle_tol, 3.2))
    for name, key, value, hi in checks:
        if value is None:
            continue
        if not 0.0 < value <= hi:
            raise InputError(None, name, f"expected a number in (0, {hi:g}], found {value:g}")
        opts = replace(opts, **{key: value})
    if report_file is not None:
        check_writable(report_file, "-o/--output", inputs=(plan_file,))
    import_mujoco()  # say it is missing before reading anything
    plan = read_plan(plan_file)
    if plan.status != "solved" or not plan.phases:
        raise InputError(plan_file, "status", f"expected a solved plan, found {plan.status!r} (a failed plan has no "
                                              "motion to simulate)")
    inputs = load_inputs(plan, plan_file)
    report = run(plan, plan_file, inputs, opts, cache_dir)
    if report_file is not None:
        atomic_write_text(report_file, json.dumps(report_json(report), indent=1) + "\n")
    return report


def report_json(r: SimReport) -> dict:
    return {"format": "regrasp.simulation/1", "plan": r.plan, "ok": r.ok, "options": asdict(r.options),
            "object_mass": r.object_mass, "object_parts": r.object_parts, "tracking_error": r.tracking_error,
            "wall_s": r.wall_s, "diverged": r.diverged, "phases": [asdict(p) for p in r.phases]}


def print_report(r: SimReport, console: Console) -> None:
    """A table per phase (largest and last drift, dropped) and a last line ``held`` or
    ``NOT HELD in phase NAME``."""
    t = Table(title=f"Simulation (object {r.object_mass:.3f} kg, {r.object_parts} convex parts, squeeze "
                    f"{r.options.squeeze_n:g} N per contact)")
    for col in ("phase", "kind", "s", "drift mm", "angle rad", "end mm", "dropped", "ok"):
        t.add_column(col, justify="left" if col in ("phase", "kind") else "right", no_wrap=col != "phase",
                     overflow="fold")
    for p in r.phases:
        t.add_row(escape(p.name), p.kind, f"{p.t1 - p.t0:.2f}", f"{p.max_position * 1000:.1f}", f"{p.max_angle:.3f}",
                  f"{p.end_position * 1000:.1f}", "yes" if p.dropped else "", "yes" if p.ok else "NO")
    console.print(t)
    console.print(f"tracking error at the end {r.tracking_error:.2g}; simulated in {r.wall_s:.1f} s")
    bad = r.first_failure
    if r.diverged:
        console.print("NOT JUDGED: the simulation diverged (MuJoCo reset its state); the drifts say nothing of the "
                      "plan")
    elif bad is None:
        console.print(f"held: the object stayed within {r.options.position_tol * 1000:g} mm and "
                      f"{r.options.angle_tol:g} rad of the plan in every phase")
    else:
        what = "dropped" if bad.dropped else (f"drifted {bad.max_position * 1000:.1f} mm and "
                                              f"{bad.max_angle:.3f} rad")
        console.print(f"NOT HELD in phase {escape(bad.name)} ({bad.kind}, from {bad.t0:.2f} s): the object {what}")
