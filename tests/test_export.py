"""`regrasp export` (issue 43) on the default scene's plan: the samples lie on the plan's
motion (every stop waypoint at its time), keep the joint limits the plan records, and put
the object where the holding hand's grasp holds it; the four files agree; bad requests
are one line with exit code 2 and nothing written."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from cli_helpers import assert_one_error_line, run

from regrasp_cli.export import sample_plan
from regrasp_cli.model.robot import Kinematics
from regrasp_cli.replay import load_inputs
from regrasp_cli.spatial import inverse
from regrasp_cli.trajectory import read_plan

RATE = 100.0


@pytest.fixture(scope="module")
def exported(default_plan):
    plan = read_plan(default_plan)
    inputs = load_inputs(plan, default_plan)
    return plan, inputs, sample_plan(plan, default_plan, inputs, RATE)


def test_the_samples_pass_every_stop_at_its_time(exported, default_plan):
    plan, inputs, s = exported
    assert s.t[0] == 0.0 and s.t[-1] == pytest.approx(plan.duration, abs=1e-12)
    assert np.allclose(np.diff(s.t)[:-1], 1 / RATE)
    for p in plan.phases:
        stops = np.arange(len(p.waypoints)) if p.blends is None else np.flatnonzero(p.blends == 0)
        at = sample_plan(plan, default_plan, inputs, RATE, t=p.times[stops])
        assert np.abs(at.q - p.waypoints[stops]).max() < 1e-9, p.name
        assert np.abs(at.qd).max() < 1e-9  # a stop is at rest


def test_the_samples_keep_the_plan_s_limits(exported):
    plan, inputs, s = exported
    assert np.all(s.q >= inputs.lower - 1e-9) and np.all(s.q <= inputs.upper + 1e-9)
    assert np.all(np.abs(s.qd) <= inputs.velocity * (1 + 1e-6))
    assert np.all(np.abs(s.qdd) <= inputs.acceleration * (1 + 1e-6))
    # velocities are the positions' derivatives: a central difference agrees inside a phase
    same = (s.phase[:-2] == s.phase[2:]) & (np.diff(s.t)[1:] == np.diff(s.t)[:-1])
    fd = (s.q[2:] - s.q[:-2]) / (s.t[2:] - s.t[:-2])[:, None]
    assert np.abs(fd - s.qd[1:-1])[same].max() < 0.02


def test_the_object_rides_with_the_holding_hand_s_grasp(exported):
    plan, inputs, s = exported
    kin = Kinematics(inputs.robot)
    held, first = 0, {}
    for i in range(0, len(s.t), 7):
        p = plan.phases[s.phase[i]]
        if p.holding:
            hand = sorted(p.holding)[0]
            X_GO = inverse(kin.fk(s.q[i], inputs.robot.hands[hand].grasp_frame)) @ s.X_WO[i]
            # rigid in the hand all phase; the grasp's, within the arm IK's tolerance (0.1 mm)
            assert np.allclose(X_GO, first.setdefault(int(s.phase[i]), X_GO), atol=1e-9)
            assert np.allclose(X_GO, inverse(plan.grasp(p.holding[hand]).X_OG), atol=1e-4)
            held += 1
        elif p.placement is not None:
            assert np.allclose(s.X_WO[i], plan.placement(p.placement).X_WO)
    assert held > 100
    closes = [e for e in s.events if e["event"] == "close"]
    opens = [e for e in s.events if e["event"] == "open"]
    assert [e["hand"] for e in closes] == ["right", "left"] and [e["hand"] for e in opens] == ["right", "left"]


def test_the_four_files_agree(tmp_path, default_plan, exported):
    _, _, s = exported
    outs = [tmp_path / n for n in ("s.csv", "s.npz", "s.json", "s.joint_trajectory.json")]
    result = run("export", default_plan, *[x for o in outs for x in ("-o", o)], "--rate", RATE)
    assert result.exit_code == 0, result.output
    rows = list(csv.reader(outs[0].open()))
    assert len(rows) == len(s.t) + 1 and rows[0][:3] == ["t", "phase", "holding"]
    nq = len(s.joint_names)
    assert np.allclose(np.array(rows[1:], dtype=object)[:, 10:10 + nq].astype(float), s.q, atol=0)
    z = np.load(outs[1])
    assert np.array_equal(z["q"], s.q) and np.array_equal(z["qdd"], s.qdd) and list(z["joint_names"]) == list(
        s.joint_names)
    d = json.loads(outs[2].read_text())
    assert d["format"] == "regrasp.samples/1" and np.array_equal(np.array(d["object_poses"]), s.X_WO)
    jt = json.loads(outs[3].read_text())
    assert jt["joint_names"] == list(s.joint_names) and len(jt["points"]) == len(s.t)
    stamps = [p["time_from_start"]["sec"] + 1e-9 * p["time_from_start"]["nanosec"] for p in jt["points"]]
    assert np.allclose(stamps, s.t, atol=1e-9) and jt["points"][5]["velocities"] == s.qd[5].tolist()


def test_bad_requests_are_one_line(tmp_path, default_plan):
    assert_one_error_line(run("export", default_plan, "-o", tmp_path / "s.txt"), ".csv")
    assert_one_error_line(run("export", default_plan, "-o", tmp_path / "s.csv", "--rate", "0"), "--rate")
    assert_one_error_line(run("export", default_plan, "-o", default_plan.with_suffix(".json")), "input")
    failed = json.loads(default_plan.read_text())
    failed.update(status="failed", failure={"stage": "grasps", "reason": "none"})
    bad = default_plan.parent / "export-failed.json"
    bad.write_text(json.dumps(failed))
    assert_one_error_line(run("export", bad, "-o", tmp_path / "f.csv"), "solved")
    assert not list(tmp_path.iterdir())
