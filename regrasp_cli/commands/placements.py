"""`regrasp placements build` and `regrasp placements show`: an object's stable placements
(Harada et al. 2014 §III-C) as an artefact, and where they fit on a scene's supports."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

from regrasp_cli.commands.report import provenance_table
from regrasp_cli.config import SceneSpec, load_scene_spec
from regrasp_cli.errors import InputError
from regrasp_cli.placement.stable import PlacementOptions, StablePlacement
from regrasp_cli.scene import scene_object


def _in_scene(spec: SceneSpec, exc: InputError) -> InputError:
    return InputError(spec.file, exc.field, exc.message) if exc.file is None else exc


def run_placements_build(scene: Path, cache_dir: Path, console: Console | None = None) -> Path:
    """Build the scene object's placements into the cache; print them and their fits."""
    from regrasp_cli.placement.artefact import build_placements

    console = console or Console()
    spec = load_scene_spec(scene)
    obj = scene_object(spec)
    try:
        path, found = build_placements(cache_dir, obj)
    except InputError as exc:
        raise _in_scene(spec, exc) from None
    console.print(_table(found, _fits(spec, obj, found), f"{obj.name}: {len(found)} stable placements"))
    console.print(f"placements: {path}")
    return path


def _fits(spec: SceneSpec, obj, found: list[StablePlacement]) -> dict[str, np.ndarray]:
    """Support name -> fits per placement (the empty dict when the scene has no support)."""
    from regrasp_cli.placement.supports import fit_placements, scene_supports

    supports = scene_supports(spec.obstacles, spec.supports, spec.file)
    fitted = fit_placements(found, supports, obj.mesh, spec.obstacles)
    return {s.name: np.bincount(fitted.stable[fitted.support == i], minlength=len(found))
            for i, s in enumerate(supports)}


def _table(found: list[StablePlacement], fits: dict[str, np.ndarray], title: str) -> Table:
    t = Table(title=title)
    for c in ("#", "tips at (deg)", "mass centre height (mm)", "facet area (cm²)", "face down",
              *(f"fits on {name}" for name in fits)):
        t.add_column(c, justify="right")
    for i, p in enumerate(found):
        t.add_row(str(i), f"{np.degrees(p.tipping_angle):.1f}", f"{1000 * p.height:.1f}", f"{1e4 * p.area:.1f}",
                  _direction(p.normal_O), *(str(int(n[i])) for n in fits.values()))
    return t


def _direction(n: np.ndarray) -> str:
    """``-y`` for an axis of the object frame, else the unit vector to 2 decimals."""
    k = int(np.argmax(np.abs(n)))
    if abs(n[k]) > 1 - 1e-6:
        return ("+" if n[k] > 0 else "-") + "xyz"[k]
    return "(" + " ".join(f"{v:.2f}" for v in n) + ")"


def show_placements(file: Path, scene: Path | None, png: Path | None, console: Console | None = None) -> None:
    """Print a placements artefact (checked against ``scene``'s object when given) and, with
    ``png``, draw them."""
    from regrasp_cli.placement.artefact import provenance, read_placements
    from regrasp_cli.commands.progress import scene_inputs
    from regrasp_cli.store import check_writable, read_provenance

    console = console or Console()
    if png is not None:
        if scene is None:
            raise InputError(None, "--png", "drawing the placements needs --scene (the object's mesh)")
        check_writable(png, "--png", inputs=(file, *scene_inputs(scene)))
    stored = expected = read_provenance(file)
    spec = obj = None
    if scene is not None:  # refused when built for another mesh
        spec = load_scene_spec(scene)
        obj = scene_object(spec)
        expected = provenance(obj, _stored_options(file))
    found = read_placements(file, expected)
    console.print(provenance_table(file, stored))
    fits = _fits(spec, obj, found) if spec is not None else {}
    console.print(_table(found, fits, f"{len(found)} stable placements"))
    if png is not None:
        from regrasp_cli.show.png import placements_png
        from regrasp_cli.store import atomic_write_bytes

        total = np.sum(list(fits.values()), axis=0) if fits else None
        atomic_write_bytes(png, placements_png(obj.mesh, found, total, title=f"{obj.name}: {len(found)} stable "
                                                                              "placements"))
        console.print(f"png: {png}")


def _stored_options(file: Path) -> PlacementOptions:
    import json

    import h5py

    try:
        with h5py.File(file, "r") as f:
            return PlacementOptions(**json.loads(f.attrs["options"]))
    except (OSError, KeyError, TypeError, ValueError) as exc:
        raise InputError(file, "options", f"not a placements file with readable options ({exc})") from None
