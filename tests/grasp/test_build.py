"""Stored grasp lists of `grasps build` (Saut et al. 2010, §IV-A) on the default scene
(configs/scenes/desk_handover.yaml, right hand, small grids): every stored grasp has its
contacts on the object surface, its fingertips at the contacts by FK, no hand-object
collision other than the fingertips, force closure; the list is sorted by quality and has
no near-duplicates; building is deterministic (again, with jobs=2 instead of 1); a list is
refused when the friction or the object changed."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import trimesh
import yaml
from scipy.spatial.transform import Rotation

from cli_helpers import copy_artefacts

from regrasp_cli.errors import InputError, StaleArtefactError
from regrasp_cli.grasp.build import (
    SCORE_NAMES,
    BuildOptions,
    artefact_path,
    build_grasps,
    provenance,
    read_grasp_list,
    remove_duplicates,
)
from regrasp_cli.grasp.quality import combine_scores, force_closure, primitive_wrenches
from regrasp_cli.grasp.single import Grasp, GraspOptions, HandModel
from regrasp_cli.grasp.surface import build_surface, sampling_step
from regrasp_cli.model.collision import ObjectPlacement, collision_world
from regrasp_cli.model.robot import Kinematics
from regrasp_cli.scene import load_problem
from regrasp_cli.spatial import inverse, rotation_angle
from regrasp_cli.store import read_artefact, read_provenance

ROOT = Path(__file__).resolve().parents[2]
ROBOT_YAML = ROOT / "configs" / "robots" / "humanoid43" / "robot.yaml"
SCENE_YAML = ROOT / "configs" / "scenes" / "desk_handover.yaml"
HAND = "right"
# small grids: 2048 grid frames and 256 samples of the pinch pass (every frame, no target)
OPTIONS = BuildOptions(grasp=replace(GraspOptions(), n_positions=8, n_orientations=256, target=0, pinch_frames=256),
                       jobs=1)


@pytest.fixture(scope="module")
def built(problem, cache_dir):
    """One build of the right hand's list in the run's cache: (GraspList, BuildReport)."""
    return build_grasps(SCENE_YAML, cache_dir, HAND, OPTIONS)


@pytest.fixture(scope="module")
def glist(built):
    g = built[0]
    assert len(g) >= 5, "the small grid should still give a handful of grasps"
    return g


@pytest.fixture(scope="module")
def surface(problem):
    h = problem.robot.hands[HAND]
    step = sampling_step(min(f.tip_radius for f in h.spec.fingers))
    return build_surface(problem.object.mesh, step, np.random.default_rng(OPTIONS.seed))


def _q(problem, finger_q):
    """The robot at rest with the hand's finger joints at ``finger_q``."""
    q = problem.robot.q_rest.copy()
    q[problem.robot.hands[HAND].idx] = finger_q
    return q


def _fresh_cache(tmp_path: Path, cache_dir: Path) -> Path:
    """An empty cache dir but for the robot's self-collision pairs (not what is tested,
    and 2 s to recompute)."""
    d = tmp_path / "cache"
    copy_artefacts(cache_dir / "self_collision", d / "self_collision")
    return d


def _datasets(path: Path) -> dict[str, np.ndarray]:
    return read_artefact(path, read_provenance(path)).data


def _assert_same_artefact(a: Path, b: Path) -> None:
    da, db = _datasets(a), _datasets(b)
    assert sorted(da) == sorted(db)
    for name in da:
        assert da[name].dtype == db[name].dtype and da[name].shape == db[name].shape, name
        if da[name].dtype.kind in "biufc":  # byte-identical (NaN marks fingers without contact)
            assert da[name].tobytes() == db[name].tobytes(), name
        assert np.array_equal(da[name], db[name], equal_nan=da[name].dtype.kind == "f"), name
    assert read_provenance(a).inputs == read_provenance(b).inputs


# --------------------------------------------------------------------------- the file


def test_report_and_stored_file(problem, cache_dir, built, glist):
    _, report = built
    h = problem.robot.hands[HAND]
    assert report.path == artefact_path(cache_dir, problem, HAND, OPTIONS)
    assert report.path.parent == Path(cache_dir).resolve() / "grasps" and report.path.suffix == ".h5"
    assert report.kept == len(glist) <= report.force_closure <= report.frames_with_contacts <= report.frames
    k, nf, nj = len(glist), len(h.spec.fingers), len(h.idx)
    assert glist.hand == HAND and glist.finger_names == ("thumb", "index", "middle", "ring")
    assert glist.X_OG.shape == (k, 4, 4) and glist.finger_q.shape == (k, nj)
    assert glist.in_contact.shape == (k, nf) and glist.in_contact.dtype == bool
    assert glist.points.shape == glist.normals.shape == (k, nf, 3)
    assert glist.scores.shape == (k, len(SCORE_NAMES)) and glist.frame_index.shape == (k,)
    assert len(set(glist.frame_index.tolist())) == k  # one grasp per frame at most
    stored = read_grasp_list(report.path, provenance(problem, HAND, OPTIONS))
    for name in ("X_OG", "finger_q", "in_contact", "points", "normals", "scores", "frame_index"):
        assert np.array_equal(getattr(stored, name), getattr(glist, name), equal_nan=name in ("points", "normals"))
    assert stored.finger_names == glist.finger_names and stored.hand == HAND


def test_poses_are_rigid_transforms(glist):
    R = glist.X_OG[:, :3, :3]
    np.testing.assert_allclose(R @ R.transpose(0, 2, 1), np.broadcast_to(np.eye(3), R.shape), atol=1e-9)
    np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=1e-9)
    np.testing.assert_array_equal(glist.X_OG[:, 3], np.broadcast_to([0.0, 0.0, 0.0, 1.0], (len(glist), 4)))


def test_thumb_and_at_least_three_contacts(glist):
    """Point contacts: three or more; the thumb always (no stable grasp without it)."""
    assert np.all(glist.in_contact[:, 0])
    assert np.all(glist.in_contact.sum(axis=1) >= 3)


def test_fingers_without_contact_stay_open(problem, glist):
    h = problem.robot.hands[HAND]
    starts = np.cumsum([0] + [len(i) for i in h.finger_idx])
    for g in range(len(glist)):
        for f in range(len(h.finger_idx)):
            if not glist.in_contact[g, f]:
                assert np.all(np.isnan(glist.points[g, f])) and np.all(np.isnan(glist.normals[g, f]))
                np.testing.assert_array_equal(glist.finger_q[g, starts[f]:starts[f + 1]], h.open[starts[f]:starts[f + 1]])
    lo, hi = problem.robot.lower[h.idx], problem.robot.upper[h.idx]
    assert np.all(glist.finger_q >= lo - 1e-12) and np.all(glist.finger_q <= hi + 1e-12)


def test_contacts_lie_on_the_object_surface_with_outward_normals(problem, glist):
    mesh = problem.object.mesh
    c = glist.in_contact
    P, N = glist.points[c], glist.normals[c]
    assert np.all(np.isfinite(P)) and np.all(np.isfinite(N))
    closest, dist, tri = trimesh.proximity.closest_point(mesh, P)
    assert dist.max() < 1.5e-3, dist.max()
    np.testing.assert_allclose(np.linalg.norm(N, axis=1), 1.0, atol=1e-9)
    # the stored normal points to the same side as the mesh face under the contact
    # (the statuette is watertight, so its face normals point outward)
    assert problem.object.watertight
    assert np.all(np.einsum("ij,ij->i", N, mesh.face_normals[tri]) > 0.0)


def test_fingertips_are_at_the_contacts_by_fk(problem, glist):
    """FK of the stored finger joints puts each contacting fingertip-sphere centre at
    p + r_tip n (object frame), within 1 mm."""
    robot = problem.robot
    h = robot.hands[HAND]
    worst = 0.0
    for g in range(len(glist)):
        q = _q(problem, glist.finger_q[g])
        X_WG = Kinematics(robot).fk(q, h.grasp_frame)
        X_OW = inverse(X_WG @ inverse(glist.X_OG[g]))
        tips = Kinematics(robot).fk_many(q, h.tip_frames)
        for f, spec in enumerate(h.spec.fingers):
            if not glist.in_contact[g, f]:
                continue
            tip_O = X_OW[:3, :3] @ tips[f][:3, 3] + X_OW[:3, 3]
            target = glist.points[g, f] + spec.tip_radius * glist.normals[g, f]
            worst = max(worst, float(np.linalg.norm(tip_O - target)))
    assert worst < 1e-3, worst


def test_no_hand_object_collision_but_at_the_fingertips(problem, glist):
    """The object attached to the hand at X_OG: no link of the hand (palm, phalanges)
    collides with it, except possibly the fingertips (they touch it).  The rest of the
    robot and the environment are the online stage's business, so the world has no
    obstacles and only pairs with the object are looked at."""
    robot = problem.robot
    h = robot.hands[HAND]
    model = robot.model
    hand_joints = {model.getJointId(robot.joint_names[i]) for i in h.idx} | {model.frames[h.grasp_frame].parentJoint}
    hand_links = {robot.link_of_geometry(g) for g, go in enumerate(robot.collision_model.geometryObjects)
                  if go.parentJoint in hand_joints}
    tip_links = {model.frames[t].name for t in h.tip_frames}
    assert tip_links < hand_links and len(hand_links - tip_links) >= 8  # palm + 2 phalanges per finger

    def hand_hits(X_GO, q):
        world = collision_world(robot, (), problem.disabled.links(),
                                ObjectPlacement(problem.object.mesh, X_GO, attached_to=HAND), problem.collision_options)
        return {b if a == "object" else a for a, b in world.colliding_pairs(q) if "object" in (a, b)} & hand_links

    # control: the object's box centre at the grasp frame puts the palm inside it
    X_GO = np.eye(4)
    X_GO[:3, 3] = -problem.object.mesh.bounds.mean(axis=0)
    assert "r_palm" in hand_hits(X_GO, _q(problem, h.open))
    bad = []
    for g in range(len(glist)):
        world = collision_world(robot, (), problem.disabled.links(),
                                ObjectPlacement(problem.object.mesh, inverse(glist.X_OG[g]), attached_to=HAND),
                                problem.collision_options)
        for a, b in world.colliding_pairs(_q(problem, glist.finger_q[g])):
            if "object" in (a, b):
                other = b if a == "object" else a
                if other in hand_links and other not in tip_links:
                    bad.append((g, other))
    assert not bad, f"hand links in the object (grasp, link): {bad}"



def test_closed_hand_does_not_collide_with_itself(problem, glist):
    """The fingertips may sink into the object, never into another finger or the palm: at
    every stored grasp's finger values the robot's own collision world (the planner's and
    the validator's, no tolerance between links) finds no pair colliding."""
    world = collision_world(problem.robot, (), problem.disabled.links(), None, problem.collision_options)
    hits = [(g, pairs) for g in range(len(glist)) if (pairs := world.colliding_pairs(_q(problem, glist.finger_q[g])))]
    assert not hits, f"grasps whose hand collides with itself: {hits}"


def test_hand_model_self_collision_is_the_robot_worlds(problem):
    """The grasp search's hand model judges finger-finger and finger-palm contact as the
    robot's collision world does (its fingertips are eroded only against the object): the
    same verdict on 300 random finger postures, the object far away, some of them
    colliding (abductions towards each other, tips folded together)."""
    robot = problem.robot
    h = robot.hands[HAND]
    hm = HandModel(robot, HAND, problem.object.mesh, problem.disabled.links(), problem.spec.planning.contact_tolerance)
    far = np.eye(4)
    far[:3, 3] = 10.0
    hm.set_object(far)
    world = collision_world(robot, (), problem.disabled.links(), None, problem.collision_options)
    rng = np.random.default_rng(7)
    verdicts = []
    for _ in range(300):
        q = _q(problem, rng.uniform(robot.lower[h.idx], robot.upper[h.idx]))
        verdicts.append((hm.collides(q, set(range(len(h.finger_idx))), None), not world.is_free(q)))
    verdicts = np.array(verdicts)
    assert 10 <= verdicts[:, 1].sum() <= 290, "the sample should hold both colliding and free postures"
    assert np.array_equal(verdicts[:, 0], verdicts[:, 1])


def test_every_grasp_is_force_closure(problem, glist, surface):
    """Force closure recomputed from the stored contacts, the scene friction, the surface
    mass centre and the torque scale of build.py; epsilon as stored."""
    h = problem.robot.hands[HAND]
    mu = problem.spec.object.friction
    rho = float(np.linalg.norm(problem.object.extents) / 2)
    for g in range(len(glist)):
        c = glist.in_contact[g]
        W = primitive_wrenches(glist.points[g][c], glist.normals[g][c], mu, surface.mass_centre, rho,
                               contact=h.spec.contact, n_edges=OPTIONS.grasp.cone_edges)
        is_fc, eps = force_closure(W)
        assert is_fc, g
        assert eps > 0.0
        np.testing.assert_allclose(eps, glist.scores[g, 0], rtol=1e-9, atol=1e-12)


def test_scores_sorted_and_consistent(problem, glist, surface):
    scores = glist.scores
    assert np.all(np.isfinite(scores))
    total = scores[:, SCORE_NAMES.index("total")]
    assert np.all(np.diff(total) <= 0.0), total
    assert np.all((scores[:, 1:] >= 0.0) & (scores[:, 1:] <= 1.0)) and np.all(scores[:, 0] > 0.0)
    rho = float(np.linalg.norm(problem.object.extents) / 2)
    for g in range(len(glist)):
        c = glist.in_contact[g]
        P = glist.points[g][c]
        eps, centroid, ellipsoid, curvature, tot = scores[g]
        assert tot == pytest.approx(combine_scores([min(eps, 1.0), centroid, ellipsoid, curvature],
                                                   OPTIONS.grasp.weights), abs=1e-12)
        assert centroid == pytest.approx(1.0 - min(1.0, np.linalg.norm(P.mean(axis=0) - surface.mass_centre) / rho),
                                         abs=1e-12)
        kappa = surface.curvature[surface.tree.query(P)[1]]
        assert curvature == pytest.approx(float(np.mean(1.0 - kappa)), abs=1e-12)


def test_no_near_duplicates(glist):
    d, a = OPTIONS.grasp.duplicate_distance, OPTIONS.grasp.duplicate_angle
    X = glist.X_OG
    for i in range(len(glist)):
        for j in range(i + 1, len(glist)):
            near = np.linalg.norm(X[i, :3, 3] - X[j, :3, 3]) < d
            assert not (near and rotation_angle(X[i, :3, :3].T @ X[j, :3, :3]) < a), (i, j)


# --------------------------------------------------------------------------- determinism


def test_building_again_with_two_jobs_gives_identical_arrays(cache_dir, built, tmp_path):
    """A second build on a fresh cache, with two worker processes instead of one: the same
    file name (jobs is not an input of the list) and the same bytes, so building is both
    repeatable and independent of the number of jobs."""
    fresh = _fresh_cache(tmp_path, cache_dir)
    glist2, report = build_grasps(SCENE_YAML, fresh, HAND, replace(OPTIONS, jobs=2))
    assert report.path.name == built[1].path.name
    _assert_same_artefact(built[1].path, report.path)
    for name in ("X_OG", "finger_q", "in_contact", "points", "normals", "scores", "frame_index"):
        assert np.array_equal(getattr(glist2, name), getattr(built[0], name), equal_nan=True), name
    # the finger workspaces too (the shared cache may hold other hands' beside this one)
    (b,) = sorted((fresh / "workspace").glob("*.h5"))
    _assert_same_artefact(Path(cache_dir) / "workspace" / b.name, b)


# --------------------------------------------------------------------------- staleness


def _scene_copy(tmp_path: Path, **object_fields) -> Path:
    d = yaml.safe_load(SCENE_YAML.read_text())
    d["robot"] = str(ROBOT_YAML)
    d["object"].update(object_fields)
    path = tmp_path / "scene.yaml"
    path.write_text(yaml.safe_dump(d, sort_keys=False))
    return path


def test_same_inputs_are_fresh(problem, built, tmp_path, cache_dir):
    """A copy of the scene (same robot, object, friction, seed) accepts the list."""
    other = load_problem(_scene_copy(tmp_path), cache_dir)
    g = read_grasp_list(built[1].path, provenance(other, HAND, OPTIONS))
    assert len(g) == len(built[0])


def test_other_friction_is_refused(built, tmp_path, cache_dir):
    other = load_problem(_scene_copy(tmp_path, friction=0.3), cache_dir)
    with pytest.raises(StaleArtefactError) as err:
        read_grasp_list(built[1].path, provenance(other, HAND, OPTIONS))
    assert isinstance(err.value, InputError)
    assert err.value.field == "input_sha256.params"
    assert "params" in str(err.value) and "mesh" not in str(err.value)
    assert str(built[1].path) in str(err.value)


def test_other_object_is_refused(built, tmp_path, cache_dir):
    other = load_problem(_scene_copy(tmp_path, mesh="builtin:mug"), cache_dir)
    with pytest.raises(StaleArtefactError) as err:
        read_grasp_list(built[1].path, provenance(other, HAND, OPTIONS))
    assert err.value.field == "input_sha256.mesh"
    assert "mesh" in str(err.value) and "params" not in str(err.value)


def test_other_options_are_refused(problem, built):
    other = replace(OPTIONS, grasp=replace(OPTIONS.grasp, n_orientations=64))
    with pytest.raises(StaleArtefactError, match="params"):
        read_grasp_list(built[1].path, provenance(problem, HAND, other))


def test_partners_share_the_object_without_the_hands_colliding(problem, glist):
    """manip.doublegrasp.partners: the other hand's grasps that can hold the object
    together with a given one; a grasp never partners with itself (two hands in one place)."""
    from types import SimpleNamespace

    from regrasp_cli.manip.doublegrasp import partners
    from regrasp_cli.model.handshape import hand_shapes, hands_collide

    shapes = hand_shapes(problem.robot, HAND, glist.finger_q)
    for k in range(min(3, len(glist))):
        found = set(partners([SimpleNamespace(grasp=k)], glist, shapes, glist, shapes).tolist())
        assert k not in found
        for j in range(len(glist)):
            assert (j in found) == (not hands_collide(shapes[k], glist.X_OG[k], shapes[j], glist.X_OG[j]))


# --------------------------------------------------------------------------- near-duplicates


def _grasp(i: int, total: float, p, yaw: float = 0.0) -> Grasp:
    X = np.eye(4)
    X[:3, :3] = Rotation.from_euler("z", yaw).as_matrix()
    X[:3, 3] = p
    scores = SimpleNamespace(total=total)
    return Grasp(i, X, np.zeros(1), np.zeros(1, bool), np.zeros((1, 3)), np.zeros((1, 3)), scores)


def test_near_duplicates_known_on_paper():
    """Best first: b (5 mm, 0.1 rad from a) goes; c (5 mm, 0.3 rad) and d (2 cm) stay; e ties
    a's score at a's pose and goes (the lower frame index wins)."""
    a, b = _grasp(0, 1.0, [0, 0, 0]), _grasp(1, 0.9, [0.005, 0, 0], 0.1)
    c, d, e = _grasp(2, 0.8, [0, 0.005, 0], 0.3), _grasp(3, 0.7, [0.02, 0, 0]), _grasp(4, 1.0, [0, 0, 0])
    kept = remove_duplicates([d, c, b, e, a], 0.01, 0.2)
    assert [g.frame_index for g in kept] == [0, 2, 3]


def test_near_duplicates_are_the_pairwise_loops():
    """Random hands packed in 3 cm: the same grasps, in the same order, as the plain
    pairwise loop over the kept ones."""
    rng = np.random.default_rng(5)
    grasps = [_grasp(i, float(rng.integers(0, 20)), rng.uniform(-0.015, 0.015, 3), rng.uniform(-0.6, 0.6))
              for i in range(300)]
    ordered = sorted(grasps, key=lambda g: (-g.scores.total, g.frame_index))
    plain: list = []
    for g in ordered:
        if not any(np.linalg.norm(g.X_OG[:3, 3] - k.X_OG[:3, 3]) < 0.01
                   and rotation_angle(g.X_OG[:3, :3].T @ k.X_OG[:3, :3]) < 0.2 for k in plain):
            plain.append(g)
    kept = remove_duplicates(grasps, 0.01, 0.2)
    assert 20 < len(kept) < 250 and [g.frame_index for g in kept] == [g.frame_index for g in plain]
