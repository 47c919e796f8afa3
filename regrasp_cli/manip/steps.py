"""The transitions of each move of the manipulation graph (:mod:`manip.graph`), with their
fixed pieces (and an in-hand move's object poses and contacts): written once, for the graph's planner (:mod:`manip.tasks.manipulation`) and
the hand-over task of seed 000 (:mod:`manip.tasks.handover`, whose plan is the path
arrive, hand-over, leave).

Each function returns :class:`~manip.solve.Step` s: a transition and its waypoint pieces,
arrays (k, nq) of the key configurations' lines (:class:`~manip.keyconf.SingleConfig`,
:class:`~manip.keyconf.ExchangeConfig`) or the label of the query that joins them.  A
held mode is named by the plan's grasp ids (``gid``)."""

from __future__ import annotations

from regrasp_cli.manip.keyconf import ExchangeConfig, SingleConfig
from regrasp_cli.manip.modes import Kind, Mode, Transition
from regrasp_cli.manip.solve import Step


def grasp(c: SingleConfig, gid: str, placement: str) -> Step:
    """The hand of ``c`` closes on the object resting at ``placement``."""
    return Step(Transition(Kind.GRASP, Mode.resting(placement), Mode.held(**{c.hand: gid}), f"close_{c.hand}",
                           (c.hand,)), (c.approach[-1:], c.q_closed[None]))


def release(c: SingleConfig, gid: str, placement: str) -> Step:
    """The hand of ``c`` opens off the object it put down at ``placement``."""
    return Step(Transition(Kind.RELEASE, Mode.held(**{c.hand: gid}), Mode.resting(placement), f"open_{c.hand}",
                           (c.hand,)), (c.q_closed[None], c.approach[-1:]))


def arrive(label: str, c: SingleConfig, gid: str, placement: str) -> list[Step]:
    """From the robot's start (query ``label``) to the hand of ``c`` closed on the object."""
    rest = Mode.resting(placement)
    return [Step(Transition(Kind.TRANSIT, rest, rest, label), (label, c.approach)), grasp(c, gid, placement)]


def leave(label: str, c: SingleConfig, gid: str, placement: str) -> list[Step]:
    """The hand of ``c`` lets go of the object at ``placement``, the robot goes to its goal
    (query ``label``)."""
    rest = Mode.resting(placement)
    return [release(c, gid, placement), Step(Transition(Kind.TRANSIT, rest, rest, label),
                                             (c.approach[::-1], label))]


def transfer(label: str, a: SingleConfig, b: SingleConfig, gid: str) -> list[Step]:
    """One hand carries the object with one grasp from ``a``'s placement to ``b``'s."""
    held = Mode.held(**{a.hand: gid})
    return [Step(Transition(Kind.TRANSFER, held, held, label), (a.lift, label, b.lift[::-1]))]


def regrasp(label: str, a: SingleConfig, gid_a: str, b: SingleConfig, gid_b: str, placement: str) -> list[Step]:
    """At ``placement`` the hand of ``a`` opens, the robot moves (query ``label``), the
    hand of ``b`` closes with its grasp (Harada et al. 2014's Type-2 connection)."""
    rest = Mode.resting(placement)
    return [release(a, gid_a, placement),
            Step(Transition(Kind.TRANSIT, rest, rest, label), (a.approach[::-1], label, b.approach)),
            grasp(b, gid_b, placement)]


def handover(carry: str, place: str, a: SingleConfig, gid_a: str, ex: ExchangeConfig, b: SingleConfig,
             gid_b: str) -> list[Step]:
    """The hand of ``a`` lifts the object and carries it (query ``carry``) to the exchange
    ``ex``, the hand of ``b`` closes on it, ``a`` opens, and ``b`` carries it (query
    ``place``) down to its placement (Saut et al. 2010)."""
    g, t = a.hand, b.hand
    held_g, held_t = Mode.held(**{g: gid_a}), Mode.held(**{t: gid_b})
    both = Mode.held(**{g: gid_a, t: gid_b})
    return [Step(Transition(Kind.TRANSFER, held_g, held_g, carry), (a.lift, carry, ex.approach)),
            Step(Transition(Kind.HANDOVER, held_g, both, f"close_{t}", (t,)), (ex.approach[-1:], ex.q_both[None])),
            Step(Transition(Kind.HANDOVER, both, held_t, f"open_{g}", (g,)), (ex.q_both[None], ex.q_release[None])),
            Step(Transition(Kind.TRANSFER, held_t, held_t, place), (ex.retreat, place, b.lift[::-1]))]


def inhand(label: str, a: SingleConfig, gid_a: str, motions: list, b: SingleConfig, gid_b: str) -> list[Step]:
    """The hand of ``a`` lifts the object, its fingers turn it (``motions``: the
    :class:`dexterous.motions.FingerMotion` of each piece) from grasp ``gid_a`` to ``gid_b`` while the arm
    holds still, and it carries the object (query ``label``:place) down to ``b``'s
    placement (seed 003 as a move of seed 001's graph)."""
    h = a.hand
    held_a, held_b = Mode.held(**{h: gid_a}), Mode.held(**{h: gid_b})
    out = [Step(Transition(Kind.TRANSFER, held_a, held_a, label + ":lift"), (a.lift,)), *turn(h, motions)]
    end = motions[-1].q[-1]
    out.append(Step(Transition(Kind.TRANSFER, held_b, held_b, label + ":place"), (end[None], label + ":place",
                                                                               b.lift[::-1])))
    return out


def turn(hand: str, motions: list) -> list[Step]:
    """The fingers of ``hand`` turn the object, the arm still: a step per
    :class:`dexterous.motions.FingerMotion` (seed 003), the whole of an in-hand plan."""
    fingers = Mode(inhand=hand)
    return [Step(Transition(m.kind, fingers, fingers, m.label, (hand,)), (m.q,), m.X_WO, m.contacts) for m in motions]
