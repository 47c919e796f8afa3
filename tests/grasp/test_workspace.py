"""Finger workspaces approximated by spheres (Algorithm 1 of Saut et al. 2010, §IV-A-2):
every sphere of every finger of the default right hand lies inside the finger's reachable
workspace (checked by finger IK), spheres come biggest first and no smaller than r_min,
fit_spheres on a case known on paper (a solid ball), and the HDF5 cache."""

from __future__ import annotations

from dataclasses import fields
from importlib.resources import files
from pathlib import Path

import numpy as np
import pytest

from regrasp_cli.grasp import workspace as ws_mod
from regrasp_cli.grasp.workspace import WorkspaceOptions, fit_spheres, hand_workspace, tip_positions
from regrasp_cli.model.ik import IKOptions, solve_position
from regrasp_cli.model.robot import Kinematics, load_robot
from regrasp_cli.store import robot_label

HAND = "right"
OPTIONS = WorkspaceOptions()
ARRAYS = ("centres", "radii", "samples", "sample_q", "sample_closing", "root")
# the centre and the points at 0.9 r along +-x, +-y, +-z
PROBES = np.vstack([np.zeros(3), 0.9 * np.eye(3), -0.9 * np.eye(3)])


@pytest.fixture(scope="module")
def ws_cache(tmp_path_factory):
    return tmp_path_factory.mktemp("ws_cache")


@pytest.fixture(scope="module")
def fingers(robot, ws_cache):
    """The right hand's workspaces with the default options, computed once (and cached)."""
    return hand_workspace(robot, HAND, OPTIONS, ws_cache)


def _open_q(robot):
    h = robot.hands[HAND]
    q = robot.q_rest.copy()
    q[h.idx] = h.open
    return q


# --------------------------------------------------------------------------- spheres


def test_one_workspace_per_finger_with_consistent_shapes(robot, fingers):
    h = robot.hands[HAND]
    assert len(fingers) == len(h.spec.fingers) == 4
    for f, w in enumerate(fingers):
        k, m = len(w.radii), len(w.samples)
        assert 1 <= k <= OPTIONS.k_max
        assert w.centres.shape == (k, 3) and w.radii.shape == (k,)
        assert w.samples.shape == (m, 3) and w.sample_q.shape == (m, len(h.finger_idx[f]))
        assert w.sample_closing.shape == (m, 3) and w.root.shape == (3,)
        assert np.all(np.isfinite(w.centres)) and np.all(np.isfinite(w.samples))
        lo, hi = robot.lower[h.finger_idx[f]], robot.upper[h.finger_idx[f]]
        # closing directions are unit vectors, except (zero) where the finger is fully
        # closed: its flexion joints (the last two) at their limits cannot move further
        norm = np.linalg.norm(w.sample_closing, axis=1)
        zero = norm < 1e-9
        np.testing.assert_allclose(norm[~zero], 1.0, atol=1e-9)
        assert zero.mean() < 0.01
        flex = w.sample_q[zero][:, -2:]
        assert np.all(np.isclose(flex, lo[-2:]) | np.isclose(flex, hi[-2:]))
        assert np.all(w.sample_q >= lo - 1e-12) and np.all(w.sample_q <= hi + 1e-12)


def test_spheres_biggest_first_and_not_below_r_min(fingers):
    for w in fingers:
        assert np.all(np.diff(w.radii) <= 0.0), w.radii
        assert np.all(w.radii >= OPTIONS.r_min)


def test_sphere_centres_are_interior_samples(fingers):
    """Algorithm 1 centres each sphere on a point of W (the interior grid)."""
    for w in fingers:
        d, _ = w.tree.query(w.centres)
        assert np.all(d < 1e-12)


def test_samples_are_the_fingertip_positions_of_their_joint_values(robot, fingers):
    """The stored samples and their joint values agree (the joint values seed finger IK)."""
    for f, w in enumerate(fingers):
        pick = np.linspace(0, len(w.samples) - 1, 40).astype(int)
        np.testing.assert_allclose(tip_positions(robot, HAND, f, w.sample_q[pick]), w.samples[pick], atol=1e-12)


@pytest.mark.parametrize("finger", range(4))
def test_every_sphere_lies_inside_the_reachable_workspace(robot, fingers, finger):
    """The centre and the points at 0.9 r in 6 axis directions of every sphere are reached
    by the fingertip centre (finger IK seeded from the nearest workspace sample)."""
    h = robot.hands[HAND]
    w = fingers[finger]
    idx, tip = h.finger_idx[finger], h.tip_frames[finger]
    q0 = _open_q(robot)
    X_WG = Kinematics(robot).fk(q0, h.grasp_frame)
    rng = np.random.default_rng(0)
    misses = []
    for i, (c, r) in enumerate(zip(w.centres, w.radii)):
        for probe in PROBES:
            p_G = c + r * probe
            q = q0.copy()
            q[idx] = w.sample_q[w.nearest(p_G)]
            res = solve_position(robot, tip, X_WG[:3, :3] @ p_G + X_WG[:3, 3], q, idx, rng, IKOptions(restarts=5))
            # the IK solution keeps the other joints and stays within the finger's limits
            assert robot.within_limits(res.q)
            np.testing.assert_array_equal(np.delete(res.q, idx), np.delete(q0, idx))
            if res.position_error >= 1e-3:
                misses.append((i, round(float(r), 4), probe.tolist(), round(res.position_error, 4)))
    assert not misses, f"sphere points out of reach (sphere, radius, direction, error m): {misses}"


# --------------------------------------------------------------------------- fit_spheres


def _ball_case(radius=0.05, h=0.005, n_envelope=20000):
    axis = np.arange(-radius, radius + h / 2, h)
    g = np.array(np.meshgrid(axis, axis, axis, indexing="ij")).reshape(3, -1).T
    W = g[np.linalg.norm(g, axis=1) < radius - 1e-12]
    # Fibonacci points on the boundary sphere (spacing ~1.25 mm)
    k = np.arange(n_envelope) + 0.5
    z = 1.0 - 2.0 * k / n_envelope
    phi = np.pi * (1.0 + 5**0.5) * k
    s = np.sqrt(1.0 - z * z)
    E = radius * np.column_stack([s * np.cos(phi), s * np.sin(phi), z])
    return W, E, radius, h


def test_fit_spheres_on_a_solid_ball():
    W, E, R, h = _ball_case()
    centres, radii = fit_spheres(W, E, k_max=12, r_min=0.004)
    assert centres.shape == (len(radii), 3) and 1 <= len(radii) <= 12
    # the first sphere is the ball itself, up to the grid spacing
    assert np.linalg.norm(centres[0]) <= h
    assert abs(radii[0] - R) <= h
    # biggest first, none below r_min, all inside the ball (up to the envelope spacing)
    assert np.all(np.diff(radii) <= 0) and np.all(radii >= 0.004)
    assert np.all(np.linalg.norm(centres, axis=1) + radii <= R + 2e-3)
    # later spheres are centred on interior points outside the earlier ones and do not
    # overlap them (their radius is the distance to the earlier spheres' surfaces too)
    for j in range(len(radii)):
        assert np.min(np.linalg.norm(W - centres[j], axis=1)) < 1e-12
        for i in range(j):
            assert np.linalg.norm(centres[i] - centres[j]) >= radii[i] + radii[j] - 1e-12


def test_fit_spheres_limits():
    W, E, R, _ = _ball_case()
    c, r = fit_spheres(W, E, k_max=1, r_min=0.001)
    assert c.shape == (1, 3) and r.shape == (1,)
    c, r = fit_spheres(W, E, k_max=10, r_min=R + 0.01)  # no sphere is that big
    assert c.shape == (0, 3) and r.shape == (0,)
    c, r = fit_spheres(W, E, k_max=0, r_min=0.001)
    assert c.shape == (0, 3) and r.shape == (0,)


# --------------------------------------------------------------------------- cache


def test_hand_workspace_is_cached_in_hdf5(robot, fingers, ws_cache, monkeypatch):
    files = sorted((ws_cache / "workspace").glob("*.h5"))
    assert len(files) == 1 and files[0].name.startswith(f"{robot_label(robot)}-{HAND}-")

    def boom(*args, **kwargs):
        raise AssertionError("finger_workspace recomputed despite a fresh cache")

    monkeypatch.setattr(ws_mod, "finger_workspace", boom)
    again = hand_workspace(robot, HAND, OPTIONS, ws_cache)
    assert len(again) == len(fingers)
    for a, b in zip(fingers, again):
        for name in ARRAYS:
            x, y = getattr(a, name), getattr(b, name)
            assert x.shape == y.shape and x.dtype == y.dtype, name
            assert np.array_equal(x, y), name


def test_the_cached_voxel_maps_are_the_spheres_grown_by_the_tip_radii(robot, fingers, ws_cache):
    """Each finger's voxel map comes with its workspace, built and read back from the
    cache: the map of its spheres grown by its fingertip's radius, each voxel of the map
    naming the interior sample nearest to its centre."""
    again = hand_workspace(robot, HAND, OPTIONS, ws_cache)
    for ws, f in zip(again, robot.hands[HAND].spec.fingers):
        fresh = ws_mod.sphere_voxels(ws, f.tip_radius)
        assert ws.voxels.inflate == f.tip_radius
        assert np.array_equal(ws.voxels.origin, fresh.origin)
        assert np.array_equal(ws.voxels.index, fresh.index) and np.array_equal(ws.voxels.nearest, fresh.nearest)
        on = np.argwhere(ws.voxels.index >= 0)[::97]
        centres = ws.voxels.origin + ws.voxels.resolution * on
        d = np.linalg.norm(centres[:, None] - ws.samples[None], axis=2)
        chosen = ws.voxels.nearest[on[:, 0], on[:, 1], on[:, 2]]
        assert np.allclose(d[np.arange(len(on)), chosen], d.min(axis=1))
        assert np.all(ws.voxels.nearest[ws.voxels.index < 0] == -1)


def test_other_options_are_not_served_from_the_cache(robot, fingers, ws_cache, monkeypatch):
    """The cache is keyed by the options: other options recompute (here: the patched
    function is called) instead of returning the default-options file."""
    calls = []

    def spy(*args, **kwargs):
        calls.append(args)
        raise RuntimeError("recompute")

    monkeypatch.setattr(ws_mod, "finger_workspace", spy)
    with pytest.raises(RuntimeError, match="recompute"):
        hand_workspace(robot, HAND, WorkspaceOptions(k_max=5), ws_cache)
    assert calls
    assert {f.name for f in fields(WorkspaceOptions)} >= {"interior_samples", "envelope_samples", "k_max", "r_min"}


def test_two_robots_right_hands_keep_their_own_files(robot, fingers, ws_cache, monkeypatch):
    """hand4's right hand beside the default robot's in one cache: its own file, and the
    default robot's still served from the cache afterwards (not overwritten)."""
    hand4 = load_robot(Path(str(files("regrasp_cli") / "data/robots/hand4/robot.yaml")))
    hand_workspace(hand4, HAND, OPTIONS, ws_cache)
    names = sorted(f.name for f in (ws_cache / "workspace").glob("*.h5"))
    assert len([n for n in names if n.startswith(f"{robot_label(hand4)}-{HAND}-")]) == 1
    assert len([n for n in names if n.startswith(f"{robot_label(robot)}-{HAND}-")]) == 1

    def boom(*args, **kwargs):
        raise AssertionError("the default robot's workspace was overwritten")

    monkeypatch.setattr(ws_mod, "finger_workspace", boom)
    assert len(hand_workspace(robot, HAND, OPTIONS, ws_cache)) == len(fingers)


# --------------------------------------------------------------------- redundant fingers

ALLEGRO = files("regrasp_cli") / "data/robots/allegro/robot.yaml"


def test_a_finger_whose_flexions_share_a_plane_fixes_its_last_joint_and_keeps_a_volume():
    """An Allegro finger: abduction, then three flexions about parallel axes.  Fixing its
    first joint (as for a thumb's base) leaves a plane and no sphere; the distal joint is
    fixed instead, and every sphere's centre and 0.9 r probes are reached by the tip."""
    allegro = load_robot(Path(str(ALLEGRO)))
    assert list(ws_mod._fixed_first(allegro, HAND, 0, 1)) == [3, 0, 1, 2]
    w = ws_mod.finger_workspace(allegro, HAND, 0, OPTIONS)
    assert len(w.radii) >= 10 and w.radii.min() >= OPTIONS.r_min
    h = allegro.hands[HAND]
    idx, tip = h.finger_idx[0], h.tip_frames[0]
    q0 = allegro.q_rest.copy()
    q0[h.idx] = h.open
    X_WG = Kinematics(allegro).fk(q0, h.grasp_frame)
    rng = np.random.default_rng(0)
    for c, r in zip(w.centres, w.radii):
        for probe in PROBES:
            p_G = c + r * probe
            q = q0.copy()
            q[idx] = w.sample_q[w.nearest(p_G)]
            res = solve_position(allegro, tip, X_WG[:3, :3] @ p_G + X_WG[:3, 3], q, idx, rng, IKOptions(restarts=5))
            assert res.position_error < 1e-3, (c, r, probe)


def test_a_thumb_with_a_base_joint_keeps_fixing_its_first_joint(robot):
    """The default robot's thumb: its base joint first, the other three span a volume."""
    h = robot.hands[HAND]
    thumb = next(i for i, f in enumerate(h.spec.fingers) if len(f.joints) > 3)
    assert list(ws_mod._fixed_first(robot, HAND, thumb, len(h.spec.fingers[thumb].joints) - 3)) == \
        list(range(len(h.spec.fingers[thumb].joints)))


def test_sphere_voxels_name_the_biggest_sphere_holding_each_voxel():
    """Every voxel centre of the map, and points off the grid, against the spheres
    themselves: the first (biggest) sphere grown by the inflation that holds it, else -1."""
    rng = np.random.default_rng(3)
    radii = np.sort(rng.uniform(0.004, 0.02, 12))[::-1]
    spheres = type("Spheres", (), {"centres": rng.uniform(-0.03, 0.03, (12, 3)), "radii": radii})()
    vox = ws_mod.sphere_voxels(spheres, inflate=0.003)
    ijk = np.indices(vox.index.shape).reshape(3, -1).T
    p = vox.origin + vox.resolution * ijk
    inside = np.linalg.norm(p[:, None] - spheres.centres[None], axis=-1) <= radii + 0.003
    expected = np.where(inside.any(axis=1), np.argmax(inside, axis=1), -1)
    assert (vox.index >= 0).sum() > 1000
    np.testing.assert_array_equal(vox.lookup(p), expected)
    assert vox.lookup((vox.origin - 0.01)[None])[0] == -1  # off the grid
