"""Cached artefacts of a scene (grasp lists, roadmap): their file names, their build
options from the defaults, the scene and the command line, and loading them, built first
when missing or stale.  Library code: progress is the caller's business (a :class:`Builder`).

File names carry the robot's identity (:func:`~regrasp_cli.store.robot_identity`), so
two robots sharing a cache never overwrite each other's artefacts.  An empty grasp list is
never written: :func:`build_grasp_list` raises :class:`~regrasp_cli.errors.EmptyGraspList`
with the reason from the build's counters.
"""

from __future__ import annotations

from pathlib import Path
from typing import Callable, Protocol

from regrasp_cli.errors import EmptyGraspList, InputError, StaleArtefactError
from regrasp_cli.grasp import build as gb
from regrasp_cli.grasp.build import BuildOptions, GraspList
from regrasp_cli.grasp.usable import usable_at_ends
from regrasp_cli.roadmap.build import RoadmapArtefact, RoadmapOptions
from regrasp_cli.scene import Problem, load_problem
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
        build_grasp_list(scene, cache_dir, hand, options)

    def roadmap(self, scene: Path, cache_dir: Path, options: RoadmapOptions, jobs: int) -> None:
        from regrasp_cli.roadmap.build import build_roadmap

        build_roadmap(scene, cache_dir, options, jobs)


# ------------------------------------------------------------------ grasp lists


def grasp_list_path(cache_dir: Path, problem: Problem, hand: str, options: BuildOptions) -> Path:
    return gb.artefact_path(cache_dir, problem, hand, options)


def build_grasp_list(scene: Path, cache_dir: Path, hand: str, options: BuildOptions,
                     progress: Callable[[int, int, int], None] | None = None,
                     problem: Problem | None = None) -> tuple[GraspList, gb.BuildReport]:
    """Build ``hand``'s grasp list into :func:`grasp_list_path` (``progress`` as for
    :func:`~regrasp_cli.grasp.build.build_grasps`; ``problem``: the scene, already loaded).

    Raises:
        EmptyGraspList: no grasp found, with the reason; nothing is written.
    """
    scene, cache_dir = Path(scene).resolve(), Path(cache_dir).resolve()
    problem = problem or load_problem(scene, cache_dir)
    with artefact_lock(grasp_list_path(cache_dir, problem, hand, options)):
        glist, report = gb.build_grasps(scene, cache_dir, hand, options, progress)
    if len(glist) == 0:
        raise EmptyGraspList(hand, empty_grasps_reason(problem, hand, report))
    return glist, report


def empty_grasps_reason(problem: Problem, hand: str, report: gb.BuildReport) -> str:
    """Why a build found no grasp, from its counters: what rejected the candidate frames."""
    obj = problem.object
    what = f"{obj.name} ({' x '.join(f'{e:.3g}' for e in obj.extents)} m)"
    if report.frames == 0:
        if problem.robot.hands[hand].kind == "jaw":
            from regrasp_cli.grasp.jaw import jaw_geometry
            from regrasp_cli.grasp.single import HandModel

            jaw = jaw_geometry(HandModel(problem.robot, hand, obj.mesh, problem.disabled.links(),
                                         problem.spec.planning.contact_tolerance))
            return (f"no antipodal pair of points on {what} fits between the jaw's pads (from "
                    f"{1000 * jaw.width_closed:.1f} to {1000 * jaw.width_open:.1f} mm apart), so no grasp frame "
                    "was tried")
        return f"no candidate grasp frame on {what}"
    few = report.frames - report.frames_blocked - report.frames_with_contacts
    causes = ((report.frames_blocked, "the palm (or a pinching finger) inside the object"), (few, "too few contacts"),
              (report.frames_with_contacts - report.force_closure, "the closed hand colliding or no force closure"))
    because = ", ".join(f"{n} with {why}" for n, why in causes if n > 0)
    return f"0 of {report.frames} candidate grasp frames on {what} gave a grasp ({because})"


def _read_grasp_list(path: Path, prov) -> GraspList:
    """A cached grasp list; an empty one (written by an earlier regrasp) is refused as stale."""
    g = gb.read_grasp_list(path, prov)
    if len(g) == 0:
        raise StaleArtefactError(path, None, "holds no grasp; rebuild it with `regrasp grasps build` to see why")
    return g


# ------------------------------------------------------------------ options


def check_positive(value, name: str) -> None:
    if value is not None and value < 1:
        raise InputError(None, name, f"expected an integer >= 1, found {value}")


def build_options(scene_seed: int, seed: int | None, jobs: int, positions: int | None, orientations: int | None,
                  target: int | None = None, weights: str | None = None, pinch_frames: int | None = None):
    from dataclasses import replace


    for value, name in ((jobs, "--jobs"), (positions, "--positions"), (orientations, "--orientations")):
        check_positive(value, name)
    options = BuildOptions(seed=scene_seed if seed is None else seed, jobs=jobs)
    g = options.grasp
    for value, name in ((target, "--target"), (pinch_frames, "--pinch-frames")):
        if value is not None and value < 0:
            raise InputError(None, name, f"expected an integer >= 0, found {value}")
    g = replace(g, n_positions=positions or g.n_positions, n_orientations=orientations or g.n_orientations,
                target=g.target if target is None else target,
                pinch_frames=g.pinch_frames if pinch_frames is None else pinch_frames)
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
    """The grasp lists of both hands, filtered for the scene (:func:`usable_at_ends`), and
    the roadmap, built when missing or stale unless ``build`` is False (then a missing or
    stale one raises an InputError naming it).
    ``builder`` builds a missing one (the CLI's shows progress); default: quietly."""
    from regrasp_cli.roadmap import build as rb

    builder = builder or QuietBuilder()

    spec = problem.spec
    options = build_options(spec.planning.seed, None, jobs, None, None, grasp_target)
    lists, hashes = {}, {}
    for hand in ("right", "left"):
        stored, hashes[f"grasps_{hand}"] = _cached(
            grasp_list_path(cache_dir, problem, hand, options), gb.provenance(problem, hand, options), build,
            lambda: builder.grasps(scene, cache_dir, hand, options), _read_grasp_list, builder)
        # the scene's filter (seed 000 §IV-B): the best grasps usable at the start or the goal
        lists[hand] = usable_at_ends(problem, stored, options.grasp.target)
    art = None
    if need_roadmap:
        r_opts = roadmap_options(spec, roadmap_nodes, False, None)
        path = rb.artefact_path(cache_dir, problem, r_opts)
        reuse = None if path.is_file() else rb.nearest_roadmap(cache_dir, problem, r_opts)
        if reuse is not None:  # a few obstacles moved: revalidated online, not rebuilt
            art, hashes["roadmap"] = reuse.roadmap, sha256_file(reuse.path)
            builder.notice(f"roadmap: reusing {reuse.path.name}, built for other obstacles ({_changes(reuse)}); the "
                           f"queries check them online (`regrasp roadmap build` builds one for this scene)")
        else:
            art, hashes["roadmap"] = _cached(path, rb.provenance(problem, r_opts), build,
                                             lambda: builder.roadmap(scene, cache_dir, r_opts, jobs), rb.read_roadmap,
                                             builder)
    return lists, art, hashes


def _changes(reuse) -> str:
    moved = f"{len(reuse.unchecked)} moved or added: {', '.join(reuse.unchecked)}, in " \
            f"{100 * reuse.blocked:.1f} % of its nodes" if reuse.unchecked else ""
    gone = f"{reuse.removed} removed" if reuse.removed else ""
    return "; ".join(x for x in (moved, gone) if x)


def rebuild_notice(path: Path, exc: StaleArtefactError) -> str:
    """The line said when a stale or damaged artefact is built again: what was wrong,
    without the advice to rebuild it (that is being done)."""
    return f"rebuilding {path}: {exc.message.split('; rebuild it with')[0]}"


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
                    builder.notice(rebuild_notice(path, exc))
                    make()
        return read(path, prov), sha256_file(path)




# ------------------------------------------------------------------ placements


def load_placements(cache_dir: Path, problem: Problem, build: bool, builder: Builder | None = None):
    """The object's stable placements (:mod:`placement.artefact`) and the file's SHA-256,
    computed when missing or stale unless ``build`` is False (then refused).

    Raises:
        InputError: the object has no stable placement (field ``object.mesh`` of the scene).
    """
    from regrasp_cli.placement import artefact as pa
    from regrasp_cli.placement.stable import PlacementOptions

    options = PlacementOptions()
    obj = problem.object

    def make() -> None:
        try:
            pa.build_placements(cache_dir, obj, options)
        except InputError as exc:
            raise InputError(problem.spec.file, exc.field, exc.message) from None

    return _cached(pa.artefact_path(cache_dir, obj, options), pa.provenance(obj, options), build, make,
                   pa.read_placements, builder or QuietBuilder())


def placements_for_style(style: str, cache_dir: Path, problem: Problem, build: bool,
                         builder: Builder | None = None) -> tuple[list, str | None]:
    """The placements a `plan --style` needs: none for ``one-arm``, ``handover`` and
    ``seed000``; for ``auto``, none either when the object has no stable placement (the
    plan says why it used none); for ``place-regrasp``, that is an InputError."""
    if style not in ("auto", "place-regrasp"):
        return [], None
    try:
        return load_placements(cache_dir, problem, build, builder)
    except InputError as exc:
        if style == "place-regrasp" or exc.field != "object.mesh":
            raise  # placements the object does not have were asked for, or --no-build refused the file
        return [], None
