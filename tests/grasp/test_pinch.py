"""Pinch frames (grasp.pinch) and the pinch pass of the grasp build on a flat object.

The tuning suite's bar (configs/bench/tune/, scripts/make_tune_suite.py) is 185 x 25 x 14 mm
with a rounded rim, lying on the desk: the bounding-box grid of §IV-A-1 finds no grasp the
hand can use there (its force-closure grasps pinch the bar across its thickness, a finger
under it), and the pinch pass must find grasps across its width whose fingertips clear the
desk, touching it at most within the contact tolerance.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from regrasp_cli.grasp.pinch import pinch_frames, tip_pairs
from regrasp_cli.grasp.workspace import FingerWorkspace
from regrasp_cli.spatial import rotation_aligning

ROOT = Path(__file__).resolve().parents[2]
BAR = ROOT / "configs" / "bench" / "tune" / "bar_behind.yaml"


def _workspace(samples: np.ndarray, closing: np.ndarray) -> FingerWorkspace:
    n = len(samples)
    return FingerWorkspace(np.zeros((1, 3)), np.ones(1), samples, np.zeros((n, 1)),
                           np.repeat(closing[None], n, 0), np.zeros(3))


@pytest.mark.parametrize("seed", range(3))
def test_axis_rotation_turns_a_onto_b(seed):
    rng = np.random.default_rng(seed)
    a = rng.normal(size=(20, 3))
    a /= np.linalg.norm(a, axis=1, keepdims=True)
    b = rng.normal(size=(20, 3))
    b /= np.linalg.norm(b, axis=1, keepdims=True)
    b[0], b[1] = -a[0], a[1]  # opposite, equal
    R = rotation_aligning(a, b)
    assert np.allclose(rotation_aligning(a[2], b[2]), R[2])
    assert np.allclose(np.einsum("kij,kj->ki", R, a), b, atol=1e-9)
    assert np.allclose(R @ np.transpose(R, (0, 2, 1)), np.eye(3), atol=1e-9)
    assert np.allclose(np.linalg.det(R), 1.0)


def test_tip_pairs_close_towards_each_other():
    """A thumb closing along +x and a finger closing along -x: only pairs with the finger
    ahead of the thumb along x (and not too oblique) are kept."""
    rng = np.random.default_rng(0)
    thumb = _workspace(rng.uniform(-0.05, 0.05, (100, 3)), np.array([1.0, 0.0, 0.0]))
    finger = _workspace(rng.uniform(-0.05, 0.05, (100, 3)), np.array([-1.0, 0.0, 0.0]))
    ia, ib = tip_pairs(thumb, finger, rng)
    a, b = thumb.samples[ia], finger.samples[ib]
    assert len(a) > 100
    u = (b - a) / np.linalg.norm(b - a, axis=1, keepdims=True)
    assert np.all(u[:, 0] > 0.3)


def test_pinch_frames_put_the_tips_on_the_targets():
    """Each frame maps a thumb sample and a finger sample onto the tip targets p + r n of an
    antipodal pair, up to the 3 mm mismatch of their distances."""
    rng = np.random.default_rng(1)
    thumb = _workspace(rng.uniform(-0.05, 0.05, (300, 3)), np.array([1.0, 0.0, 0.0]))
    finger = _workspace(rng.uniform(-0.05, 0.05, (300, 3)), np.array([-1.0, 0.0, 0.0]))
    r = 0.01
    # a 30 mm wide slab across x in O, turned: pairs on its two faces
    R_O = Rotation.random(random_state=2).as_matrix()
    k = 12
    p1 = rng.uniform(-0.02, 0.02, (k, 3)) * [0, 1, 1] + [-0.015, 0, 0]
    p2 = p1 + [0.03, 0, 0]
    n1 = np.tile([-1.0, 0, 0], (k, 1))
    p1, p2, n1 = p1 @ R_O.T, p2 @ R_O.T, n1 @ R_O.T
    X, pair, which, _, _ = pinch_frames(thumb, [finger], (r, [r]), p1, n1, p2, -n1, rng, rolls=4)
    assert np.array_equal(pair, np.tile(np.arange(k), 4)) and np.all(which == 0)
    assert X.shape == (4 * k, 4, 4)
    c1, c2 = p1 + r * n1, p2 - r * n1  # the fingertip centres wanted
    for j in range(k):
        for x in X[pair == j]:
            assert np.allclose(x[:3, :3] @ x[:3, :3].T, np.eye(3), atol=1e-9)
            t = np.linalg.inv(x)  # O -> G
            a_G = c1[j] @ t[:3, :3].T + t[:3, 3]
            b_G = c2[j] @ t[:3, :3].T + t[:3, 3]
            # some thumb sample and some finger sample lie within 1.5 mm (half the mismatch)
            assert np.min(np.linalg.norm(thumb.samples - a_G, axis=1)) < 0.0016
            assert np.min(np.linalg.norm(finger.samples - b_G, axis=1)) < 0.0016


def test_pinch_pass_grasps_a_flat_bar_on_the_desk(tmp_path):
    """The grid's frames give no grasp a hand can use on the bar lying on the desk (they go
    through the desk); the pinch pass gives some, across the bar's width."""
    from regrasp_cli.grasp.build import BuildOptions, _context, build_grasps
    from regrasp_cli.grasp.single import GraspOptions
    from regrasp_cli.model.handshape import hand_hits_static, hand_shapes, static_geometry
    from regrasp_cli.scene import load_problem

    options = BuildOptions(grasp=GraspOptions(n_orientations=512, target=0), jobs=1)
    cache = tmp_path / "cache"
    glist, report = build_grasps(BAR, cache, "right", options)
    n_grid = len(_context(BAR, cache, "right", options).frames)
    problem = load_problem(BAR, cache)
    env, task = static_geometry(problem.spec.obstacles), problem.spec.task
    tol = problem.spec.planning.contact_tolerance
    usable = [k for k, shape in enumerate(hand_shapes(problem.robot, "right", glist.finger_q, tol))
              if any(not hand_hits_static(shape, X_WO @ glist.X_OG[k], env, touching=True)
                     for X_WO in (task.X_WO_start, task.X_WO_goal))]
    assert len(usable) >= 3, report
    assert np.all(glist.frame_index[usable] >= n_grid)  # every one from a pinch frame
    assert np.all(glist.scores[:, 0] > 0)  # force closure (epsilon quality > 0)
    for k in usable:
        # across the width (y in the bar's frame): the thumb on one side, a finger on the other
        pts = glist.points[k][glist.in_contact[k]]
        assert pts[:, 1].min() < -0.005 and pts[:, 1].max() > 0.005, pts
        # above the desk's contact tolerance: every contact on the upper half of the rim
        assert np.all(pts[:, 2] > -0.002), pts
