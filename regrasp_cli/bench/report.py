"""The outputs of a benchmark: the Markdown summary and its table rows (which `regrasp
bench` also draws with rich), and the plot of time per phase per planner (matplotlib,
PNG), all from run records through :mod:`regrasp_cli.bench.aggregate`."""

from __future__ import annotations

import io
import math

from regrasp_cli.bench.aggregate import (PLOT_PHASES, QUERIES, TABLE_ONE_COLUMNS, ordered, phase_medians,
                                         seed_ratios, select, spread, summarise, table_one)
from regrasp_cli.bench.suite import DEFAULT_ITERATIONS

SUMMARY_COLUMNS = ("scene", "planner", "solved", "success", "total median (s)", "total IQR (s)",
                   "planner median (s)", "validate median (s)", "path length median", "peak RSS (MB)",
                   "failures")
RATIO_COLUMNS = ("scene", "planner / roadmap", "seeds both solved", "median ratio", "IQR", "min–max",
                 "only roadmap solved", "only planner solved", "neither",
                 "median ratio, failures at give-up (≥)")


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
                         str(q.only_reference), str(q.only_planner), str(q.neither),
                         f"{_f(q.lower_bound.median)}x (n={q.lower_bound.n})" if q.lower_bound.n else "–"))
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


# Saut et al. 2010, §VI and Table I (Justin, a 2010 dual-core Opteron): the figures our
# tables are set against
PAPER = {
    "grasp lists": "about 1 min per hand; 17 (right) and 22 (left) grasps",
    "roadmap": "about 5 min; 50 + 50 Vis-PRM nodes, about 1,700 Super Graph nodes",
    "grasp configurations": "4.2 s single + 2.6 s double",
    "queries": {"grasp": (68, 3.0), "carry": (71, 4.1), "place": (44, 2.3), "rest": (51, 2.1)},  # total n, T
    "online": 11.6,  # s, the four queries with the roadmap (without the grasp configurations)
    "single query": 35.0,  # s, the same with a single-query planner (RRT-Connect)
}
PAPER_COLUMNS = ("", "paper (§VI, Table I)", "ours")


def _key_stage(name: str) -> bool:
    """Is the stage ``name`` ("nodes", or "handover: nodes" as the styles name theirs) one
    of the paper's grasp configurations: the hand-over's single-grasp nodes, its double
    grasps or its exchange pose?"""
    style, _, stage = name.rpartition(": ")
    return style in ("", "handover") and stage in ("nodes", "double grasps", "exchange")


def paper_rows(records: list[dict], offline: dict[str, dict], scene: str,
               reference: str = "roadmap") -> list[tuple[str, str, str]]:
    """Our numbers on ``scene`` beside the paper's: offline stages (as timed before the
    runs: a cached artefact was loaded, not built), the grasp configurations, Table I's
    totals per query and the online time of ``reference`` and of every other planner of
    the scene (single-query ones, set against the paper's RRT-Connect), with their
    per-seed ratios (medians over solved runs)."""
    off = offline.get(scene, {})

    def stage(name: str) -> str:
        v = off.get(name)
        if v is None:
            return "–"
        size = ", ".join(f"{k} {n}" for k, n in v.get("size", {}).items())
        return f"{v['s']:.1f} s ({v['status']}){'; ' + size if size else ''}"

    sg = off.get("super graph ready", {}).get("size", {})
    roadmap = stage("roadmap") + (f"; {sg['nodes']:,} Super Graph nodes" if sg else "")
    ok = select(records, scene, reference, solved=True)
    grasps = spread(sum(v for k, v in r["stages_s"].items() if _key_stage(k)) for r in ok)
    rows = [("grasp lists (ours: both hands, 2 processes)", PAPER["grasp lists"], stage("grasp lists")),
            ("roadmap", PAPER["roadmap"], roadmap),
            ("single + double grasp configurations (and exchange pose)", PAPER["grasp configurations"],
             f"{_f(grasps.median)} s" if grasps.n else "–")]
    table = {row[0]: row for row in table_one(ok)}
    for q in QUERIES:
        n, t = PAPER["queries"][q]
        ours = table.get(q)
        rows.append((f"{q}: n, T", f"{n}, {t:.1f} s",
                     "–" if ours is None or math.isnan(ours[5]) else f"{ours[5]:.0f}, {ours[6]:.2f} s"))
    total = table.get("total")
    rows.append((f"the four queries, {reference}", f"{PAPER['online']:.1f} s",
                 "–" if total is None or math.isnan(total[6]) else f"{total[6]:.2f} s ({len(ok)} solved)"))
    # per run: Table I's total T (the four queries' planning + lazy validation)
    derived = [dict(r, queries_s=sum(q["planning_s"] + q["validation_s"] for q in r.get("queries", {}).values()))
               for r in select(records, scene)]
    for peer in ordered(r["planner"] for r in select(records, scene)):
        if peer == reference:
            continue
        runs = select(records, scene, peer)
        solved = [r for r in runs if r["solved"]]
        t = table_one(solved)[-1][6] if solved else float("nan")
        rows.append((f"the four queries, {peer}", f"{PAPER['single query']:.0f} s",
                     f"{_f(t)} s ({len(solved)}/{len(runs)} solved)" if solved else f"0/{len(runs)} solved"))
        ratio = seed_ratios(derived, scene, peer, reference, key="queries_s")
        ours = f"{_f(ratio.ratio.median)}x per seed ({ratio.ratio.n} both solved)" if ratio.ratio.n else "–"
        if ratio.lower_bound.n:
            ours += f"; ≥ {_f(ratio.lower_bound.median)}x counting failures ({ratio.lower_bound.n} seeds)"
        rows.append((f"{peer} / {reference}, the four queries", f"{PAPER['single query'] / PAPER['online']:.1f}x",
                     ours))
    return rows


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
        L += ["", f"## Ratio to {reference}, per seed (total time; seeds where both solved)", "",
              f"The last column takes every seed {reference} solved, a failure of the other planner counted at "
              "the time it gave up: a lower bound, since solving would have taken longer.", ""]
        L += _md(RATIO_COLUMNS, rr)
        rp = ratio_rows(records, reference, key="planner_s")
        L += ["", "Same, planner time only (without writing and `regrasp validate`):", ""]
        L += _md(RATIO_COLUMNS, rp)
    L += paper_section(records, offline, reference)
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


def paper_section(records: list[dict], offline: dict[str, dict], reference: str = "roadmap",
                  heading: str = "##") -> list[str]:
    """The "next to the paper" tables, one per scene the reference ran on, each under a
    markdown heading of level ``heading``."""
    L = []
    for scene in ordered(r["scene"] for r in records):
        if not select(records, scene, reference):
            continue
        L += ["", f"{heading} Next to the paper: {scene}", "",
              "The paper's numbers are for its own scene and robot (Justin), on 2010 hardware; ours are medians "
              "over solved runs, T of a query being its planning plus its lazy path validation.", ""]
        L += _md(PAPER_COLUMNS, paper_rows(records, offline, scene, reference))
    return L


def docs_block(records: list[dict], meta: dict, reference: str = "roadmap") -> str:
    """What docs/BENCHMARKS.md shows of a results folder: its provenance, the runs and
    ratio tables and the paper comparison (the rest stays in its summary.md)."""
    m, suite = meta["machine"], meta["suite"]
    libs = ", ".join(f"{k} {v}" for k, v in m.get("libraries", {}).items())
    L = [f"{m['date'][:10]}, {m['cpu']}, {m['cores']} cores, Python {m['python']}, regrasp {m['regrasp']}"
         f"{f' ({libs})' if libs else ''}; "
         f"{meta['runs']} runs of suite `{suite['name']}` ({len(suite['seeds'])} seeds, budget "
         f"{suite['budget_s']:g} s per run, {suite.get('iterations', DEFAULT_ITERATIONS)} RRT-Connect iterations "
         "per query), "
         f"{meta['jobs']} at a time ({meta['backend']}).", ""]
    L += _md(SUMMARY_COLUMNS, summary_rows(records, reference))
    rr = ratio_rows(records, reference, key="planner_s")
    if rr:
        L += ["", f"Per-seed ratio of planner times to {reference} (without writing and `regrasp validate`; the last "
                  "column counts failures at the time they gave up, a lower bound):", ""]
        L += _md(RATIO_COLUMNS, rr)
    L += paper_section(records, meta.get("offline", {}), reference, heading="####")  # inside a suite's ###
    return "\n".join(L) + "\n"


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
