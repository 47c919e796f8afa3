"""The hand-over planner given an empty grasp list says so (not "0 of 0 grasps clear the
obstacles"), and its early check of the ends names the colliding pair."""

from __future__ import annotations

import numpy as np

from regrasp_cli.grasp.build import GraspList
from regrasp_cli.manip.context import OnlineOptions
from regrasp_cli.manip.solve import ends_failure
from regrasp_cli.manip.status import Stage
from regrasp_cli.manip.tasks import handover


def _empty(problem, hand: str) -> GraspList:
    h = problem.robot.hands[hand]
    nf, nj = len(h.spec.fingers), len(h.idx)
    return GraspList(hand, tuple(f.name for f in h.spec.fingers), np.zeros((0, 4, 4)), np.zeros((0, nj)),
                     np.zeros((0, nf), dtype=bool), np.zeros((0, nf, 3)), np.zeros((0, nf, 3)), np.zeros((0, 5)),
                     np.zeros(0, dtype=np.int64))


def test_an_empty_grasp_list_fails_at_grasps_naming_the_hand(problem):
    lists = {"right": _empty(problem, "right"), "left": _empty(problem, "left")}
    out = handover.plan(problem, lists, None, OnlineOptions(planner="rrt-connect", jobs=1), seed=0)
    assert out.failure is not None and out.failure.stage == Stage.GRASPS
    assert out.failure.reason.startswith("the right hand's grasp list is empty")
    assert "clear the obstacles" not in out.failure.reason and out.phases == ()


def test_ends_failure_is_none_for_free_ends(problem):
    assert ends_failure(problem, OnlineOptions(jobs=1)) is None
