"""Progress of library work shown on stderr: the CLI's side of the library's callbacks."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

from regrasp_cli.model.selfcollision import PairProgress
from regrasp_cli.scene import Problem, load_problem


@contextmanager
def self_collision_bar(console: Console | None = None) -> Iterator[PairProgress]:
    """A ``progress(done, total)`` callback drawing a bar on stderr while a robot's
    self-collision matrix is computed (its first use); nothing when it is read from the
    cache.  The bar is transient, and rich draws none when stderr is not a terminal."""
    bar = Progress(TextColumn("self-collision matrix (first use of this robot): link pairs"), BarColumn(),
                   MofNCompleteColumn(), TimeElapsedColumn(), console=console or Console(stderr=True),
                   transient=True)
    task = []

    def update(done: int, total: int) -> None:
        if not task:
            bar.start()
            task.append(bar.add_task("pairs", total=total))
        bar.update(task[0], completed=done, total=total)

    try:
        yield update
    finally:
        if task:
            bar.stop()


def load_problem_shown(scene: str | Path, cache_dir: Path | None) -> Problem:
    """:func:`~regrasp_cli.scene.load_problem` with the self-collision bar."""
    with self_collision_bar() as progress:
        return load_problem(scene, cache_dir, progress)


def scene_inputs(scene: Path | None) -> tuple[Path, ...]:
    """The files the pick-and-place scene ``scene`` reads (none without one): outputs
    must differ from them.  A malformed scene raises the InputError its loading would."""
    from regrasp_cli.config import load_scene_spec, scene_files

    return () if scene is None else scene_files(load_scene_spec(scene))
