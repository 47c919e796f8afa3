"""Finger gaiting as plan phases: each transfer of seed 003's turn an ``inhand-transfer``
and each finger regrasp an ``inhand-regrasp``, ``touching`` the hand, holding nothing
rigidly (the fingers move the object), with the object's pose (in the robot base frame
W) and the fingertip contacts (finger name, point and outward normal in the object frame)
at every waypoint: every finger during a transfer, every finger but the moving one while
it is lifted in a regrasp.  Steps and timing are :mod:`regrasp_cli.manip.steps`'s and
:func:`regrasp_cli.manip.solve.time_steps`'s, as for every move.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from regrasp_cli.dexterous.gait import Regrasp, Transfer
from regrasp_cli.manip.modes import Kind


def _contacts(names: list[str], p: np.ndarray, n: np.ndarray, skip: int | None = None) -> tuple[dict, ...]:
    return tuple({"finger": names[f], "point": p[f], "normal": n[f]} for f in range(len(names)) if f != skip)


class FingerMotion(NamedTuple):
    """One piece of finger gaiting as a phase: its kind and label, waypoints (k, nq), the
    object's poses (k, 4, 4) in W and the contacts at each waypoint."""

    kind: Kind
    label: str
    q: np.ndarray
    X_WO: np.ndarray
    contacts: tuple


def piece_motions(pieces, names: list[str], X_WG: np.ndarray) -> list[FingerMotion]:
    """Per piece (:class:`~dexterous.gait.Transfer` or :class:`~dexterous.gait.Regrasp`),
    its :class:`FingerMotion`, the object's poses in W (the hand's grasp frame at ``X_WG``),
    the contacts of the fingers ``names``."""
    out = []
    for k, piece in enumerate(pieces):
        if isinstance(piece, Transfer):
            X = X_WG @ piece.X_GO
            c = tuple(_contacts(names, p, n) for p, n in zip(piece.p, piece.n))
            out.append(FingerMotion(Kind.INHAND_TRANSFER, f"turn {k}", piece.q, X, c))
        else:
            assert isinstance(piece, Regrasp)
            X = np.repeat((X_WG @ piece.before.X_GO)[None], len(piece.q), axis=0)
            before, after = piece.before, piece.after
            lifted = _contacts(names, before.p, before.n, skip=piece.finger)
            contacts = (_contacts(names, before.p, before.n),) + (lifted,) * (len(piece.q) - 2) + (
                _contacts(names, after.p, after.n),)
            out.append(FingerMotion(Kind.INHAND_REGRASP, f"{names[piece.finger]} steps {k}", piece.q, X, contacts))
    return out
