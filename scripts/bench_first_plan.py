"""Benchmark: a new object's first plan, from an empty grasp cache.

For each YCB scan's scene of ``configs/bench/ycb.yaml`` (the goal behind the lamp, seed 0),
runs ``regrasp plan`` as a user would with a new object: the robot's artefacts (roadmap,
self-collision pairs, finger workspaces) already cached, no grasp list yet.  Prints per
object the wall time of the whole command (both hands' lists, planning, timing, the
plan's check), whether the plan is solved and valid, and the median, as a Markdown table.
Benchmark only: the meshes are read from ../shared/meshes/ycb/.

    .venv/bin/python scripts/bench_first_plan.py [--only mug,banana] [--jobs 2]
"""

from __future__ import annotations

import argparse
import json
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
SCENES = ROOT / "configs" / "bench" / "scenes"
REGRASP = Path(sys.executable).parent / "regrasp"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", default="", help="comma-separated substrings of the scene names to run")
    ap.add_argument("--jobs", type=int, default=2)
    args = ap.parse_args()
    sys.path.insert(0, str(HERE))
    from benchlib import machine

    scenes = sorted(SCENES.glob("ycb16_*_behind.yaml"))
    scenes = [s for s in scenes if not args.only or any(o in s.stem for o in args.only.split(","))]
    print(machine(jobs=args.jobs, seed=0) + "\n")
    print("| object | first plan (s) | status | valid |")
    print("|---|---|---|---|")
    times = []
    with tempfile.TemporaryDirectory() as tmp:
        cache = Path(tmp) / "cache"
        # the robot's artefacts, once: the default scene's roadmap, pairs and workspaces
        subprocess.run([str(REGRASP), "--cache-dir", str(cache), "plan", str(ROOT / "configs" / "scenes" /
                        "desk_handover.yaml"), "-o", str(Path(tmp) / "warm.json"), "--jobs", str(args.jobs)],
                       capture_output=True, check=False)
        for scene in scenes:
            shutil.rmtree(cache / "grasps", ignore_errors=True)
            out = Path(tmp) / f"{scene.stem}.json"
            t = time.perf_counter()
            r = subprocess.run([str(REGRASP), "--cache-dir", str(cache), "plan", str(scene), "-o", str(out),
                                "--jobs", str(args.jobs)], capture_output=True, text=True, check=False)
            wall = time.perf_counter() - t
            status = json.loads(out.read_text())["status"] if out.is_file() else "no plan"
            valid = r.returncode == 0 and any(line.strip() == "valid" for line in r.stdout.splitlines())
            times.append(wall)
            print(f"| {scene.stem.removeprefix('ycb16_').removesuffix('_behind')} | {wall:.1f} | {status} | "
                  f"{'yes' if valid else 'no'} |", flush=True)
    print(f"\nmedian {statistics.median(times):.1f} s over {len(times)} objects; slowest {max(times):.1f} s")


if __name__ == "__main__":
    main()
