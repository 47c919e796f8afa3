"""Benchmark of `regrasp grasps build`: distinct force-closure grasps per hand and time.

Runs the grasp-list build for the default scene's statuette and, when it is present, for
the paper's horse (../shared/meshes/horse_1334.stl, a benchmark-only mesh), each in a
fresh cache so nothing is reused, ``--repeats`` times, and prints the median wall time,
grasps kept, grasps/s and the time split between stages, as a Markdown table.

    .venv/bin/python scripts/bench_grasps.py [--jobs 2] [--repeats 3] [--hand right]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from benchlib import fresh_cache, machine  # noqa: E402

from regrasp_cli.grasp.build import BuildOptions, build_grasps  # noqa: E402

SCENE = ROOT / "configs" / "scenes" / "desk_handover.yaml"
HORSE = ROOT.parent / "shared" / "meshes" / "horse_1334.stl"


def horse_scene(tmp: Path) -> Path:
    """The default scene with the horse as the object (path given absolutely)."""
    data = yaml.safe_load(SCENE.read_text())
    if not str(data["robot"]).startswith("builtin:"):
        data["robot"] = str((SCENE.parent / data["robot"]).resolve())
    data["object"]["mesh"] = str(HORSE)
    path = tmp / "horse_scene.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def run(scene: Path, hand: str, jobs: int, repeats: int, robot_cache: Path) -> dict:
    """Each repeat in a fresh cache holding only the robot's self-collision matrix (a robot
    artefact shared by every stage): surface, workspace spheres and grasps are rebuilt."""
    times, kept, fc, frames, stages = [], [], [], [], []
    for _ in range(repeats):
        with tempfile.TemporaryDirectory() as cache:
            fresh_cache(robot_cache, Path(cache))
            glist, rep = build_grasps(scene, Path(cache), hand, BuildOptions(jobs=jobs))
        times.append(sum(rep.seconds.values()))
        kept.append(rep.kept)
        fc.append(rep.force_closure)
        frames.append(rep.frames)
        stages.append(rep.seconds)
    med = statistics.median(times)
    i = times.index(sorted(times)[len(times) // 2])
    return {"time": med, "kept": statistics.median(kept), "fc": statistics.median(fc), "frames": frames[0],
            "stages": stages[i], "times": times}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--hand", default="right")
    args = ap.parse_args()
    print(machine(jobs=args.jobs, repeats=args.repeats, hand=args.hand) + "\n")
    cases = [("builtin:statuette", SCENE)]
    with tempfile.TemporaryDirectory() as tmp:
        robot_cache = Path(tmp) / "robot_cache"
        from regrasp_cli.scene import load_problem

        load_problem(SCENE, robot_cache)  # computes the self-collision matrix once
        if HORSE.is_file():
            cases.append(("horse_1334.stl", horse_scene(Path(tmp))))
        print("| object | frames | force-closure grasps | distinct kept | wall time (s, median) | grasps/s | "
              "prep / search / write (s) |")
        print("|---|---|---|---|---|---|---|")
        for name, scene in cases:
            r = run(scene, args.hand, args.jobs, args.repeats, robot_cache)
            s = r["stages"]
            print(f"| {name} | {r['frames']} | {r['fc']:.0f} | {r['kept']:.0f} | {r['time']:.2f} | "
                  f"{r['kept'] / r['time']:.1f} | " + " / ".join(f"{v:.2f}" for v in s.values()) + " |")


if __name__ == "__main__":
    main()
