"""Write the tuning suite (configs/bench/tune.yaml): procedural objects of the shapes that
unseen objects fail on (flat, thin-walled, small, low and long, bent), each in the default
desk scene with the two goals of the YCB suite.  The planner is changed while looking at
this suite; the YCB suite (configs/bench/ycb.yaml) is the held-out measure.

    python scripts/make_tune_suite.py      # rewrites configs/bench/tune/ and tune.yaml
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import trimesh
from trimesh import creation

from regrasp_cli.model.objects import make_builtin

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "configs" / "bench" / "tune"
DEFAULT_SCENE = ROOT / "regrasp_cli" / "data" / "scenes" / "desk_handover.yaml"
DESK_TOP = 0.74  # m: the desk's top in the default scene
GOALS = {"behind": ([0.62, 0.78], -math.pi / 2), "front": ([0.44, 0.76], 0.0)}


def _shell(profile_out: list, thickness: float) -> trimesh.Trimesh:
    """A revolved open vessel: outer profile (r, z) points from the bottom centre up, walls
    ``thickness`` thick."""
    outer = [list(p) for p in profile_out]
    inner = [[max(r - thickness, 0.0), z + (thickness if i == 0 else 0.0)] for i, (r, z) in enumerate(profile_out)]
    inner[0][0] = 0.0
    return creation.revolve(outer + inner[::-1][:-1] + [[0.0, thickness]], sections=48)


def _flat_capsule(length: float, width: float, thick: float) -> trimesh.Trimesh:
    """A bar lying flat along x with a rounded (elliptic) rim, like a scanned tool handle."""
    c = creation.capsule(height=length - width, radius=width / 2, count=[24, 24])
    c.apply_transform(trimesh.transformations.rotation_matrix(math.pi / 2, [0, 1, 0]))
    c.apply_scale([1.0, 1.0, thick / width])
    return c


def _shears() -> trimesh.Trimesh:
    """A blade and two finger rings lying flat: three shells, as scans are."""
    blade = _flat_capsule(0.11, 0.02, 0.008)
    blade.apply_translation([0.085, 0.0, 0.0])
    rings = [creation.torus(major_radius=0.022, minor_radius=0.007) for _ in range(2)]
    rings[0].apply_translation([-0.03, 0.022, 0.0])
    rings[1].apply_translation([-0.03, -0.022, 0.0])
    return trimesh.util.concatenate([blade, *rings])


def objects() -> dict[str, trimesh.Trimesh]:
    arc = [creation.capsule(height=0.05, radius=0.017, count=[12, 12]) for _ in range(4)]
    for i, c in enumerate(arc):  # a bent fruit lying on its side: four capsules on an arc
        a = math.radians(-45 + 30 * i)
        c.apply_transform(trimesh.transformations.rotation_matrix(math.pi / 2, [0, 1, 0]))
        c.apply_transform(trimesh.transformations.rotation_matrix(a, [0, 0, 1]))
        c.apply_translation([0.09 * math.sin(a), 0.09 * (1 - math.cos(a)), 0.0])
    handle = creation.cylinder(radius=0.012, height=0.28, sections=24)
    handle.apply_transform(trimesh.transformations.rotation_matrix(math.pi / 2, [0, 1, 0]))
    head = creation.box(extents=[0.03, 0.10, 0.03])
    head.apply_translation([0.15, 0.0, 0.003])
    out = {
        "plate": creation.box(extents=[0.19, 0.045, 0.014]),  # flat, like a spanner
        "bar": _flat_capsule(0.185, 0.025, 0.014),  # flat with a rounded rim
        "shears": _shears(),
        "bowl": _shell([[0.0, 0.0], [0.04, 0.0], [0.075, 0.05], [0.08, 0.055]], 0.003),
        "ball": creation.icosphere(subdivisions=3, radius=0.036),
        "short_can": creation.cylinder(radius=0.034, height=0.09, sections=40),
        "mallet": trimesh.util.concatenate([handle, head]),  # not a union: two shells, as scans are
        "bent": trimesh.util.concatenate(arc),
        "cup": _shell([[0.0, 0.0], [0.03, 0.0], [0.04, 0.08]], 0.002),
    }
    out["mug"] = make_builtin("mug")  # a tall mug with a handle (builtin:mug)
    for m in out.values():  # centred on the bounding box, as the YCB scans are
        m.apply_translation(-m.bounds.mean(axis=0))
    return out


def scene_text(name: str, mesh: trimesh.Trimesh, goal: str) -> str:
    lines = DEFAULT_SCENE.read_text().splitlines()
    obstacles = [ln for ln in lines if ln.startswith("  - {name:")]
    z = DESK_TOP + 0.001 - float(mesh.bounds[0, 2])
    (gx, gy), gyaw = GOALS[goal]
    return "\n".join([
        "format: regrasp.scene/1",
        f"# Tuning suite (configs/bench/tune.yaml, scripts/make_tune_suite.py): procedural '{name}' on the desk of",
        f"# the default scene, start on the right, goal {goal} of the lamp.",
        "robot: ../../robots/humanoid43/robot.yaml",
        f"object: {{mesh: meshes/{name}.stl, scale: 1.0, friction: 0.5}}",
        "obstacles:", *obstacles,
        "task:",
        f"  object_start: {{xyz: [0.40, -0.85, {z:.4f}], rpy: [0, 0, 1.5708]}}",
        f"  object_goal: {{xyz: [{gx}, {gy}, {z:.4f}], rpy: [0, 0, {gyaw:.4f}]}}",
        "  robot_start: rest", "  robot_goal: rest",
        "planning: {seed: 0}", ""])


def main() -> None:
    (OUT / "meshes").mkdir(parents=True, exist_ok=True)
    scenes = []
    for name, mesh in objects().items():
        mesh.export(OUT / "meshes" / f"{name}.stl")
        for goal in GOALS:
            path = OUT / f"{name}_{goal}.yaml"
            path.write_text(scene_text(name, mesh, goal))
            scenes.append(f"  - tune/{path.name}")
    (ROOT / "configs" / "bench" / "tune.yaml").write_text("\n".join([
        "# Tuning suite (`regrasp bench configs/bench/tune.yaml`): procedural objects of the shapes unseen",
        "# objects fail on (flat, thin-walled, small, low and long, bent), written by",
        "# scripts/make_tune_suite.py.  Changes to grasping and planning are made looking at this suite;",
        "# the YCB suite (ycb.yaml) is the held-out measure.",
        "format: regrasp.bench/1", "name: tune", "scenes:", *scenes,
        "planners: [roadmap]", "seeds: 2", "budget_s: 60", ""]))


if __name__ == "__main__":
    main()
