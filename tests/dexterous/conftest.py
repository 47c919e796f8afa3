"""A GS_n scratch for seed 003's case: `builtin:hand4` (four 3-DoF fingers round a palm)
and a 7 cm sphere, built afresh for each test module (its memos and counters are a query's)."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from conftest import ROOT

from regrasp_cli.dexterous.gsn import GsScratch
from regrasp_cli.dexterous.surface import MeshSurface
from regrasp_cli.grasp.single import HandModel
from regrasp_cli.grasp.surface import build_surface, sampling_step
from regrasp_cli.grasp.workspace import hand_workspace
from regrasp_cli.model.robot import load_robot
from regrasp_cli.model.selfcollision import disabled_pairs

R = 0.035  # m, the sphere's radius


@pytest.fixture(scope="module")
def hand4_ball(cache_dir) -> GsScratch:
    robot = load_robot(ROOT / "regrasp_cli" / "data" / "robots" / "hand4" / "robot.yaml")
    mesh = trimesh.creation.icosphere(subdivisions=3, radius=R)
    hm = HandModel(robot, "right", mesh, disabled_pairs(robot, cache_dir).links(), 0.002)
    ws = hand_workspace(robot, "right", cache_dir=cache_dir)
    sampled = build_surface(mesh, sampling_step(0.004), np.random.default_rng(0))
    return GsScratch(hm, ws, sampled, MeshSurface.of(mesh), R)
