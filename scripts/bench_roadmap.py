"""Benchmark of `regrasp roadmap build`: Super Graph size and build time against the size of
the elementary roadmaps (Saut et al. 2010 §VI: 50 + 50 Vis-PRM nodes, about 1,700 Super
Graph nodes, about 5 minutes).

Each case is built in a fresh cache (only the robot's self-collision matrix is reused) and
repeated ``--repeats`` times; the table gives the median wall time, the time per stage,
the sizes and the collision checks per second.

    .venv/bin/python scripts/bench_roadmap.py [--nodes 25 50 100] [--jobs 2] [--repeats 1] [--tree]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from benchlib import fresh_cache, machine  # noqa: E402

from regrasp_cli.roadmap.build import RoadmapOptions, build_roadmap  # noqa: E402
from regrasp_cli.scene import load_problem  # noqa: E402

SCENE = ROOT / "configs" / "scenes" / "desk_handover.yaml"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--nodes", type=int, nargs="+", default=[25, 50, 100])
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--tree", action="store_true")
    args = ap.parse_args()
    print(machine(jobs=args.jobs, repeats=args.repeats, mode='tree' if args.tree else 'graph') + "\n")
    print("| nodes per elementary roadmap | R_r / R_l | Super Graph | wall time (s, median) | "
          "elementary / SG nodes / SG edges (s) | collision checks | checks/s |")
    print("|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        robot_cache = Path(tmp) / "robot"
        load_problem(SCENE, robot_cache)
        for n in args.nodes:
            runs = []
            for _ in range(args.repeats):
                cache = Path(tmp) / f"c{n}-{len(runs)}"
                fresh_cache(robot_cache, cache)
                art, rep = build_roadmap(SCENE, cache, RoadmapOptions(nodes=n, tree=args.tree), args.jobs)
                runs.append((sum(rep.seconds.values()), art, rep))
            times = [r[0] for r in runs]
            t, art, rep = sorted(runs, key=lambda r: r[0])[len(runs) // 2]
            s = rep.seconds
            sg = art.graph
            print(f"| {n} | {len(art.right.nodes)}+{len(art.right.edges)}e / {len(art.left.nodes)}+"
                  f"{len(art.left.edges)}e | {len(sg.nodes)} nodes, {len(sg.edges)} edges | "
                  f"{statistics.median(times):.1f} | {s['elementary roadmaps']:.1f} / {s['Super Graph nodes']:.1f} / "
                  f"{s['Super Graph edges']:.1f} | {rep.rows['collision checks']} | {rep.rows['collision checks / s']} |",
                  flush=True)


if __name__ == "__main__":
    main()
