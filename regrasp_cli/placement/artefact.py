"""The stable placements of an object as an offline artefact (HDF5, :mod:`regrasp_cli.store`):
one file per object mesh and options, ``placements/<object>-<10 hex digits>.h5``,
refused when the mesh or the options changed.  They depend on the object alone; where
they fit in a scene (:mod:`placement.supports`) is computed when a scene is planned.

Datasets (n placements, k the most footprint vertices): ``X_SO`` (n, 4, 4), ``normal_O``
(n, 3), ``height``, ``margin``, ``tipping_angle``, ``area`` (n,), ``footprint`` (n, k, 2)
padded with NaN, ``footprint_size`` (n,).
"""

from __future__ import annotations

from dataclasses import asdict
from pathlib import Path

import numpy as np

from regrasp_cli.errors import InputError
from regrasp_cli.grasp.surface import mass_centre_of
from regrasp_cli.model.objects import ObjectMesh, mesh_sha256
from regrasp_cli.placement.stable import PlacementOptions, StablePlacement, stable_placements
from regrasp_cli.store import Provenance, artefact_lock, canonical_json, file_label, read_artefact, sha256_params, \
    write_artefact

FORMAT, FORMAT_VERSION = "regrasp.placements", 1
REBUILD = "regrasp placements build"


def provenance(obj: ObjectMesh, options: PlacementOptions) -> Provenance:
    params = {"placement": asdict(options), "mass_centre": "volume" if obj.watertight else "surface"}
    return Provenance(FORMAT, FORMAT_VERSION, {"mesh": mesh_sha256(obj), "params": sha256_params(params)})


def artefact_path(cache_dir: Path, obj: ObjectMesh, options: PlacementOptions) -> Path:
    name = file_label(obj.name.replace("builtin:", "builtin_"))
    return Path(cache_dir) / "placements" / f"{name}-{provenance(obj, options).inputs['params'][:10]}.h5"


def compute_placements(obj: ObjectMesh, options: PlacementOptions = PlacementOptions()) -> list[StablePlacement]:
    """The object's stable placements, most stable first.

    Raises:
        InputError: it has none (field ``object.mesh``): no facet of its hull holds it.
    """
    found = stable_placements(obj.mesh, mass_centre_of(obj.mesh, obj.watertight), options)
    if not found:
        raise InputError(None, "object.mesh", f"{obj.name} has no stable placement: no face of its convex hull "
                                              f"holds its mass centre {1000 * options.margin:g} mm inside with a "
                                              f"tipping angle of at least {options.min_tipping_angle:g} rad "
                                              "(a ball or a lying cylinder rolls)")
    return found


def write_placements(path: Path, obj: ObjectMesh, options: PlacementOptions,
                     found: list[StablePlacement]) -> None:
    k = max(len(p.footprint) for p in found)
    foot = np.full((len(found), k, 2), np.nan)
    for i, p in enumerate(found):
        foot[i, :len(p.footprint)] = p.footprint
    write_artefact(path, provenance(obj, options), {
        "X_SO": np.array([p.X_SO for p in found]), "normal_O": np.array([p.normal_O for p in found]),
        "height": np.array([p.height for p in found]), "margin": np.array([p.margin for p in found]),
        "tipping_angle": np.array([p.tipping_angle for p in found]), "area": np.array([p.area for p in found]),
        "footprint": foot, "footprint_size": np.array([len(p.footprint) for p in found], dtype=np.int64),
    }, attrs={"object": obj.name, "options": canonical_json(asdict(options))})


def read_placements(path: Path, expected: Provenance) -> list[StablePlacement]:
    """The placements stored at ``path``; refused (stale or corrupt) as any artefact."""
    a = read_artefact(path, expected, rebuild=REBUILD)
    return [StablePlacement(a["X_SO"][i], a["normal_O"][i], float(a["height"][i]), float(a["margin"][i]),
                            float(a["tipping_angle"][i]), float(a["area"][i]),
                            a["footprint"][i, :int(a["footprint_size"][i])])
            for i in range(len(a["height"]))]


def build_placements(cache_dir: Path, obj: ObjectMesh,
                     options: PlacementOptions = PlacementOptions()) -> tuple[Path, list[StablePlacement]]:
    """Compute and store the object's placements (nothing is written when it has none)."""
    path = artefact_path(cache_dir, obj, options)
    with artefact_lock(path):
        found = compute_placements(obj, options)
        write_placements(path, obj, options, found)
    return path, found
