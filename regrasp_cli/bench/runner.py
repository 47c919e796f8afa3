"""The runs of a benchmark suite: the offline stages timed once per scene, then every
(scene, planner, seed) run in a joblib worker (loky processes here, or the workers of a
Dask cluster), each inside a forked child process with a wall-clock budget.

A run is what `regrasp plan` does online: the planner (double grasps, exchange pose, key
configurations, the four queries with their lazy validation, timing; Saut et al. 2010
§IV-B, §V-B, §V-C), writing the plan JSON, then the independent validator
(`regrasp validate`).  It is solved when the planner returned a plan and the validator
found no issue.  A run that raises, dies or outlives its budget is a failure with its
stage (``crash``, ``budget``, or the planner's stage) and reason; it never stops the suite.

One record per run (a JSON object, one line of ``runs.jsonl``)::

    scene, planner, seed, solved, stage, reason     stage (a manip.status.Stage value)/reason None when solved
    transition                                      the failing transition's label (stage "transition")
    total_s                                         planner + write + validate (s), or time to failure
    planner_s, write_s, validation_s                the three parts (s)
    stages_s: {double grasps, exchange, queries, timing}
    queries: {grasp|carry|place|rest: {n, invalid_edges, rrt_calls, planning_s, validation_s}}
    validation: {valid, issues, first_issues, configurations_checked} or None
    counts                                          the outcome's deterministic counts (the styles apart)
    path_length                                     sum of weighted joint-space segment lengths
    regrasps                                        changes of the holding hand (1: a hand-over)
    motion_s, waypoints, plan                       plan duration, waypoint count, plan file
    peak_rss_mb                                     peak resident memory of the run's process (MB)
    traceback                                       only for a run that raised (stage ``crash``)

The path length uses the same metric for every planner (:func:`joint_weights` of the
robot at rest), so that lengths compare across planners.
"""

from __future__ import annotations

import functools
import os
import pickle
import resource
import select
import signal
import sys
import time
import traceback
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable

import numpy as np

from regrasp_cli.manip.status import Stage
from regrasp_cli.bench.suite import DEFAULT_ITERATIONS, REFERENCE, Suite


@dataclass(frozen=True)
class RunItem:
    """One run to do; plain values only (it crosses process boundaries)."""

    scene: str  # the scene's label in the records
    scene_file: str
    planner: str
    seed: int
    cache_dir: str
    plan_file: str
    budget_s: float
    roadmap_nodes: int
    grasp_target: int | None
    iterations: int = DEFAULT_ITERATIONS  # RRT-Connect iterations per query (every planner)
    style: str = "auto"
    exhaustive: int = 0
    sampler: str = "faces"
    held_speed: float | None = None
    labels: tuple[tuple[str, object], ...] = ()  # more fields of its record (an in-hand run's hand, object, goal)


def scene_labels(suite: Suite) -> dict[Path, str]:
    """A short unique label per scene: the file stem, or the path relative to the suite
    file when two stems clash."""
    stems = [p.stem for p in suite.scenes]
    if len(set(stems)) == len(stems):
        return dict(zip(suite.scenes, stems))
    return {p: os.path.relpath(p, suite.file.parent) for p in suite.scenes}


def items_of(suite: Suite, cache_dir: Path, plan_dir: Path) -> list[RunItem]:
    """Every run, seed-major; for each seed the planners' order rotates with the seed, so
    warm-up and machine noise fall on them alike."""
    labels = scene_labels(suite)
    items = []
    for scene in suite.scenes:
        for i, seed in enumerate(suite.seeds):
            k = i % len(suite.planners)
            for planner in suite.planners[k:] + suite.planners[:k]:
                name = f"{labels[scene]}-{planner}-{seed}".replace("/", "_").replace(os.sep, "_")
                items.append(RunItem(labels[scene], str(scene), planner, seed, str(Path(cache_dir).resolve()),
                                     str((plan_dir / f"{name}.json").resolve()), suite.budget_s,
                                     suite.roadmap_nodes, suite.grasp_target, suite.iterations, suite.style,
                                     suite.exhaustive, suite.sampler, suite.held_speed))
    return items


# ------------------------------------------------------------------ offline stages


def _snapshot(folder: Path) -> dict[str, int]:
    return {str(p): p.stat().st_mtime_ns for p in folder.glob("*.h5")} if folder.is_dir() else {}


def offline_stages(suite: Suite, cache_dir: Path, jobs: int, builder=None) -> dict[str, dict]:
    """Per scene label: seconds and status (``built`` or ``cached``) of loading the
    problem, the grasp lists of both hands and the roadmap (when a planner needs it),
    building whichever is missing or stale, and of making the Super Graph ready."""
    from regrasp_cli.artefacts import load_artefacts, load_placements
    from regrasp_cli.errors import EmptyResultError, InputError
    from regrasp_cli.manip.queries import Roadmap
    from regrasp_cli.scene import load_problem

    need_roadmap = REFERENCE in suite.planners
    rows, problems = {}, {}
    for scene in suite.scenes:  # every scene read before any is built on: a bad one is refused at once
        t0 = time.perf_counter()
        problems[scene] = load_problem(scene, cache_dir)
        rows[scene] = {"problem": {"s": time.perf_counter() - t0, "status": "loaded"}}
    out = {}
    for scene, label in scene_labels(suite).items():
        row, problem = rows[scene], problems[scene]
        for what, folder, roadmap in (("grasp lists", "grasps", False), ("roadmap", "roadmap", True)):
            if roadmap and not need_roadmap:
                continue
            before = _snapshot(Path(cache_dir) / folder)
            t0 = time.perf_counter()
            try:
                lists, art, _ = load_artefacts(scene, cache_dir, problem, True, jobs, roadmap, builder,
                                               suite.roadmap_nodes, suite.grasp_target)
            except EmptyResultError as exc:  # the scene's runs fail on the missing artefact, the others go on
                row[what] = {"s": time.perf_counter() - t0, "status": f"empty ({exc})"}
                break
            seconds = time.perf_counter() - t0
            built = _snapshot(Path(cache_dir) / folder) != before
            row[what] = {"s": seconds, "status": "built" if built else "cached"}
            if not roadmap:
                row[what]["size"] = {h: len(g.X_OG) for h, g in lists.items()}
            else:
                t0 = time.perf_counter()
                rm = Roadmap.of(art)
                row["super graph ready"] = {"s": time.perf_counter() - t0, "status": "loaded",
                                            "size": {"nodes": len(rm.nodes), "edges": len(rm.edges)}}
        if suite.style in ("auto", "place-regrasp"):
            t0 = time.perf_counter()
            try:
                found = load_placements(Path(cache_dir), problem, True)[0]
                row["placements"] = {"s": time.perf_counter() - t0, "status": "ready", "size": {"stable": len(found)}}
            except InputError as exc:  # no stable placement: the runs say so
                row["placements"] = {"s": time.perf_counter() - t0, "status": f"empty ({exc.message})"}
        out[label] = row
    return out


# ------------------------------------------------------------------ one run


def _stamp(scene_file: str, cache_dir: str) -> tuple:
    """When the scene file and the cached artefacts last changed: part of the key of the
    worker's context, so that a reused worker never plans with inputs since rebuilt (the
    parent rebuilds stale artefacts, which changes their files)."""
    files = [Path(scene_file), *sorted(Path(cache_dir).glob("grasps/*.h5")),
             *sorted(Path(cache_dir).glob("roadmap/*.h5"))]
    return tuple((str(p), p.stat().st_mtime_ns, p.stat().st_size) for p in files if p.exists())


def request_of(item: RunItem):
    """The pipeline's :class:`~regrasp_cli.pipeline.Request` of a run: one process, the
    suite's RRT-Connect budget for every planner, OMPL's wall-clock guard the run's budget."""
    from regrasp_cli.pipeline import Request

    return Request(planner=item.planner, style=item.style, seed=item.seed, jobs=1, sampler=item.sampler,
                   roadmap_nodes=item.roadmap_nodes, grasp_target=item.grasp_target, iterations=item.iterations,
                   ompl_time=item.budget_s, held_speed=item.held_speed)


@functools.lru_cache(maxsize=4)
def _context(scene_file: str, cache_dir: str, request, stamp: tuple):
    """The loaded task (:func:`~regrasp_cli.pipeline.load_task`) and path-length weights of
    a scene, loaded once per worker process (the parent built the artefacts; placements an
    object does not have are found missing here in tenths of a second) and again whenever
    the ``stamp`` of its inputs changes."""
    from regrasp_cli.motion.local import joint_weights
    from regrasp_cli.pipeline import load_task

    loaded = load_task(Path(scene_file), Path(cache_dir), request)
    # one metric for every planner, so that path lengths compare
    return loaded, joint_weights(loaded.problem.robot)


def _item_context(item: RunItem):
    # what loading reads (the cache key of _context)
    request = replace(request_of(item), seed=None, iterations=None, ompl_time=None, held_speed=None)
    return _context(item.scene_file, item.cache_dir, request, _stamp(item.scene_file, item.cache_dir))


def path_length(phases, weights: np.ndarray) -> float:
    """Sum of the weighted joint-space lengths of the straight segments between
    consecutive waypoints of every phase (``phases``: objects with ``waypoints`` (k, nq))."""
    from regrasp_cli.motion.local import distance

    total = 0.0
    for p in phases:
        w = np.asarray(p.waypoints, dtype=float)
        if len(w) > 1:
            total += float(np.sum(distance(w[:-1], w[1:], weights)))
    return total


def regrasps(phases) -> int:
    """How many times a grasp is replaced by another (1 for a hand-over): changes of the
    holding grasp over the phases where one hand holds (``holding``: hand -> grasp id)."""
    holders = [tuple(p.holding.items()) for p in phases if len(p.holding) == 1]
    return sum(a != b for a, b in zip(holders, holders[1:]))


def _base(item: RunItem) -> dict:
    return {"scene": item.scene, **dict(item.labels), "planner": item.planner, "seed": item.seed, "solved": False,
            "stage": None, "transition": None, "reason": None, "total_s": None, "planner_s": None, "write_s": None,
            "validation_s": None, "stages_s": {}, "queries": {}, "validation": None, "path_length": None,
            "regrasps": None, "motion_s": None, "waypoints": None, "plan": None, "peak_rss_mb": None,
            "style": None, "placements": None, "styles": None, "exhaustive": None, "counts": None}


def peak_rss_mb() -> float:
    """Peak resident memory of this process (MB)."""
    kb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return kb / (1024.0 * 1024.0) if sys.platform == "darwin" else kb / 1024.0  # bytes on macOS


def execute(item: RunItem) -> dict:
    """The run itself, in this process (:func:`regrasp_cli.pipeline.run_task`); raises
    whatever the planner raises."""
    from regrasp_cli.manip.tasks import manipulation
    from regrasp_cli.pipeline import run_task

    loaded, weights = _item_context(item)
    rec = _base(item)
    out_file = Path(item.plan_file)
    graph = {}
    run = run_task(loaded, request_of(item), out_file, check=True, timings=True, keep=graph, validate_jobs=1)
    outcome, plan, report = run.outcome, run.plan, run.report
    rec.update({
        "total_s": sum(run.seconds.values()), "planner_s": run.seconds["planner"], "write_s": run.seconds["write"],
        "validation_s": run.seconds["validation"], "stages_s": {k: float(v) for k, v in outcome.stages.items()},
        "queries": {q: {"n": s.nodes, "invalid_edges": s.invalid_edges, "rrt_calls": s.rrt_calls,
                        "planning_s": s.planning_s, "validation_s": s.validation_s} for q, s in outcome.transitions.items()},
        "plan": out_file.name, "counts": {k: v for k, v in outcome.counts.items() if k != "styles"},
    })
    if outcome.failure is not None:
        f = outcome.failure
        rec["stage"], rec["transition"], rec["reason"] = f.stage.value, f.transition, f.reason
        return rec
    rec.update({"path_length": path_length(plan.phases, weights), "regrasps": regrasps(plan.phases),
                "motion_s": float(plan.duration), "waypoints": int(sum(len(p.waypoints) for p in plan.phases)),
                "validation": {"valid": report.valid, "issues": len(report.issues),
                               "first_issues": [str(i) for i in report.issues[:3]],
                               "configurations_checked": int(report.configurations_checked)}})
    if outcome.task != "inhand":
        rec.update({"style": outcome.counts.get("style", "handover"), "placements": outcome.counts.get("placements", 0),
                    "styles": outcome.counts.get("styles")})
    if item.exhaustive and "graph" in graph:
        t4 = time.perf_counter()
        fewer, solved = manipulation.fewer_regrasps(graph["graph"], list(loaded.stable), rec["regrasps"],
                                                    item.exhaustive)
        rec["exhaustive"] = {"fewer_exist": fewer, "edges_solved": solved, "s": time.perf_counter() - t4}
    if run.refused is None:
        rec["solved"] = True
    else:
        rec["stage"], rec["reason"] = run.refused.stage.value, run.refused.reason
    return rec


def _crash(item: RunItem, exc: BaseException, seconds: float) -> dict:
    rec = _base(item)
    message = " ".join(str(exc).split()) or "(no message)"
    rec.update({"stage": Stage.CRASH.value, "reason": f"{type(exc).__name__}: {message}", "total_s": seconds,
                "traceback": traceback.format_exc(limit=8)})
    return rec


def _child(fd: int, item: RunItem, work: Callable[[RunItem], dict]) -> None:
    t0 = time.perf_counter()
    try:
        rec = work(item)
    except BaseException as exc:  # noqa: BLE001 - every failure becomes a record
        rec = _crash(item, exc, time.perf_counter() - t0)
    rec["peak_rss_mb"] = peak_rss_mb()
    data = pickle.dumps(rec)
    with os.fdopen(fd, "wb") as pipe:
        pipe.write(len(data).to_bytes(8, "big") + data)


def _whole(buf: bytearray) -> bytes | None:
    if len(buf) >= 8 and len(buf) >= 8 + int.from_bytes(buf[:8], "big"):
        return bytes(buf[8:])
    return None


def _await(fd: int, pid: int, deadline: float) -> tuple[bytes | None, int | None]:
    """Wait for the child ``pid`` to send its record on the pipe ``fd`` (its length in 8
    bytes, then its pickle) until ``deadline`` (a ``time.perf_counter`` value).  Returns
    (pickle, status) once the record is whole, (None, status) when the child ended without
    sending it, (None, None) when the deadline passed; ``status`` is the child's wait
    status when it was reaped here, else None (the caller then kills and reaps it).

    The child is polled as well as the pipe: in a Dask worker with several threads, the
    child of a sibling run may hold a copy of this pipe's write end, so EOF can come late."""
    buf = bytearray()
    while (whole := _whole(buf)) is None:
        left = deadline - time.perf_counter()
        if left <= 0:
            return None, None
        if select.select([fd], [], [], min(left, 0.1))[0]:
            chunk = os.read(fd, 1 << 16)
            if chunk:
                buf += chunk
                continue
            return None, os.waitpid(pid, 0)[1]  # EOF without a whole record: the child is gone
        ended, status = os.waitpid(pid, os.WNOHANG)
        if ended:
            while select.select([fd], [], [], 0)[0] and (chunk := os.read(fd, 1 << 16)):
                buf += chunk
            if (whole := _whole(buf)) is None:
                return None, status
            return whole, status
    return whole, None


def run_one(item: RunItem, work: Callable[[RunItem], dict] = execute) -> dict:
    """``work(item)`` in a forked child process, killed after ``item.budget_s`` seconds;
    always returns a record.  The scene and artefacts are loaded here first (cached per
    process, not counted in the budget), so the child inherits them.

    The child is a plain ``os.fork`` with a pipe, not a ``multiprocessing.Process``: Dask
    workers are daemonic processes, which multiprocessing forbids to have children."""
    t0 = time.perf_counter()
    try:
        if work is execute:
            _item_context(item)
    except BaseException as exc:  # noqa: BLE001
        return _crash(item, exc, time.perf_counter() - t0)
    recv, send = os.pipe()
    t0 = time.perf_counter()
    pid = os.fork()
    if pid == 0:  # the child: never returns into the caller (pytest, joblib, dask)
        try:
            os.close(recv)
            _child(send, item, work)
        finally:
            os._exit(0)  # no atexit handlers of the parent in the fork
    os.close(send)
    status = None
    try:
        data, status = _await(recv, pid, t0 + item.budget_s)
        if data is not None:
            return pickle.loads(data)
        rec = _base(item)
        if status is None:
            rec.update({"stage": Stage.BUDGET.value, "reason": f"exceeded the budget of {item.budget_s:g} s (killed)",
                        "total_s": time.perf_counter() - t0})
            return rec
        code = os.waitstatus_to_exitcode(status)
        how = f"killed by signal {-code}" if code < 0 else f"exit code {code}"
        rec.update({"stage": Stage.CRASH.value, "reason": f"the run's process died ({how})",
                    "total_s": time.perf_counter() - t0})
        return rec
    finally:
        os.close(recv)
        if status is None:  # over budget, or done but not yet reaped
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            os.waitpid(pid, 0)


def forget_contexts() -> None:
    """Drop the scenes and artefacts this process loaded for its runs (run on every Dask
    worker before and after a suite: a cluster outlives one bench command)."""
    _context.cache_clear()


def run_items(items: list[RunItem], jobs: int, on_record: Callable[[dict], None], client=None) -> list[dict]:
    """Every item in ``jobs`` loky processes (this process when jobs == 1), or, given a
    connected ``distributed.Client``, on the workers of its Dask cluster (joblib's dask
    backend, all the cluster's threads); calls ``on_record`` in this process as each
    record arrives (in item order)."""
    from joblib import Parallel, delayed, parallel_config

    if client is None:
        config = parallel_config(backend="loky")
    else:
        client.run(forget_contexts)
        config = parallel_config(backend="dask", client=client)
    records = []
    try:
        with config:
            for rec in Parallel(n_jobs=jobs, return_as="generator")(delayed(run_one)(it) for it in items):
                records.append(rec)
                on_record(rec)
    finally:
        _context.cache_clear()
        if client is not None:
            client.run(forget_contexts)
    return records
