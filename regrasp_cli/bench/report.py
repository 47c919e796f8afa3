"""The outputs of a benchmark: the Markdown summary, the same tables with rich, and the
plot of time per phase per planner (matplotlib, PNG), all from run records through
:mod:`regrasp_cli.bench.aggregate`."""

from __future__ import annotations

import io
import math

from regrasp_cli.bench.aggregate import (PLOT_PHASES, TABLE_ONE_COLUMNS, ordered, phase_medians, seed_ratios,
                                         select, summarise, table_one)

SUMMARY_COLUMNS = ("scene", "planner", "solved", "success", "total median (s)", "total IQR (s)",
                   "planner median (s)", "validate median (s)", "path length median", "peak RSS (MB)",
                   "failures")
RATIO_COLUMNS = ("scene", "planner / roadmap", "seeds both solved", "median ratio", "IQR", "min–max",
                 "only roadmap solved", "only planner solved", "neither")


def _f(x, d: int = 2) -> str:
    return "–" if x is None or (isinstance(x, float) and math.isnan(x)) else f"{x:.{d}f}"


def summary_rows(records: list[dict], reference: str = "roadmap") -> list[tuple[str, ...]]:
    rows = []
    for scene in ordered(r["scene"] for r in records):
        for planner in ordered(r["planner"] for r in select(records, scene)):
            s = summarise(records, scene, planner)
            fails = ", ".join(f"{k} {v}" for k, v in s.failures.items()) or "–"
            rows.append((scene, planner, f"{s.solved}/{s.runs}", f"{100 * s.success_rate:.0f} %",
                         _f(s.total_s.median), f"{_f(s.total_s.q25)}–{_f(s.total_s.q75)}" if s.total_s.n else "–",
                         _f(s.planner_s.median), _f(s.validation_s.median), _f(s.path_length.median),
                         _f(s.peak_rss_mb.median, 0), fails))
    return rows


def ratio_rows(records: list[dict], reference: str = "roadmap", key: str = "total_s") -> list[tuple[str, ...]]:
    rows = []
    for scene in ordered(r["scene"] for r in records):
        planners = ordered(r["planner"] for r in select(records, scene))
        if reference not in planners:
            continue
        for planner in planners:
            if planner == reference:
                continue
            q = seed_ratios(records, scene, planner, reference, key)
            r = q.ratio
            rows.append((scene, planner, str(r.n), f"{_f(r.median)}x" if r.n else "–",
                         f"{_f(r.q25)}–{_f(r.q75)}" if r.n else "–", f"{_f(r.min)}–{_f(r.max)}" if r.n else "–",
                         str(q.only_reference), str(q.only_planner), str(q.neither)))
    return rows


def table_one_rows(records: list[dict]) -> dict[tuple[str, str], list[tuple[str, ...]]]:
    """Per (scene, planner): Table I over its solved runs, formatted."""
    out = {}
    for scene in ordered(r["scene"] for r in records):
        for planner in ordered(r["planner"] for r in select(records, scene)):
            ok = select(records, scene, planner, solved=True)
            out[scene, planner] = [(q, _f(a, 0), _f(b), _f(c, 0), _f(d), _f(e, 0), _f(f))
                                   for q, a, b, c, d, e, f in table_one(ok)]
    return out


def _md(columns, rows) -> list[str]:
    cell = lambda s: str(s).replace("|", "/")  # noqa: E731
    return ["| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)] + \
           ["| " + " | ".join(cell(c) for c in row) + " |" for row in rows]


def markdown(records: list[dict], header: list[str], offline: dict[str, dict], reference: str = "roadmap") -> str:
    L = list(header)
    L += ["", "## Offline stages (once per scene, before the runs)", "",
          "| scene | stage | status | s | size |", "|---|---|---|---|---|"]
    for scene, row in offline.items():
        for stage, v in row.items():
            size = ", ".join(f"{k} {n}" for k, n in v.get("size", {}).items()) or "–"
            L.append(f"| {scene} | {stage} | {v['status']} | {v['s']:.2f} | {size} |")
    L += ["", "## Runs", "",
          "Times are over solved runs (planner + writing the plan + `regrasp validate`); the success rate "
          "counts every run.  IQR: 25 %–75 %.", ""]
    L += _md(SUMMARY_COLUMNS, summary_rows(records, reference))
    rr = ratio_rows(records, reference)
    if rr:
        L += ["", f"## Ratio to {reference}, per seed (total time; seeds where both solved)", ""]
        L += _md(RATIO_COLUMNS, rr)
        rp = ratio_rows(records, reference, key="planner_s")
        L += ["", "Same, planner time only (without writing and `regrasp validate`):", ""]
        L += _md(RATIO_COLUMNS, rp)
    L += ["", "## Table I (medians over solved runs; n nodes, T seconds)", "",
          "planning n: Super Graph nodes on the path + tree nodes; validation n: invalid edges found by the "
          "lazy checks; total: per run, planning + validation; the total row sums the four queries per run."]
    for (scene, planner), rows in table_one_rows(records).items():
        L += ["", f"### {scene}, {planner}", ""]
        L += _md(TABLE_ONE_COLUMNS, rows)
    fails = [r for r in records if not r["solved"]]
    L += ["", f"## Failures ({len(fails)})", ""]
    if fails:
        L += _md(("scene", "planner", "seed", "stage", "reason", "time (s)"),
                 [(r["scene"], r["planner"], r["seed"], r["stage"], r["reason"], _f(r["total_s"]))
                  for r in fails])
    else:
        L.append("none")
    return "\n".join(L) + "\n"


def print_tables(records: list[dict], console, reference: str = "roadmap") -> None:
    from rich.table import Table

    def table(title, columns, rows):
        t = Table(title=title)
        for c in columns:
            t.add_column(c, justify="left" if c in ("scene", "planner", "query", "failures") else "right")
        for row in rows:
            t.add_row(*map(str, row))
        console.print(t)

    table("Runs (times over solved runs, s)", SUMMARY_COLUMNS, summary_rows(records, reference))
    rr = ratio_rows(records, reference)
    if rr:
        table(f"Ratio to {reference} per seed (total time)", RATIO_COLUMNS, rr)
    for (scene, planner), rows in table_one_rows(records).items():
        table(f"Table I: {scene}, {planner} (medians over solved runs)", TABLE_ONE_COLUMNS, rows)


def plot_png(records: list[dict], title: str) -> bytes:
    """Left: median seconds per phase of the solved runs, stacked, one bar per (scene,
    planner); right: the distribution of the total time of solved runs (box plot), with
    the success rate under each planner."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    keys = [(s, p) for s in ordered(r["scene"] for r in records)
            for p in ordered(r["planner"] for r in select(records, s))]
    multi = len({s for s, _ in keys}) > 1
    labels = [f"{s}\n{p}" if multi else p for s, p in keys]
    fig = Figure(figsize=(max(9.0, 2.2 * len(keys) + 5.0), 4.8), layout="constrained")
    ax, bx = fig.subplots(1, 2, width_ratios=[1.6, 1])
    bottoms = [0.0] * len(keys)
    medians = [phase_medians(select(records, s, p, solved=True)) for s, p in keys]
    cmap = matplotlib.colormaps["tab10"]
    for i, phase in enumerate(PLOT_PHASES):
        h = [0.0 if math.isnan(m[phase]) else m[phase] for m in medians]
        ax.bar(range(len(keys)), h, bottom=bottoms, label=phase, color=cmap(i % 10))
        bottoms = [b + x for b, x in zip(bottoms, h)]
    ax.set_xticks(range(len(keys)), labels)
    ax.set_ylabel("median time of solved runs (s)")
    ax.set_title("time per phase")
    ax.legend(fontsize="small", loc="upper left", bbox_to_anchor=(1.01, 1.0))
    totals = [[r["total_s"] for r in select(records, s, p, solved=True)] for s, p in keys]
    bx.boxplot([t if t else [float("nan")] for t in totals], showfliers=True)
    rates = []
    for s, p in keys:
        rs = select(records, s, p)
        rates.append(f"{sum(bool(r['solved']) for r in rs)}/{len(rs)}")
    bx.set_xticks(range(1, len(keys) + 1), [f"{lab}\n{rate} solved" for lab, rate in zip(labels, rates)])
    bx.set_ylabel("total time of solved runs (s)")
    bx.set_title("total time")
    fig.suptitle(title)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100)
    return buf.getvalue()
