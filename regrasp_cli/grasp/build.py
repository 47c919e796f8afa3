"""`regrasp grasps build`: the grasp list of a hand for an object (Saut et al. 2010, §IV-A).

Pipeline (fingertip hands; jaws: :mod:`.jaw`): object surface model (:mod:`.surface`) -> finger workspace spheres
(:mod:`.workspace`, Algorithm 1, cached) -> grasp frames (contacts first: :mod:`.pinch`
frames across antipodal pairs, those whose two hinted fingers clear the object first; then,
when they leave the list short, the grid of :mod:`.frames`: positions in the object's
bounding box x an incremental SO(3) grid) -> the grasp of each frame,
a chunk of frames at a time (:mod:`.fingertips`, which skips what the object's distance
grid shows buried: :func:`.surface.distance_grid`), chunks in parallel over forked
processes -> force-closure filter and quality (:mod:`.quality`) -> near-duplicates removed
-> sorted by quality -> HDF5 artefact.

A grasp list is context independent, as in the paper (§IV-A): it depends on the hand
alone (its robot.yaml section, the joints, frames and collision geometry of its palm and
fingers and the link pairs never checked among them:
:func:`~regrasp_cli.model.handshape.hand_inputs`), the object mesh, the friction
coefficient, the contact tolerance, the build options and the seed (:func:`provenance`),
never on a scene's obstacles or poses, the rest posture or the arms.  Which grasps a
scene lets a hand use is decided online, where §IV-B filters the lists
(:mod:`manip.doublegrasp`).

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
from regrasp_cli.model.handshape import hand_hits_static, hand_inputs, hand_shapes, static_geometry_of
from regrasp_cli.grasp.quality import GraspScores, QualityWeights
from regrasp_cli.grasp.fingertips import Hints, grasps_for_frames, hints_clear
from regrasp_cli.grasp.single import Grasp, GraspOptions, HandModel
from regrasp_cli.grasp.surface import MAX_SAMPLES, DistanceGrid, Surface, build_surface, distance_grid, sampling_step
from regrasp_cli.grasp.workspace import FingerWorkspace, WorkspaceOptions, hand_workspace
from regrasp_cli.model.objects import mesh_sha256
from regrasp_cli.parallel import ordered_map
from regrasp_cli.scene import Problem, load_problem
from regrasp_cli.spatial import rotation_aligning
from regrasp_cli.store import (Provenance, canonical_json, file_label, read_artefact, robot_label, sha256_params,
                               write_artefact)

FORMAT, FORMAT_VERSION = "regrasp.grasps", 1
CHUNK = 256  # frames per work item; the target is checked after each
PINCH_WIDTH = 0.12  # m: widest antipodal pair tried for a pinch frame (the fingertips' reach decides)
PINCH_ROLLS = 8  # turns of the hand about a pinch pair's axis tried (those burying a link dropped)
PINCH_PLACEMENTS = 3  # the pinch pass levels its pairs with the supports of this many stable placements
PINCH_BLOCK = 2048  # pinch frames sorted by hints_clear at a time (a pass has up to tens of thousands)
DISTANCE_MARGIN = 0.02  # m: the object's distance grid reaches this far out of its bounding box ...
DISTANCE_STEP, DISTANCE_SAMPLES = 0.003, 30_000  # ... and reads samples this far apart (m), at most this many
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
    list_index: np.ndarray | None = None  # (k,) index in the stored list (a subset's rows: :meth:`rows`)

    def __len__(self) -> int:
        return len(self.X_OG)

    def stored_index(self, k: int) -> int:
        """The index in the stored list of row ``k``."""
        return int(k if self.list_index is None else self.list_index[k])

    def rows(self, ks: np.ndarray) -> "GraspList":
        """The grasps ``ks`` (indices of this list), in that order."""
        ks = np.asarray(ks, dtype=int)
        index = ks if self.list_index is None else self.list_index[ks]
        return GraspList(self.hand, self.finger_names, self.X_OG[ks], self.finger_q[ks], self.in_contact[ks],
                         self.points[ks], self.normals[ks], self.scores[ks], self.frame_index[ks], index)


@dataclass(frozen=True)
class BuildReport:
    hand: str
    path: Path
    frames: int
    frames_blocked: int  # the palm in the object, or a pinch frame's pinching fingers (.fingertips)
    pinch_frames: int  # of the frames, those of the pinch pass (.pinch)
    frames_with_contacts: int  # frames that got enough contacts for the stability test
    force_closure: int
    kept: int  # after removing near-duplicates
    seconds: dict[str, float]  # time per stage


# ------------------------------------------------------------------ inputs and paths


def _params(problem: Problem, hand: str, options: BuildOptions) -> dict:
    return {"hand": hand, "friction": problem.spec.object.friction, "seed": options.seed,
            "contact_tolerance": problem.spec.planning.contact_tolerance,
            "grasp": asdict(options.grasp), "workspace": asdict(options.workspace)}


def provenance(problem: Problem, hand: str, options: BuildOptions) -> Provenance:
    """What a list depends on: the hand (:func:`~regrasp_cli.model.handshape.hand_inputs`),
    the object mesh and the build parameters (friction, contact tolerance, options, seed)."""
    return Provenance(FORMAT, FORMAT_VERSION, {
        "hand": sha256_params(hand_inputs(problem.robot, hand, problem.disabled.links())),
        "mesh": mesh_sha256(problem.object), "params": sha256_params(_params(problem, hand, options))})


def artefact_path(cache_dir: Path, problem: Problem, hand: str, options: BuildOptions) -> Path:
    """``grasps/<object>-<robot>-<hand>-<10 hex digits of the hand and the build parameters>.h5``:
    two hands that differ in anything a grasp depends on never share a file, and an edit
    of the robot elsewhere (arms, rest posture, the other hand) keeps the name."""
    name = file_label(problem.object.name.replace("builtin:", "builtin_"))
    inputs = provenance(problem, hand, options).inputs
    key = sha256_params([inputs["hand"], inputs["params"]])[:10]
    return Path(cache_dir) / "grasps" / f"{name}-{robot_label(problem.robot)}-{hand}-{key}.h5"


def _supports(problem: Problem) -> list[tuple[np.ndarray, float]]:
    """The support planes of the object's most stable placements (at most
    :data:`PINCH_PLACEMENTS`), each as its outward normal n (3,) and offset d in O: the
    support is the plane n . x = d, the object on the side n . x <= d.  An object without
    a stable placement (a rounded bar, a ball) gets the two planes across the thinnest axis
    of its oriented bounding box, on which it would settle.  They depend on the object alone."""
    from regrasp_cli.placement.artefact import compute_placements

    v = np.asarray(problem.object.mesh.vertices)
    try:
        normals = [pl.normal_O for pl in compute_placements(problem.object)[:PINCH_PLACEMENTS]]
    except InputError:
        box = problem.object.mesh.bounding_box_oriented
        axis = box.primitive.transform[:3, np.argmin(box.primitive.extents)]
        normals = [axis, -axis]
    return [(n, float(np.max(v @ n))) for n in normals]


class _SupportClear:
    """Which supports of :func:`_supports` a grasp's hand clears (the hand alone at the
    grasp, the object resting on the support; its fingertips may touch the support as they
    touch the object, within the contact tolerance): the grasps a hand can use on any table
    where the object lies so.  It depends on the object and the hand alone, and decides
    when the list is long enough (:attr:`GraspOptions.support_share`).  Memoised per
    grasp frame."""

    def __init__(self, problem: Problem, hand: str, supports: list[tuple[np.ndarray, float]]):
        import coal

        self.robot, self.hand = problem.robot, hand
        self.tolerance = problem.spec.planning.contact_tolerance
        size = 4.0  # m: a slab far wider than any hand, under the support plane
        self.slabs = []
        for n, d in supports:
            X = np.eye(4)
            X[:3, :3] = rotation_aligning(np.array([0.0, 0.0, 1.0]), n)
            X[:3, 3] = (d + size / 2) * n
            self.slabs.append(static_geometry_of([coal.Box(size, size, size)], [X]))
        self.memo: dict[int, np.ndarray] = {}

    def counts(self, grasps: list[Grasp]) -> np.ndarray:
        """Per support, how many of ``grasps`` clear it."""
        new = [g for g in grasps if g.frame_index not in self.memo]
        if new:  # posed in one call: a call's set-up costs as much as a few hands
            shapes = hand_shapes(self.robot, self.hand, np.array([g.finger_q for g in new]), self.tolerance)
            for g, shape in zip(new, shapes):
                self.memo[g.frame_index] = np.array([not hand_hits_static(shape, g.X_OG, slab, touching=True)
                                                     for slab in self.slabs], dtype=bool).reshape(len(self.slabs))
        return np.array([self.memo[g.frame_index] for g in grasps], dtype=int).reshape(-1, len(self.slabs)).sum(axis=0)


def _fine_surface(context: _Search, rng: np.random.Generator) -> Surface:
    """The object's surface sampled twice as finely as the grid's (a 14 mm rim gets one row
    of samples), curvature read from the grid's samples, so that the scores of the grid's
    and the pinch passes' grasps compare: the surface of the pinch passes."""
    grid = context.surface
    r_tip = min(f.tip_radius for f in context.hand_model.hand.spec.fingers)
    fine = build_surface(context.problem.object.mesh, sampling_step(r_tip) / 2, rng, like=grid)
    return replace(fine, curvature=grid.curvature[grid.tree.query(fine.points)[1]])


def _pinch_pass(context: _Search, grid: Surface, fine: Surface, support: tuple[np.ndarray, float] | None,
                rng: np.random.Generator) -> tuple[_Search, np.ndarray]:
    """The search of a pinch pass (:mod:`.pinch`) over the ``fine`` surface: ``context``
    with the pass's frames appended to its frames (so that frame indices stay unique
    across passes), their hints and the pass's surface; and the indices of the new frames.
    For a support (one of the object's most stable placements, :func:`_supports`) only the
    samples where a fingertip clears it are kept and the pairs are levelled with it: the
    pinches across a flat object lying there.  ``None``: pairs anywhere on the surface.
    Which grasps a scene lets a hand use is decided online (:mod:`manip.doublegrasp`)."""
    problem, options = context.problem, context.options
    h = context.hand_model.hand
    spec, thumb, ws = h.spec, h.opposing, context.workspaces
    r_tip = min(f.tip_radius for f in spec.fingers)
    clearance = r_tip - problem.spec.planning.contact_tolerance  # tip centre above the support
    others = [f for f in range(len(ws)) if f != thumb]
    radii = (spec.fingers[thumb].tip_radius, [spec.fingers[f].tip_radius for f in others])
    if support is None:
        among, level = np.arange(len(fine.points)), None
    else:
        n_O, d = support
        among, level = np.flatnonzero((fine.points + r_tip * fine.normals) @ n_O <= d - clearance), -n_O
    p1, n1, p2, n2 = antipodal_pairs(problem.object.mesh, fine, problem.spec.object.friction, (0.0, PINCH_WIDTH),
                                     options.grasp.pinch_frames, rng, among=among, level=level)
    if support is not None:
        keep = (p2 + r_tip * n2) @ n_O <= d - clearance  # the second fingertip clears the support too
        p1, n1, p2, n2 = p1[keep], n1[keep], p2[keep], n2[keep]
    # contacts only where a fingertip clears the support (a pinch on a flat object whose
    # other fingers take contacts low on its rim goes through it), plus the rays' hits
    surface = fine.subset(among).plus(p2, n2, grid.curvature[grid.tree.query(p2)[1]])
    frames, pair, finger, thumb_sample, finger_sample = pinch_frames(
        ws[thumb], [ws[f] for f in others], radii, p1, n1, p2, n2, rng, PINCH_ROLLS)
    n, k = len(context.frames), len(frames)
    nan, none = np.full((n, 3), np.nan), np.full(n, -1)  # the earlier frames are not this pass's
    hints = Hints(np.concatenate([none, np.array(others)[finger] if k else np.zeros(0, int)]),
                  *(np.concatenate([nan, x[pair]]) for x in (p1, n1, p2, n2)),
                  np.concatenate([none, thumb_sample]), np.concatenate([none, finger_sample]))
    return (context._replace(surface=surface, frames=np.concatenate([context.frames, frames]), hints=hints),
            np.arange(n, n + k))


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
    hints: Hints | None = None  # per frame, the contacts to try first (pinch frames)
    distance: DistanceGrid | None = None  # the object's signed distance (fingertip hands' candidate ranking)


def _check_size(problem: Problem, hand: str, step: float) -> None:
    """Refuse an object too large for the hand: one whose surface sampled at the
    fingertip's step (``step``, m) would take more than the surface model's limit of
    samples (:data:`.surface.MAX_SAMPLES`), most likely a mesh in millimetres read as
    metres or a wrong ``object.scale``; the line names the scene, the object and the hand."""
    area = float(problem.object.mesh.area)
    if area / step**2 > MAX_SAMPLES:
        shape = hand_shapes(problem.robot, hand, problem.robot.hands[hand].open)[0]
        lo = (shape.centres - shape.radii[:, None]).min(axis=0)
        hi = (shape.centres + shape.radii[:, None]).max(axis=0)
        extents = ' x '.join(f'{e:.3g}' for e in problem.object.extents)
        raise InputError(problem.spec.file, "object.mesh",
                         f"{problem.object.name} ({extents} m, {area:.3g} m^2 of surface) is far larger than the {hand} "
                         f"hand ({np.linalg.norm(hi - lo):.2g} m across): sampling it at the fingertip's "
                         f"{1000 * step:g} mm would take over {MAX_SAMPLES:,} points; is object.scale, or the "
                         "mesh's unit, wrong?")


def _dense(problem: Problem, surface: Surface, seed: int) -> Surface:
    """The object's surface sampled every :data:`DISTANCE_STEP` (coarser on a large object:
    at most :data:`DISTANCE_SAMPLES` samples), its faces oriented as ``surface``'s: what
    the distance grid reads."""
    step = max(DISTANCE_STEP, float(np.sqrt(problem.object.mesh.area / DISTANCE_SAMPLES)))
    return build_surface(problem.object.mesh, step, np.random.default_rng([seed, 2]), like=surface)


def _context(scene: Path, cache_dir: Path, hand: str, options: BuildOptions) -> _Search:
    problem = load_problem(scene, cache_dir)
    robot = problem.robot
    if hand not in robot.hands:
        raise InputError(robot.spec.file, "hands", f"the robot has no {hand} hand (it has: {', '.join(robot.hands)})")
    tip_radius = min(f.tip_radius for f in robot.hands[hand].spec.fingers)
    _check_size(problem, hand, sampling_step(tip_radius) / 2)  # the pinch passes sample twice as finely
    rng = np.random.default_rng(options.seed)
    surface = build_surface(problem.object.mesh, sampling_step(tip_radius), rng)
    hm = HandModel(robot, hand, problem.object.mesh, problem.disabled.links(), problem.spec.planning.contact_tolerance,
                   options.grasp.link_clearance)
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
    hm.voxels(ws), hm.chains(), hm.probes(), hm.palm_probes()  # built here, so that forked workers inherit them
    frames = grasp_frames(problem.object.mesh.bounds, options.grasp.n_positions, options.grasp.n_orientations)
    distance = distance_grid(_dense(problem, surface, options.seed), DISTANCE_MARGIN)
    return _Search(problem, surface, ws, hm, rho, frames, options, None, distance)


def _run_chunk(context: _Search, indices: np.ndarray):
    problem, surface, ws, hm, rho, frames, options, hints, distance = context
    friction = problem.spec.object.friction
    if not isinstance(ws, (Jaw, PadHand)):  # fingertip hands: the whole chunk at once
        return grasps_for_frames(hm, ws, surface, frames[indices], indices, friction, rho, options.grasp,
                                 None if hints is None else hints.rows(indices), distance)
    grasps, stats = [], {}
    for i in indices:
        if isinstance(ws, Jaw):
            g, st = jaw_grasp(hm, ws, surface, frames[i], int(i), friction, rho, options.grasp)
        elif isinstance(ws, PadHand):
            g, st = pad_grasp(hm, ws, surface, frames[i], int(i), friction, rho, options.grasp)
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

    Each grasp is compared with every kept one in array operations (the search calls this
    after every chunk, on every grasp so far)."""
    ordered = sorted(grasps, key=lambda g: (-g.scores.total, g.frame_index))
    kept: list[Grasp] = []
    X_kept = np.empty((len(ordered), 4, 4))  # the kept hands, in O
    cos_angle = np.cos(angle)
    for g in ordered:
        n = len(kept)
        near = np.flatnonzero(np.linalg.norm(X_kept[:n, :3, 3] - g.X_OG[:3, 3], axis=1) < distance)
        # the angle of R_g^T R_k is below ``angle`` when its trace, sum_ij R_g R_k, is above 1 + 2 cos(angle)
        if not len(near) or not np.any(np.einsum("ij,kij->k", g.X_OG[:3, :3], X_kept[near, :3, :3])
                                       > 1.0 + 2.0 * cos_angle):
            X_kept[n] = g.X_OG
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
    # Frames go in fixed chunks, orientation-major (every position for the first
    # orientations of the incremental SO(3) grid, then the next ones), and the results are
    # consumed in order: stopping at the target after a chunk boundary leaves a well-spread
    # set and the result does not depend on the number of jobs.  The workers are forked
    # once, after the context above is built, so they inherit it instead of rebuilding it
    # (about 1 s each); chunks still in flight when the target is reached are dropped.
    jaw = isinstance(context.workspaces, (Jaw, PadHand))  # their frames come in random order already
    order = np.arange(n) if jaw else _frame_order(n // options.grasp.n_orientations, options.grasp.n_orientations)

    supports = _supports(problem)
    clear = _SupportClear(problem, hand, supports)
    g_opts = options.grasp
    per_support = int(np.ceil(g_opts.support_share * g_opts.target))

    def enough(kept: list[Grasp]) -> bool:
        """The target reached: enough distinct grasps, and enough clear of each support."""
        return bool(g_opts.target) and len(kept) >= g_opts.target and bool(np.all(clear.counts(kept) >= per_support))

    def long_enough(kept: list[Grasp]) -> bool:
        return bool(g_opts.target) and len(kept) >= g_opts.target

    def search(context: _Search, order: np.ndarray, stop) -> bool:
        """Run the frames of ``order`` until ``stop(kept)``; True once the target is reached."""
        nonlocal kept, done
        chunks = [order[i:i + CHUNK] for i in range(0, len(order), CHUNK)]
        total = done + len(order)
        outputs = ordered_map(_run_chunk, chunks, options.jobs, context)
        try:
            for chunk, out in zip(chunks, outputs):
                results.append(out)
                done += len(chunk)
                kept = remove_duplicates([g for gs, _ in results for g in gs], g_opts.duplicate_distance,
                                         g_opts.duplicate_angle)
                if progress:
                    progress(done, total, len(kept))
                if stop(kept):
                    break
        finally:
            outputs.close()  # stops the workers still busy with chunks we do not need
        return enough(kept)

    def clear_first(pinch: _Search, indices: np.ndarray, stop) -> np.ndarray:
        """Search the frames ``indices`` of a pinch pass a block at a time, those whose
        hinted fingers clear the object first (the test costs as much per frame as a
        search of the frames that pass it, hence blocks); return the others."""
        rest = []
        for s in range(0, len(indices), PINCH_BLOCK):
            block = indices[s:s + PINCH_BLOCK]
            if stop(kept):
                rest.append(block)
                continue
            ok = hints_clear(pinch.hand_model, pinch.workspaces, pinch.frames[block], pinch.hints.rows(block),
                             pinch.distance)
            rest.append(block[~ok])
            search(pinch, block[ok], stop)
        return np.concatenate(rest) if rest else indices

    pinch_done = 0
    if jaw or not g_opts.pinch_frames:  # their frames are few and in random order: every support counts
        search(context, order, enough)
    else:
        # contacts first: pinch frames on each support of the object's stable placements
        # until enough grasps clear it, then anywhere on it; the grid of §IV-A-1 last
        # (a support no pinch suits, such as a box's widest face for a small hand, leaves
        # its pass short: only the number of grasps then asks for more frames).  A pass's
        # frames whose hinted fingers bury a link in the object (:func:`.fingertips.hints_clear`)
        # go after every pass's other frames: their hints fail, and they seldom give a grasp.
        stops = [lambda kept, i=i: clear.counts(kept)[i] >= per_support and long_enough(kept)
                 for i in range(len(supports))] + [long_enough]
        rng = np.random.default_rng([options.seed, 1])
        fine = _fine_surface(context, rng)
        pinch, later = context, []
        for support, stop in zip([*supports, None], stops):
            if stop(kept):  # a pass is built (its rays cast) only when its turn comes
                continue
            pinch, indices = _pinch_pass(pinch, context.surface, fine, support, rng)
            before = done
            later.append((pinch, clear_first(pinch, indices, stop), stop))
            pinch_done += done - before
        for pass_context, rest, stop in later:
            if not stop(kept):
                before = done
                search(pass_context, rest, stop)
                pinch_done += done - before
        if not long_enough(kept):
            search(context, order, long_enough)
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
    report = BuildReport(hand, path, done, stats.get("palm", 0) + stats.get("buried", 0), pinch_done,
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
