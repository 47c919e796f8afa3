"""Exceptions of the project.

Every failure a user can cause is a :class:`RegraspError`; the CLI turns it into one
line on stderr and exit code 2 (``InputError``) or 1 (a planning failure).  Messages
name the file, the field and what was expected, so they say how to fix the problem.
"""

from __future__ import annotations

import reprlib
from pathlib import Path

_SHOWN = reprlib.Repr()  # keyword arguments only from Python 3.12
_SHOWN.maxlevel, _SHOWN.maxlist, _SHOWN.maxtuple, _SHOWN.maxdict, _SHOWN.maxstring = 3, 6, 6, 4, 60


def shown(value: object, width: int = 80) -> str:
    """A short repr of a value a user wrote, for a message: nested containers cut after a
    few items and levels, the whole at most ``width`` characters.  A plain ``repr`` of a
    YAML value would expand every alias of it (a "billion laughs" of 1 KiB prints for
    hours) and may span lines."""
    text = _SHOWN.repr(value)
    return one_line(text if len(text) <= width else text[: width - 3] + "...")


def one_line(text: str) -> str:
    """``text`` with its control characters escaped (``\\n``, ``\\x1b``): a message naming a
    file or a value the user chose stays one line, without terminal escapes."""
    return "".join(c if c.isprintable() or c == " " else c.encode("unicode_escape").decode("ascii") for c in text)


class RegraspError(Exception):
    """Base class of the errors the CLI reports as one line."""

    exit_code = 1


class InputError(RegraspError):
    """Malformed or inconsistent user input: a file, a field, a value (exit code 2).

    Args:
        file: the file at fault (``None`` when the input came from the command line).
        field: dotted path of the field inside the file, e.g. ``task.object_start.quat``.
        message: what is wrong and what was expected.
    """

    exit_code = 2

    def __init__(self, file: str | Path | None, field: str | None, message: str):
        self.file = None if file is None else str(file)
        self.field = field
        self.message = message
        where = ": ".join(p for p in (self.file, self.field) if p)  # one_line'd where printed (cli)
        super().__init__(f"{where}: {message}" if where else message)


class StaleArtefactError(InputError):
    """A cached artefact whose recorded input hashes do not match the current inputs."""


class CorruptArtefactError(StaleArtefactError):
    """A cached artefact whose contents are damaged: unreadable (truncated, empty) or not
    matching the checksum written with them.  Rebuilding fixes it, like a stale one."""


class EmptyResultError(RegraspError):
    """A build that found nothing: a grasp list without grasps, a roadmap without nodes
    (exit code 1).  Nothing is written; the message says what rejected every candidate,
    so that the scene, robot or options can be fixed.

    Args:
        message: what is empty and why, e.g. ``the right hand's grasp list is empty: ...``.
    """

    exit_code = 1

    def __init__(self, message: str):
        self.message = message
        super().__init__(message)


class EmptyGraspList(EmptyResultError):
    """No grasp of the object for a hand: ``hand`` names it."""

    def __init__(self, hand: str, reason: str):
        self.hand, self.reason = hand, reason
        super().__init__(f"the {hand} hand's grasp list is empty: {reason}")


class EmptyRoadmap(EmptyResultError):
    """An elementary roadmap or the Super Graph without a node."""
