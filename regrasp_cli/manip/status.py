"""Where a planning run stopped: one enum for the planner, the plan JSON
(``failure.stage``), the CLI's message and the benchmark records.

An empty grasp list is ``Stage.GRASPS`` ("the right hand's grasp list is empty: ..."),
an empty roadmap ``Stage.ROADMAP``, both with the reason the build found.

A failing transition (a transit or transfer that found no path) is ``Stage.TRANSITION``,
with the task's label of that transition in ``PlanningFailed.transition`` (for seed 000's
hand-over: grasp, carry, place or rest).
"""

from __future__ import annotations

from enum import Enum

from regrasp_cli.errors import RegraspError


class Stage(str, Enum):
    ENDS = "ends"  # the robot's start or goal configuration is in collision or too close
    GRASPS = "grasps"  # no grasp configurations at the object's placements (§IV-B double grasps)
    KEYS = "key configurations"  # no configuration where the transitions meet (e.g. the exchange)
    TRANSITION = "transition"  # a transit or transfer found no path
    ROADMAP = "roadmap"  # the offline roadmap the planner needs has no node (the build says why)
    VALIDATION = "validation"  # the written plan fails the independent validator
    # outcomes of a benchmark run that never reached the planner's answer
    BUDGET = "budget"
    CRASH = "crash"


class PlanningFailed(RegraspError):
    """No plan: ``stage`` is where it failed, ``reason`` why, ``transition`` which
    transition when the stage is TRANSITION (exit code 1)."""

    exit_code = 1

    def __init__(self, stage: Stage, reason: str, transition: str | None = None):
        self.stage, self.reason, self.transition = Stage(stage), reason, transition
        where = stage.value + (f" ({transition})" if transition else "")
        super().__init__(f"planning failed at stage '{where}': {reason}")

    def as_dict(self) -> dict:
        """``failure`` of the plan JSON and of a benchmark record."""
        return {"stage": self.stage.value, "transition": self.transition, "reason": self.reason}
