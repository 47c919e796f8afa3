"""Manipulation modes and the kinds of transition between them.

The planner's model of a manipulation task follows HPP's constraint graph ("a Node is a
state of the robot with constraints; an Edge is a transition between two Nodes") and the
foliations of Harada et al. 2014 (§III: CP, the object resting at a placement; CG_r, CG_l,
held by one hand; CG_r∩CG_l, by both) and Saut et al. (seed 003, §III-§IV: GS_n, the
object in the fingers of one hand):

* a :class:`Mode` says where the object is: resting at a placement (``placement``), held
  rigidly by one or two hands each with a grasp (``holding``), or moving in the fingers of
  a hand (``inhand``);
* a transition of :class:`Kind` joins two modes: ``transit`` (the robot moves, the object
  rests: a path in one CP leaf), ``transfer`` (the object moves with its holders, grasps
  fixed: a CG leaf), ``grasp``/``release`` (a hand's fingers close on or open off a
  resting object: CP -> CP∩CG and back), ``handover`` (a hand closes on or opens off the
  object another hand holds: CG_r∩CG_l), ``inhand-transfer`` / ``inhand-regrasp`` (seed
  003: the fingers move the object with contacts fixed / one finger moves to a new
  contact while the others keep force closure).

A task (``manip.tasks``) is a path through modes; each step is solved by the solver of its
kind.  This module is a leaf: the plan format (:mod:`regrasp_cli.trajectory`) and the
validator read the kinds from here.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import Enum


class Kind(str, Enum):
    """Transition kinds, as written in a plan's ``phases[].kind``."""

    TRANSIT = "transit"
    TRANSFER = "transfer"
    GRASP = "grasp"
    RELEASE = "release"
    HANDOVER = "handover"
    INHAND_TRANSFER = "inhand-transfer"
    INHAND_REGRASP = "inhand-regrasp"

    @property
    def object_rests(self) -> bool:
        """The object lies at a placement during the whole transition."""
        return self in (Kind.TRANSIT, Kind.GRASP, Kind.RELEASE)

    @property
    def fingers_on_object(self) -> bool:
        """Some hand's fingers move on the object (``touching`` is not empty)."""
        return self in (Kind.GRASP, Kind.RELEASE, Kind.HANDOVER, Kind.INHAND_TRANSFER, Kind.INHAND_REGRASP)

    @property
    def inhand(self) -> bool:
        return self in (Kind.INHAND_TRANSFER, Kind.INHAND_REGRASP)


KIND_NAMES = tuple(k.value for k in Kind)


@dataclass(frozen=True)
class Mode:
    """Where the object is: at rest at ``placement`` (an id of the task's placements), or
    held, ``holding`` mapping each holding hand to its grasp id; ``inhand`` names the hand
    whose fingers move it (seed 003).  Exactly one of the three describes the object."""

    placement: str | None = None
    holding: tuple[tuple[str, str], ...] = field(default=())  # ((hand, grasp id), ...) sorted by hand
    inhand: str | None = None

    def __post_init__(self):
        held = bool(self.holding) or self.inhand is not None
        if (self.placement is None) == (not held):
            raise ValueError("a mode has the object either at a placement or in hands, not both or neither")

    @classmethod
    def resting(cls, placement: str) -> "Mode":
        return cls(placement=placement)

    @classmethod
    def held(cls, **grasps: str) -> "Mode":
        """``Mode.held(right="right-3")``: held by the given hands with those grasp ids."""
        return cls(holding=tuple(sorted(grasps.items())))

    @property
    def hands(self) -> tuple[str, ...]:
        return tuple(h for h, _ in self.holding)

    def __str__(self) -> str:
        if self.placement is not None:
            return f"resting at {self.placement}"
        if self.inhand is not None:
            return f"in the {self.inhand} hand's fingers"
        return "held by " + " and ".join(f"{h} ({g})" for h, g in self.holding)


@dataclass(frozen=True)
class Transition:
    """One edge of a mode path: ``kind`` from ``before`` to ``after`` (the same mode for
    transit and transfer), ``touching`` the hands whose fingers move on the object, and a
    ``label`` for reports (the task's name for the step, e.g. seed 000's "carry")."""

    kind: Kind
    before: Mode
    after: Mode
    label: str
    touching: tuple[str, ...] = ()

    @property
    def holding(self) -> tuple[tuple[str, str], ...]:
        """Hands that hold the object rigidly during the whole transition: those of both
        ends (a hand closing or opening is ``touching``)."""
        after = dict(self.after.holding)
        return tuple((h, g) for h, g in self.before.holding if after.get(h) == g)

    @property
    def placement(self) -> str | None:
        """The placement the object rests at during the whole transition, if it rests."""
        if not self.kind.object_rests:
            return None
        return self.before.placement if self.before.placement is not None else self.after.placement
