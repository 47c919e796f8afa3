"""`regrasp export PLAN -o FILE ...`: a solved plan sampled for a controller
(:mod:`regrasp_cli.export`)."""

from __future__ import annotations

from pathlib import Path

from regrasp_cli.errors import InputError
from regrasp_cli.export import SUFFIXES, sample_plan, suffix_of, write
from regrasp_cli.replay import load_inputs
from regrasp_cli.store import check_writable
from regrasp_cli.trajectory import read_plan

MAX_RATE = 100_000.0  # Hz


def run_export(plan_file: Path, outputs: tuple[Path, ...], rate: float) -> list[Path]:
    """Sample ``plan_file`` at ``rate`` Hz and write each of ``outputs`` in the format its
    name asks for; the paths written."""
    if not outputs:
        raise InputError(None, "-o/--output", f"nothing to do: give -o FILE ({', '.join(SUFFIXES)})")
    if not 0 < rate <= MAX_RATE:
        raise InputError(None, "--rate", f"expected a rate in (0, {MAX_RATE:g}] Hz, found {rate:g}")
    for out in outputs:
        if suffix_of(out) is None:
            raise InputError(None, "-o/--output", f"expected a file name ending in {', '.join(SUFFIXES)}, "
                                                  f"found {out.name}")
        check_writable(out, "-o/--output", inputs=(plan_file,))
    plan = read_plan(plan_file)
    if plan.status != "solved":
        raise InputError(plan_file, "status", f"expected a solved plan, found {plan.status!r} (a failed plan has no "
                                              "motion to export)")
    inputs = load_inputs(plan, plan_file)
    try:
        samples = sample_plan(plan, plan_file, inputs, rate)
    except ValueError as exc:
        raise InputError(plan_file, "phases", str(exc)) from None
    for out in outputs:
        write(samples, out)
    return list(outputs)
