"""Reading the files a user names, with bounded work whatever they hold.

* Only regular files are read: a FIFO would block the command and a device (``/dev/zero``)
  never end; a folder is not a file.  Each is refused by its type before it is opened.
* At most :data:`MAX_BYTES` are read from a text input (scene, robot.yaml, suite, plan):
  the largest plan of the shipped suites is under 2 MiB.
* A YAML document keeps its aliases shared when loaded (PyYAML's safe loader), but any
  code that walks it, or formats it into a message, expands them: nine levels of nine
  aliases are 387 million values from 1 KiB.  :func:`check_expansion` counts the values
  with the aliases expanded, in time linear in the document, and refuses more than
  :data:`MAX_VALUES` (or an alias of itself) before anything else reads it.
* JSON nested deeper than Python's recursion limit is refused as such.
"""

from __future__ import annotations

import json
import os
import stat
from pathlib import Path
from typing import Any

from regrasp_cli.errors import InputError

MAX_BYTES = 64 << 20  # text inputs: scene, robot.yaml, suite, plan
MAX_VALUES = 1_000_000  # values of a YAML document, its aliases expanded


def regular_file(path: Path, what: str = "file") -> os.stat_result:
    """``path``'s status when it is a regular file (symbolic links followed), else an
    InputError saying what it is."""
    try:
        st = os.stat(path)
    except FileNotFoundError:
        raise InputError(path, None, f"cannot read the {what}: no such file") from None
    except OSError as exc:
        raise InputError(path, None, f"cannot read the {what} ({exc.strerror or exc})") from None
    if stat.S_ISDIR(st.st_mode):
        raise InputError(path, None, f"is a folder; expected a {what}")
    if not stat.S_ISREG(st.st_mode):
        kind = "a FIFO" if stat.S_ISFIFO(st.st_mode) else "a device" if stat.S_ISCHR(st.st_mode) or \
            stat.S_ISBLK(st.st_mode) else "a socket" if stat.S_ISSOCK(st.st_mode) else "not a regular file"
        raise InputError(path, None, f"is {kind}; expected a regular {what}")
    return st


def read_text(path: str | Path, what: str = "file", max_bytes: int = MAX_BYTES) -> str:
    """The UTF-8 text of the regular file ``path``, at most ``max_bytes`` long.

    Raises:
        InputError: naming ``path``: missing, not a regular file, too large, unreadable.
    """
    path = Path(path)
    if regular_file(path, what).st_size > max_bytes:
        raise InputError(path, None, f"larger than {max_bytes >> 20} MiB; expected a {what} of at most that size")
    try:
        with open(path, "rb") as f:
            data = f.read(max_bytes + 1)  # the size may have grown since stat
        if len(data) > max_bytes:
            raise InputError(path, None, f"larger than {max_bytes >> 20} MiB; expected a {what} of at most that size")
        return data.decode("utf-8")
    except OSError as exc:
        raise InputError(path, None, f"cannot read the {what} ({exc.strerror or exc})") from None
    except UnicodeDecodeError as exc:
        raise InputError(path, None, f"not UTF-8 text (byte {exc.start}); expected a {what}") from None


def check_expansion(data: Any, path: Path, limit: int = MAX_VALUES) -> None:
    """Refuse a loaded YAML document that holds more than ``limit`` values once its
    aliases are expanded, or a value that contains itself.  Shared values are counted
    once per reference without being walked again, so the check is linear in the file."""
    sizes: dict[int, int] = {}
    walking: set[int] = set()

    def size(v: Any) -> int:
        if not isinstance(v, (list, dict)):
            return 1
        key = id(v)
        if key in sizes:
            return sizes[key]
        if key in walking:
            raise InputError(path, None, "a YAML alias inside the value it names (a recursive document)")
        walking.add(key)
        items = list(v.keys()) + list(v.values()) if isinstance(v, dict) else v
        n = 1
        for item in items:
            n += size(item)
            if n > limit:
                raise InputError(path, None, f"more than {limit:,} values once its YAML aliases are expanded; "
                                             f"expected a configuration file")
        walking.discard(key)
        sizes[key] = n
        return n

    try:
        size(data)
    except RecursionError:
        raise InputError(path, None, "nested too deeply; expected a configuration file") from None


def loads_json(text: str, path: Path) -> Any:
    """``json.loads`` with errors as InputErrors naming ``path``."""
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise InputError(path, None, f"not valid JSON (line {exc.lineno}: {exc.msg})") from None
    except RecursionError:
        raise InputError(path, None, "JSON nested too deeply; expected a plan") from None
