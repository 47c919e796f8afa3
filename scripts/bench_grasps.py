"""Benchmark of `regrasp grasps build`: distinct force-closure grasps per second per hand.

For each object (the default scene's statuette, the paper's horse and the 16 YCB scans of
../shared/meshes/ycb/, the last two benchmark-only and read from outside the repository),
builds one hand's grasp list with the default options in a fresh grasp cache (the robot's
self-collision matrix and finger workspaces with their voxel maps kept: robot artefacts,
built once), with one job, and prints per object the frames tried, force-closure grasps,
distinct grasps kept, the wall time and grasps per second, and the median and the worst
object, as a Markdown table.

    .venv/bin/python scripts/bench_grasps.py [--jobs 1] [--hand right] [--only mug,horse]
    .venv/bin/python scripts/bench_grasps.py --root ../old   # a worktree of an older commit, same objects

``--root`` runs the code of another checkout (a worktree of an older commit), for a
side-by-side comparison on the same machine; its options are its own defaults.
"""

from __future__ import annotations

import argparse
import statistics
import warnings
from dataclasses import replace
import sys
import tempfile
import time
from pathlib import Path

import yaml

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
SHARED = ROOT.parent / "shared" / "meshes"
SCENE = ROOT / "configs" / "scenes" / "desk_handover.yaml"


def objects() -> list[tuple[str, str]]:
    """(label, mesh) of every benchmark object present on this machine."""
    out = [("statuette", "builtin:statuette")]
    if (SHARED / "horse_1334.stl").is_file():
        out.append(("horse", str(SHARED / "horse_1334.stl")))
    out += [(p.stem, str(p)) for p in sorted((SHARED / "ycb").glob("*.stl"))]
    return out


def scene_for(mesh: str, tmp: Path, label: str) -> Path:
    """The default scene with ``mesh`` as the object (paths made absolute)."""
    data = yaml.safe_load(SCENE.read_text())
    data["robot"] = str((ROOT / "configs" / "robots" / "humanoid43" / "robot.yaml").resolve())
    data["object"]["mesh"] = mesh
    path = tmp / f"{label}.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--hand", default="right")
    ap.add_argument("--target", type=int, default=None, help="distinct grasps per list (default: the build's)")
    ap.add_argument("--only", default="", help="comma-separated substrings of the object labels to run")
    ap.add_argument("--root", type=Path, default=ROOT, help="the checkout whose code is run")
    args = ap.parse_args()
    warnings.simplefilter("ignore")  # the scans are not watertight: said once per mesh, not here
    sys.path.insert(0, str(args.root.resolve()))
    sys.path.insert(1, str(HERE))
    from benchlib import machine

    from regrasp_cli.grasp.build import BuildOptions, build_grasps
    from regrasp_cli.grasp.workspace import WorkspaceOptions, hand_workspace
    from regrasp_cli.scene import load_problem

    print(machine(jobs=args.jobs, hand=args.hand, target=args.target or "default", code=str(args.root)) + "\n")
    cases = [(label, mesh) for label, mesh in objects() if not args.only or any(s in label for s in args.only.split(","))]
    rates = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp, cache = Path(tmp), Path(tmp) / "cache"
        print("| object | frames | force closure | kept | wall time (s) | grasps/s |")
        print("|---|---|---|---|---|---|")
        for label, mesh in cases:
            scene = scene_for(mesh, tmp, label)
            robot = load_problem(scene, cache).robot  # the robot's self-collision matrix, once
            hand_workspace(robot, args.hand, WorkspaceOptions(), cache)  # and the finger workspaces
            for old in (cache / "grasps").glob("*.h5") if (cache / "grasps").is_dir() else ():
                old.unlink()
            t = time.perf_counter()
            options = BuildOptions(jobs=args.jobs)
            if args.target is not None:
                options = replace(options, grasp=replace(options.grasp, target=args.target))
            _, rep = build_grasps(scene, cache, args.hand, options)
            wall = time.perf_counter() - t
            rates.append((rep.kept / wall, label))
            print(f"| {label} | {rep.frames} | {rep.force_closure} | {rep.kept} | {wall:.1f} | {rep.kept / wall:.1f} |",
                  flush=True)
    med = statistics.median(r for r, _ in rates)
    worst = min(rates)
    print(f"\nmedian {med:.1f} grasps/s over {len(rates)} objects; worst {worst[0]:.1f} ({worst[1]})")


if __name__ == "__main__":
    main()
