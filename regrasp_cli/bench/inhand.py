"""The in-hand benchmark suite (seed 003; ``format: regrasp.inhand-bench/1``), run by
`regrasp bench` like the pick-and-place suites.

For each hand, each of its objects and each of ``goals`` goal orientations (uniform on
SO(3), goal k drawn from seed k, about the object's own centre, which starts at the
hand's grasp frame), the run writes the in-hand scene (``OUT/scenes/``); the runs are
then those of any suite (:mod:`regrasp_cli.bench.runner`: the pipeline of `regrasp
inhand plan`, each forked with its budget, the plan written to ``OUT/plans/`` and checked
with `regrasp validate`, the same record with the run's hand, object, goal and goal angle).
A run is solved when the plan is valid.

Fields: ``name``; ``hands`` (each ``{robot, side, label, objects}``: a robot.yaml path
relative to the suite or ``builtin:NAME``, the hand's side (default right), a label
(default the robot's file stem or built-in name), and the labels of the objects it is
given, default all); ``objects`` (each ``{mesh, scale, friction, label, optional}``,
paths relative to the suite file, the label's default the mesh's; ``optional: true``
skips a missing file, for meshes not shipped); the name and the labels name files and
folders (letters, digits, '.', '_', '-', as a pick-and-place suite's name); ``goals``
(runs per hand and object, default 20), from ``first_goal`` (default 0); ``nodes`` (the trees' budget of expansions, default a
scene's, ``InhandPlanning.nodes``); ``mode`` (``single-query`` or ``multi-query``, default
single-query: with multi-query, each hand and object's roadmap is learned before the
runs, and its time reported apart); ``budget_s`` (seconds a run may take before it is
killed, default 600).  Every error is an :class:`InputError` naming the
file and field, the suite's for a bad hand or object found only when a run's scene is
loaded (each hand and object's is loaded before anything is written).
"""

from __future__ import annotations

import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml
from scipy.spatial.transform import Rotation

from regrasp_cli.bench.runner import RunItem
from regrasp_cli.bench.suite import MAX_SEEDS, file_name
from regrasp_cli.config import INHAND_MODES, Fields, InhandPlanning, read_yaml, resolve_path
from regrasp_cli.dexterous.task import PLANNER
from regrasp_cli.errors import InputError, shown
from regrasp_cli.roadmap.build import RoadmapOptions

INHAND_SUITE_FORMAT = "regrasp.inhand-bench/1"


@dataclass(frozen=True)
class InhandObject:
    mesh: str  # builtin:NAME or an absolute path
    label: str
    scale: float = 1.0
    friction: float = 0.8
    field: str = "objects"  # where the suite file gives it, e.g. objects[2]


@dataclass(frozen=True)
class InhandHand:
    robot: str  # builtin:NAME or an absolute path
    side: str
    label: str
    objects: tuple[str, ...]  # object labels
    field: str = "hands"  # where the suite file gives it, e.g. hands[0]


@dataclass(frozen=True)
class InhandSuite:
    file: Path
    name: str
    hands: tuple[InhandHand, ...]
    objects: tuple[InhandObject, ...]
    goals: tuple[int, ...]
    nodes: int = InhandPlanning.nodes
    mode: str = "single-query"
    skipped: tuple[str, ...] = ()  # optional meshes not found
    budget_s: float = 600.0


def suite_format(path: str | Path) -> str | None:
    """The ``format`` field of a suite file, to tell the two kinds apart (None when absent)."""
    _, data = read_yaml(path)
    return data.get("format") if isinstance(data, dict) else None


def load_inhand_suite(path: str | Path) -> InhandSuite:
    """Read and check an in-hand suite file."""
    file, data = read_yaml(path)
    f = Fields(file, data)
    f.only("format", "name", "hands", "objects", "goals", "first_goal", "nodes", "mode", "budget_s")
    if f.str("format") != INHAND_SUITE_FORMAT:
        raise f.error("format", f"expected {shown(INHAND_SUITE_FORMAT)}, found {shown(f.data['format'])}")
    objects, skipped = _objects(f)
    labels = {o.label for o in objects} | set(skipped)
    hands = _hands(f, labels)
    goals, first = f.int("goals", 20, minimum=1), f.int("first_goal", 0, minimum=0)
    if goals > MAX_SEEDS:
        raise f.error("goals", f"expected at most {MAX_SEEDS:,} goals, found {goals}")
    mode = f.str("mode", "single-query")
    if mode not in INHAND_MODES:
        raise f.error("mode", f"expected one of {', '.join(INHAND_MODES)}, found {shown(mode)}")
    name = file_name(file, "name", f.str("name"), "the results folder")
    return InhandSuite(file, name, hands, objects, tuple(range(first, first + goals)),
                       f.int("nodes", InhandPlanning.nodes, minimum=1), mode, skipped,
                       f.float("budget_s", InhandSuite.budget_s, positive=True))


def _objects(f: Fields) -> tuple[tuple[InhandObject, ...], tuple[str, ...]]:
    raw = f.raw("objects")
    if not isinstance(raw, list) or not raw:
        raise f.error("objects", "expected a non-empty list of {mesh, label, scale, friction, optional}")
    out, skipped = [], []
    for i, _ in enumerate(raw):
        o = Fields(f.file, raw[i], f"objects[{i}]")
        o.only("mesh", "label", "scale", "friction", "optional")
        mesh = o.str("mesh")
        label = file_name(f.file, f"objects[{i}].label", o.str("label", Path(mesh).stem.replace("builtin:", "")),
                          "the runs' scene and plan files")
        if not mesh.startswith("builtin:"):
            path = resolve_path(f.file, f"objects[{i}].mesh", mesh, must_exist=False)
            if not path.is_file():
                if o.bool("optional", False):
                    skipped.append(label)
                    continue
                raise o.error("mesh", f"no such file {path}")
            mesh = str(path)
        out.append(InhandObject(mesh, label, o.float("scale", 1.0, positive=True),
                                o.float("friction", 0.8, positive=True), f"objects[{i}]"))
    if len({o.label for o in out}) != len(out):
        raise f.error("objects", "two objects have the same label")
    return tuple(out), tuple(skipped)


def _hands(f: Fields, labels: set[str]) -> tuple[InhandHand, ...]:
    raw = f.raw("hands")
    if not isinstance(raw, list) or not raw:
        raise f.error("hands", "expected a non-empty list of {robot, side, label, objects}")
    out = []
    for i, _ in enumerate(raw):
        h = Fields(f.file, raw[i], f"hands[{i}]")
        h.only("robot", "side", "label", "objects")
        robot = h.str("robot")
        if not robot.startswith("builtin:"):
            robot = str(resolve_path(f.file, f"hands[{i}].robot", robot))  # must exist
        objects = h.names("objects", tuple(sorted(labels)))
        unknown = [o for o in objects if o not in labels]
        if unknown:
            raise h.error("objects", f"no object labelled {', '.join(unknown)} (objects: {', '.join(sorted(labels))})")
        label = file_name(f.file, f"hands[{i}].label", h.str("label", Path(robot).stem.replace("builtin:", "")),
                          "the runs' scene and plan files")
        out.append(InhandHand(robot, h.str("side", "right"), label, objects, f"hands[{i}]"))
    if len({h.label for h in out}) != len(out):
        raise f.error("hands", "two hands have the same label")
    return tuple(out)


def items_of(suite: InhandSuite, out: Path, cache_dir: Path) -> list[RunItem]:
    """One run per hand, object and goal, its scene written to ``out/scenes/`` once each
    hand and object's problem has loaded as the runs will load it: a bad one is an
    InputError naming the suite's field, and nothing is written.  Plans go to
    ``out/plans/``, named as the scenes."""
    from regrasp_cli.model.objects import load_object_mesh

    scenes: dict[Path, dict] = {}
    items = []
    for h in suite.hands:
        for o in (o for o in suite.objects if o.label in h.objects):
            obj = load_object_mesh(o.mesh, base_dir=suite.file.parent, scale=o.scale, file=suite.file,
                                   field=f"{o.field}.mesh")
            centre = obj.mesh.bounds.mean(axis=0)
            for k in suite.goals:
                rpy = Rotation.random(random_state=np.random.default_rng(k)).as_euler("xyz")
                path = out / "scenes" / f"{h.label}-{o.label}-{k:02d}.yaml"
                if path in scenes:  # labels joined by '-' can meet: a-b + c, a + b-c
                    raise InputError(suite.file, f"{h.field}.label", f"with object {o.label}, its scenes are named "
                                     f"as another hand and object's ({path.name}): choose another label")
                scenes[path] = _scene(suite, h, o, [float(-x) for x in centre], rpy, k)
                labels = (("hand", h.label), ("object", o.label), ("goal", k),
                          ("goal_angle_rad", float(Rotation.from_euler("xyz", rpy).magnitude())))
                items.append(RunItem(path.stem, str(path.resolve()), PLANNER, k, str(Path(cache_dir).resolve()),
                                     str((out / "plans" / f"{path.stem}.json").resolve()), suite.budget_s,
                                     RoadmapOptions.nodes, None, labels=labels))
            _check_scene(suite, h, o, scenes[path], cache_dir)  # the goals' scenes differ in goal and seed only
    (out / "scenes").mkdir(parents=True, exist_ok=True)
    (out / "plans").mkdir(exist_ok=True)
    for path, scene in scenes.items():
        path.write_text(yaml.safe_dump(scene, sort_keys=False))
    return items


def _scene(suite: InhandSuite, h: InhandHand, o: InhandObject, p_GO: list[float], rpy: np.ndarray,
           seed: int) -> dict:
    """The in-hand scene of one run: the object's centre at the grasp frame (``p_GO``, m),
    turned to ``rpy`` (rad)."""
    return {"format": "regrasp.inhand/1", "robot": h.robot, "hand": h.side,
            "object": {"mesh": o.mesh, "scale": o.scale, "friction": o.friction},
            "object_start": {"xyz": p_GO}, "object_goal": {"rpy": [float(x) for x in rpy]},
            "planning": {"seed": seed, "nodes": suite.nodes, "mode": suite.mode}}


def _check_scene(suite: InhandSuite, h: InhandHand, o: InhandObject, scene: dict, cache_dir: Path | None) -> None:
    """Load the problem of ``scene`` (hand ``h`` and object ``o``'s) from a temporary
    copy: an InputError in it names the suite's field it comes from instead (the
    generated file is the bench's, not the user's); others, e.g. a robot.yaml's, as they are."""
    from regrasp_cli.dexterous.task import load_inhand_problem

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "scene.yaml"
        path.write_text(yaml.safe_dump(scene, sort_keys=False))
        try:
            load_inhand_problem(path, cache_dir)
        except InputError as exc:
            if exc.file is None or Path(exc.file).resolve() != path.resolve():
                raise
            raise InputError(suite.file, _suite_field(exc.field, h, o), exc.message) from None


def _suite_field(field: str | None, h: InhandHand, o: InhandObject) -> str:
    """The suite's field that a generated scene's ``field`` comes from."""
    head, _, rest = (field or "").partition(".")
    if head == "object":
        return f"{o.field}.{rest}" if rest else o.field
    if head == "planning" and rest in ("nodes", "mode"):
        return rest
    return {"robot": f"{h.field}.robot", "hand": f"{h.field}.side"}.get(head, h.field)


def prepare(items: list[RunItem], cache_dir: Path, mode: str, notice=None) -> dict[str, float]:
    """Each hand's artefacts (finger workspaces, self-collision pairs) built once before
    the workers; with multi-query, each hand and object's roadmap too: its learning time
    per ``hand/object`` (0 when found fresh in the cache).  ``notice(text)`` is told
    before each roadmap."""
    from regrasp_cli.dexterous.task import inhand_roadmap, load_inhand_problem

    learned = {}
    runs = [(dict(it.labels), it.scene_file) for it in items]
    for labels, scene in {(r["hand"], r["object"] if mode == "multi-query" else ""): (r, f) for r, f in runs}.values():
        problem = load_inhand_problem(scene, cache_dir)
        if mode == "multi-query":
            if notice is not None:
                notice(f"the {labels['hand']} roadmap for the {labels['object']} (learned once, or found in the cache)")
            t = time.perf_counter()
            _, _, built = inhand_roadmap(problem)
            learned[f"{labels['hand']}/{labels['object']}"] = time.perf_counter() - t if built else 0.0
    return learned


def summary(records: list[dict]) -> str:
    """The table per hand and object: success, planning time, node counts, gaits."""
    lines = ["| hand | object | solved (valid) | median planning (s) | IQR (s) | generated (median) | kept (median) | "
             "gaits (median) | transfers (median) | failures |", "|---|---|---|---|---|---|---|---|---|---|"]
    for hand, obj in dict.fromkeys((r["hand"], r["object"]) for r in records):
        rs = [r for r in records if (r["hand"], r["object"]) == (hand, obj)]
        ok = [r for r in rs if r["solved"]]
        t = np.array([r["planner_s"] for r in rs if r["planner_s"] is not None] or [np.nan])

        def med(k: str) -> str:
            return f"{np.median([r['counts'][k] for r in ok]):.0f}" if ok else "–"

        fails: dict[str, int] = {}
        for r in rs:
            if not r["solved"]:
                fails[r["stage"]] = fails.get(r["stage"], 0) + 1
        lines.append(f"| {hand} | {obj} | {len(ok)}/{len(rs)} | {np.median(t):.2f} | "
                     f"{np.percentile(t, 25):.2f}–{np.percentile(t, 75):.2f} | {med('nodes_generated')} | "
                     f"{med('nodes_kept')} | {med('finger_regrasps')} | {med('transfers')} | "
                     f"{', '.join(f'{k} {v}' for k, v in fails.items()) or '–'} |")
    return "\n".join(lines) + "\n"


def check_overrides(planners: str | None, iterations: int | None) -> None:
    """The pick-and-place suite's options have no meaning here: refused, not ignored."""
    for name, value in (("--planners", planners), ("--iterations", iterations)):
        if value is not None:
            raise InputError(None, name, f"not for an in-hand suite ({INHAND_SUITE_FORMAT}): its runs have the "
                                         f"suite's nodes as their budget")
