"""scripts/bench_docs.py (`make bench-docs`): a results folder's tables replace its block
of BENCHMARKS.md and nothing else, its files are copied beside, and a missing block is one
error line with exit 2 that leaves the document as it was."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from bench.test_aggregate import RECORDS

SCRIPT = Path(__file__).resolve().parents[2] / "scripts" / "bench_docs.py"
META = {"machine": {"date": "2026-11-22T18:00:00+00:00", "cpu": "Test CPU", "cores": 2, "python": "3.11.7",
                    "regrasp": "0.1.0", "libraries": {"pin": "4.1.0", "ompl": "2.0.1"}},
        "suite": {"name": "tiny", "seeds": list(range(6)), "budget_s": 60.0, "iterations": 3000},
        "jobs": 2, "backend": "loky", "runs": len(RECORDS),
        "offline": {"desk": {"grasp lists": {"s": 5.0, "status": "built", "size": {"right": 121, "left": 120}}}}}


def results(tmp_path: Path) -> Path:
    out = tmp_path / "results"
    out.mkdir()
    (out / "meta.json").write_text(json.dumps(META))
    (out / "runs.jsonl").write_text("".join(json.dumps(r) + "\n" for r in RECORDS))
    (out / "summary.md").write_text("# summary\n")
    (out / "times.png").write_bytes(b"\x89PNG\r\n\x1a\n")
    return out


def docs(tmp_path: Path, body: str) -> Path:
    d = tmp_path / "docs"
    (d / "bench").mkdir(parents=True)
    (d / "BENCHMARKS.md").write_text(body)
    return d


def run(*args) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(SCRIPT), *map(str, args)], capture_output=True, text=True)


def test_the_block_is_rewritten_from_the_records(tmp_path):
    d = docs(tmp_path, "# Benchmarks\n\nbefore\n<!-- bench:tiny -->\nold table\n<!-- /bench:tiny -->\nafter\n")
    r = run(results(tmp_path), "--docs", d)
    assert r.returncode == 0, r.stderr
    text = (d / "BENCHMARKS.md").read_text()
    assert text.startswith("# Benchmarks\n\nbefore\n<!-- bench:tiny -->\n")
    assert text.endswith("<!-- /bench:tiny -->\nafter\n")
    assert "old table" not in text
    assert "Test CPU, 2 cores" in text and "regrasp 0.1.0 (pin 4.1.0, ompl 2.0.1)" in text
    assert "3000 RRT-Connect iterations per query" in text
    assert "| desk | roadmap | 4/6 | 67 % |" in text  # aggregated again from runs.jsonl
    assert "| desk | rrt-connect | 2 | 3.50x |" in text  # planner time ratio: total / 2 in the records
    assert "\n#### Next to the paper: desk" in text and "| the four queries, roadmap | 11.6 s |" in text
    assert "5.0 s (built); right 121, left 120" in text
    for part in ("summary.md", "runs.jsonl", "times.png"):
        assert (d / "bench" / f"tiny-{part}").is_file()
    # running it again gives the same document
    before = (d / "BENCHMARKS.md").read_text()
    assert run(tmp_path / "results", "--docs", d).returncode == 0
    assert (d / "BENCHMARKS.md").read_text() == before


def test_a_missing_block_is_one_error_line_and_changes_nothing(tmp_path):
    d = docs(tmp_path, "# Benchmarks\n<!-- bench:other -->\n<!-- /bench:other -->\n")
    r = run(results(tmp_path), "--docs", d)
    assert r.returncode == 2
    assert r.stderr.count("\n") == 1 and "<!-- bench:tiny -->" in r.stderr and "BENCHMARKS.md" in r.stderr
    assert (d / "BENCHMARKS.md").read_text() == "# Benchmarks\n<!-- bench:other -->\n<!-- /bench:other -->\n"
    assert not list((d / "bench").iterdir())
