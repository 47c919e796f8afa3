"""docs/FORMAT.md is enough to implement a plan's motion (issue 43): the functions below
follow its section 4 formulas alone, reading the plan file with ``json`` (nothing of
``regrasp_cli.motion``), and give what `regrasp export` samples to 1e-9, on the default
scene's plan (blended phases on speed grids, stop-at-every-waypoint phases) and an
in-hand plan (the object's poses between waypoints too)."""

from __future__ import annotations

import json

import numpy as np

from regrasp_cli.export import sample_plan
from regrasp_cli.replay import load_inputs
from regrasp_cli.trajectory import read_plan


# ------------------------------------------------------------------ FORMAT.md, section 4.1


def stops_motion(w: np.ndarray, times: np.ndarray, v: np.ndarray, a: np.ndarray, t: float):
    k = min(max(int(np.searchsorted(times, t, side="right")) - 1, 0), len(w) - 2)
    T, tau, dq = times[k + 1] - times[k], min(max(t - times[k], 0.0), times[k + 1] - times[k]), w[k + 1] - w[k]
    c_a = np.max(np.abs(dq) / a)
    if not np.any(dq):
        return w[k].copy(), np.zeros_like(dq), np.zeros_like(dq)
    V = 2 / (T + np.sqrt(max(T * T - 4 * c_a, 0.0)))
    R = min(V * c_a, T / 2)
    if tau < R:
        s, sd, sdd = V * tau * tau / (2 * R), V * tau / R, V / R
    elif tau > T - R:
        s, sd, sdd = 1 - V * (T - tau) ** 2 / (2 * R), V * (T - tau) / R, -V / R
    else:
        s, sd, sdd = V * (tau - R / 2), V, 0.0
    return w[k] + s * dq, sd * dq, sdd * dq


# ------------------------------------------------------------------ FORMAT.md, section 4.2


def pieces(w: np.ndarray, r: np.ndarray) -> list[tuple[np.ndarray, np.ndarray, np.ndarray, float]]:
    out = []
    L = np.linalg.norm(np.diff(w, axis=0), axis=1)
    d = np.diff(w, axis=0) / L[:, None]
    for i in range(len(w) - 1):
        if i > 0 and r[i] > 0:
            out.append((w[i] - r[i] * d[i - 1], w[i], w[i] + r[i] * d[i], 2 * r[i]))
        p0 = w[i] + r[i] * d[i] if r[i] > 0 else w[i]
        p1 = w[i + 1] - r[i + 1] * d[i] if r[i + 1] > 0 else w[i + 1]
        lam = float(np.linalg.norm(p1 - p0))
        if lam > 1e-12 * max(1.0, L[i]):
            out.append((p0, (p0 + p1) / 2, p1, lam))
    return out


def path_at(ps, s: float, from_below: bool):
    S = np.concatenate([[0.0], np.cumsum([p[3] for p in ps])])
    k = int(np.searchsorted(S, s, side="left" if from_below else "right")) - 1
    k = min(max(k, 0), len(ps) - 1)
    A, C, B, lam = ps[k]
    u = min(max((s - S[k]) / lam, 0.0), 1.0)
    return ((1 - u) ** 2 * A + 2 * u * (1 - u) * C + u * u * B, 2 * ((1 - u) * (C - A) + u * (B - C)) / lam,
            2 * (A - 2 * C + B) / lam ** 2)


def blended_motion(w: np.ndarray, r: np.ndarray, grid: dict, t: float):
    s_g, v_g, t_g = (np.asarray(grid[k], float) for k in ("s", "speed", "t"))
    t = min(max(t, t_g[0]), t_g[-1])
    k = min(int(np.searchsorted(t_g, t, side="right")) - 1, len(t_g) - 2)
    u = (v_g[k + 1] ** 2 - v_g[k] ** 2) / (2 * (s_g[k + 1] - s_g[k]))
    tau = t - t_g[k]
    s = min(s_g[k] + v_g[k] * tau + u * tau * tau / 2, s_g[k + 1])
    sd = max(v_g[k] + u * tau, 0.0)
    if t >= t_g[-1]:
        s, sd = s_g[-1], v_g[-1]
    P, dP, ddP = path_at(pieces(w, r), s, from_below=s >= s_g[k + 1])
    return P, dP * sd, ddP * sd * sd + dP * u


def motion(d: dict, t: float):
    """q, qd, qdd of the plan dict ``d`` at time t: the phase that starts at or before t."""
    starts = [p["times"][0] for p in d["phases"]]
    k = min(max(int(np.searchsorted(starts, t, side="right")) - 1, 0), len(d["phases"]) - 1)
    p = d["phases"][k]
    w, times = np.array(p["waypoints"], float), np.array(p["times"], float)
    if p.get("timing") is None:
        lim = d["limits"]
        return stops_motion(w, times, np.array(lim["velocity"]), np.array(lim["acceleration"]), t)
    return blended_motion(w, np.array(p["blends"], float), p["timing"], t)


# ------------------------------------------------------------------ FORMAT.md, section 4.3


def inhand_pose(d: dict, t: float, q: np.ndarray) -> np.ndarray | None:
    """The object's pose at t in a phase with ``object_poses`` (None in others)."""
    starts = [p["times"][0] for p in d["phases"]]
    p = d["phases"][min(max(int(np.searchsorted(starts, t, side="right")) - 1, 0), len(d["phases"]) - 1)]
    if p.get("object_poses") is None:
        return None
    w, times, X = np.array(p["waypoints"]), np.array(p["times"]), np.array(p["object_poses"])
    i = min(max(int(np.searchsorted(times, t, side="right")) - 1, 0), len(w) - 2)
    dq = w[i + 1] - w[i]
    f = float(np.clip((q - w[i]) @ dq / (dq @ dq), 0, 1)) if dq @ dq > 0 else 0.0
    R = X[i, :3, :3].T @ X[i + 1, :3, :3]  # slerp: the rotation's angle scaled by f about its axis
    angle = np.arccos(np.clip((np.trace(R) - 1) / 2, -1, 1))
    out = np.eye(4)
    out[:3, 3] = (1 - f) * X[i, :3, 3] + f * X[i + 1, :3, 3]
    if angle < 1e-12:
        out[:3, :3] = X[i, :3, :3]
        return out
    axis = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]]) / (2 * np.sin(angle))
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    a = f * angle
    out[:3, :3] = X[i, :3, :3] @ (np.eye(3) + np.sin(a) * K + (1 - np.cos(a)) * K @ K)
    return out


# ------------------------------------------------------------------ against the export


def _matches(path) -> int:
    d = json.loads(path.read_text())
    plan = read_plan(path)
    s = sample_plan(plan, path, load_inputs(plan, path), 50.0)
    for i in range(len(s.t)):
        q, qd, qdd = motion(d, float(s.t[i]))
        assert np.abs(q - s.q[i]).max() < 1e-9, (i, s.t[i])
        assert np.abs(qd - s.qd[i]).max() < 1e-9, (i, s.t[i])
        assert np.abs(qdd - s.qdd[i]).max() < 1e-9, (i, s.t[i])
        X = inhand_pose(d, float(s.t[i]), q)
        assert X is None or np.abs(X - s.X_WO[i]).max() < 1e-9, (i, s.t[i])
    return len(s.t)


def test_format_md_gives_the_exported_motion_of_a_pick_and_place_plan(default_plan):
    d = json.loads(default_plan.read_text())
    kinds = {p.get("timing") is None for p in d["phases"]}
    assert kinds == {True, False}  # both kinds of phase are exercised
    assert _matches(default_plan) > 500


def test_format_md_gives_the_exported_motion_of_an_inhand_plan(tmp_path, cache_dir):
    from cli_helpers import run
    from conftest import ROOT

    out = tmp_path / "inhand.json"
    scene = ROOT / "regrasp_cli" / "data" / "scenes" / "inhand_ball.yaml"
    result = run("--cache-dir", cache_dir, "inhand", "plan", scene, "-o", out, "--no-timings")
    assert result.exit_code == 0, result.output
    assert _matches(out) > 100
