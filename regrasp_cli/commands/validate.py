"""`regrasp validate PLAN`: the validator's report printed (rich)."""

from __future__ import annotations

from rich.console import Console
from rich.markup import escape
from rich.table import Table

from regrasp_cli.validate import ValidationReport


def print_validation(report: ValidationReport, console: Console) -> None:
    """A table per phase (waypoints, configurations checked, seconds, issues), the issues
    one per line, and a last line ``valid`` or ``INVALID: N issues``."""
    count = {}
    for i in report.issues:
        count[i.phase] = count.get(i.phase, 0) + 1
    t = Table(title="Plan validation")
    for col, justify in (("phase", "left"), ("kind", "left"), ("waypoints", "right"), ("configurations", "right"),
                         ("seconds", "right"), ("issues", "right")):
        t.add_column(col, justify=justify)
    for s in report.phases:
        t.add_row(s.name, s.kind, str(s.waypoints), str(s.configurations), f"{s.seconds:.3f}",
                  str(count.get(s.name, 0)))
    grasp_issues = sum(1 for i in report.issues if i.check == "grasp" and i.phase is None)
    if "grasps" in report.seconds:
        t.add_row("grasps", "", "", "", f"{report.seconds['grasps']:.3f}", str(grasp_issues))
    console.print(t)
    for i in report.issues:
        console.print(escape(str(i)))
    n = len(report.issues)
    console.print("valid" if report.valid else f"INVALID: {n} issue{'s' * (n != 1)}")
