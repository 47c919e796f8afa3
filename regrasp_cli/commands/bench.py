"""`regrasp bench SUITE.yaml`: run a benchmark suite and write its results folder:
``runs.jsonl`` (one record per run, rewritten atomically as runs finish), ``summary.md``
(the tables), ``times.png`` (time per phase per planner), ``meta.json`` (machine,
suite, offline stages, wall time) and ``ompl/<scene>.log`` (OMPL's benchmark log format,
see :mod:`regrasp_cli.bench.ompllog`); the tables are also printed.  An in-hand suite
(:mod:`regrasp_cli.bench.inhand`) writes runs.jsonl, summary.md, meta.json, plans/ and
scenes/."""

from __future__ import annotations

import datetime
import json
import os
import platform
import time
from pathlib import Path

from rich.console import Console

from regrasp_cli import __version__
from regrasp_cli.bench.suite import REFERENCE, Suite, load_suite, with_overrides
from regrasp_cli.errors import InputError
from regrasp_cli.store import atomic_write_bytes, atomic_write_text, check_writable


LIBRARIES = ("pin", "coal", "numpy", "scipy", "ompl")  # distributions whose versions a result depends on


def versions() -> dict[str, str]:
    """Installed versions of :data:`LIBRARIES` (absent ones left out)."""
    from importlib import metadata

    out = {}
    for name in LIBRARIES:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            pass
    return out


def machine() -> dict:
    cpu = "?"
    try:
        with open("/proc/cpuinfo") as f:
            cpu = next((ln.split(":", 1)[1].strip() for ln in f if ln.startswith("model name")), "?")
    except OSError:
        cpu = platform.processor() or "?"
    return {"cpu": cpu, "cores": os.cpu_count(), "python": platform.python_version(),
            "platform": platform.platform(), "regrasp": __version__, "libraries": versions(),
            "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")}


def _plain(x):
    return x.tolist() if hasattr(x, "tolist") else str(x)


def jsonl(records: list[dict]) -> str:
    return "".join(json.dumps(r, default=_plain, sort_keys=False) + "\n" for r in records)


def dask_client(scheduler: str | None):
    """A ``distributed.Client`` connected to the Dask scheduler at ``scheduler``, which has
    at least one worker (the caller closes it)."""
    if scheduler is None:
        raise InputError(None, "--scheduler", "--backend dask runs on an existing Dask cluster: give its "
                                              "scheduler's address, e.g. --scheduler tcp://host:8786")
    try:
        from distributed import Client
    except ImportError:
        raise InputError(None, "--backend", "dask needs the optional extra: pip install 'regrasp[dask]'") from None
    _check_address(scheduler)
    try:
        client = Client(scheduler, timeout=10, set_as_default=False)
    except (OSError, ValueError) as exc:  # refused, timed out (TimeoutError is an OSError), bad address
        message = " ".join(str(exc).split()) or type(exc).__name__
        raise InputError(None, "--scheduler", f"cannot connect to the Dask scheduler at {scheduler}: {message}") \
            from None
    try:
        client.wait_for_workers(1, timeout=10)
    except TimeoutError:
        client.close()
        raise InputError(None, "--scheduler", f"the Dask scheduler at {scheduler} has no worker (waited 10 s)") \
            from None
    return client


def _check_address(scheduler: str) -> None:
    """Refuse a scheduler address that a ``distributed.Client`` would fail on other than by
    a network error (its OSError): such a Client is left half made, and when collected it
    waits 20 s to close, then prints a traceback."""
    from distributed.comm import get_address_host_port, parse_address
    from distributed.security import Security

    try:
        _, port = get_address_host_port(scheduler)
        if not 0 < port < 65536:
            raise ValueError(f"port {port} is not in 1-65535")
        if parse_address(scheduler)[0] == "tls" and Security().get_connection_args("client")["ssl_context"] is None:
            raise ValueError("it needs Dask's TLS settings (distributed.comm.tls.ca-file, .client.cert, .client.key)")
    except (OSError, ValueError) as exc:  # OSError: a TLS file of the Dask configuration not found
        raise InputError(None, "--scheduler", f"expected an address such as tcp://host:8786, found {scheduler!r}: "
                                              f"{' '.join(str(exc).split())}") from None


def run_bench(suite_file: Path, cache_dir: Path, out_dir: Path | None, jobs: int, seeds: int | None = None,
              planners: str | None = None, budget_s: float | None = None,
              console: Console | None = None, backend: str = "loky", scheduler: str | None = None,
              iterations: int | None = None) -> list[dict]:
    """The `bench` command; returns the run records (sorted by scene, planner, seed).
    ``backend`` is ``loky`` (local processes) or ``dask`` (the cluster at ``scheduler``)."""
    console = console or Console()
    if jobs < 1:
        raise InputError(None, "--jobs", f"expected an integer >= 1, found {jobs}")
    if backend not in ("loky", "dask"):
        raise InputError(None, "--backend", f"expected loky or dask, found {backend!r}")
    if backend == "loky" and scheduler is not None:
        raise InputError(None, "--scheduler", "only for --backend dask")
    from regrasp_cli.bench.inhand import INHAND_SUITE_FORMAT, suite_format

    inhand_suite = suite_format(suite_file) == INHAND_SUITE_FORMAT
    client = dask_client(scheduler) if backend == "dask" else None
    try:
        if inhand_suite:
            return run_inhand_bench(suite_file, cache_dir, out_dir, jobs, seeds, planners, budget_s, iterations,
                                    console, client)
        return _run_bench(suite_file, cache_dir, out_dir, jobs, seeds, planners, budget_s, console, client,
                          iterations)
    finally:
        if client is not None:
            client.close()


def _run_bench(suite_file: Path, cache_dir: Path, out_dir: Path | None, jobs: int, seeds: int | None,
               planners: str | None, budget_s: float | None, console: Console, client,
               iterations: int | None = None) -> list[dict]:
    from regrasp_cli.bench.ompllog import scene_logs
    from regrasp_cli.bench.report import markdown, plot_png
    from regrasp_cli.bench.runner import items_of, offline_stages, run_items
    from regrasp_cli.commands.report import CliBuilder

    err = Console(stderr=True)
    where = "loky" if client is None else f"dask at {client.scheduler.address}"
    suite: Suite = with_overrides(load_suite(suite_file), seeds, planners, budget_s, iterations)
    out_dir = Path("bench-results") / suite.name if out_dir is None else Path(out_dir)
    check_writable(out_dir, "--output", folder=True)
    offline = offline_stages(suite, cache_dir, jobs, CliBuilder(err))  # bad scenes refused before out_dir exists
    plan_dir = out_dir / "plans"
    plan_dir.mkdir(parents=True, exist_ok=True)
    items = items_of(suite, cache_dir, plan_dir)
    meta = {"machine": machine(), "suite": {"file": str(suite.file), "name": suite.name,
                                            "scenes": [str(s) for s in suite.scenes],
                                            "planners": list(suite.planners), "seeds": list(suite.seeds),
                                            "budget_s": suite.budget_s, "iterations": suite.iterations,
                                            "roadmap_nodes": suite.roadmap_nodes,
                                            "grasp_target": suite.grasp_target, "held_speed": suite.held_speed},
            "jobs": jobs, "backend": where, "runs": len(items), "offline": offline}
    atomic_write_text(out_dir / "meta.json", json.dumps(meta, indent=1, default=_plain) + "\n")
    err.print(f"{len(items)} runs ({len(suite.scenes)} scene(s) x {len(suite.planners)} planner(s) x "
              f"{len(suite.seeds)} seed(s)), {f'{jobs} job(s)' if client is None else where}, "
              f"budget {suite.budget_s:g} s per run, {suite.iterations} RRT-Connect iterations per query")

    done: list[dict] = []

    def on_record(rec: dict) -> None:
        done.append(rec)
        state = "solved" if rec["solved"] else f"FAILED at {rec['stage']}: {rec['reason']}"
        t = "–" if rec["total_s"] is None else f"{rec['total_s']:.2f} s"
        err.print(f"[{len(done)}/{len(items)}] {rec['scene']} {rec['planner']} seed {rec['seed']}: {t}, {state}",
                  markup=False, highlight=False)
        atomic_write_text(out_dir / "runs.jsonl", jsonl(done))

    t0 = time.perf_counter()
    run_items(items, jobs, on_record, client)
    meta["wall_s"] = time.perf_counter() - t0
    atomic_write_text(out_dir / "meta.json", json.dumps(meta, indent=1, default=_plain) + "\n")
    rank = {p: i for i, p in enumerate(suite.planners)}
    records = sorted(done, key=lambda r: (r["scene"], rank[r["planner"]], r["seed"]))
    atomic_write_text(out_dir / "runs.jsonl", jsonl(records))

    m = meta["machine"]
    header = [f"# Benchmark `{suite.name}`", "",
              f"{m['date']}; {m['cpu']}, {m['cores']} cores, Python {m['python']}, regrasp {m['regrasp']} "
              f"({', '.join(f'{k} {v}' for k, v in m['libraries'].items())}); "
              f"{len(items)} runs, jobs={jobs}, budget {suite.budget_s:g} s per run, "
              f"{suite.iterations} RRT-Connect iterations per query; seeds "
              f"{', '.join(map(str, suite.seeds)) if len(suite.seeds) <= 8 else f'{len(suite.seeds)} ({suite.seeds[0]}..)'}.",
              "", f"Each run in its own process (joblib workers: {where}; the run forked with its budget), planner "
              "jobs=1; a run is solved when the plan passes `regrasp validate`."]
    atomic_write_text(out_dir / "summary.md", markdown(records, header, offline, REFERENCE))
    atomic_write_bytes(out_dir / "times.png", plot_png(records, f"{suite.name}: {len(suite.seeds)} seeds"))
    for name, log in scene_logs(records, meta).items():  # for ompl_benchmark_statistics and Planner Arena
        (out_dir / "ompl").mkdir(exist_ok=True)
        atomic_write_text(out_dir / "ompl" / name, log)
    print_tables(records, console, REFERENCE, offline)
    console.print(f"results: {out_dir}/ (runs.jsonl, summary.md, times.png, meta.json, ompl/*.log, plans/)")
    return records


def run_inhand_bench(suite_file: Path, cache_dir: Path, out_dir: Path | None, jobs: int, seeds: int | None,
                     planners: str | None, budget_s: float | None, iterations: int | None,
                     console: Console, client=None) -> list[dict]:
    """An in-hand suite (:mod:`regrasp_cli.bench.inhand`): ``--seeds N`` runs goals 0 ..
    N-1, ``--budget-s`` overrides the suite's budget per run; the runs are any suite's
    (:func:`~regrasp_cli.bench.runner.run_items`: forked with their budget, in loky or
    Dask workers); results as a pick-and-place suite's (runs.jsonl, summary.md,
    meta.json, plans/, and the scenes/ the runs planned)."""
    from dataclasses import replace

    from regrasp_cli.bench import inhand
    from regrasp_cli.bench.runner import run_items
    from regrasp_cli.bench.suite import checked_budget, seeds_of

    inhand.check_overrides(planners, iterations)
    suite = inhand.load_inhand_suite(suite_file)
    if seeds is not None:
        suite = replace(suite, goals=seeds_of(None, "--seeds", seeds))
    if budget_s is not None:
        suite = replace(suite, budget_s=checked_budget(budget_s))
    out_dir = Path("bench-results") / suite.name if out_dir is None else Path(out_dir)
    check_writable(out_dir, "--output", folder=True)
    err = Console(stderr=True)
    for label in suite.skipped:
        err.print(f"skipped (mesh not found, optional): {label}", markup=False, highlight=False)
    items = inhand.items_of(suite, out_dir, cache_dir)
    learned = inhand.prepare(items, cache_dir, suite.mode, lambda text: err.print(text, markup=False, highlight=False))
    where = "loky" if client is None else f"dask at {client.scheduler.address}"
    meta = {"machine": machine(), "suite": {"file": str(suite.file), "name": suite.name, "mode": suite.mode,
                                            "goals": list(suite.goals), "nodes": suite.nodes,
                                            "budget_s": suite.budget_s},
            "jobs": jobs, "backend": where, "runs": len(items), "roadmap_learning_s": learned}
    err.print(f"{len(items)} in-hand runs ({suite.mode}), {f'{jobs} job(s)' if client is None else where}, "
              f"budget {suite.budget_s:g} s per run")
    done: list[dict] = []

    def on_record(rec: dict) -> None:
        done.append(rec)
        state = "solved" if rec["solved"] else f"FAILED at {rec['stage']}: {rec['reason']}"
        err.print(f"[{len(done)}/{len(items)}] {rec['hand']} {rec['object']} goal {rec['goal']}: "
                  f"{rec['total_s']:.1f} s, {state}", markup=False, highlight=False)
        atomic_write_text(out_dir / "runs.jsonl", jsonl(done))

    t0 = time.perf_counter()
    run_items(items, jobs, on_record, client)
    meta["wall_s"] = time.perf_counter() - t0
    atomic_write_text(out_dir / "meta.json", json.dumps(meta, indent=1, default=_plain) + "\n")
    m = meta["machine"]
    table = inhand.summary(done)
    atomic_write_text(out_dir / "summary.md", f"# In-hand benchmark `{suite.name}` ({suite.mode})\n\n{m['date']}; "
                                              f"{m['cpu']}, {m['cores']} cores; {len(items)} runs, jobs={jobs}; "
                                              f"a run is solved when its plan passes `regrasp validate`.\n\n{table}")
    console.print(table)
    console.print(f"results: {out_dir}/ (runs.jsonl, summary.md, meta.json, plans/, scenes/)")
    return done


def print_tables(records: list[dict], console: Console, reference: str = "roadmap",
                 offline: dict | None = None) -> None:
    """The tables of the Markdown summary (bench.report), drawn with rich."""
    from rich.table import Table
    from regrasp_cli.bench.aggregate import TABLE_ONE_COLUMNS, ordered, select
    from regrasp_cli.bench.report import (PAPER_COLUMNS, RATIO_COLUMNS, SUMMARY_COLUMNS, paper_rows, ratio_rows,
                                          summary_rows, table_one_rows)

    def table(title, columns, rows):
        t = Table(title=title)
        for c in columns:
            t.add_column(c, justify="left" if c in ("scene", "planner", "query", "failures", "") else "right")
        for row in rows:
            t.add_row(*map(str, row))
        console.print(t)

    table("Runs (times over solved runs, s)", SUMMARY_COLUMNS, summary_rows(records, reference))
    rr = ratio_rows(records, reference)
    if rr:
        table(f"Ratio to {reference} per seed (total time)", RATIO_COLUMNS, rr)
    for (scene, planner), rows in table_one_rows(records).items():
        table(f"Table I: {scene}, {planner} (medians over solved runs)", TABLE_ONE_COLUMNS, rows)
    for scene in ordered(r["scene"] for r in records):
        if select(records, scene, reference):
            table(f"Next to the paper: {scene}", PAPER_COLUMNS, paper_rows(records, offline or {}, scene, reference))
