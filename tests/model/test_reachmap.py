"""Reach maps (model.reachmap) on a few configurations known exactly: the cube of each
configuration's grasp frame (pinocchio's forward kinematics) holds the direction its
approach axis points along, and nothing else is reached; the cached map is read back,
not rebuilt, and a damaged one is rebuilt."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from regrasp_cli.model import reachmap
from regrasp_cli.model.reachmap import DIRECTIONS, ReachOptions, approach_axis, arm_dofs, reach_map, reach_map_of
from regrasp_cli.model.robot import Kinematics, load_robot

ROBOTS = Path(__file__).resolve().parents[2] / "configs" / "robots"


@pytest.fixture(scope="module")
def robot():
    return load_robot(ROBOTS / "hironx" / "robot.yaml")


def test_the_map_holds_each_configuration_s_grasp_frame_and_direction(robot):
    kin, dofs = Kinematics(robot), arm_dofs(robot, "right")
    rng = np.random.default_rng(0)
    Q = rng.uniform(robot.lower[dofs], robot.upper[dofs], (3, len(dofs)))
    m = reach_map_of(robot, "right", Q, 0.05)
    assert np.count_nonzero(m.masks) <= 3
    a_G = approach_axis(robot, "right")
    for row in Q:
        q = robot.q_rest.copy()
        q[dofs] = row
        X_WG = kin.fk(q, robot.hands["right"].grasp_frame)
        a_W = X_WG[:3, :3] @ a_G
        assert m.reaches(X_WG[None, :3, 3], a_W[None], cone=0.5)[0]  # the bin nearest to a_W is within 0.5 rad
        assert not m.reaches(X_WG[None, :3, 3], -a_W[None], cone=0.5)[0]  # the opposite direction was not seen
        bit = int(np.argmax(DIRECTIONS @ a_W))
        assert m.mask(X_WG[None, :3, 3])[0] & (1 << bit)
    # a cube 12 cm from every sampled grasp frame, and points outside the map, are not reached
    centres = m.centres()
    far = centres.min(axis=0) - 0.12
    assert not m.reaches(far[None])[0] and not m.reaches(np.array([[10.0, 0.0, 0.0]]))[0]


def test_the_cached_map_is_read_back_and_a_damaged_one_rebuilt(robot, tmp_path, monkeypatch):
    options = ReachOptions(samples=2000)
    built = reach_map(robot, "left", tmp_path, options)
    (path,) = (tmp_path / "reach").glob("*.h5")

    def refuse(*args, **kwargs):
        raise AssertionError("rebuilt a fresh map")

    monkeypatch.setattr(reachmap, "build_reach_map", refuse)
    again = reach_map(robot, "left", tmp_path, options)
    np.testing.assert_array_equal(again.masks, built.masks)
    np.testing.assert_array_equal(again.origin, built.origin)
    monkeypatch.undo()
    path.write_bytes(path.read_bytes()[:200])  # truncated
    rebuilt = reach_map(robot, "left", tmp_path, options)
    np.testing.assert_array_equal(rebuilt.masks, built.masks)
