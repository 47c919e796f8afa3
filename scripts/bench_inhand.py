"""In-hand benchmark (seed 003): `python scripts/bench_inhand.py configs/bench/inhand.yaml -o OUT`.

For each object of the suite and each of ``goals`` random goal orientations (uniform on
SO(3), drawn from the run's seed), it writes the in-hand scene (``OUT/scenes/``), plans
it with the same functions as `regrasp inhand plan`, writes the plan (``OUT/plans/``),
checks it with `regrasp validate`'s in-hand checks, and records one JSON line per run in
``OUT/runs.jsonl``: solved (valid), the stage that failed, times, configurations
generated and nodes kept (the paper's 105 and 21), transfers and finger gaits.  The
object starts with its bounding box centred in the hand's grasp frame.  ``OUT/summary.md``
has the table per object: success, median time and IQR, node counts, gaits.

The suite (``format: regrasp.inhand-bench/1``): ``name``; ``hands`` (each ``{robot,
side, label, objects}``: a robot.yaml path or ``builtin:NAME``, the hand's side (default
right), and the labels of the objects it is given, default all); ``objects`` (each
``{mesh, scale, friction, label}``, paths relative to the suite file; ``optional: true``
skips a missing file); ``goals`` (runs per hand and object, default 20), from goal
``first_goal`` (default 0); ``nodes`` (the tree's budget, default 1500).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
import trimesh
import yaml
from joblib import Parallel, delayed
from scipy.spatial.transform import Rotation

from regrasp_cli.config import read_yaml
from regrasp_cli.dexterous.record import make_inhand_plan
from regrasp_cli.dexterous.task import load_inhand_problem, plan_inhand
from regrasp_cli.errors import RegraspError
from regrasp_cli.model.objects import load_object_mesh
from regrasp_cli.trajectory import write_plan
from regrasp_cli.validate import validate_plan


def runs_of(suite_file: Path, out: Path) -> list[dict]:
    file, d = read_yaml(suite_file)
    if d.get("format") != "regrasp.inhand-bench/1":
        sys.exit(f"{file}: format: expected 'regrasp.inhand-bench/1'")
    goals, nodes, first = int(d.get("goals", 20)), int(d.get("nodes", 1500)), int(d.get("first_goal", 0))
    runs = []
    for h in d["hands"]:
        hand = h["robot"] if h["robot"].startswith("builtin:") else str((file.parent / h["robot"]).resolve())
        label = h.get("label", Path(hand).stem)
        objects = [o for o in d["objects"] if h.get("objects") is None or o["label"] in h["objects"]]
        runs += _hand_runs(file, out, hand, h.get("side", "right"), label, objects, range(first, first + goals), nodes)
    return runs


def _hand_runs(file: Path, out: Path, hand: str, side: str, hand_label: str, objects: list[dict],
               goals: range, nodes: int) -> list[dict]:
    runs = []
    for o in objects:
        mesh = o["mesh"]
        if not mesh.startswith("builtin:"):
            path = (file.parent / mesh).resolve()
            if not path.is_file():
                if o.get("optional"):
                    print(f"skipped (missing): {path}")
                    continue
                sys.exit(f"{file}: objects: no such file {path}")
            mesh = str(path)
        obj = load_object_mesh(mesh, base_dir=file.parent, scale=o.get("scale", 1.0))
        centre = obj.mesh.bounds.mean(axis=0)
        label = o.get("label", Path(mesh).stem.replace("builtin:", ""))
        for k in goals:
            rng = np.random.default_rng(k)
            rpy = Rotation.random(random_state=rng).as_euler("xyz")
            scene = {"format": "regrasp.inhand/1", "robot": hand, "hand": side,
                     "object": {"mesh": mesh, "scale": float(o.get("scale", 1.0)),
                                "friction": float(o.get("friction", 0.8))},
                     "object_start": {"xyz": [float(-x) for x in centre]},
                     "object_goal": {"rpy": [float(x) for x in rpy]},
                     "planning": {"seed": k, "nodes": nodes}}
            path = out / "scenes" / f"{hand_label}-{label}-{k:02d}.yaml"
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(yaml.safe_dump(scene, sort_keys=False))
            angle = float(Rotation.from_euler("xyz", rpy).magnitude())
            runs.append({"hand": hand_label, "object": label, "goal": k, "scene": str(path), "goal_angle_rad": angle})
    return runs


def run(item: dict, out: Path, cache_dir: Path) -> dict:
    rec = dict(item)
    t0 = time.perf_counter()
    try:
        problem = load_inhand_problem(item["scene"], cache_dir)
        o = plan_inhand(problem, cache_dir, problem.spec.planning.seed)
        plan_file = out / "plans" / (Path(item["scene"]).stem + ".json")
        plan_file.parent.mkdir(parents=True, exist_ok=True)
        write_plan(plan_file, make_inhand_plan(problem, o, problem.spec.planning.seed, plan_file, cache_dir, True))
        rec.update({k: v for k, v in o.stats.items() if k != "gs_failures"})
        rec["planning_s"] = o.stats["planning_s"]
        if o.failure is not None:
            rec.update(solved=False, stage=o.failure.stage.value, reason=o.failure.reason)
        else:
            t = time.perf_counter()
            report = validate_plan(plan_file)
            rec.update(solved=report.valid, validation_s=time.perf_counter() - t,
                       stage=None if report.valid else "validation",
                       reason=None if report.valid else str(report.issues[0]))
    except RegraspError as exc:  # input refused: a failure of the run, with its one line
        rec.update(solved=False, stage="input", reason=str(exc))
    except Exception as exc:  # noqa: BLE001 - a crash is a failed run, recorded, not the end of the suite
        rec.update(solved=False, stage="crash", reason=repr(exc))
    rec["total_s"] = time.perf_counter() - t0
    return rec


def summary(records: list[dict]) -> str:
    lines = ["| hand | object | solved (valid) | median planning (s) | IQR (s) | generated (median) | kept (median) | "
             "gaits (median) | transfers (median) | failures |", "|---|---|---|---|---|---|---|---|---|---|"]
    for hand, obj in dict.fromkeys((r["hand"], r["object"]) for r in records):
        rs = [r for r in records if (r["hand"], r["object"]) == (hand, obj)]
        ok = [r for r in rs if r["solved"]]
        t = np.array([r["planning_s"] for r in rs if "planning_s" in r])
        med = lambda k: f"{np.median([r[k] for r in ok]):.0f}" if ok else "–"  # noqa: E731
        fails = {}
        for r in rs:
            if not r["solved"]:
                fails[r["stage"]] = fails.get(r["stage"], 0) + 1
        lines.append(f"| {hand} | {obj} | {len(ok)}/{len(rs)} | {np.median(t):.2f} | "
                     f"{np.percentile(t, 25):.2f}–{np.percentile(t, 75):.2f} | {med('nodes_generated')} | "
                     f"{med('nodes_kept')} | {med('regrasps')} | {med('transfers')} | "
                     f"{', '.join(f'{k} {v}' for k, v in fails.items()) or '–'} |")
    return "\n".join(lines) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("suite", type=Path)
    ap.add_argument("-o", "--output", type=Path, default=Path("bench-inhand"))
    ap.add_argument("--cache-dir", type=Path, default=Path("cache"))
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--only", help="run only this hand's or object's label")
    a = ap.parse_args()
    a.output.mkdir(parents=True, exist_ok=True)
    items = [r for r in runs_of(a.suite, a.output) if a.only in (None, r["hand"], r["object"])]
    for first in {r["hand"]: r for r in items}.values():  # each hand's artefacts (workspace,
        load_inhand_problem(first["scene"], a.cache_dir)   # self-collision pairs) before the workers
    records = []
    with open(a.output / "runs.jsonl", "w") as f:
        for rec in Parallel(n_jobs=a.jobs, return_as="generator")(delayed(run)(i, a.output, a.cache_dir) for i in items):
            records.append(rec)
            f.write(json.dumps(rec) + "\n")
            f.flush()
            print(f"{rec['hand']} {rec['object']} goal {rec['goal']}: {'solved' if rec['solved'] else rec['stage']} "
                  f"in {rec['total_s']:.1f} s", flush=True)
    (a.output / "summary.md").write_text(summary(records))
    print(summary(records))


if __name__ == "__main__":
    trimesh.util.log.setLevel("ERROR")
    main()
