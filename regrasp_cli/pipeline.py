"""One pipeline for every task (issue 42): a scene in, a checked plan file out.

The scene's ``format`` names its task: ``regrasp.scene/1`` a pick-and-place (seed 000's
hand-over and seed 001's manipulation graph, chosen by ``style``), ``regrasp.inhand/1``
a reorientation in one hand by finger gaiting (seed 003).  For both,
:func:`load_task` reads the problem and the artefacts it needs (grasp lists, roadmap,
stable placements; built when missing unless told not to) and :func:`run_task` solves it
(a :class:`~regrasp_cli.manip.solve.Outcome`: timed steps), records it as a plan/2,
writes it and checks it with the independent validator (:mod:`regrasp_cli.validate`);
a plan the validator refuses is rewritten with status ``failed``.  `regrasp plan`,
`regrasp inhand plan` and every run of `regrasp bench` are these two calls.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Callable

from regrasp_cli.artefacts import Builder, load_artefacts, placements_for_style
from regrasp_cli.config import INHAND_FORMAT, read_yaml
from regrasp_cli.dexterous.task import PLANNER, load_inhand_problem, plan_inhand
from regrasp_cli.errors import EmptyGraspList, EmptyRoadmap, InputError
from regrasp_cli.manip.context import OnlineOptions
from regrasp_cli.manip.queries import Roadmap
from regrasp_cli.manip.record import make_plan
from regrasp_cli.manip.solve import Outcome, ends_failure
from regrasp_cli.manip.status import PlanningFailed, Stage
from regrasp_cli.manip.tasks import manipulation
from regrasp_cli.model.selfcollision import PairProgress
from regrasp_cli.placement.supports import scene_supports
from regrasp_cli.roadmap.build import RoadmapOptions
from regrasp_cli.scene import Problem, load_problem
from regrasp_cli.trajectory import Plan, write_plan, write_refused
from regrasp_cli.validate import ValidationReport, validate_plan

PICK_AND_PLACE, INHAND = "pick-and-place", "inhand"


@dataclass(frozen=True)
class Request:
    """How to plan: the command's options, or a benchmark run's.  ``seed`` None is the
    scene's; ``iterations`` (RRT-Connect iterations per query), ``ompl_time`` (s) and
    ``held_speed`` None are :class:`OnlineOptions`'; ``mode`` (in-hand: single- or
    multi-query) None the scene's."""

    planner: str = OnlineOptions.planner
    style: str = "auto"
    seed: int | None = None
    jobs: int = OnlineOptions.jobs
    sampler: str = "faces"
    roadmap_nodes: int = RoadmapOptions.nodes
    grasp_target: int | None = None
    iterations: int | None = None
    ompl_time: float | None = None
    mode: str | None = None
    held_speed: float | None = None

    def options(self, task: str) -> OnlineOptions:
        """The planner's options for ``task`` (the in-hand planner is named in the plan)."""
        o = OnlineOptions(planner=PLANNER if task == INHAND else self.planner, jobs=self.jobs)
        if self.iterations is not None:
            o = replace(o, rrt=replace(o.rrt, max_iterations=self.iterations))
        if self.held_speed is not None:
            o = replace(o, held_speed=self.held_speed)
        return o if self.ompl_time is None else replace(o, ompl_time=self.ompl_time)


@dataclass(frozen=True)
class Loaded:
    """A task ready to solve: its problem and artefacts (pick-and-place: the grasp lists
    by hand, the Super Graph or None, the artefacts' SHA-256 by name, the stable
    placements), and ``failure`` when the run must fail before solving (the
    robot's ends in collision, an empty grasp list or roadmap)."""

    task: str
    problem: Problem
    lists: dict = field(default_factory=dict)
    roadmap: Roadmap | None = None
    hashes: dict = field(default_factory=dict)
    stable: tuple = ()
    failure: PlanningFailed | None = None


def task_of(scene: str | Path) -> str:
    """The task of the scene file (by its ``format``); a malformed one is refused when loaded."""
    _, data = read_yaml(scene)
    return INHAND if isinstance(data, dict) and data.get("format") == INHAND_FORMAT else PICK_AND_PLACE


def load_task(scene: str | Path, cache_dir: Path, request: Request, build: bool = True, builder: Builder | None = None,
              progress: PairProgress | None = None) -> Loaded:
    """The scene's problem and artefacts.  Missing or stale artefacts are built (``builder``
    shows it) or, with ``build`` False, refused with an InputError naming them; the robot's
    ends are checked before any is built (nothing else matters if they collide).
    ``progress(done, total)``: the self-collision matrix's, the first time a robot is used."""
    if task_of(scene) == INHAND:
        problem = load_inhand_problem(scene, cache_dir)
        if request.mode is not None:
            planning = replace(problem.spec.planning, mode=request.mode)
            problem = replace(problem, spec=replace(problem.spec, planning=planning))
        return Loaded(INHAND, problem)
    problem = load_problem(scene, cache_dir, progress)
    if request.style == "place-regrasp" and not scene_supports(problem.spec.obstacles, problem.spec.supports, scene):
        raise InputError(scene, "obstacles", "--style place-regrasp puts the object down, and the scene has no "
                                             "support surface (a box with an axis along z, or an upright cylinder)")
    loaded = Loaded(PICK_AND_PLACE, problem)
    failure = ends_failure(problem, request.options(PICK_AND_PLACE))  # milliseconds: before any artefact
    if failure is not None:
        return replace(loaded, failure=failure)
    stable, sha = placements_for_style(request.style, cache_dir, problem, build, builder)
    try:
        lists, art, hashes = load_artefacts(Path(scene), cache_dir, problem, build, request.jobs,
                                            request.planner == "roadmap", builder, request.roadmap_nodes,
                                            request.grasp_target)
    except (EmptyGraspList, EmptyRoadmap) as exc:
        stage = Stage.GRASPS if isinstance(exc, EmptyGraspList) else Stage.ROADMAP
        return replace(loaded, failure=PlanningFailed(stage, exc.message))
    if sha is not None:
        hashes = {"placements": sha, **hashes}
    return replace(loaded, lists=lists, roadmap=None if art is None else Roadmap.of(art), hashes=hashes,
                   stable=tuple(stable))


def seed_of(loaded: Loaded, request: Request) -> int:
    """The run's seed: the request's, else the scene's."""
    return loaded.problem.spec.planning.seed if request.seed is None else request.seed


def solve_task(loaded: Loaded, request: Request, progress: Callable[[int, int], None] | None = None,
               builder: Builder | None = None, keep: dict | None = None) -> Outcome:
    """The loaded task solved: its outcome (``failure`` set when it failed).  ``progress``
    (done, budget) follows the in-hand search; ``keep`` receives the manipulation graph."""
    if loaded.task == INHAND:
        return plan_inhand(loaded.problem, seed_of(loaded, request), progress, builder)
    if loaded.failure is not None:
        return manipulation.failed(loaded.problem, loaded.failure, request.style)
    return manipulation.plan_style(loaded.problem, loaded.lists, loaded.roadmap, request.options(loaded.task),
                                   seed_of(loaded, request), request.style, list(loaded.stable), keep=keep,
                                   sampler=request.sampler)


@dataclass(frozen=True)
class TaskRun:
    """A planned, written and checked run: the plan as written (status ``failed`` when
    refused), the outcome, the validator's report (None when not checked or not solved),
    ``refused`` (the validator's failure, or None), and seconds per part (``planner``,
    ``write``, ``validation``)."""

    plan: Plan
    outcome: Outcome
    report: ValidationReport | None
    refused: PlanningFailed | None
    seconds: dict

    @property
    def failure(self) -> PlanningFailed | None:
        """Why the run did not give a valid plan, or None."""
        return self.outcome.failure or self.refused


def run_task(loaded: Loaded, request: Request, out_file: Path, check: bool = True, timings: bool = True,
             progress: Callable[[int, int], None] | None = None, builder: Builder | None = None,
             keep: dict | None = None, validate_jobs: int = 2) -> TaskRun:
    """Solve, record, write ``out_file`` and (``check``) validate it; paths in the plan are
    relative to its folder, and without ``timings`` it holds no wall-clock time (the same
    seed gives the same bytes)."""
    t0 = time.perf_counter()
    outcome = solve_task(loaded, request, progress, builder, keep)
    t1 = time.perf_counter()
    cache_dir = loaded.problem.cache_dir
    plan = make_plan(loaded.problem, loaded.lists, outcome, request.options(loaded.task), seed_of(loaded, request), out_file,
                     cache_dir, loaded.hashes, timings)
    write_plan(out_file, plan)
    t2 = time.perf_counter()
    report = refused = None
    if check and outcome.failure is None:
        report = validate_plan(out_file, jobs=validate_jobs)
        if not report.valid:
            refused = PlanningFailed(Stage.VALIDATION, report.refusal())
            write_refused(out_file, plan, refused.as_dict())
    t3 = time.perf_counter()
    return TaskRun(plan, outcome, report, refused, {"planner": t1 - t0, "write": t2 - t1, "validation": t3 - t2})
