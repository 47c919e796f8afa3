"""`regrasp simulate` (issue 43): the squeeze is an internal force of the grasp, and a
jaw pinch in MuJoCo holds its object exactly when Coulomb says it can (2 mu F against
m g); the report names the phase that lost it; bad input is one line, exit code 2."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from cli_helpers import SMALL, assert_one_error_line, run

from regrasp_cli.export import sample_plan
from regrasp_cli.replay import load_inputs
from regrasp_cli.simulate import SimOptions, internal_forces, point_jacobian, squeeze_torques
from regrasp_cli.trajectory import read_plan

ROOT = Path(__file__).resolve().parents[1]
SCENE = ROOT / "configs" / "scenes" / "hironx_onearm.yaml"
G = 9.81


def _check_internal(P, N, F, mu, force):
    N = N / np.linalg.norm(N, axis=1, keepdims=True)
    assert np.abs(F.sum(axis=0)).max() < 1e-6 * force
    torque = np.cross(P - P.mean(axis=0), F).sum(axis=0)
    assert np.abs(torque).max() < 1e-6 * force
    fn = -(F * N).sum(axis=1)
    ft = np.linalg.norm(F + fn[:, None] * N, axis=1)
    assert np.all(fn > 0) and fn.mean() == pytest.approx(force)
    # the linearised cone lies inside the true one (8 tangent directions: within 1 / cos(pi / 8))
    assert np.all(ft <= mu * fn / np.cos(np.pi / 8) + 1e-9)


def test_an_antipodal_pinch_squeezes_along_its_normals():
    P = np.array([[0.02, 0.0, 0.0], [-0.02, 0.0, 0.0]])
    N = np.array([[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0]])
    F = internal_forces(P, N, 0.5, 20.0)
    assert np.allclose(F, -20.0 * N, atol=1e-6)


def test_three_fingers_on_a_sphere_squeeze_with_no_net_wrench():
    rng = np.random.default_rng(3)
    for _ in range(20):
        a = rng.uniform(0, 2 * np.pi) + np.array([0.0, 2.1, 4.2]) + rng.normal(0, 0.15, 3)
        z = rng.normal(0, 0.2, 3)
        N = np.stack([np.cos(a), np.sin(a), z], axis=1)
        N /= np.linalg.norm(N, axis=1, keepdims=True)
        P = 0.03 * N
        _check_internal(P, N, internal_forces(P, N, 0.5, 10.0), 0.5, 10.0)


def test_a_pinch_that_needs_more_friction_squeezes_along_the_line_between_its_contacts():
    """Two contacts 90 degrees apart on a cylinder: the only internal force is along the
    line joining them, 45 degrees off each normal (it needs mu 1; with 0.5 it will slip)."""
    P = np.array([[0.02, 0.0, 0.0], [0.0, 0.02, 0.0]])
    N = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    F = internal_forces(P, N, 0.5, 5.0)
    line = (P[1] - P[0]) / np.linalg.norm(P[1] - P[0])
    assert np.allclose(F[0], 5.0 * np.sqrt(2) * line, atol=1e-6) and np.allclose(F[1], -F[0])


def test_contacts_that_cannot_squeeze_push_along_their_normals():
    P = np.array([[0.02, 0.0, 0.0], [0.02, 0.01, 0.0]])
    N = np.array([[1.0, 0.0, 0.0], [1.0, 0.0, 0.0]])  # side by side on one face
    assert np.allclose(internal_forces(P, N, 0.5, 5.0), -5.0 * N)
    assert np.allclose(internal_forces(P[:1], N[:1], 0.5, 5.0), -5.0 * N[:1])


def test_the_squeeze_acts_at_the_contact_not_at_the_fingertip_frame(robot):
    """The point 2 cm off the humanoid's index fingertip frame (a revolute finger) moves
    as its Jacobian says: finite differences of its position agree to 1e-6 (a frame's
    Jacobian would be off by w x r, the torque for a pad's contact wrong with it)."""
    import pinocchio as pin

    model, data = robot.model, robot.model.createData()
    h = robot.hands["right"]
    frame = h.tip_frames[1]
    rng = np.random.default_rng(0)
    q = robot.q_rest.copy()
    q[h.idx] = h.open + rng.uniform(0.1, 0.4, len(h.idx))
    qd = np.zeros(robot.nq)
    qd[h.finger_idx[1]] = rng.normal(size=len(h.finger_idx[1]))

    def point(x: np.ndarray) -> np.ndarray:
        pin.framesForwardKinematics(model, data, robot.to_pin(x))
        X = data.oMf[frame]
        return X.translation + X.rotation @ np.array([0.0, 0.02, 0.0])

    p_W = point(q)
    pin.computeJointJacobians(model, data, robot.to_pin(q))
    pin.updateFramePlacements(model, data)
    J = point_jacobian(model, data, frame, p_W)
    eps = 1e-6
    fd = (point(q + eps * qd) - point(q - eps * qd)) / (2 * eps)
    assert np.linalg.norm(J @ qd - fd) < 1e-6 and np.linalg.norm(fd) > 1e-3


@pytest.fixture(scope="module")
def pinch(tmp_path_factory):
    """A one-arm plan of HiroNX's jaw (two contacts) and its simulation report."""
    d = tmp_path_factory.mktemp("simulate")
    cache = d / "cache"
    result = run("--cache-dir", cache, "plan", SCENE, "-o", d / "plan.json", *SMALL, "--seed", 0)
    assert result.exit_code == 0, result.output
    sim = run("--cache-dir", cache, "simulate", d / "plan.json", "-o", d / "report.json")
    return d, cache, sim, json.loads((d / "report.json").read_text())


def test_a_jaw_pinch_with_the_plan_s_friction_holds(pinch):
    d, _, sim, report = pinch
    assert sim.exit_code == 0, sim.output
    assert "held" in sim.output and report["ok"] is True
    plan = json.loads((d / "plan.json").read_text())
    assert [p["name"] for p in report["phases"]] == [p["name"] for p in plan["phases"]]
    assert all(p["max_position"] <= 0.01 and p["max_angle"] <= 0.1 and not p["dropped"] for p in report["phases"])
    assert report["tracking_error"] < 1e-3


def test_a_closing_hand_squeezes_only_as_its_fingers_arrive(pinch):
    """A closing hand's squeeze is off until the last ``squeeze_ramp`` s of its closing
    (before, it drove the fingers still in flight ahead of the plan, and they pushed the
    humanoid's statuette 4 mm along the table), full once it holds."""
    d = pinch[0]
    file = d / "plan.json"
    plan = read_plan(file)
    inputs = load_inputs(plan, file)
    opts = SimOptions()
    samples = sample_plan(plan, file, inputs, 1.0 / opts.timestep)
    tau = np.abs(squeeze_torques(plan, inputs, samples, opts.squeeze_n, opts.squeeze_ramp)).max(axis=1)
    k = next(i for i, p in enumerate(plan.phases) if p.kind.value == "grasp")
    closing, t_end = samples.phase == k, plan.phases[k].times[-1]
    early = closing & (samples.t < t_end - opts.squeeze_ramp)
    assert early.any() and tau[early].max() == 0.0
    assert tau[closing][-1] > 0.0
    assert np.all(tau[samples.phase == k + 1] > 0.0)  # the next phase holds it


@pytest.mark.parametrize("share", [0.4, 4.0])
def test_the_pinch_slips_exactly_when_coulomb_says_it_must(pinch, share):
    """Two contacts pressing F each hold at most 2 mu F: friction for ``share`` times the
    weight m g slips in the first phase that lifts it (0.4), holds with room to spare (4)."""
    d, cache, _, report = pinch
    plan = json.loads((d / "plan.json").read_text())
    force = report["options"]["squeeze_n"]
    plan["object"]["friction"] = share * report["object_mass"] * G / (2 * force)
    copy = d / f"friction-{share}.json"
    copy.write_text(json.dumps(plan))
    result = run("--cache-dir", cache, "simulate", copy)
    lifted = next(p["name"] for p in plan["phases"] if p["holding"] and p["kind"] == "transfer")
    if share < 1:
        assert result.exit_code == 1, result.output
        assert f"NOT HELD in phase {lifted}" in " ".join(result.output.split())
    else:
        assert result.exit_code == 0, result.output


def test_bad_input_is_one_line_and_writes_nothing(pinch, tmp_path, monkeypatch):
    d, cache, _, _ = pinch
    plan = json.loads((d / "plan.json").read_text())
    out = tmp_path / "report.json"

    def variant(name, **change):
        p = {**plan, **change}
        (d / name).write_text(json.dumps(p))
        return d / name

    old = variant("old.json", format="regrasp.plan/1")
    assert_one_error_line(run("--cache-dir", cache, "simulate", old, "-o", out), "format")
    failed = variant("failed.json", status="failed", failure={"stage": "grasps", "reason": "none"})
    assert_one_error_line(run("--cache-dir", cache, "simulate", failed, "-o", out), "solved")
    gone = variant("no-mesh.json", object={**plan["object"], "mesh": "missing/block.stl"})
    assert_one_error_line(run("--cache-dir", cache, "simulate", gone, "-o", out), "mesh")
    assert_one_error_line(run("simulate", d / "plan.json", "--squeeze", "0"), "--squeeze")
    assert not out.exists()

    import importlib

    real = importlib.import_module

    def without_mujoco(name, *args):
        if name == "mujoco":
            raise ModuleNotFoundError("No module named 'mujoco'", name="mujoco")
        return real(name, *args)

    monkeypatch.setattr("regrasp_cli.simulate.importlib.import_module", without_mujoco)
    assert_one_error_line(run("simulate", d / "plan.json", "-o", out), "mujoco", "regrasp[sim]")
    assert not out.exists()


BALL = ROOT / "regrasp_cli" / "data" / "scenes" / "inhand_ball.yaml"


@pytest.fixture(scope="module")
def ball(tmp_path_factory):
    """The shipped in-hand ball plan (hand4, seed 003's experiment) and its simulation."""
    d = tmp_path_factory.mktemp("simulate_ball")
    cache = d / "cache"
    result = run("--cache-dir", cache, "inhand", "plan", BALL, "-o", d / "plan.json", "--no-timings")
    assert result.exit_code == 0, result.output
    sim = run("--cache-dir", cache, "simulate", d / "plan.json", "-o", d / "report.json")
    return d, cache, sim, json.loads((d / "report.json").read_text())


def test_the_shipped_ball_turned_in_the_hand_holds_in_physics(ball):
    """Issue 43: every finger step and every turn of the ball plan keeps the ball within
    1 cm and 0.1 rad of the plan, the fingertips rolling on it (point contacts) and each
    finger letting go only where the other three hold it with margin."""
    d, _, sim, report = ball
    assert sim.exit_code == 0, sim.output
    kinds = {p["kind"] for p in report["phases"]}
    assert kinds == {"inhand-transfer", "inhand-regrasp"} and report["ok"] is True
    assert all(p["ok"] and p["max_angle"] <= 0.1 for p in report["phases"])


def test_rigid_fingertips_touch_without_torsional_friction(ball):
    """hand4's robot.yaml says ``tip_patch: 0`` (rigid tips, seed 003's point contacts): its
    fingers touch the object with friction and no torsion (condim 3), taking precedence
    over the object's soft-finger torsion (condim 4, which the palm's contacts keep); the
    same hand with 5 mm patches touches with their torsional friction."""
    import copy
    from dataclasses import replace

    from regrasp_cli.grasp.quality import default_torsion_mu
    from regrasp_cli.simulate import build_world

    d, cache, _, _ = ball
    plan = read_plan(d / "plan.json")
    inputs = load_inputs(plan, d / "plan.json")
    mu = inputs.friction
    for patch, condim, torsion in ((0.0, 3, 0.0), (0.005, 4, default_torsion_mu(mu, 0.005))):
        robot = copy.copy(inputs.robot)  # the same robot, its hands' tips made of another stuff
        robot.hands = {k: replace(h, spec=replace(h.spec, tip_patch=patch)) for k, h in robot.hands.items()}
        world = build_world(replace(inputs, robot=robot), np.eye(4), SimOptions(), cache)
        m = world.model
        fingers = {robot.joint_names[i] for h in robot.hands.values() for i in h.idx}
        on_finger = np.array([m.body(int(m.geom_bodyid[g])).name in fingers for g in range(m.ngeom)])
        obj = m.geom_bodyid == world.object_body
        assert on_finger.sum() >= 8 and np.all(m.geom_condim[on_finger] == condim)
        assert np.allclose(m.geom_friction[on_finger, :2], [mu, torsion])
        assert m.geom_priority[on_finger].min() > m.geom_priority[obj].max()
        assert np.all(m.geom_condim[obj] == 4) and np.all(m.geom_friction[obj, 1] > 0.0)
    assert inputs.robot.hands["right"].spec.tip_patch == 0.0  # as shipped


def test_a_stepping_finger_hands_its_load_to_the_others_before_it_lifts(ball):
    """In a finger's regrasp the squeeze goes over to the n-1 others' within the first
    ``squeeze_ramp`` s, while the finger still touches: from then on the lifted finger
    pushes nothing and the others' pushes balance (no net force)."""
    from regrasp_cli.simulate import contact_pushes

    d, _, _, _ = ball
    plan = read_plan(d / "plan.json")
    inputs = load_inputs(plan, d / "plan.json")
    opts = SimOptions()
    samples = sample_plan(plan, d / "plan.json", inputs, 1.0 / opts.timestep)
    pushes = contact_pushes(plan, inputs, samples, opts.squeeze_n, opts.squeeze_ramp)
    k, p = next((k, p) for k, p in enumerate(plan.phases) if p.kind.value == "inhand-regrasp")
    lifted = ({c["finger"] for c in p.contacts[0]} - {c["finger"] for c in p.contacts[1]}).pop()
    at = np.flatnonzero(samples.phase == k)
    t = samples.t[at]
    first = at[np.searchsorted(t, p.times[0] + 1e-9)]
    assert any(f == lifted and np.linalg.norm(F) > 1.0 for _, f, F, _, _ in pushes[first])
    for i in at[(t >= p.times[0] + opts.squeeze_ramp) & (t <= p.times[-2])]:
        assert all(np.linalg.norm(F) < 1e-9 for _, f, F, _, _ in pushes[i] if f == lifted)
        total = sum(w * F for _, f, F, w, _ in pushes[i])
        assert np.linalg.norm(total) < 1e-6 * opts.squeeze_n
