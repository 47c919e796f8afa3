"""A real pip install (issue 14): the wheel built from this checkout, installed (not
editable) into a fresh virtual environment outside the checkout, lists and copies the
shipped examples and plans the default scene from the copy; the plan validates.

The new environment borrows the already installed dependencies (pinocchio, trimesh, ...)
through a ``.pth`` file adding this environment's site-packages after its own (with their
``.pth`` files: pinocchio and coal live in a cmeel prefix), so that the test does not
download them again; the new environment's own copy of `regrasp_cli` comes first on
``sys.path`` (this checkout's editable finder only answers what the path does not), and
the test checks that it is the one imported.  The installed copy plans with the small
artefacts (20 grasps per hand, 12-node roadmaps) that the checkout built for
conftest.default_plan, copied into its cache, and builds none: artefacts are keyed by the
contents of their inputs, not by where the package is installed."""

from __future__ import annotations

import json
import os
import site
import subprocess
import sys
from pathlib import Path

from cli_helpers import copy_artefacts

ROOT = Path(__file__).resolve().parents[1]


def _run(args, cwd: Path, timeout: float = 900) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "REGRASP_CACHE")}
    env["COLUMNS"] = "250"
    done = subprocess.run([str(a) for a in args], cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)
    assert done.returncode == 0, (args, done.stdout[-3000:], done.stderr[-3000:])
    return done


def test_the_wheel_installs_outside_the_checkout_and_plans_the_shipped_scene(problem, cache_dir, default_plan,
                                                                              tmp_path):
    dist, venv, work = tmp_path / "dist", tmp_path / "venv", tmp_path / "work"
    _run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--quiet", "-w", dist, ROOT], cwd=tmp_path)
    (wheel,) = dist.glob("regrasp-*.whl")
    _run([sys.executable, "-m", "venv", "--without-pip", venv], cwd=tmp_path)
    py = venv / "bin" / "python"
    _run([sys.executable, "-m", "pip", "--python", py, "install", "--no-deps", "--quiet", wheel], cwd=tmp_path)
    (purelib,) = (venv / "lib").glob("python3.*/site-packages")
    (purelib / "borrowed_dependencies.pth").write_text(
        "".join(f"import site; site.addsitedir({p!r})\n" for p in site.getsitepackages()))

    where = _run([py, "-c", "import regrasp_cli; print(regrasp_cli.__file__)"], cwd=tmp_path).stdout.strip()
    assert Path(where).is_relative_to(purelib), where  # the installed copy, not this checkout
    assert (purelib / "regrasp_cli" / "data" / "robots" / "humanoid43" / "robot.urdf").is_file()

    regrasp = venv / "bin" / "regrasp"
    listed = _run([regrasp, "examples"], cwd=tmp_path).stdout
    assert "builtin:humanoid43" in listed and "scenes/desk_handover.yaml" in listed
    _run([regrasp, "examples", work], cwd=tmp_path)
    scene = work / "scenes" / "desk_handover.yaml"
    assert "robot: builtin:humanoid43" in scene.read_text()

    # the checkout's small artefacts serve the installed copy: keyed by the robot files'
    # and the scene's contents, not by where they are installed
    cache = copy_artefacts(Path(cache_dir), tmp_path / "cache")
    out = work / "plan.json"
    _run([regrasp, "--cache-dir", cache, "plan", scene, "-o", out, "--grasp-target", "40", "--roadmap-nodes", "12",
          "--no-build"], cwd=work)
    plan = json.loads(out.read_text())
    assert plan["status"] == "solved"
    urdf = (out.parent / plan["robot"]["urdf"]).resolve()
    assert urdf.is_relative_to(purelib.resolve()), urdf  # the shipped robot
    _run([regrasp, "validate", out], cwd=work)
