"""The fingertip search (grasp.fingertips) on paper-known objects, a 6 cm cube and a
sphere held by the default robot's right hand: every grasp it returns is force closure,
its contacts lie on the object's surface with their outward normals, its fingertip
centres (pinocchio's FK on the whole robot) sit at ``p + r n`` within the IK tolerance, and
the closed hand clears the object but with its fingertips; a frame's grasp does not depend
on the other frames of its batch; the batched finger IK reaches or says it failed."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from regrasp_cli.grasp.fingertips import batch_ik, grasp_for_frame, grasps_for_frames
from regrasp_cli.grasp.frames import grasp_frames
from regrasp_cli.grasp.single import GraspOptions, HandModel
from regrasp_cli.grasp.surface import build_surface, distance_grid, sampling_step
from regrasp_cli.grasp.workspace import WorkspaceOptions, hand_workspace
from regrasp_cli.model.robot import Kinematics
from regrasp_cli.spatial import inverse

HAND = "right"
MESHES = {"cube": trimesh.creation.box((0.06, 0.06, 0.06)), "sphere": trimesh.creation.icosphere(3, 0.035)}


@pytest.fixture(scope="module", params=[(m, d) for m in sorted(MESHES) for d in ("", "distance")],
                ids=lambda p: "-".join(filter(None, p)))
def searched(request, problem, cache_dir):
    """(hand model, workspaces, surface, frames, rho, grasps, counters, mesh) for one mesh,
    with or without the object's distance grid (which orders and skips candidates)."""
    mesh = MESHES[request.param[0]]
    robot = problem.robot
    hm = HandModel(robot, HAND, mesh, problem.disabled.links(), 0.002)
    ws = hand_workspace(robot, HAND, WorkspaceOptions(), cache_dir)
    surface = build_surface(mesh, sampling_step(0.010), np.random.default_rng(0))
    frames = grasp_frames(mesh.bounds, 2, 128)
    rho = float(np.linalg.norm(mesh.extents) / 2)
    distance = distance_grid(build_surface(mesh, 0.003, np.random.default_rng(1)), 0.02) if request.param[1] else None
    grasps, stats = grasps_for_frames(hm, ws, surface, frames, np.arange(len(frames)), 0.5, rho, GraspOptions(),
                                      distance=distance)
    return hm, ws, surface, frames, rho, grasps, stats, mesh, distance


def test_grasps_are_force_closure_with_fingertips_on_their_contacts(searched):
    hm, _, surface, frames, _, grasps, stats, mesh, _ = searched
    assert len(grasps) >= 3, stats
    assert stats["buried"] + stats["palm"] + stats["few_contacts"] + stats["hand_collision"] \
        + stats["not_force_closure"] + len(grasps) == len(frames)
    robot, h = hm.robot, hm.hand
    kin = Kinematics(robot)
    for g in grasps:
        assert g.scores.is_force_closure and g.scores.epsilon > 0
        assert g.in_contact.sum() >= 3 and g.in_contact[h.opposing]
        np.testing.assert_array_equal(g.X_OG, frames[g.frame_index])
        q = hm.q.copy()
        q[h.idx] = g.finger_q
        assert robot.within_limits(q)
        X_OW = g.X_OG @ inverse(kin.fk(q, h.grasp_frame))  # the world in O for this hand pose
        for f in np.flatnonzero(g.in_contact):
            p, n = g.points[f], g.normals[f]
            _, dist, tri = trimesh.proximity.closest_point(mesh, p[None])
            assert dist[0] < 1e-6 and mesh.face_normals[tri[0]] @ n > 0.99
            tip_O = X_OW[:3, :3] @ kin.fk(q, h.tip_frames[f])[:3, 3] + X_OW[:3, 3]
            r = h.spec.fingers[f].tip_radius
            assert np.linalg.norm(tip_O - (p + r * n)) <= GraspOptions().ik_tolerance
        hm.set_object(g.X_OG)
        assert not hm.collides(q, set(range(len(h.finger_idx))), None)


def test_a_frames_grasp_does_not_depend_on_its_batch(searched):
    hm, ws, surface, frames, rho, grasps, _, _, distance = searched
    for g in grasps[:4]:
        alone, _ = grasp_for_frame(hm, ws, surface, frames[g.frame_index], g.frame_index, 0.5, rho, GraspOptions(),
                                   distance)
        assert alone is not None
        np.testing.assert_array_equal(alone.finger_q, g.finger_q)
        np.testing.assert_array_equal(alone.points, g.points)
    missing = sorted(set(range(len(frames))) - {g.frame_index for g in grasps})[:4]
    for i in missing:
        assert grasp_for_frame(hm, ws, surface, frames[i], i, 0.5, rho, GraspOptions(), distance)[0] is None


def test_ik_in_rounds_finds_the_grasps_of_one_batch(searched, monkeypatch):
    """The rounds of IK (a frame's first candidates, then the next of the frames still
    open) pick, per finger, the first candidate that passes: the grasps of one round."""
    import regrasp_cli.grasp.fingertips as fingertips

    hm, ws, surface, frames, rho, grasps, stats, _, distance = searched
    monkeypatch.setattr(fingertips, "IK_ROUNDS", ((0, 1_000_000),))
    once, once_stats = grasps_for_frames(hm, ws, surface, frames, np.arange(len(frames)), 0.5, rho, GraspOptions(),
                                         distance=distance)
    assert [g.frame_index for g in once] == [g.frame_index for g in grasps]
    for a, b in zip(once, grasps):
        np.testing.assert_array_equal(a.finger_q, b.finger_q)
        np.testing.assert_array_equal(a.points, b.points)
    assert once_stats["ik"] >= stats["ik"]  # the rounds skip the rows after a frame's success


@pytest.mark.parametrize("name", sorted(MESHES))
def test_the_distance_grid_saves_exact_checks_not_grasps(problem, cache_dir, name):
    """With the object's distance grid, frames whose palm is buried are not searched and
    candidates whose phalanges are buried not checked: fewer collision checks fail, and
    about as many grasps are found (the checks that decide are the same)."""
    mesh, robot = MESHES[name], problem.robot
    ws = hand_workspace(robot, HAND, WorkspaceOptions(), cache_dir)
    surface = build_surface(mesh, sampling_step(0.010), np.random.default_rng(0))
    frames = grasp_frames(mesh.bounds, 2, 128)
    rho = float(np.linalg.norm(mesh.extents) / 2)
    distance = distance_grid(build_surface(mesh, 0.003, np.random.default_rng(1)), 0.02)
    runs = [grasps_for_frames(HandModel(robot, HAND, mesh, problem.disabled.links(), 0.002), ws, surface, frames,
                              np.arange(len(frames)), 0.5, rho, GraspOptions(), distance=d) for d in (None, distance)]
    (plain, plain_stats), (ranked, stats) = runs
    assert stats["collisions"] < 0.7 * plain_stats["collisions"]  # about 0.25 on the cube, 0.6 on the sphere
    assert len(ranked) >= 0.8 * len(plain)


def test_link_probes_lie_inside_their_geometry():
    import coal

    from regrasp_cli.grasp.single import link_probes

    c, r = link_probes(coal.Cylinder(0.009, 0.05))  # radius, length along z
    assert len(r) >= 5 and np.all(np.linalg.norm(c[:, :2], axis=1) + r <= 0.009 + 1e-12)
    assert np.all(np.abs(c[:, 2]) + r <= 0.025 + 1e-12) and np.ptp(c[:, 2]) > 0.025
    c, r = link_probes(coal.Box(0.1, 0.09, 0.03))
    assert np.all(np.abs(c) + r[:, None] <= np.array([0.05, 0.045, 0.015]) + 1e-12)
    assert np.ptp(c[:, 0]) > 0.06 and np.ptp(c[:, 1]) > 0.05  # spread over the palm's face
    c, r = link_probes(coal.Sphere(0.02))
    assert len(r) == 1 and np.allclose(c, 0) and r[0] == pytest.approx(0.02)


def test_link_probes_follow_the_finger(problem):
    """At random finger values, each probe sphere of a finger lies inside one of that
    finger's cylinders as pinocchio places them."""
    from regrasp_cli.model.handshape import hand_shapes

    robot, h = problem.robot, problem.robot.hands[HAND]
    hm = HandModel(robot, HAND, MESHES["cube"], problem.disabled.links(), 0.002)
    rng = np.random.default_rng(4)
    values = rng.uniform(robot.lower[h.idx], robot.upper[h.idx], (5, len(h.idx)))
    for v in values:
        shape = hand_shapes(robot, HAND, v[None])[0]
        q = hm.q.copy()
        q[h.idx] = v
        for f, (lp, chain) in enumerate(zip(hm.probes(), hm.chains())):
            assert len(lp.radii) >= 4
            c_G = lp.centres(chain.forward(q[chain.dofs][None])[0])[0]
            inside = np.zeros(len(c_G), dtype=bool)
            for geometry, X_GL in zip(shape.geometries, shape.X_GL):
                if hasattr(geometry, "halfLength") and hasattr(geometry, "radius"):
                    p = (c_G - X_GL[:3, 3]) @ X_GL[:3, :3]
                    inside |= (np.linalg.norm(p[:, :2], axis=1) + lp.radii <= geometry.radius + 1e-9) \
                        & (np.abs(p[:, 2]) + lp.radii <= geometry.halfLength + 1e-9)
            assert inside.all(), f


def test_batch_ik_reaches_or_says_it_failed(robot):
    h = robot.hands[HAND]
    hm = HandModel(robot, HAND, trimesh.creation.box((0.05, 0.05, 0.05)), set(), 0.002)
    chain = hm.chains()[1]
    idx = h.finger_idx[1]
    rng = np.random.default_rng(3)
    Q_true = rng.uniform(robot.lower[idx], robot.upper[idx], (50, len(idx)))
    targets = chain.tip_and_jacobian(Q_true)[0]
    targets[-10:] += 0.5  # half a metre away: out of reach
    seeds = np.clip(Q_true + rng.normal(0, 0.1, Q_true.shape), robot.lower[idx], robot.upper[idx])
    Q, ok, _ = batch_ik(chain, robot.lower[idx], robot.upper[idx], seeds, targets, 30, 2e-4)
    assert not ok[-10:].any()
    assert ok[:40].mean() > 0.9
    reached = chain.tip_and_jacobian(Q[ok])[0]
    assert np.all(np.linalg.norm(reached - targets[ok], axis=1) < 2e-4)
    assert np.all((Q >= robot.lower[idx]) & (Q <= robot.upper[idx]))


def test_links_but_the_fingertips_keep_the_clearance_from_the_object(problem):
    """A 6 cm cube moved until the palm is 0.1 mm from it: the palm is free of it without a
    clearance, colliding with 0.3 mm (GraspOptions.link_clearance); 0.5 mm away, free."""
    import pinocchio as pin

    robot = problem.robot
    strict = HandModel(robot, HAND, MESHES["cube"], problem.disabled.links(), 0.002, clearance=3e-4)
    loose = HandModel(robot, HAND, MESHES["cube"], problem.disabled.links(), 0.002)

    def palm_gap(X_OG):
        """(distance, unit direction in G from the cube to the palm) of the nearest palm geometry."""
        loose.set_object(X_OG)
        pin.updateGeometryPlacements(robot.model, loose.data, loose.gm, loose.gd, robot.to_pin(loose.q))
        found = [pin.computeDistance(loose.gm, loose.gd, k) for k, cp in enumerate(loose.gm.collisionPairs)
                 if cp.second == loose.obj and loose.owner[cp.first] == -1]
        r = min(found, key=lambda r: r.min_distance)
        u_W = r.getNearestPoint1() - r.getNearestPoint2()
        return r.min_distance, inverse(loose.X_WG)[:3, :3] @ u_W / np.linalg.norm(u_W)

    def moved(X_OG, step_G):
        X_GO = inverse(X_OG)
        X_GO[:3, 3] += step_G
        return inverse(X_GO)

    X_OG = np.eye(4)
    X_OG[:3, 3] = [0.0, 0.0, -0.2]
    for _ in range(6):  # straight at the palm's nearest point
        d, u = palm_gap(X_OG)
        X_OG = moved(X_OG, (d - 1e-4) * u)
    d, u = palm_gap(X_OG)
    assert abs(d - 1e-4) < 2e-5
    for hm, hits in ((strict, True), (loose, False)):
        hm.set_object(X_OG)
        assert hm.collides(hm.q, set(), -1) == hits
    X_OG = moved(X_OG, -4e-4 * u)
    strict.set_object(X_OG)
    assert palm_gap(X_OG)[0] > 4e-4 and not strict.collides(strict.q, set(), -1)
