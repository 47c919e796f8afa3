"""A request (the `plan` command's options, or a benchmark run's) reaches the planner's options."""

from __future__ import annotations

from regrasp_cli.manip.context import OnlineOptions
from regrasp_cli.pipeline import PICK_AND_PLACE, Request


def test_a_request_passes_its_held_speed_to_the_planner():
    assert Request().options(PICK_AND_PLACE).held_speed == OnlineOptions.held_speed == 0.5
    assert Request(held_speed=1.0).options(PICK_AND_PLACE).held_speed == 1.0
    assert Request(held_speed=1.0, iterations=7).options(PICK_AND_PLACE).rrt.max_iterations == 7
