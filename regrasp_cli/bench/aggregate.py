"""Statistics over benchmark run records: pure functions of lists of dicts (the lines of
``runs.jsonl``, see :mod:`regrasp_cli.bench.runner` for the fields), so they can be
tested on hand-made records and re-run on old results.

Conventions, as in OMPL's benchmark database and Planner Arena: times are statistics over
the solved runs (a failed run has no time to solve) and the success rate is reported
beside them; quantiles are numpy's linear interpolation (the 25 % and 75 % points give
the IQR); a planner's speed relative to the reference (``roadmap``) is the ratio of the
two times *per seed*, over the seeds where both solved, with the counts of the others,
and again over every seed the reference solved with the planner's failures counted at
the time they gave up (a lower bound of the ratio: solving would have taken longer).
Table I follows Saut et al. 2010: one row per query (Grasp, Carry, Place, Rest), n nodes
and T seconds of the online planning and of the path validation, and their total.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from regrasp_cli.manip.tasks.handover import TRANSITIONS as QUERIES  # the task benchmarked (seed 000)
# the parts of a run's time drawn in the plot, in order: the planner's stages with the
# queries split (planning + lazy validation of each; "queries, other": the rest of the
# queries stage, key configuration lines and process overhead), then writing and
# `regrasp validate`
PLOT_PHASES = ("double grasps", "exchange", *QUERIES, "queries, other", "timing", "write", "validate")


@dataclass(frozen=True)
class Spread:
    """Median and quartiles of a sample; ``n`` values (all NaN when n == 0)."""

    n: int
    median: float
    q25: float
    q75: float
    min: float
    max: float

    @property
    def iqr(self) -> float:
        return self.q75 - self.q25


def spread(values) -> Spread:
    x = np.asarray([float(v) for v in values], dtype=float)
    if x.size == 0:
        nan = float("nan")
        return Spread(0, nan, nan, nan, nan, nan)
    q25, med, q75 = np.percentile(x, [25, 50, 75])
    return Spread(int(x.size), float(med), float(q25), float(q75), float(x.min()), float(x.max()))


def select(records: list[dict], scene: str | None = None, planner: str | None = None,
           solved: bool | None = None) -> list[dict]:
    return [r for r in records if (scene is None or r["scene"] == scene)
            and (planner is None or r["planner"] == planner) and (solved is None or bool(r["solved"]) == solved)]


def ordered(values) -> list:
    """Distinct values in order of first appearance."""
    return list(dict.fromkeys(values))


@dataclass(frozen=True)
class PlannerSummary:
    scene: str
    planner: str
    runs: int
    solved: int
    total_s: Spread  # over solved runs: planner + writing + `regrasp validate`
    planner_s: Spread  # over solved runs: the planner alone
    validation_s: Spread  # over solved runs: `regrasp validate`
    path_length: Spread  # over solved runs
    peak_rss_mb: Spread  # over the runs that report it
    failures: dict[str, int]  # stage -> count

    @property
    def success_rate(self) -> float:
        return self.solved / self.runs if self.runs else float("nan")


def summarise(records: list[dict], scene: str, planner: str) -> PlannerSummary:
    rs = select(records, scene, planner)
    ok = [r for r in rs if r["solved"]]
    failures: dict[str, int] = {}
    for r in rs:
        if not r["solved"]:
            key = r["stage"] + (f" ({r['transition']})" if r.get("transition") else "")
            failures[key] = failures.get(key, 0) + 1
    return PlannerSummary(
        scene, planner, len(rs), len(ok),
        spread(r["total_s"] for r in ok), spread(r["planner_s"] for r in ok),
        spread(r["validation_s"] for r in ok), spread(r["path_length"] for r in ok),
        spread(r["peak_rss_mb"] for r in rs if r.get("peak_rss_mb") is not None), dict(sorted(failures.items())))


@dataclass(frozen=True)
class Ratio:
    """``planner`` time / ``reference`` time per seed, over the seeds where both solved."""

    scene: str
    planner: str
    reference: str
    per_seed: tuple[tuple[int, float], ...]  # (seed, ratio) where both solved, by seed
    ratio: Spread
    only_reference: int  # seeds solved by the reference only
    only_planner: int
    neither: int
    # over the seeds the reference solved, the planner's failures at their give-up time
    lower_bound: Spread = spread(())


def seed_ratios(records: list[dict], scene: str, planner: str, reference: str = "roadmap",
                key: str = "total_s") -> Ratio:
    ref = {r["seed"]: r for r in select(records, scene, reference)}
    other = {r["seed"]: r for r in select(records, scene, planner)}
    per_seed, only_ref, only_p, neither, bound = [], 0, 0, 0, []
    for seed in sorted(set(ref) & set(other)):
        a, b = ref[seed], other[seed]
        if a["solved"] and b["solved"]:
            per_seed.append((seed, float(b[key]) / float(a[key])))
            bound.append(per_seed[-1][1])
        elif a["solved"]:
            only_ref += 1
            gave_up = b[key] if b.get(key) is not None else b.get("total_s")
            if gave_up is not None:
                bound.append(float(gave_up) / float(a[key]))
        elif b["solved"]:
            only_p += 1
        else:
            neither += 1
    return Ratio(scene, planner, reference, tuple(per_seed), spread(v for _, v in per_seed), only_ref, only_p, neither,
                 spread(bound))


TABLE_ONE_COLUMNS = ("query", "planning n", "planning T (s)", "validation n", "validation T (s)", "total n",
                     "total T (s)")


def table_one(records: list[dict]) -> list[tuple[str, float, float, float, float, float, float]]:
    """Table I of the paper over ``records`` (usually the solved runs of one planner on one
    scene): a row per query and a ``total`` row, each value the median over the runs of
    planning n (nodes: Super Graph nodes on the path + tree nodes), planning T, validation
    n (invalid edges found by the lazy checks), validation T, and per run their sums
    (total n, total T).  The ``total`` row takes the medians of the per-run sums over the
    four queries.  Columns: :data:`TABLE_ONE_COLUMNS`; NaN where no run reached a query."""
    rows = []
    per_run_totals: list[list[float]] = [[0.0] * 6 for _ in records]
    for q in QUERIES:
        values = []
        for k, r in enumerate(records):
            s = r.get("queries", {}).get(q)
            if s is None:
                continue
            v = [s["n"], s["planning_s"], s["invalid_edges"], s["validation_s"],
                 s["n"] + s["invalid_edges"], s["planning_s"] + s["validation_s"]]
            values.append(v)
            per_run_totals[k] = [a + b for a, b in zip(per_run_totals[k], v)]
        rows.append((q, *(spread(col).median for col in zip(*values))) if values else (q, *[float("nan")] * 6))
    reached = [t for t, r in zip(per_run_totals, records) if r.get("queries")]
    rows.append(("total", *(spread(col).median for col in zip(*reached))) if reached
                else ("total", *[float("nan")] * 6))
    return rows


def phase_medians(records: list[dict]) -> dict[str, float]:
    """Median seconds of each of :data:`PLOT_PHASES` over ``records`` (solved runs)."""
    def part(r: dict, p: str) -> float:
        if p in QUERIES:
            s = r.get("queries", {}).get(p)
            return 0.0 if s is None else s["planning_s"] + s["validation_s"]
        if p == "queries, other":
            spent = sum(s["planning_s"] + s["validation_s"] for s in r.get("queries", {}).values())
            return max(0.0, r["stages_s"].get("queries", 0.0) - spent)
        if p == "write":
            return r["write_s"]
        if p == "validate":
            return r["validation_s"]
        return r["stages_s"].get(p, 0.0)

    return {p: spread(part(r, p) for r in records).median if records else float("nan") for p in PLOT_PHASES}
