"""`regrasp grasps build SCENE --meshes DIR`: the grasp lists of a folder of meshes (a
dataset), one task per mesh x hand, on local loky processes or on the workers of an
existing Dask cluster (as `regrasp bench --backend dask`).

A task builds what `regrasp grasps build` builds for a scene whose object is that mesh:
the scene's YAML with ``object.mesh`` set to the mesh's absolute path and its other paths
made absolute, written to a temporary folder of the process that runs the task.  A grasp
list is context independent (Saut et al. 2010, §IV-A): it lands in the cache under the
name a one-scene build gives it, so `regrasp plan` of any scene with that robot, mesh,
friction and options finds it.  A task that fails (unreadable or flat mesh, no grasp)
returns its reason and the others go on; the results do not depend on the backend nor on
the number of jobs (each task builds with one job, from the seed).
"""

from __future__ import annotations

import copy
import tempfile
import threading
import time
import warnings
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Callable

import click
import yaml
from rich.console import Console
from rich.markup import escape
from rich.table import Table

from regrasp_cli.errors import EmptyGraspList, InputError, RegraspError

if TYPE_CHECKING:
    from regrasp_cli.grasp.build import BuildOptions

MESH_SUFFIXES = (".obj", ".stl", ".ply", ".off", ".glb")  # the mesh files of a dataset folder (trimesh reads them)

# The grasp search keeps process-wide state (regrasp_cli.parallel's running map), so two
# builds must not run at once in one process, as two threads of a Dask worker would.
_ONE_BUILD_AT_A_TIME = threading.Lock()


@dataclass(frozen=True)
class MeshTask:
    """One grasp list to build: ``hand``'s, for the scene ``scene_yaml`` (its object the
    mesh ``mesh``, every path in it absolute), into ``cache_dir`` (absolute)."""

    scene_yaml: str
    mesh: Path
    hand: str
    options: BuildOptions  # jobs = 1: the tasks are the parallelism
    cache_dir: Path


@dataclass(frozen=True)
class MeshResult:
    """What a task did: ``reason`` is None when the list was built (``grasps`` of them,
    written to ``path``), else why not; ``warnings``: those the build raised (e.g. a mesh
    that is not watertight), to show where the command runs."""

    mesh: str  # the mesh file's name
    hand: str
    grasps: int | None
    seconds: float  # wall-clock time of the build
    reason: str | None = None
    path: Path | None = None
    warnings: tuple[str, ...] = ()

    @property
    def ok(self) -> bool:
        return self.reason is None


# ------------------------------------------------------------------ inputs


def mesh_files(folder: Path) -> list[Path]:
    """The mesh files directly in ``folder`` (suffix in :data:`MESH_SUFFIXES`, any case),
    sorted by name, as absolute paths.

    Raises:
        InputError: ``folder`` is not a folder, or holds no mesh file (field ``--meshes``).
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise InputError(None, "--meshes", f"no such folder: {folder}")
    meshes = sorted((p.resolve() for p in folder.iterdir() if p.is_file() and p.suffix.lower() in MESH_SUFFIXES),
                    key=lambda p: p.name)
    if not meshes:
        raise InputError(None, "--meshes", f"no mesh file ({' '.join(MESH_SUFFIXES)}) in {folder}")
    return meshes


def scene_with_mesh(spec, data: dict, mesh: Path) -> dict:
    """The scene's YAML mapping ``data`` (parsed into ``spec``, a SceneSpec) with
    ``object.mesh`` set to ``mesh`` and its other paths (robot.yaml, obstacle meshes) made
    absolute, so that a copy in any folder loads the same scene; ``builtin:`` names and
    ``package://`` URIs do not depend on the folder and stay as they are."""
    from regrasp_cli.examples import BUILTIN_PREFIX

    d = copy.deepcopy(data)
    if not str(d["robot"]).startswith(BUILTIN_PREFIX):
        d["robot"] = str(spec.robot)
    d["object"] = {**d["object"], "mesh": str(mesh)}
    for raw, obstacle in zip(d.get("obstacles") or [], spec.obstacles):
        if obstacle.mesh is not None and not str(raw["mesh"]["file"]).startswith("package://"):
            raw["mesh"] = {**raw["mesh"], "file": str(obstacle.mesh)}
    return d


def tasks_of(scene: Path, meshes: list[Path], hands: list[str], options: BuildOptions,
             cache_dir: Path) -> list[MeshTask]:
    """One task per mesh x hand, mesh-major, each building with one job."""
    from regrasp_cli.config import load_scene_spec, read_yaml

    spec = load_scene_spec(scene)
    _, data = read_yaml(scene)
    options, cache_dir = replace(options, jobs=1), Path(cache_dir).resolve()
    return [MeshTask(yaml.safe_dump(scene_with_mesh(spec, data, mesh), sort_keys=False), mesh, hand, options,
                     cache_dir)
            for mesh in meshes for hand in hands]


# ------------------------------------------------------------------ one task


def build_one(task: MeshTask) -> MeshResult:
    """Build ``task``'s grasp list as `regrasp grasps build` would for its scene; a failure
    becomes the result's reason instead of an exception, so that one bad mesh of a
    dataset does not stop the others."""
    from regrasp_cli.artefacts import build_grasp_list  # imported before the clock starts

    with _ONE_BUILD_AT_A_TIME, tempfile.TemporaryDirectory(prefix="regrasp-scene-") as folder, \
            warnings.catch_warnings(record=True) as caught:
        t0 = time.perf_counter()  # not counting the wait for another thread's build
        warnings.simplefilter("always")
        scene = Path(folder) / f"{task.mesh.stem}.yaml"
        scene.write_text(task.scene_yaml)
        try:
            glist, report = build_grasp_list(scene, task.cache_dir, task.hand, task.options)
            grasps, path, reason = len(glist), report.path, None
        except Exception as exc:  # noqa: BLE001 - every failure of a task is its result
            grasps, path, reason = None, None, failure_reason(exc, scene)
    return MeshResult(task.mesh.name, task.hand, grasps, time.perf_counter() - t0, reason, path,
                      tuple(dict.fromkeys(str(w.message) for w in caught)))


def failure_reason(exc: Exception, scene: Path) -> str:
    """Why a task failed, in one line, without the name of its temporary scene file."""
    if isinstance(exc, EmptyGraspList):
        return f"no grasp: {exc.reason}"
    if isinstance(exc, InputError) and exc.file is not None and Path(exc.file).resolve() == scene.resolve():
        return ": ".join(p for p in (exc.field, exc.message) if p)
    if isinstance(exc, RegraspError):
        return str(exc)
    return f"{type(exc).__name__}: {' '.join(str(exc).split()) or '(no message)'}"


# ------------------------------------------------------------------ all tasks


def run_tasks(tasks: list[MeshTask], jobs: int, client, on_result: Callable[[MeshResult], None]) -> list[MeshResult]:
    """:func:`build_one` of every task, in ``jobs`` loky processes (this one when jobs ==
    1), or, given a connected ``distributed.Client``, on its cluster's workers (all their
    threads); ``on_result`` is called here as each result arrives, in task order."""
    from joblib import Parallel, delayed, parallel_config

    config = parallel_config(backend="loky") if client is None else parallel_config(backend="dask", client=client)
    results = []
    with config:
        for result in Parallel(n_jobs=jobs if client is None else -1, return_as="generator")(
                delayed(build_one)(t) for t in tasks):
            results.append(result)
            on_result(result)
    return results


def run_dataset_build(scene: Path, cache_dir: Path, meshes_dir: Path, hand: str, seed: int | None, jobs: int,
                      positions: int | None, orientations: int | None, target: int | None = None,
                      weights: str | None = None, pinch_frames: int | None = None, backend: str = "loky",
                      scheduler: str | None = None, console: Console | None = None) -> list[MeshResult]:
    """`regrasp grasps build SCENE --meshes DIR`: every mesh x hand (``hand``: right, left
    or both), the build options as `regrasp grasps build`'s; prints a line per task and
    the table of results.

    Raises:
        InputError: bad input (the folder, the scene, an option, the backend); nothing is built.
        RegraspError: some tasks failed (exit code 1), naming them, after the others were built.
    """
    from regrasp_cli.artefacts import build_options
    from regrasp_cli.commands.bench import dask_client
    from regrasp_cli.config import load_scene_spec

    console = console or Console()
    check_backend(backend, scheduler)
    meshes = mesh_files(meshes_dir)
    options = build_options(load_scene_spec(scene).planning.seed, seed, jobs, positions, orientations, target, weights,
                            pinch_frames)
    client = dask_client(scheduler) if backend == "dask" else None
    try:
        hands = scene_hands(scene, cache_dir, hand)
        tasks = tasks_of(scene, meshes, hands, options, cache_dir)
        where = f"{jobs} loky job(s)" if client is None else f"dask at {client.scheduler.address}"
        console.print(f"{len(tasks)} grasp lists ({len(meshes)} mesh(es) x {len(hands)} hand(s)), {where}",
                      markup=False, highlight=False)
        results = run_tasks(tasks, jobs, client, _progress(len(tasks), console))
    finally:
        if client is not None:
            client.close()
    print_results(results, console)
    failed = [r for r in results if not r.ok]
    if failed:
        raise RegraspError(f"{len(failed)} of {len(results)} grasp lists failed: {_names(failed)}")
    return results


def check_backend(backend: str, scheduler: str | None) -> None:
    """``--backend`` and ``--scheduler`` as `regrasp bench` takes them (the scheduler's
    address is checked when connecting)."""
    if backend not in ("loky", "dask"):
        raise InputError(None, "--backend", f"expected loky or dask, found {backend!r}")
    if backend == "loky" and scheduler is not None:
        raise InputError(None, "--scheduler", "only for --backend dask")


def scene_hands(scene: Path, cache_dir: Path, hand: str) -> list[str]:
    """The hands of ``--hand`` (right, left or both), after loading the scene once here:
    its errors come before any task, and its robot's self-collision matrix is cached
    before the tasks need it.

    Raises:
        InputError: the scene is bad, or its robot lacks one of the hands.
    """
    from regrasp_cli.commands.progress import load_problem_shown

    hands = ["right", "left"] if hand == "both" else [hand]
    robot = load_problem_shown(scene, cache_dir).robot
    for h in hands:
        if h not in robot.hands:
            raise InputError(robot.spec.file, "hands", f"the robot has no {h} hand (it has: {', '.join(robot.hands)})")
    return hands


def _progress(total: int, console: Console) -> Callable[[MeshResult], None]:
    """A line per finished task (``[k/total] mesh hand: grasps or why not``); the warnings
    of its mesh on stderr."""
    done = [0]

    def show(r: MeshResult) -> None:
        done[0] += 1
        state = f"{r.grasps} grasps" if r.ok else f"failed: {r.reason}"
        console.print(f"[{done[0]}/{total}] {r.mesh} {r.hand} hand: {state} ({r.seconds:.1f} s)",
                      markup=False, highlight=False)
        for line in r.warnings:
            click.echo(f"warning: {line}", err=True)

    return show


def _names(results: list[MeshResult]) -> str:
    """``a.stl (right, left), b.obj (right)``: the meshes and hands of ``results``."""
    hands: dict[str, list[str]] = {}
    for r in results:
        hands.setdefault(r.mesh, []).append(r.hand)
    return ", ".join(f"{mesh} ({', '.join(hs)})" for mesh, hs in hands.items())


def print_results(results: list[MeshResult], console: Console) -> None:
    """The table of the tasks: mesh, hand, grasps, seconds, status (ok, or why not)."""
    t = Table(title="Grasp lists of the meshes")
    for c, justify in (("mesh", "left"), ("hand", "left"), ("grasps", "right"), ("time (s)", "right"),
                       ("status", "left")):
        t.add_column(c, justify=justify)
    for r in results:
        t.add_row(r.mesh, r.hand, "-" if r.grasps is None else str(r.grasps), f"{r.seconds:.1f}",
                  "ok" if r.ok else f"[red]failed[/]: {escape(r.reason)}")
    console.print(t)
    built = next((r.path for r in results if r.ok), None)
    if built is not None:
        console.print(f"grasp lists: {built.parent}/", markup=False, highlight=False)
