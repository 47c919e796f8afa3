"""`regrasp grasps build`: the grasp list of a hand for an object (Saut et al. 2010, §IV-A).

Pipeline (fingertip hands; jaws: :mod:`.jaw`): object surface model (:mod:`.surface`) -> finger workspace spheres
(:mod:`.workspace`, Algorithm 1, cached) -> grasp frames (:mod:`.frames`: positions in
the object's bounding box x an incremental SO(3) grid; then :mod:`.pinch` frames across
antipodal pairs, tried only when the grid leaves the list short) -> one grasp attempt per frame
(:mod:`.single`), in parallel over forked processes -> force-closure filter and quality
(:mod:`.quality`) -> near-duplicates removed -> sorted by quality -> HDF5 artefact.

A grasp list depends on the robot (URDF and the whole robot.yaml), the object mesh, the
friction coefficient, the options, and today also on the scene: it keeps only the grasps
whose hand clears the obstacles with the object at the task's start or goal pose
(:class:`_Usable`), so the obstacles and both poses are hashed into its parameters
(:func:`_params`).  This departs from the paper, whose lists are context independent and
filtered against the environment online (§IV-A, §IV-B); docs/DESIGN-NOTES.md, "The list".
Two grasps are near-duplicates when their hand poses differ by less than
``duplicate_distance`` in position and ``duplicate_angle`` in orientation; the better one
is kept.  The result is deterministic for a given seed whatever the number of jobs.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import NamedTuple

import numpy as np

from regrasp_cli.errors import InputError
from regrasp_cli.grasp.frames import grasp_frames
from regrasp_cli.grasp.jaw import Jaw, antipodal_pairs, jaw_frames, jaw_geometry, jaw_grasp
from regrasp_cli.grasp.pads import PadHand, pad_frames, pad_geometry, pad_grasp
from regrasp_cli.grasp.pinch import pinch_frames
from regrasp_cli.model.handshape import hand_hits_static, hand_shapes, single_shape, static_geometry
from regrasp_cli.grasp.quality import GraspScores, QualityWeights
from regrasp_cli.grasp.single import ContactHint, Grasp, GraspOptions, HandModel, grasp_for_frame
from regrasp_cli.grasp.surface import Surface, build_surface, sampling_step
from regrasp_cli.grasp.workspace import FingerWorkspace, WorkspaceOptions, hand_workspace
from regrasp_cli.model.objects import mesh_sha256
from regrasp_cli.parallel import ordered_map
from regrasp_cli.scene import Problem, load_problem, obstacles_sha256
from regrasp_cli.spatial import rotation_angle
from regrasp_cli.store import (Provenance, canonical_json, file_label, read_artefact, robot_identity, sha256_params,
                               write_artefact)

FORMAT, FORMAT_VERSION = "regrasp.grasps", 1
CHUNK = 256  # frames per work item; the target is checked after each
PINCH_WIDTH = 0.12  # m: widest antipodal pair tried for a pinch frame (the fingertips' reach decides)
SCORE_NAMES = ("epsilon", "centroid", "ellipsoid", "curvature", "total")


@dataclass(frozen=True)
class BuildOptions:
    grasp: GraspOptions = field(default_factory=GraspOptions)
    workspace: WorkspaceOptions = field(default_factory=WorkspaceOptions)
    seed: int = 0
    jobs: int = 1


@dataclass(frozen=True)
class GraspList:
    """A hand's grasp list, best first (arrays over grasps, first axis k)."""

    hand: str
    finger_names: tuple[str, ...]
    X_OG: np.ndarray  # (k, 4, 4) grasp frame G in the object frame O
    finger_q: np.ndarray  # (k, n_hand_joints)
    in_contact: np.ndarray  # (k, n_fingers) bool
    points: np.ndarray  # (k, n_fingers, 3) contact points, frame O (NaN: no contact)
    normals: np.ndarray  # (k, n_fingers, 3) outward normals, frame O
    scores: np.ndarray  # (k, 5): epsilon, centroid, ellipsoid, curvature, total
    frame_index: np.ndarray  # (k,) index of the grasp frame each grasp came from

    def __len__(self) -> int:
        return len(self.X_OG)


@dataclass(frozen=True)
class BuildReport:
    hand: str
    path: Path
    frames: int
    frames_palm_blocked: int
    pinch_frames: int  # of the frames, those of the pinch pass (.pinch)
    frames_with_contacts: int  # frames that got enough contacts for the stability test
    force_closure: int
    kept: int  # after removing near-duplicates
    seconds: dict[str, float]  # time per stage


# ------------------------------------------------------------------ inputs and paths


def _params(problem: Problem, hand: str, options: BuildOptions) -> dict:
    task = problem.spec.task
    return {"hand": hand, "friction": problem.spec.object.friction, "seed": options.seed,
            "contact_tolerance": problem.spec.planning.contact_tolerance,
            "grasp": asdict(options.grasp), "workspace": asdict(options.workspace),
            # the list keeps the grasps usable at the task's object poses (_Usable)
            "usable_at": {"obstacles": obstacles_sha256(problem.spec.obstacles), "fingertips_touch": True,
                          "poses": np.round([task.X_WO_start, task.X_WO_goal], 9).tolist()}}


class _Usable:
    """Is a grasp usable in the scene's task: does the hand alone, at the grasp, clear the
    obstacles with the object at its start pose or at its goal pose (where a hand picks
    or places it)?  Its fingertips may touch the support as they touch the object
    (:mod:`model.collision`).  A grasp from under the object goes through its support at both, and
    no planner can use it (the double-grasp filter, :mod:`manip.doublegrasp`, would drop
    it): the list is filled with usable grasps instead, so its target counts what
    matters.  Memoised per grasp frame."""

    def __init__(self, problem: Problem, hand: str):
        self.robot, self.hand = problem.robot, hand
        self.env = static_geometry(problem.spec.obstacles)
        self.poses = (problem.spec.task.X_WO_start, problem.spec.task.X_WO_goal)
        self.tolerance = problem.spec.planning.contact_tolerance  # the fingertips may touch the support
        self.memo: dict[int, bool] = {}

    def __call__(self, g: Grasp) -> bool:
        if g.frame_index not in self.memo:
            shape = hand_shapes(self.robot, self.hand, g.finger_q, self.tolerance)[0]
            self.memo[g.frame_index] = any(not hand_hits_static(shape, X_WO @ g.X_OG, self.env, touching=True)
                                           for X_WO in self.poses)
        return self.memo[g.frame_index]


def provenance(problem: Problem, hand: str, options: BuildOptions) -> Provenance:
    r = problem.robot
    return Provenance(FORMAT, FORMAT_VERSION, {
        "urdf": r.urdf_sha256, "robot_yaml": r.robot_yaml_sha256, "mesh": mesh_sha256(problem.object),
        "params": sha256_params(_params(problem, hand, options))})


def artefact_path(cache_dir: Path, problem: Problem, hand: str, options: BuildOptions) -> Path:
    """``grasps/<object>-<robot identity>-<hand>-<10 hex digits of the build parameters>.h5``:
    two robots sharing a cache never overwrite each other's lists."""
    name = file_label(problem.object.name.replace("builtin:", "builtin_"))
    key = provenance(problem, hand, options).inputs["params"][:10]
    return Path(cache_dir) / "grasps" / f"{name}-{robot_identity(problem.robot)}-{hand}-{key}.h5"


def _pinch_search(context: _Search) -> _Search:
    """The search of the pinch pass (:mod:`.pinch`): the grid's frames followed by pinch
    frames (so frame indices stay unique), on a surface sampled twice as finely (a 14 mm
    rim gets one row of samples at the grid's step), of which only the samples where a
    fingertip clears the support at the start or goal pose are kept.  Half the pairs are
    levelled with each pose's vertical."""
    problem, options = context.problem, context.options
    rng = np.random.default_rng([options.seed, 1])
    h = context.hand_model.hand
    spec, thumb, ws = h.spec, h.opposing, context.workspaces
    r_tip = min(f.tip_radius for f in spec.fingers)
    surface = build_surface(problem.object.mesh, sampling_step(r_tip) / 2, rng)
    grid = context.surface  # curvature read from its samples, so that the scores of both passes compare
    surface = replace(surface, curvature=grid.curvature[grid.tree.query(surface.points)[1]])
    among = _tips_clear(problem, surface, r_tip)
    pairs = []
    for X_WO in (problem.spec.task.X_WO_start, problem.spec.task.X_WO_goal):
        p1, n1, p2, n2 = antipodal_pairs(problem.object.mesh, surface, problem.spec.object.friction, (0.0, PINCH_WIDTH),
                                         options.grasp.pinch_frames // 2, rng, among=among, level=X_WO[2, :3])
        keep = _tips_clear(problem, surface, r_tip, p2, n2)  # the second fingertip clears it too
        pairs.append((p1[keep], n1[keep], p2[keep], n2[keep]))
    p1, n1, p2, n2 = (np.concatenate(x) for x in zip(*pairs))
    # contacts only where a fingertip clears the support (a pinch on a flat object whose
    # other fingers take contacts low on its rim goes through the desk), plus the rays' hits
    surface = surface.subset(among).plus(p2, n2, grid.curvature[grid.tree.query(p2)[1]])
    others = [f for f in range(len(ws)) if f != thumb]
    frames, pair, finger = pinch_frames(ws[thumb], [ws[f] for f in others],
                                        (spec.fingers[thumb].tip_radius, [spec.fingers[f].tip_radius for f in others]),
                                        p1, n1, p2, n2, rng)
    n = len(context.frames)
    hints = {n + k: ContactHint(others[f], p1[j], n1[j], p2[j], n2[j]) for k, (j, f) in enumerate(zip(pair, finger))}
    return context._replace(surface=surface, frames=np.concatenate([context.frames, frames]), hints=hints)


def _tips_clear(problem: Problem, surface: Surface, r_tip: float, points: np.ndarray | None = None,
                normals: np.ndarray | None = None) -> np.ndarray:
    """Indices of the contacts (the surface samples, or ``points`` and ``normals`` (k, 3)
    in O) where a fingertip of radius ``r_tip`` touching the object clears the obstacles
    (up to the contact tolerance it may touch them with) at the task's start or goal pose:
    the pinches a hand can use there (:class:`_Usable`)."""
    import coal

    p = surface.points if points is None else points
    n = surface.normals if normals is None else normals
    env = static_geometry(problem.spec.obstacles)
    tip = single_shape(coal.Sphere(r_tip - problem.spec.planning.contact_tolerance))
    task = problem.spec.task
    clear = np.zeros(len(p), dtype=bool)
    X = np.eye(4)
    for X_WO in (task.X_WO_start, task.X_WO_goal):
        c_W = (p + r_tip * n) @ X_WO[:3, :3].T + X_WO[:3, 3]
        for k in np.flatnonzero(~clear):
            X[:3, 3] = c_W[k]
            clear[k] = not hand_hits_static(tip, X, env)
    return np.flatnonzero(clear)


# ------------------------------------------------------------------ per-process work


class _Search(NamedTuple):
    """Everything a worker needs, built once in the parent and inherited by forked workers."""

    problem: Problem
    surface: Surface
    workspaces: tuple[FingerWorkspace, ...] | Jaw | PadHand  # per finger; a jaw's or pad hand's geometry instead
    hand_model: HandModel
    rho: float  # m: torque scale (half the object's bounding-box diagonal)
    frames: np.ndarray  # (n, 4, 4) candidate grasp frames X_OG
    options: BuildOptions
    hints: dict | None = None  # frame index -> ContactHint (pinch frames)


def _context(scene: Path, cache_dir: Path, hand: str, options: BuildOptions) -> _Search:
    problem = load_problem(scene, cache_dir)
    robot = problem.robot
    if hand not in robot.hands:
        raise InputError(robot.spec.file, "hands", f"the robot has no {hand} hand (it has: {', '.join(robot.hands)})")
    tip_radius = min(f.tip_radius for f in robot.hands[hand].spec.fingers)
    rng = np.random.default_rng(options.seed)
    surface = build_surface(problem.object.mesh, sampling_step(tip_radius), rng)
    hm = HandModel(robot, hand, problem.object.mesh, problem.disabled.links(), problem.spec.planning.contact_tolerance)
    rho = float(np.linalg.norm(problem.object.extents) / 2)
    if robot.hands[hand].kind == "pads":
        pads = pad_geometry(hm)
        frames = pad_frames(pads, problem.object.mesh, surface, options.grasp.antipodal_samples, rng)
        return _Search(problem, surface, pads, hm, rho, frames, options)
    if robot.hands[hand].kind == "jaw":
        geometry = jaw_geometry(hm)
        pairs = antipodal_pairs(problem.object.mesh, surface, problem.spec.object.friction,
                                (geometry.width_closed, geometry.width_open), options.grasp.antipodal_samples, rng)
        return _Search(problem, surface, geometry, hm, rho, jaw_frames(geometry, pairs[0], pairs[2], rng), options)
    ws = hand_workspace(robot, hand, options.workspace, cache_dir)
    hm.voxels(ws)  # built here, so that forked workers inherit them
    frames = grasp_frames(problem.object.mesh.bounds, options.grasp.n_positions, options.grasp.n_orientations)
    return _Search(problem, surface, ws, hm, rho, frames, options)


def _run_chunk(context: _Search, indices: np.ndarray):
    problem, surface, ws, hm, rho, frames, options, hints = context
    friction = problem.spec.object.friction
    grasps, stats = [], {}
    for i in indices:
        if isinstance(ws, Jaw):
            g, st = jaw_grasp(hm, ws, surface, frames[i], int(i), friction, rho, options.grasp)
        elif isinstance(ws, PadHand):
            g, st = pad_grasp(hm, ws, surface, frames[i], int(i), friction, rho, options.grasp)
        else:
            g, st = grasp_for_frame(hm, ws, surface, frames[i], int(i), friction, rho, options.grasp,
                                    None if hints is None else hints.get(int(i)))
        for k, v in st.items():
            stats[k] = stats.get(k, 0) + v
        if g is not None:
            grasps.append(g)
    return grasps, stats


# ------------------------------------------------------------------ build


def _frame_order(n_positions_grid: int, n_orientations: int) -> np.ndarray:
    """Frame indices (position-major in :func:`grasp_frames`) in orientation-major order."""
    n_pos = n_positions_grid
    return (np.arange(n_orientations)[:, None] + np.arange(n_pos)[None, :] * n_orientations).ravel()


def remove_duplicates(grasps: list[Grasp], distance: float, angle: float) -> list[Grasp]:
    """Best first; a grasp is dropped when a better kept one has its hand within
    ``distance`` (m) and ``angle`` (rad).

    The kept hands' positions are compared in one array operation, with a margin far above
    its rounding; only those it finds near get the exact pairwise test, so the result is
    the pairwise loop's (the search calls this after every chunk, on every grasp so far)."""
    ordered = sorted(grasps, key=lambda g: (-g.scores.total, g.frame_index))
    kept: list[Grasp] = []
    p_kept = np.empty((len(ordered), 3))  # positions of the kept hands, in O
    for g in ordered:
        p = g.X_OG[:3, 3]
        near = np.flatnonzero(np.linalg.norm(p_kept[:len(kept)] - p, axis=1) < distance * (1 + 1e-9))
        if not any(np.linalg.norm(p - kept[i].X_OG[:3, 3]) < distance
                   and rotation_angle(g.X_OG[:3, :3].T @ kept[i].X_OG[:3, :3]) < angle for i in near):
            p_kept[len(kept)] = p
            kept.append(g)
    return kept


def build_grasps(scene: Path, cache_dir: Path, hand: str, options: BuildOptions,
                 progress=None) -> tuple[GraspList, BuildReport]:
    """Compute and store the grasp list of ``hand`` (not stored when empty);
    ``progress(done, total, kept)`` is called after each wave of frames."""
    scene, cache_dir = Path(scene).resolve(), Path(cache_dir).resolve()
    cache_dir.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    context = _context(scene, cache_dir, hand, options)
    problem, frames = context.problem, context.frames
    t_prep = time.perf_counter() - t0

    n = len(frames)
    t1 = time.perf_counter()
    results, kept, done = [], [], 0
    usable = _Usable(problem, hand)
    # Frames go in fixed chunks, orientation-major (every position for the first
    # orientations of the incremental SO(3) grid, then the next ones), and the results are
    # consumed in order: stopping at the target after a chunk boundary leaves a well-spread
    # set and the result does not depend on the number of jobs.  The workers are forked
    # once, after the context above is built, so they inherit it instead of rebuilding it
    # (about 1 s each); chunks still in flight when the target is reached are dropped.
    jaw = isinstance(context.workspaces, (Jaw, PadHand))  # their frames come in random order already
    order = np.arange(n) if jaw else _frame_order(n // options.grasp.n_orientations, options.grasp.n_orientations)

    def search(context: _Search, order: np.ndarray, total: int) -> bool:
        """Run the frames of ``order``; True once the target is reached."""
        nonlocal kept, done
        chunks = [order[i:i + CHUNK] for i in range(0, len(order), CHUNK)]
        outputs = ordered_map(_run_chunk, chunks, options.jobs, context)
        try:
            for chunk, out in zip(chunks, outputs):
                results.append(out)
                done += len(chunk)
                kept = [g for g in remove_duplicates([g for gs, _ in results for g in gs],
                                                     options.grasp.duplicate_distance, options.grasp.duplicate_angle)
                        if usable(g)]
                if progress:
                    progress(done, total, len(kept))
                if options.grasp.target and len(kept) >= options.grasp.target:
                    return True
            return False
        finally:
            outputs.close()  # stops the workers still busy with chunks we do not need

    done_grid = None
    if not search(context, order, n) and not jaw and options.grasp.pinch_frames:
        done_grid = done
        pinch = _pinch_search(context)  # the grid left the list short: pinch frames (.pinch)
        search(pinch, np.arange(n, len(pinch.frames)), len(pinch.frames))
    t_frames = time.perf_counter() - t1

    t2 = time.perf_counter()
    grasps = [g for gs, _ in results for g in gs]
    stats: dict[str, int] = {}
    for _, st in results:
        for k, v in st.items():
            stats[k] = stats.get(k, 0) + v
    glist = _to_list(problem, hand, kept)
    path = artefact_path(cache_dir, problem, hand, options)
    if kept:  # an empty list is never written: the caller says why (artefacts.build_grasp_list)
        write_grasp_list(path, provenance(problem, hand, options), glist, options)
    t_write = time.perf_counter() - t2

    tested = len(grasps) + stats.get("not_force_closure", 0)
    report = BuildReport(hand, path, done, stats.get("palm", 0), 0 if done_grid is None else done - done_grid,
                         tested + stats.get("hand_collision", 0),
                         len(grasps), len(kept),
                         {"surface + workspace + frames": t_prep, "grasp search (frames)": t_frames,
                          "duplicates + write": t_write})
    return glist, report


def _to_list(problem: Problem, hand: str, grasps: list[Grasp]) -> GraspList:
    h = problem.robot.hands[hand]
    nf, nj = len(h.spec.fingers), len(h.idx)
    k = len(grasps)
    stack = (lambda xs, shape: np.array(xs, dtype=float).reshape((k, *shape)))
    return GraspList(
        hand, tuple(f.name for f in h.spec.fingers),
        stack([g.X_OG for g in grasps], (4, 4)), stack([g.finger_q for g in grasps], (nj,)),
        np.array([g.in_contact for g in grasps], dtype=bool).reshape(k, nf),
        stack([g.points for g in grasps], (nf, 3)), stack([g.normals for g in grasps], (nf, 3)),
        stack([[getattr(g.scores, s) for s in SCORE_NAMES] for g in grasps], (5,)),
        np.array([g.frame_index for g in grasps], dtype=np.int64))


# ------------------------------------------------------------------ storage


def write_grasp_list(path: Path, prov: Provenance, g: GraspList, options: BuildOptions) -> None:
    write_artefact(path, prov, {
        "hand_in_object": g.X_OG, "finger_q": g.finger_q, "in_contact": g.in_contact,
        "contact_points": g.points, "contact_normals": g.normals, "scores": g.scores,
        "frame_index": g.frame_index,
        "finger_names": np.array(g.finger_names), "score_names": np.array(SCORE_NAMES),
    }, attrs={"hand": g.hand, "options": canonical_json({k: v for k, v in asdict(options).items() if k != "jobs"})})


def stored_options(path: Path) -> BuildOptions:
    """The build options recorded in a grasp list (to check it against a scene)."""
    import json

    import h5py

    try:
        with h5py.File(path, "r") as f:
            d = json.loads(f.attrs["options"])
        g = dict(d["grasp"])
        g["weights"] = QualityWeights(**g["weights"])
        return BuildOptions(grasp=GraspOptions(**g), workspace=WorkspaceOptions(**d["workspace"]), seed=d["seed"])
    except (OSError, KeyError, TypeError, ValueError) as exc:
        raise InputError(path, "options", f"not a grasp list with readable build options ({exc})") from None


def read_grasp_list(path: Path, expected: Provenance | None = None) -> GraspList:
    """Load a grasp list; with ``expected``, refuse it when its inputs changed."""
    from regrasp_cli.store import read_provenance

    a = read_artefact(path, expected or read_provenance(path), rebuild="regrasp grasps build")
    names = tuple(s.decode() if isinstance(s, bytes) else str(s) for s in a["finger_names"])
    return GraspList(str(a.attrs["hand"]), names, a["hand_in_object"], a["finger_q"], a["in_contact"].astype(bool),
                     a["contact_points"], a["contact_normals"], a["scores"], a["frame_index"])


def load_or_build(scene: Path, cache_dir: Path, hand: str, options: BuildOptions) -> GraspList:
    """The cached grasp list if fresh, else a new one (used by the online planner)."""
    from regrasp_cli.store import artefact_lock, is_fresh

    problem = load_problem(scene, cache_dir)
    prov = provenance(problem, hand, options)
    path = artefact_path(cache_dir, problem, hand, options)
    with artefact_lock(path):  # another process building it: wait, then read its list
        if path.is_file() and is_fresh(path, prov):
            return read_grasp_list(path, prov)
        return build_grasps(scene, cache_dir, hand, options)[0]


def scores_of(g: GraspList, i: int) -> GraspScores:
    return GraspScores(*map(float, g.scores[i]))
