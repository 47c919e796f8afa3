"""Smoothing of a finger-gaiting path (seed 003 §V, last paragraph: "a smoothing step is
conducted in order to filter the unavoidable jolts due to the probabilistic method").

The tree's path gaits more than it needs to: between two transfers the object is still,
and its fingers step one after the other, a finger often twice (a random regrasp, then
one aimed at the goal), or back where it was.  Only where each finger ends matters to the
next transfer.  :func:`smooth` replaces each such run of regrasps by one step per finger
whose joints changed, straight to its final contact and joints, in the first order (of
the fingers' last steps, then the other orders) in which every step is feasible
(:func:`gait.finger_step`: the others hold the object, the lifted finger clears it).  A
run ends where it ended, so the transfers around it are unchanged.

Consecutive transfers are joined into one (the object moves on, the fingertips rolling on).
"""

from __future__ import annotations

import numpy as np

from regrasp_cli.dexterous.gait import GaitOptions, Piece, Regrasp, Transfer, regrasp_to
from regrasp_cli.dexterous.gsn import GsScratch

MAX_ORDERS = 24  # orders of the fingers tried per run of regrasps (4! for four fingers)


def _shorter_run(s: GsScratch, run: list[Regrasp], rng: np.random.Generator, o: GaitOptions) -> list[Regrasp]:
    """The run of regrasps ``run`` (the object still) in fewer steps, or ``run``."""
    start, end = run[0].before, run[-1].after
    idx = s.hm.hand.finger_idx
    moved = [f for f in range(len(start.p)) if not np.array_equal(start.q[idx[f]], end.q[idx[f]])]
    if len(moved) >= len(run):
        return run
    last = {r.finger: k for k, r in enumerate(run)}
    shorter = regrasp_to(s, start, end, rng, o, sorted(moved, key=lambda f: last.get(f, -1)), MAX_ORDERS)
    return run if shorter is None else shorter


def _joined(a: Transfer, b: Transfer) -> Transfer:
    return Transfer(*(np.concatenate([getattr(a, k), getattr(b, k)[1:]]) for k in ("X_GO", "q", "p", "n")))


def smooth(s: GsScratch, pieces: list[Piece], rng: np.random.Generator, o: GaitOptions = GaitOptions()) -> list[Piece]:
    """``pieces`` with each run of regrasps shortened and consecutive transfers joined;
    the path still starts and ends at the same configurations."""
    out: list[Piece] = []
    run: list[Regrasp] = []
    for piece in pieces + [None]:
        if isinstance(piece, Regrasp):
            run.append(piece)
            continue
        if run:
            out += _shorter_run(s, run, rng, o)
            run = []
        if piece is None:
            break
        if out and isinstance(out[-1], Transfer):
            out[-1] = _joined(out[-1], piece)
        else:
            out.append(piece)
    return out
