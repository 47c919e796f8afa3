"""`regrasp show` and `regrasp grasps show --png`: check the options, draw, write, print
where the files are.

Viewing only (not a paper section).  Bad options and bad files raise
:class:`~regrasp_cli.errors.InputError` naming the option or the file and field, before
anything is written.
"""

from __future__ import annotations

import re
from pathlib import Path

import click

from regrasp_cli.commands.progress import scene_inputs
from regrasp_cli.errors import InputError
from regrasp_cli.store import check_writable
from regrasp_cli.show.motion import MAX_FPS

SIZE_RANGE = (160, 4096)  # pixels, each side of a key-frame picture
MAX_BEST = 60  # grasps in one picture


def parse_size(text: str) -> tuple[int, int]:
    """``WIDTHxHEIGHT`` in pixels, each in :data:`SIZE_RANGE`."""
    m = re.fullmatch(r"\s*(\d+)\s*[xX]\s*(\d+)\s*", text)
    if not m:
        raise InputError(None, "--size", f"expected WIDTHxHEIGHT in pixels (e.g. 960x720), found {text!r}")
    w, h = int(m.group(1)), int(m.group(2))
    lo, hi = SIZE_RANGE
    if not (lo <= w <= hi and lo <= h <= hi):
        raise InputError(None, "--size", f"expected each side in [{lo}, {hi}] pixels, found {w}x{h}")
    return w, h


def _output_file(path: Path, option: str, inputs: tuple[Path, ...]) -> None:
    check_writable(path, option, inputs=inputs)


def run_show(plan_file: Path, html: Path | None, png: Path | None, fps: int, size: str, source: str) -> None:
    """Write the animated page (``html``) and/or the key-frame pictures (``png``, a
    directory) of the plan ``plan_file``; print the paths written."""
    from regrasp_cli.show.motion import load_plan_view

    if html is None and png is None:
        raise InputError(None, "--html/--png", "nothing to do: give --html FILE, --png DIR or both")
    if not 1 <= fps <= MAX_FPS:
        raise InputError(None, "--fps", f"expected frames per second in [1, {MAX_FPS}], found {fps}")
    wh = parse_size(size)
    if html is not None:
        _output_file(html, "--html", (plan_file,))
    if png is not None:
        check_writable(png, "--png", folder=True)
    view = load_plan_view(plan_file)
    if html is not None:
        from regrasp_cli.show.html import write_plan_html

        write_plan_html(view, html, fps, source)
        mb = html.stat().st_size / 1e6
        click.echo(f"html: {html} ({mb:.1f} MB, {len(view.plan.phases)} phases over {view.duration:.1f} s; "
                   "open it in a web browser)")
    if png is not None:
        from regrasp_cli.show.png import write_key_frames

        for path in write_key_frames(view, png, wh, source):
            click.echo(f"png: {path}")


def check_grasps_png(png: Path | None, scene: Path | None, best: int, file: Path) -> None:
    """The options of `grasps show --png` (of the grasp list ``file``), checked before
    anything is printed."""
    if png is None:
        return
    if scene is None:
        raise InputError(None, "--png", "drawing grasps needs the object and the hand, which a grasp list names only "
                                        "by their SHA-256: give --scene SCENE too")
    if not 1 <= best <= MAX_BEST:
        raise InputError(None, "--best", f"expected 1 to {MAX_BEST} grasps to draw, found {best}")
    _output_file(png, "--png", (file, *scene_inputs(scene)))


def run_grasps_png(file: Path, best: int, scene: Path, cache_dir: Path, png: Path) -> Path:
    """Draw the ``best`` first grasps of the list ``file`` (checked against ``scene``'s
    robot and object; refused if stale) into the picture ``png``."""
    import h5py

    from regrasp_cli.grasp.build import provenance, read_grasp_list, stored_options
    from regrasp_cli.commands.progress import load_problem_shown
    from regrasp_cli.show.png import grasps_png
    from regrasp_cli.store import atomic_write_bytes

    problem = load_problem_shown(scene, cache_dir)
    try:
        with h5py.File(file, "r") as f:
            hand = str(f.attrs["hand"])
    except (OSError, KeyError) as exc:
        raise InputError(file, "hand", f"not a readable grasp list ({exc})") from None
    if hand not in problem.robot.hands:
        raise InputError(file, "hand", f"the {hand} hand is not a hand of {scene}'s robot")
    glist = read_grasp_list(file, provenance(problem, hand, stored_options(file)))
    title = f"{file.name}: best {min(best, len(glist))} of {len(glist)} grasps of the {hand} hand"
    atomic_write_bytes(png, grasps_png(glist, problem.object.mesh, best, problem.robot, title=title))
    return png
