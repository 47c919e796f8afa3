"""Why a roadmap has no or few nodes: the collisions that reject its samples.

Vis-PRM (:mod:`.visprm`) and the Super Graph composition (:mod:`.compose`) see only
``is_free(q) -> bool``; :func:`tallied` wraps such a check so that a rejected
configuration is counted, and the colliding pairs of the first :data:`DIAGNOSED` ones
are listed (link-link or link-``obstacle:NAME``, by
:meth:`~regrasp_cli.model.collision.CollisionWorld.colliding_pairs`).  A free
configuration costs nothing more; a rejected one a full narrow-phase pass for the first
:data:`DIAGNOSED` only (about 0.2-0.9 ms each on the shipped robots), so a build is not
slowed measurably.  Samples are drawn independently and uniformly within the joint
limits, so the first rejections are a fair sample of all of them, and no sample is
rejected by a joint limit.

A :class:`Rejections` is the scratch of one build (or of one worker's roadmap), returned
beside the roadmap, never stored in it.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

DIAGNOSED = 100  # rejected configurations per tally whose colliding pairs are listed
TOP = 3  # pairs named in a message
FEW = 0.2  # fewer nodes than this fraction of those asked for (of the candidates, for the Super Graph): a warning


@dataclass
class Rejections:
    """Counts of one check: configurations ``checked`` and ``collided``, and how many of
    the first :data:`DIAGNOSED` collisions each pair (names, sorted) took part in."""

    checked: int = 0
    collided: int = 0
    diagnosed: int = 0
    pairs: Counter = field(default_factory=Counter)

    def record(self, pairs: list[tuple[str, str]]) -> None:
        """One rejected configuration, with its colliding pairs (each counted once)."""
        self.collided += 1
        self.diagnosed += 1
        self.pairs.update({tuple(sorted(p, key=_obstacle_last)) for p in pairs})

    def top(self, n: int = TOP) -> list[tuple[tuple[str, str], int]]:
        """The ``n`` pairs in the most diagnosed collisions, most first (ties by name)."""
        return sorted(self.pairs.items(), key=lambda kv: (-kv[1], kv[0]))[:n]

    def describe(self, what: str = "configurations collide") -> str:
        """E.g. ``2000 of 2000 configurations collide; the pairs in most of the 100 looked
        at: r_wrist–obstacle:cage 100, r_hand–obstacle:cage 97, torso–r_elbow 12``."""
        text = f"{self.collided} of {self.checked} {what}"
        if not self.pairs:
            return text
        named = ", ".join(f"{a}–{b} {k}" for (a, b), k in self.top())
        return f"{text}; the pairs in most of the {self.diagnosed} looked at: {named}"


def _obstacle_last(name: str) -> tuple[bool, str]:
    """Sort key of a pair's names: links by name, then ``obstacle:NAME`` and ``object``."""
    return name.startswith("obstacle:") or name == "object", name


def tallied(is_free: Callable[[np.ndarray], bool], colliding_pairs: Callable[[np.ndarray], list[tuple[str, str]]],
            tally: Rejections) -> Callable[[np.ndarray], bool]:
    """``is_free`` that also counts into ``tally`` (which it changes): every check, every
    rejection, and the ``colliding_pairs(q)`` of the first :data:`DIAGNOSED` rejections."""

    def check(q: np.ndarray) -> bool:
        tally.checked += 1
        if is_free(q):
            return True
        if tally.diagnosed < DIAGNOSED:
            tally.record(colliding_pairs(q))
        else:
            tally.collided += 1
        return False

    return check


def pairs_text(pairs: list[tuple[str, str]], n: int = TOP) -> str:
    """``a–b, c–d`` (the first ``n`` distinct ones, then how many more)."""
    pairs = list(dict.fromkeys(pairs))  # a link of several geometries may hit one obstacle twice
    shown = ", ".join(f"{a}–{b}" for a, b in pairs[:n])
    return shown + (f" and {len(pairs) - n} more" if len(pairs) > n else "")
