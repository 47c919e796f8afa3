"""`regrasp show --html`: one self-contained file (MeshCat's viewer and the scene inlined,
nothing fetched from a network) whose animation moves every link with geometry and the
object, over the whole plan, with the plan's phases; the same plan gives the same bytes."""

from __future__ import annotations

import base64
import json
import re

import numpy as np
import pytest
import umsgpack

from regrasp_cli.manip.modes import Kind
from regrasp_cli.model.robot import Kinematics
from regrasp_cli.show.geometry import robot_links
from regrasp_cli.show.html import pose_keys
from regrasp_cli.spatial import inverse


def page_data(page) -> dict:
    text = page.read_text(encoding="utf-8")
    m = re.search(r'<script id="plan-data" type="application/json">(.*?)</script>', text, re.S)
    assert m, "no plan data in the page"
    return json.loads(m.group(1))


def commands(page) -> list[dict]:
    return [umsgpack.unpackb(base64.b64decode(c)) for c in page_data(page)["commands"]]


@pytest.fixture(scope="module")
def page(shown):
    result, page, _ = shown
    assert result.exit_code == 0, (result.output, result.exception)
    assert f"html: {page}" in result.stdout
    return page


def test_the_page_is_one_self_contained_file(page):
    text = page.read_text(encoding="utf-8")
    assert text.startswith("<!DOCTYPE html>") and text.rstrip().endswith("</html>")
    assert "MeshCat.Viewer" in text  # the viewer bundle is inlined
    assert not re.search(r"<script[^>]*\ssrc\s*=", text, re.I), "a script is loaded from elsewhere"
    assert not re.search(r"<link[^>]*\shref\s*=", text, re.I), "a stylesheet or resource is loaded from elsewhere"
    urls = set(re.findall(r"https?://[^\s\"'<>)]+", text))
    assert all(u.startswith("http://www.w3.org/") for u in urls), urls  # XML namespace names only
    assert "viewer.connect(" not in text  # MeshCat's viewer is never connected to a server
    assert page.stat().st_size < 10e6


def test_every_link_and_the_object_are_animated_over_the_whole_plan(page, view):
    cmds = commands(page)
    anim = cmds[-1]
    assert anim["type"] == "set_animation" and anim["options"]["play"] is True
    clips = {a["path"]: a["clip"] for a in anim["animations"]}
    links = robot_links(view.inputs.robot)
    expected = {f"/plan/robot/{ls.link}" for ls in links} | {"/plan/object"}
    assert set(clips) == expected
    for path, clip in clips.items():
        tracks = {t["name"]: t["keys"] for t in clip["tracks"]}
        assert set(tracks) == {".position", ".quaternion"}, path
        for keys in tracks.values():
            times = [k["time"] / clip["fps"] for k in keys]
            assert times[0] == 0.0 and times[-1] == pytest.approx(view.duration, abs=1e-3), path
    # every shape of every link is drawn below its link's node
    drawn = {c["path"] for c in cmds if c["type"] == "set_object"}
    for ls in links:
        for s in ls.shapes:
            assert f"/plan/robot/{ls.link}/{s.name}" in drawn


def test_the_object_track_passes_through_the_exchange_pose(page, view):
    """The object's position keys, interpolated as the viewer does (linearly), put it at
    the start placement first, and at the end of the carry (the first transfer) where the
    carrying hand's grasp puts it: the exchange pose (keys are float32)."""
    anim = commands(page)[-1]
    clip = next(a["clip"] for a in anim["animations"] if a["path"] == "/plan/object")
    keys = next(t["keys"] for t in clip["tracks"] if t["name"] == ".position")
    carry = next(p for p in view.plan.phases if p.kind == Kind.TRANSFER)
    (hand, gid), = carry.holding.items()
    robot = view.inputs.robot
    X_exchange = Kinematics(robot).fk(carry.waypoints[-1], robot.hands[hand].grasp_frame) @ inverse(view.plan.grasp(gid).X_OG)
    times = np.array([k["time"] / clip["fps"] for k in keys])
    values = np.array([k["value"] for k in keys])
    p = [np.interp(float(carry.times[-1]), times, values[:, j]) for j in range(3)]
    np.testing.assert_allclose(p, X_exchange[:3, 3], atol=1e-4)
    np.testing.assert_allclose(values[0], view.plan.placement("start").X_WO[:3, 3], atol=1e-5)


def test_the_page_lists_the_phases_and_key_frames(page, view):
    data = page_data(page)
    assert [p["name"] for p in data["phases"]] == [p.name for p in view.plan.phases]
    for p, ph in zip(data["phases"], view.plan.phases):
        assert p["start"] == pytest.approx(ph.times[0]) and p["end"] == pytest.approx(ph.times[-1])
        assert p["holding"] == list(ph.holding) and p["kind"] == ph.kind.value
    assert data["duration"] == pytest.approx(view.duration)
    assert [k["name"] for k in data["keyframes"]] == ["start", "pick", "exchange", "place", "end"]


def test_the_same_plan_gives_the_same_page(view, tmp_path):
    from regrasp_cli.show.html import write_plan_html

    a, b = write_plan_html(view, tmp_path / "a.html", fps=5), write_plan_html(view, tmp_path / "b.html", fps=5)
    assert a.read_bytes() == b.read_bytes()


def test_pose_keys_drop_only_what_interpolation_restores():
    """A pose at rest, then moving, then at rest: the kept keys interpolate linearly back
    to every sample; quaternion signs stay continuous across a flip of the input."""
    t = np.linspace(0.0, 2.0, 21)
    X = np.tile(np.eye(4), (21, 1, 1))
    x = np.clip(t - 0.5, 0.0, 1.0)  # rest until 0.5 s, moves 1 m/s until 1.5 s, rests
    X[:, 0, 3] = x
    pos, quat = pose_keys(t, X, fps=1.0)
    assert len(pos["frames"]) < len(t)
    assert pos["frames"][0] == 0.0 and pos["frames"][-1] == 2.0
    back = np.interp(t, pos["frames"], np.array(pos["values"])[:, 0])
    np.testing.assert_allclose(back, x, atol=1e-12)
    assert len(quat["frames"]) == 2  # the orientation never changes

    from scipy.spatial.transform import Rotation

    angles = np.linspace(0.0, 2 * np.pi, 9)  # a full turn: scipy's quaternions flip sign on the way
    R = Rotation.from_rotvec(np.outer(angles, [0.0, 0.0, 1.0])).as_matrix()
    X = np.tile(np.eye(4), (9, 1, 1))
    X[:, :3, :3] = R
    _, quat = pose_keys(np.arange(9.0), X, fps=1.0)
    q = np.array(quat["values"])
    assert np.all(np.einsum("ij,ij->i", q[1:], q[:-1]) > 0)



def test_the_floor_is_under_the_lowest_point_when_it_is_below_the_root():
    """A robot whose root link is its pelvis: its feet and the table legs below W's origin
    stand on the floor, not through it (issue 41); otherwise the floor is at z = 0."""
    from regrasp_cli.show.html import _floor_grid

    assert np.all(_floor_grid(np.array([-1.0, -1.0, -0.95]), np.ones(3))[:, 2] == -0.95)
    assert np.all(_floor_grid(np.array([-1.0, -1.0, 0.3]), np.ones(3))[:, 2] == 0.0)
