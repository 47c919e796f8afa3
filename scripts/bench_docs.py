"""Put the results of `regrasp bench` into the documentation (`make bench-docs`).

For each results folder given (default: bench-results/default and bench-results/hard,
where they exist), copy its summary.md, runs.jsonl and times.png to
docs/bench/<suite>-{summary.md,runs.jsonl,times.png} and rewrite the block of
docs/BENCHMARKS.md between ``<!-- bench:<suite> -->`` and ``<!-- /bench:<suite> -->`` with
the tables of :func:`regrasp_cli.bench.report.docs_block`, re-aggregated from the records.
A folder whose block is missing from BENCHMARKS.md is an error (exit 2): add the two
markers where its tables belong.
"""

from __future__ import annotations

import argparse
import json
import re
import shutil
import sys
from pathlib import Path

from regrasp_cli.bench.report import docs_block
from regrasp_cli.store import atomic_write_text

ROOT = Path(__file__).resolve().parents[1]


def update(results: Path, docs: Path, text: str) -> str:
    meta = json.loads((results / "meta.json").read_text())
    name = meta["suite"]["name"]
    records = [json.loads(line) for line in (results / "runs.jsonl").read_text().splitlines() if line.strip()]
    begin, end = f"<!-- bench:{name} -->", f"<!-- /bench:{name} -->"
    pattern = re.compile(re.escape(begin) + r".*?" + re.escape(end), re.S)
    if not pattern.search(text):
        raise SystemExit(f"error: {docs / 'BENCHMARKS.md'}: no {begin} ... {end} block for {results}")
    for part in ("summary.md", "runs.jsonl", "times.png"):
        shutil.copyfile(results / part, docs / "bench" / f"{name}-{part}")
    block = docs_block(records, meta)
    print(f"{results}: {len(records)} runs -> docs/bench/{name}-*, block {begin}")
    return pattern.sub(lambda _: f"{begin}\n{block}{end}", text)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("results", nargs="*", type=Path, help="results folders of `regrasp bench`")
    ap.add_argument("--docs", type=Path, default=ROOT / "docs")
    args = ap.parse_args()
    folders = args.results or [p for p in (ROOT / "bench-results" / "default", ROOT / "bench-results" / "hard")
                                if (p / "meta.json").is_file()]
    if not folders:
        print("error: no results folder (run `make bench` first)", file=sys.stderr)
        return 2
    path = args.docs / "BENCHMARKS.md"
    text = path.read_text()
    try:
        for results in folders:
            text = update(results, args.docs, text)
    except SystemExit as exc:
        print(exc, file=sys.stderr)
        return 2
    atomic_write_text(path, text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
