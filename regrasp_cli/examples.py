"""The robots and example scenes shipped with the package (``regrasp_cli/data/``).

A scene names a shipped robot as ``robot: builtin:NAME`` (e.g. ``builtin:humanoid43``),
so the example scenes work wherever they are copied; :func:`copy_examples` puts the
scenes and robots in a folder for a user to edit (`regrasp examples DIR`).
"""

from __future__ import annotations

import shutil
from importlib.resources import files
from pathlib import Path

from regrasp_cli.errors import InputError

BUILTIN_PREFIX = "builtin:"


def data_dir() -> Path:
    """The package's data folder (a real folder: the package is installed unzipped)."""
    return Path(str(files("regrasp_cli") / "data"))


def robot_names() -> tuple[str, ...]:
    return tuple(sorted(p.parent.name for p in (data_dir() / "robots").glob("*/robot.yaml")))


def scene_files() -> tuple[Path, ...]:
    return tuple(sorted((data_dir() / "scenes").glob("*.yaml")))


def builtin_robot(file: Path | None, where: str, value: str) -> Path:
    """The robot.yaml of ``builtin:NAME``.

    Raises:
        InputError: an unknown name, naming the shipped ones.
    """
    name = value[len(BUILTIN_PREFIX):]
    path = data_dir() / "robots" / name / "robot.yaml"
    if not name or "/" in name or not path.is_file():
        raise InputError(file, where, f"unknown built-in robot {value!r} (built-in: "
                                      f"{', '.join(BUILTIN_PREFIX + n for n in robot_names())})")
    return path


def copy_examples(dest: Path, force: bool = False) -> list[Path]:
    """Copy the example scenes to ``dest/scenes`` and the robots to ``dest/robots``;
    returns the files written.  Existing files are kept unless ``force``.

    Raises:
        InputError: a file would be overwritten (without ``force``), or ``dest`` is a file.
    """
    dest = Path(dest)
    src = data_dir()
    pairs = [(p, dest / p.relative_to(src)) for folder in ("scenes", "robots")
             for p in sorted((src / folder).rglob("*")) if p.is_file() and p.suffix in (".yaml", ".urdf")]
    if dest.exists() and not dest.is_dir():
        raise InputError(None, "DIR", f"{dest} exists and is not a folder")
    clash = [d for _, d in pairs if d.exists()]
    if clash and not force:
        raise InputError(None, "DIR", f"{clash[0]} exists (and {len(clash) - 1} more); give --force to overwrite")
    for s, d in pairs:
        d.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(s, d)
    return [d for _, d in pairs]
