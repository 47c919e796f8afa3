"""Cached artefacts of a scene (grasp lists, roadmap): their build options from the
defaults, the scene and the command line, and loading them, built first when missing
or stale.  Library code: progress is the caller's business (a :class:`Builder`)."""

from __future__ import annotations

from pathlib import Path
from typing import Protocol

from regrasp_cli.errors import InputError, StaleArtefactError
from regrasp_cli.grasp.build import BuildOptions, GraspList
from regrasp_cli.roadmap.build import RoadmapArtefact, RoadmapOptions
from regrasp_cli.scene import Problem
from regrasp_cli.store import artefact_lock, sha256_file


class Builder(Protocol):
    """Builds a missing or stale artefact (the CLI's shows progress bars and a summary)."""

    def notice(self, message: str) -> None: ...

    def grasps(self, scene: Path, cache_dir: Path, hand: str, options: BuildOptions) -> None: ...

    def roadmap(self, scene: Path, cache_dir: Path, options: RoadmapOptions, jobs: int) -> None: ...


class QuietBuilder:
    def notice(self, message: str) -> None:
        pass

    def grasps(self, scene: Path, cache_dir: Path, hand: str, options: BuildOptions) -> None:
        from regrasp_cli.grasp.build import build_grasps

        build_grasps(scene, cache_dir, hand, options)

    def roadmap(self, scene: Path, cache_dir: Path, options: RoadmapOptions, jobs: int) -> None:
        from regrasp_cli.roadmap.build import build_roadmap

        build_roadmap(scene, cache_dir, options, jobs)


def _positive(value, name: str) -> None:
    if value is not None and value < 1:
        raise InputError(None, name, f"expected an integer >= 1, found {value}")


def build_options(scene_seed: int, seed: int | None, jobs: int, positions: int | None, orientations: int | None,
                  target: int | None = None, weights: str | None = None):
    from dataclasses import replace


    for value, name in ((jobs, "--jobs"), (positions, "--positions"), (orientations, "--orientations")):
        _positive(value, name)
    options = BuildOptions(seed=scene_seed if seed is None else seed, jobs=jobs)
    g = options.grasp
    if target is not None and target < 0:
        raise InputError(None, "--target", f"expected an integer >= 0, found {target}")
    g = replace(g, n_positions=positions or g.n_positions, n_orientations=orientations or g.n_orientations,
                target=g.target if target is None else target)
    if weights is not None:
        from regrasp_cli.grasp.quality import QualityWeights

        try:
            w = [float(x) for x in weights.split(",")]
        except ValueError:
            w = []
        if len(w) != 4 or any(not (x >= 0) for x in w) or sum(w) <= 0:
            raise InputError(None, "--weights", f"expected four numbers >= 0 (not all 0) separated by commas, "
                                                f"found {weights!r}")
        g = replace(g, weights=QualityWeights(*w))
    return replace(options, grasp=g)


def roadmap_options(scene_spec, nodes: int, tree: bool, seed: int | None):
    if nodes < 1:
        raise InputError(None, "--nodes", f"expected an integer >= 1, found {nodes}")
    return RoadmapOptions(nodes=nodes, tree=tree, seed=scene_spec.planning.seed if seed is None else seed)


def load_artefacts(scene: Path, cache_dir: Path, problem: Problem, build: bool, jobs: int, need_roadmap: bool,
                   builder: Builder | None = None, roadmap_nodes: int = RoadmapOptions.nodes,
                   grasp_target: int | None = None) -> tuple[dict[str, GraspList], RoadmapArtefact | None, dict[str, str]]:
    """The grasp lists of both hands and the roadmap, built when missing or stale unless
    ``build`` is False (then a missing or stale one raises an InputError naming it).
    ``builder`` builds a missing one (the CLI's shows progress); default: quietly."""
    from regrasp_cli.grasp import build as gb
    from regrasp_cli.roadmap import build as rb

    builder = builder or QuietBuilder()

    spec = problem.spec
    options = build_options(spec.planning.seed, None, jobs, None, None, grasp_target)
    lists, hashes = {}, {}
    for hand in ("right", "left"):
        lists[hand], hashes[f"grasps_{hand}"] = _cached(
            gb.artefact_path(cache_dir, problem, hand, options), gb.provenance(problem, hand, options), build,
            lambda: builder.grasps(scene, cache_dir, hand, options), gb.read_grasp_list, builder)
    art = None
    if need_roadmap:
        r_opts = roadmap_options(spec, roadmap_nodes, False, None)
        art, hashes["roadmap"] = _cached(
            rb.artefact_path(cache_dir, problem, r_opts), rb.provenance(problem, r_opts), build,
            lambda: builder.roadmap(scene, cache_dir, r_opts, jobs), rb.read_roadmap, builder)
    return lists, art, hashes


def _cached(path: Path, prov, build: bool, make, read, builder: Builder):
    """``read(path, prov)`` and the file's SHA-256, after ``make()`` when the artefact is
    missing, stale or damaged (and ``build``; else ``read`` refuses it), all under the
    artefact's lock: a concurrent run waits and reuses what this one built."""
    with artefact_lock(path, create=build):
        if build:
            if not path.is_file():
                make()
            else:
                try:  # read once: the freshness check is the read itself
                    return read(path, prov), sha256_file(path)
                except StaleArtefactError as exc:
                    builder.notice(f"rebuilding {path}: {exc.message.split('; rebuild it with')[0]}")
                    make()
        return read(path, prov), sha256_file(path)


