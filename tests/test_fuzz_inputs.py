"""Seeded random mutations of the four files a user writes or hands over (issue 40): a
scene, a robot.yaml, an in-hand scene and a plan, each fed to the command that reads it.
Whatever the mutation, the command ends with exit code 0, 1 or 2 and no traceback, within
a process limited to 4 GiB (a MemoryError is a traceback) and a guard on the whole batch
(a hang fails the test instead of stalling the run).

A case makes one or two mutations; each picks one node of the file's tree and deletes it,
replaces it by a hostile value (nothing, a bool, a huge or tiny or non-finite number, an
empty or 5,000-character or multi-line string, an empty or nested container), nudges a
number by a few percent (the file often stays valid, and the command gets past its
parser), scales it by up to 10^+-3, cuts or duplicates a list, adds an unknown key, or
wraps the value in a list; then, one time in four, the text itself is cut short, has a
byte flipped or a small alias bomb appended.

The batches run in a subprocess each (in-process CLI calls there), so that the pytest
workers keep their memory.  The in-hand scenes keep a budget of 300 expansions and the
plans are checked by `validate` only, so that a batch stays within about a minute.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from cli_helpers import ROOT, SCENE_YAML, copy_artefacts, scene_dict

CASES = 50  # per kind: 200 in all
MEMORY = 4 << 30  # bytes of address space of a batch's process
GUARD_S = 900  # a batch that hangs fails; the batches take 20-60 s
HOSTILE = (None, True, -1, 0, 2 ** 63, 1e308, -1e308, math.nan, math.inf, 1e-300, "", "x" * 5000,
           "a\nerror: forged", "../../../etc/passwd", "builtin:nothing", [], {}, [[1.0, 2.0, 3.0]] * 3,
           {"a": {"b": [1]}})


# ------------------------------------------------------------------ mutations


def _nodes(tree, path=()) -> list[tuple]:
    """Every (container, key) of the tree, depth first."""
    out = []
    items = tree.items() if isinstance(tree, dict) else enumerate(tree) if isinstance(tree, list) else ()
    for k, v in items:
        out.append((tree, k))
        out += _nodes(v, path + (k,))
    return out


OPS = ("delete", "hostile", "nudge", "scale", "unknown key", "wrap")
OP_P = (0.15, 0.25, 0.25, 0.15, 0.1, 0.1)


def mutate(tree, rng: np.random.Generator):
    """One random change of ``tree`` (a dict from YAML or JSON), in place."""
    nodes = _nodes(tree)
    parent, key = nodes[int(rng.integers(len(nodes)))]
    value = parent[key]
    op = OPS[int(rng.choice(len(OPS), p=OP_P))]
    number = isinstance(value, (int, float)) and not isinstance(value, bool)
    if op == "delete":
        del parent[key]
    elif op == "hostile":
        parent[key] = HOSTILE[int(rng.integers(len(HOSTILE)))]
    elif op == "nudge" and number:  # often still valid: the command gets past the parser
        parent[key] = type(value)(value * (1 + rng.normal(0, 0.05)) + (0 if isinstance(value, int) else
                                                                        rng.normal(0, 0.01)))
    elif op == "scale" and number:
        parent[key] = type(value)(value * rng.choice([-1, 1]) * 10 ** rng.uniform(-3, 3)) if value else 1e6
    elif op in ("nudge", "scale") and isinstance(value, list) and value:
        parent[key] = value[: int(rng.integers(len(value)))] if rng.random() < 0.5 else value + value[-1:]
    elif op == "unknown key" and isinstance(value, dict):
        value["unexpected_key"] = 1
    elif op == "wrap":
        parent[key] = [value]


def damage_text(text: str, rng: np.random.Generator, yaml_text: bool) -> str:
    """One time in four: the text cut short, a byte flipped, or (YAML) a bomb appended."""
    r = rng.random()
    if r < 0.75 or not text:
        return text
    if r < 0.85:
        return text[: int(rng.integers(len(text)))]
    if r < 0.95 or not yaml_text:
        i = int(rng.integers(len(text)))
        return text[:i] + chr((ord(text[i]) ^ (1 << int(rng.integers(7)))) or 1) + text[i + 1:]
    bomb = ["&b0 [1, 1, 1, 1, 1, 1, 1, 1, 1]"] + [f"&b{i} [{', '.join([f'*b{i - 1}'] * 9)}]" for i in range(1, 8)]
    return text + f"\nextra: [{', '.join(bomb)}]\n"


# ------------------------------------------------------------------ one batch (in a subprocess)


def drive(kind: str, seed: int, n: int, folder: str, base: str, cache: str) -> None:
    """Run ``n`` mutated cases of ``kind`` and print one JSON line per case."""
    import resource
    import time

    from click.testing import CliRunner

    from regrasp_cli.cli import main

    resource.setrlimit(resource.RLIMIT_AS, (MEMORY, MEMORY))
    folder_p, runner = Path(folder), CliRunner(env={"COLUMNS": "250"})
    original = yaml.safe_load(Path(base).read_text()) if kind != "plan" else json.loads(Path(base).read_text())
    for i in range(n):
        rng = np.random.default_rng([seed, i])
        tree = json.loads(json.dumps(original))
        for _ in range(1 + int(rng.integers(2))):
            if _nodes(tree):
                mutate(tree, rng)
        if kind == "inhand" and isinstance(tree, dict) and isinstance(tree.get("planning"), dict):
            tree["planning"]["nodes"] = 300  # the case stays short: the budget is not what is fuzzed
        if kind == "plan":
            text, name = damage_text(json.dumps(tree), rng, False), f"fuzz-case{i}.json"
        else:
            text, name = damage_text(yaml.safe_dump(tree, sort_keys=False), rng, True), f"case{i}.yaml"
        path = folder_p / name
        path.write_text(text)
        args = {"scene": ["--cache-dir", cache, "plan", path, "--no-build", "-o", folder_p / f"out{i}.json"],
                "robot": ["--cache-dir", cache, "info", folder_p / "scene.yaml"],
                "inhand": ["--cache-dir", cache, "inhand", "plan", path, "-o", folder_p / f"out{i}.json",
                           "--no-check"],
                "plan": ["validate", path]}[kind]
        if kind == "robot":
            path.replace(folder_p / "robot.yaml")
        t = time.perf_counter()
        result = runner.invoke(main, [str(a) for a in args])
        crashed = result.exception is not None and not isinstance(result.exception, SystemExit)
        print(json.dumps({"case": i, "exit": result.exit_code, "traceback": crashed or "Traceback" in result.output,
                          "error": repr(result.exception) if crashed else "", "s": round(time.perf_counter() - t, 2),
                          "last": (result.output.strip().splitlines() or [""])[-1][:300]}), flush=True)


# ------------------------------------------------------------------ the tests


@pytest.fixture(scope="module")
def fuzz_cache(cache_dir, tmp_path_factory) -> Path:
    """The robots' self-collision pairs and finger workspaces, without the artefacts of a
    plan: a scene mutated to a valid one stops at its missing grasp lists (exit 2)."""
    cache = tmp_path_factory.mktemp("fuzz_cache")
    for folder in ("self_collision", "workspace"):
        if (Path(cache_dir) / folder).is_dir():
            copy_artefacts(Path(cache_dir) / folder, cache / folder)
    return cache


def _batch(kind: str, base: Path, folder: Path, cache: Path) -> list[dict]:
    code = (f"import sys; sys.path[:0] = [{str(ROOT / 'tests')!r}, {str(ROOT)!r}]; from test_fuzz_inputs import drive; "
            f"drive({kind!r}, 40, {CASES}, {str(folder)!r}, {str(base)!r}, {str(cache)!r})")
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=GUARD_S, env=env)
    rows = [json.loads(ln) for ln in p.stdout.splitlines() if ln.startswith("{")]
    assert p.returncode == 0 and len(rows) == CASES, (p.returncode, p.stdout[-3000:], p.stderr[-3000:])
    return rows


def _check(rows: list[dict], reached) -> None:
    """No case ends outside {0, 1, 2} or with a traceback; some cases get past the
    parser (``reached(row)``), so that the batch tests more than the parser."""
    bad = [r for r in rows if r["exit"] not in (0, 1, 2) or r["traceback"]]
    assert not bad, bad[:5]
    assert sum(map(reached, rows)) >= 3, [r["last"] for r in rows]


def test_mutated_scenes(tmp_path, fuzz_cache):
    """A scene that loads stops at its missing grasp lists or placements (--no-build)."""
    base = tmp_path / "base.yaml"
    base.write_text(yaml.safe_dump(scene_dict(), sort_keys=False))
    _check(_batch("scene", base, tmp_path, fuzz_cache), lambda r: "build it with" in r["last"] or r["exit"] != 2)


def test_mutated_robot_yamls(tmp_path, fuzz_cache):
    robot = yaml.safe_load((ROOT / "configs/robots/humanoid43/robot.yaml").read_text())
    robot["urdf"] = str(ROOT / "configs/robots/humanoid43/robot.urdf")
    base = tmp_path / "base.yaml"
    base.write_text(yaml.safe_dump(robot, sort_keys=False))
    (tmp_path / "scene.yaml").write_text(yaml.safe_dump(dict(scene_dict(), robot="robot.yaml"), sort_keys=False))
    _check(_batch("robot", base, tmp_path, fuzz_cache), lambda r: r["exit"] == 0)


def test_mutated_inhand_scenes(tmp_path, fuzz_cache):
    base = tmp_path / "base.yaml"
    base.write_bytes((ROOT / "regrasp_cli/data/scenes/inhand_ball.yaml").read_bytes())
    _check(_batch("inhand", base, tmp_path, fuzz_cache), lambda r: r["exit"] != 2)


def test_mutated_plans(default_plan, fuzz_cache):
    """In the plan's folder: the files it names are relative to it."""
    _check(_batch("plan", default_plan, default_plan.parent, fuzz_cache), lambda r: r["exit"] != 2)
