"""Run records in OMPL's benchmark log format, for Planner Arena.

OMPL's benchmarking tools write one text log per experiment; ``ompl_benchmark_statistics``
(shipped with the ``ompl`` package) turns logs into the SQLite database that Planner Arena
(plannerarena.org, or its local copy) plots.  :func:`experiment_log` writes one
experiment per scene of a suite in that format (``ompl_benchmark_statistics`` reads one
experiment per file), so our runs sit beside any OMPL benchmark:

    ompl_benchmark_statistics bench-results/default/ompl/*.log -d default.db

Per run, the columns Planner Arena knows by name: ``time`` (the planner's seconds, or
the time to give up for a failure, as OMPL records it), ``solved`` (the plan passed
`regrasp validate`), ``memory`` (peak resident MB), ``solution length`` (weighted
joint-space length), ``graph states`` (Table I's n summed over the four queries) and
``correct solution``; then ours: the outcome as an enum (solved or the failing stage),
total and validation seconds, each query's seconds, invalid edges, the motion's
duration and the seed.  Missing values are written empty, as OMPL does.
"""

from __future__ import annotations

import platform

from regrasp_cli.bench.aggregate import QUERIES, ordered, select
from regrasp_cli.manip.status import Stage
from regrasp_cli.bench.suite import DEFAULT_ITERATIONS

# the outcome of a run: solved, or the stage where it stopped (planner stages, the
# validator, the runner's budget and crash records)
OUTCOMES = ("solved", *(s.value for s in Stage), "other")
ENUM = "outcome"

COLUMNS = (  # (name, OMPL type, value of a record)
    ("time", "REAL", lambda r: r["planner_s"] if r.get("planner_s") is not None else r.get("total_s")),
    ("solved", "BOOLEAN", lambda r: int(bool(r["solved"]))),
    ("memory", "REAL", lambda r: r.get("peak_rss_mb")),
    ("solution length", "REAL", lambda r: r.get("path_length")),
    ("graph states", "INTEGER", lambda r: sum(q["n"] for q in r["queries"].values()) if r.get("queries") else None),
    ("correct solution", "BOOLEAN",
     lambda r: None if r.get("validation") is None else int(bool(r["validation"]["valid"]))),
    (ENUM, "ENUM", lambda r: OUTCOMES.index("solved" if r["solved"] else
                                            r["stage"] if r["stage"] in OUTCOMES else "other")),
    ("total time", "REAL", lambda r: r.get("total_s")),
    ("validation time", "REAL", lambda r: r.get("validation_s")),
    *((f"{q} time", "REAL",
       (lambda q: lambda r: (r["queries"][q]["planning_s"] + r["queries"][q]["validation_s"])
        if q in r.get("queries", {}) else None)(q)) for q in QUERIES),
    ("invalid edges", "INTEGER",
     lambda r: sum(q["invalid_edges"] for q in r["queries"].values()) if r.get("queries") else None),
    ("motion duration", "REAL", lambda r: r.get("motion_s")),
    ("seed", "INTEGER", lambda r: r["seed"]),
)


def _value(x) -> str:
    return "" if x is None else (repr(float(x)) if isinstance(x, float) else str(x))


def experiment_log(records: list[dict], meta: dict, scene: str) -> str:
    """The OMPL benchmark log (text) of ``scene``'s runs in ``records``; ``meta`` is the
    results folder's meta.json (machine, suite, jobs, backend)."""
    m, suite = meta["machine"], meta["suite"]
    rs = select(records, scene)
    planners = ordered(r["planner"] for r in rs)
    iterations = suite.get("iterations", DEFAULT_ITERATIONS)
    setup = [f"regrasp bench, suite {suite['name']} ({suite.get('file', '?')}), scene {scene}",
             f"budget {suite['budget_s']:g} s per run, {iterations} RRT-Connect iterations per "
             f"query, roadmap {suite.get('roadmap_nodes', '?')} nodes per arm, joblib {meta.get('backend', '?')} "
             f"x {meta.get('jobs', '?')}",
             "libraries: " + ", ".join(f"{k} {v}" for k, v in m.get("libraries", {}).items())]
    L = [f"regrasp version {m['regrasp']}",
         "Experiment " + f"{suite['name']}-{scene}".replace(" ", "_"),
         f"Running on {platform.node() or 'localhost'}",
         f"Starting at {m['date']}",
         "<<<|", *setup, "|>>>",
         "<<<|", f"{m['cpu']}, {m['cores']} cores, Python {m['python']}, {m.get('platform', '')}", "|>>>",
         f"{min(suite['seeds']) if suite.get('seeds') else 0} is the random seed",
         f"{suite['budget_s']:g} seconds per run",
         "0 MB per run",
         f"{len(suite.get('seeds', ())) or max((len(select(rs, planner=p)) for p in planners), default=0)} "
         "runs per planner",
         f"{meta.get('wall_s', sum(r.get('total_s') or 0.0 for r in rs)):.3f} seconds spent to collect the data",
         "1 enum types",
         "|".join((ENUM, *OUTCOMES)),
         f"{len(planners)} planners"]
    for planner in planners:
        runs = sorted(select(rs, planner=planner), key=lambda r: r["seed"])
        L += [planner, "2 common properties",
              f"iterations INTEGER = {iterations}",
              f"budget REAL = {suite['budget_s']:g}",
              f"{len(COLUMNS)} properties for each run"]
        L += [f"{name} {kind}" for name, kind, _ in COLUMNS]
        L.append(f"{len(runs)} runs")
        L += ["".join(f"{_value(get(r))}; " for _, _, get in COLUMNS) for r in runs]
        L.append(".")
    return "\n".join(L) + "\n"


def scene_logs(records: list[dict], meta: dict) -> dict[str, str]:
    """File name (``<scene>.log``, path separators replaced) -> log, per scene."""
    return {scene.replace("/", "_") + ".log": experiment_log(records, meta, scene)
            for scene in ordered(r["scene"] for r in records)}
