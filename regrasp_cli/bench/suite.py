"""The benchmark suite file (``format: regrasp.bench/1``) -> a frozen :class:`Suite`.

Fields: ``name``; ``scenes`` (scene.yaml paths relative to the suite file); ``planners``
(names of :data:`PLANNERS`); ``seeds`` (a count N, meaning 0 .. N-1, or a list of
integers; default 20); ``budget_s`` (wall-clock seconds per run, default 60); optional
``iterations`` (RRT-Connect iterations per query, default 3000: the budget of the
single-query planners, ours and OMPL's, and of the roadmap planner's fallback, so that
every planner gets the same), ``roadmap_nodes`` (default 50) and ``grasp_target``
(default: the grasp builder's), ``style`` (as `regrasp plan --style`, default ``auto``),
``sampler`` (as `regrasp plan --sampler`, default ``faces``), ``held_speed`` (as `regrasp
plan --held-speed`, in (0, 1], default the planner's 0.5) and ``exhaustive`` (default false: after each solved run, look for a path of fewer
regrasps over the same manipulation graph, solving the motions of every edge it needs, up
to ``exhaustive`` edges; the record says whether the plan's count is the minimum).
Every error is an :class:`~regrasp_cli.errors.InputError` naming the file and field.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, replace
from pathlib import Path

from regrasp_cli.config import Fields, read_yaml, resolve_path
from regrasp_cli.errors import InputError, shown
from regrasp_cli.roadmap.build import RoadmapOptions

SUITE_FORMAT = "regrasp.bench/1"
# planners a suite may name; the roadmap is the reference of the per-seed ratios, and the
# only one that loads the offline roadmap
PLANNERS = ("roadmap", "rrt-connect", "ompl-rrtconnect")
REFERENCE = "roadmap"
DEFAULT_SEEDS = 20
DEFAULT_BUDGET_S = 60.0
DEFAULT_ITERATIONS = 3000  # OnlineOptions().rrt.max_iterations
MAX_SEEDS = 10_000  # runs per scene and planner: 10,000 plans of 2 s are most of a day already
STYLES = ("auto", "one-arm", "handover", "inhand", "place-regrasp", "seed000")  # regrasp plan --style
SAMPLERS = ("faces", "vis-prm")  # regrasp plan --sampler
_FILE_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]*")  # one path component, never '..'


@dataclass(frozen=True)
class Suite:
    file: Path
    name: str
    scenes: tuple[Path, ...]
    planners: tuple[str, ...]
    seeds: tuple[int, ...]
    budget_s: float = DEFAULT_BUDGET_S
    roadmap_nodes: int = RoadmapOptions.nodes
    grasp_target: int | None = None
    iterations: int = DEFAULT_ITERATIONS
    style: str = "auto"
    exhaustive: int = 0  # edges whose motions the exhaustive check may solve per run (0: no check)
    sampler: str = "faces"
    held_speed: float | None = None  # None: the planner's (OnlineOptions.held_speed)


def _planners(file: Path | None, field: str, names: list) -> tuple[str, ...]:
    if not names:
        raise InputError(file, field, f"expected at least one planner of: {', '.join(PLANNERS)}")
    for name in names:
        if name not in PLANNERS:
            raise InputError(file, field, f"unknown planner {shown(name)}; expected one of: {', '.join(PLANNERS)}")
    if len(set(names)) != len(names):
        raise InputError(file, field, "a planner is listed twice")
    return tuple(names)


def load_suite(path: str | Path) -> Suite:
    """Read and check a suite file."""
    file, data = read_yaml(path)
    f = Fields(file, data)
    f.only("format", "name", "scenes", "planners", "seeds", "budget_s", "iterations", "roadmap_nodes",
           "grasp_target", "style", "exhaustive", "sampler", "held_speed")
    fmt = f.str("format")
    if fmt != SUITE_FORMAT:
        raise f.error("format", f"expected {shown(SUITE_FORMAT)}, found {shown(fmt)}")
    name = file_name(file, "name", f.str("name"), "the results folder")
    scenes = f.raw("scenes")
    if not isinstance(scenes, list) or not scenes or not all(isinstance(s, str) and s for s in scenes):
        raise f.error("scenes", "expected a non-empty list of scene.yaml paths (relative to the suite file)")
    scene_paths = tuple(resolve_path(file, f"scenes[{i}]", s) for i, s in enumerate(scenes))
    if len(set(scene_paths)) != len(scene_paths):
        raise f.error("scenes", "a scene is listed twice")
    planners = f.raw("planners")
    if not isinstance(planners, list) or not all(isinstance(p, str) for p in planners):
        raise f.error("planners", f"expected a list of planner names ({', '.join(PLANNERS)})")
    seeds = seeds_of(file, "seeds", f.data.get("seeds", DEFAULT_SEEDS))
    budget = f.float("budget_s", DEFAULT_BUDGET_S, positive=True)
    nodes = f.int("roadmap_nodes", 50, minimum=1)
    iterations = f.int("iterations", DEFAULT_ITERATIONS, minimum=1)
    target = f.data.get("grasp_target")
    if target is not None:
        target = f.int("grasp_target", minimum=0)
    style = f.str("style", "auto")
    if style not in STYLES:
        raise f.error("style", f"expected one of {', '.join(STYLES)}, found {shown(style)}")
    sampler = f.str("sampler", "faces")
    if sampler not in SAMPLERS:
        raise f.error("sampler", f"expected one of {', '.join(SAMPLERS)}, found {shown(sampler)}")
    held = f.float("held_speed", None, positive=True, maximum=1.0)
    return Suite(file, name, scene_paths, _planners(file, "planners", planners), seeds, float(budget), nodes, target,
                 iterations, style, f.int("exhaustive", 0, minimum=0), sampler, held)


def file_name(file: Path | None, field: str, value: str, names: str) -> str:
    """``value`` when it can name a file or folder inside another one (letters, digits,
    '.', '_' or '-', first a letter or digit: no separator, no '..'), else an InputError
    saying it ``names`` (e.g. "the results folder")."""
    if not _FILE_NAME.fullmatch(value):
        raise InputError(file, field, f"expected letters, digits, '.', '_' or '-' (it names {names}), found {shown(value)}")
    return value


def seeds_of(file: Path | None, field: str, value) -> tuple[int, ...]:
    """A count N (seeds 0 .. N-1, at most :data:`MAX_SEEDS`) or a list of distinct
    integers >= 0."""
    if isinstance(value, bool):
        raise InputError(file, field, "expected a count or a list of integer seeds, found bool")
    if isinstance(value, int):
        if not 1 <= value <= MAX_SEEDS:
            raise InputError(file, field, f"expected a count from 1 to {MAX_SEEDS:,}, found {value}")
        return tuple(range(value))
    if isinstance(value, list) and value and all(isinstance(s, int) and not isinstance(s, bool) and s >= 0
                                                  for s in value):
        if len(set(value)) != len(value):
            raise InputError(file, field, "a seed is listed twice")
        if len(value) > MAX_SEEDS:
            raise InputError(file, field, f"expected at most {MAX_SEEDS:,} seeds, found {len(value):,}")
        return tuple(value)
    raise InputError(file, field, f"expected a count >= 1 or a non-empty list of integers >= 0, found {shown(value)}")


def with_overrides(suite: Suite, seeds: int | None = None, planners: str | None = None,
                   budget_s: float | None = None, iterations: int | None = None) -> Suite:
    """The suite with the command line's ``--seeds N``, ``--planners a,b``, ``--budget-s``
    and ``--iterations``."""
    if seeds is not None:
        suite = replace(suite, seeds=seeds_of(None, "--seeds", seeds))
    if planners is not None:
        names = [p.strip() for p in planners.split(",") if p.strip()]
        suite = replace(suite, planners=_planners(None, "--planners", names))
    if budget_s is not None:
        suite = replace(suite, budget_s=checked_budget(budget_s))
    if iterations is not None:
        if isinstance(iterations, bool) or not isinstance(iterations, int) or iterations < 1:
            raise InputError(None, "--iterations", f"expected an integer >= 1, found {iterations}")
        suite = replace(suite, iterations=iterations)
    return suite


def checked_budget(budget_s: float) -> float:
    """The command line's ``--budget-s``: finite seconds > 0, else an InputError."""
    if not (budget_s > 0 and math.isfinite(budget_s)):
        raise InputError(None, "--budget-s", f"expected a number of seconds > 0, found {budget_s}")
    return float(budget_s)
