"""One self-contained HTML file that animates a plan in 3D, in MeshCat's viewer.

Viewing only (not a paper section).  MeshCat (three.js in the browser) is driven by
msgpack-encoded scene commands; its Python package builds them (``meshcat.geometry``,
``meshcat.commands``, ``meshcat.animation``) and ships the viewer as one JavaScript bundle
(``viewer/dist/main.min.js``).  MeshCat's own static export (the ``get_scene`` answer of
its ZeroMQ server, ``meshcat/servers/zmqserver.py``) is that bundle inlined in a page
followed by the base64 commands; we compose the same page ourselves, without starting the
server (no ZeroMQ, no tornado, no network): the bundle and the commands are inlined, and
the commands are decoded and applied in order, synchronously (MeshCat's export goes
through ``fetch`` of ``data:`` URLs, whose order of completion is not guaranteed).

The scene, in the plan's robot base frame W under the node ``/plan`` (translated so that
the middle of the motion is at the viewer's orbit centre):

* ``/plan/robot/<link>``: one node per link with geometry, its shapes below it; the
  link's pose X_WL is an animation track (position and quaternion keys);
* ``/plan/obstacles/<name>``: static; ``/plan/object``: the object, a track of X_WO that
  follows the holding hand while it is carried; ``/plan/goal``: a ghost of the object at
  its goal pose; ``/plan/floor`` and ``/plan/axes`` (x red, y green, z blue at W).

The motion is sampled at ``fps`` per second plus every waypoint time (the robot stops
there), and keys are dropped inside stretches where a node does not move (linear
interpolation between the kept keys gives the same values).  Above MeshCat's canvas the
page shows the current phase, who holds the object and the time; below, play/pause, a
time slider, the speed, and a strip of the phases (click one to jump to its start; the
space bar plays and pauses, the arrow keys step between phases).  MeshCat's own panel
(top right) keeps its scene tree (show or hide any node) and animation controls.
"""

from __future__ import annotations

import base64
import html as html_escape
import json
from importlib.metadata import version
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from regrasp_cli.errors import RegraspError
from regrasp_cli.show.geometry import (VIEW_DIRECTION, Shape, bounds, link_poses, mesh_shape, obstacle_shapes,
                                       shape_triangles)
from regrasp_cli.show.motion import Motion, PlanView, frame_soup, holding_text, key_frames, plan_soups, sample_motion
from regrasp_cli.store import atomic_write_text

KEY_TOL = 1e-6  # m or quaternion units: a key equal to its neighbours within this is dropped
GOAL_OPACITY = 0.3
MAX_FACES = 6000  # triangles of one robot mesh (more are decimated, to keep the page small)
CAMERA_FOV = 40.0  # degrees, vertical
CAMERA_DISTANCE = 2.2  # times the radius of the sphere around the motion
FLOOR_STEP = 0.25  # m between floor grid lines
BACKGROUND = ([0.97, 0.97, 0.98], [0.80, 0.82, 0.86])  # top, bottom colours (RGB in [0, 1])
# MeshCat clips count time in frames of the clip's fps; with 1 frame per second the keys
# are in seconds whatever the sampling rate, and the viewer's time slider reads seconds.
FPS_UNIT = 1.0
R_YZ = np.array([[1.0, 0, 0, 0], [0, 0, -1, 0], [0, 1, 0, 0], [0, 0, 0, 1]])  # three.js cylinders are along y: y -> z


# ------------------------------------------------------------------ MeshCat commands


def _path(*entries: str):
    from meshcat.path import Path as MeshcatPath

    return MeshcatPath(tuple(e.replace("/", "_") for e in entries))


def _hex(rgba) -> int:
    r, g, b = (int(round(255 * float(c))) for c in rgba[:3])
    return (r << 16) | (g << 8) | b


def _set_object(geometry, rgba, path, opacity: float | None = None) -> dict:
    """A ``set_object`` command with uuids made from the path, so that the same plan
    gives the same page."""
    import meshcat.geometry as mg
    from meshcat.commands import SetObject

    alpha = float(rgba[3]) if opacity is None else opacity
    material = mg.MeshLambertMaterial(color=_hex(rgba), opacity=alpha)
    obj = mg.Mesh(geometry, material)
    name = path.lower()
    geometry.uuid, material.uuid, obj.uuid = f"{name}#geometry", f"{name}#material", f"{name}#object"
    return SetObject(obj, path=path).lower()


def _set_transform(X: np.ndarray, path) -> dict:
    from meshcat.commands import SetTransform

    return SetTransform(np.asarray(X, dtype=float), path).lower()


def _set_property(path, key: str, value) -> dict:
    from meshcat.commands import SetProperty

    return SetProperty(key, value, path).lower()


def shape_commands(shape: Shape, path, opacity: float | None = None) -> list[dict]:
    """Commands drawing ``shape`` at node ``path`` (posed by its X_PS in the parent node):
    MeshCat primitives for boxes, spheres and cylinders, triangles otherwise."""
    import meshcat.geometry as mg

    X = shape.X_PS
    if shape.kind == "box":
        geometry = mg.Box(list(shape.size))
    elif shape.kind == "sphere":
        geometry = mg.Sphere(shape.size[0])
    elif shape.kind == "cylinder":
        geometry = mg.Cylinder(shape.size[1], shape.size[0])
        X = X @ R_YZ
    elif shape.kind == "mesh":
        geometry = mg.TriangularMeshGeometry(shape.vertices, shape.faces)
    else:  # capsule: a triangle soup (flat shaded)
        tri = shape_triangles(shape)
        geometry = mg.TriangularMeshGeometry(tri.reshape(-1, 3), np.arange(3 * len(tri)).reshape(-1, 3))
    return [_set_object(geometry, shape.rgba, path, opacity), _set_transform(X, path)]


def _lines(points: np.ndarray, path, rgb: np.ndarray | None = None, colour: int = 0x888888) -> dict:
    """Line segments between consecutive pairs of points (2k, 3), optionally coloured per vertex."""
    import meshcat.geometry as mg
    from meshcat.commands import SetObject

    geometry = mg.PointsGeometry(np.asarray(points, dtype=np.float32).T,
                                 None if rgb is None else np.asarray(rgb, dtype=np.float32).T)
    material = mg.LineBasicMaterial(color=colour, vertexColors=rgb is not None, linewidth=1.0)
    obj = mg.LineSegments(geometry, material)
    name = path.lower()
    geometry.uuid, material.uuid, obj.uuid = f"{name}#geometry", f"{name}#material", f"{name}#object"
    return SetObject(obj, path=path).lower()


def _floor_grid(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Grid lines (2k, 3) covering [lo, hi] in x and y, every FLOOR_STEP, at z = 0 or under
    the lowest point when it is lower (a robot whose root link is its pelvis stands on a
    floor below W's origin)."""
    z = min(float(lo[2]), 0.0)
    x0, x1 = np.floor(lo[0] / FLOOR_STEP - 1) * FLOOR_STEP, np.ceil(hi[0] / FLOOR_STEP + 1) * FLOOR_STEP
    y0, y1 = np.floor(lo[1] / FLOOR_STEP - 1) * FLOOR_STEP, np.ceil(hi[1] / FLOOR_STEP + 1) * FLOOR_STEP
    pts = []
    for x in np.arange(x0, x1 + 1e-9, FLOOR_STEP):
        pts += [[x, y0, z], [x, y1, z]]
    for y in np.arange(y0, y1 + 1e-9, FLOOR_STEP):
        pts += [[x0, y, z], [x1, y, z]]
    return np.array(pts)


def pose_keys(t: np.ndarray, X: np.ndarray, fps: float) -> tuple[dict, dict]:
    """Position and quaternion keys ``{frames, values}`` of poses X (m, 4, 4) at times t
    (m,) s; frames are t * fps (MeshCat's clips count time in frames of the clip's fps).
    Quaternions are [x, y, z, w] (three.js) with signs kept continuous; a key equal to
    both neighbours is dropped (the first and the last are always kept)."""
    p = X[:, :3, 3]
    quat = Rotation.from_matrix(X[:, :3, :3]).as_quat()
    flip = np.ones(len(quat))
    flip[1:] = np.sign(np.einsum("ij,ij->i", quat[1:], quat[:-1]))
    flip[flip == 0] = 1.0
    quat *= np.cumprod(flip)[:, None]
    frames = t * fps
    out = []
    for v in (p, quat):
        change = np.any(np.abs(np.diff(v, axis=0)) > KEY_TOL, axis=1)
        keep = np.ones(len(v), dtype=bool)
        if len(v) > 2:
            keep[1:-1] = change[:-1] | change[1:]
        out.append({"frames": frames[keep].tolist(), "values": v[keep].tolist()})
    return out[0], out[1]


def animation_command(tracks: dict, fps: float) -> dict:
    """A ``set_animation`` command: ``tracks`` maps a node path to (position keys,
    quaternion keys) from :func:`pose_keys`; it starts playing once, from 0."""
    from meshcat.animation import Animation, AnimationClip, AnimationTrack
    from meshcat.commands import SetAnimation

    clips = {}
    for path, (pos, quat) in tracks.items():
        clip = AnimationClip(fps=fps, name=path.lower())
        clip.tracks = {"position": AnimationTrack("position", "vector3", pos["frames"], pos["values"]),
                       "quaternion": AnimationTrack("quaternion", "quaternion", quat["frames"], quat["values"])}
        clips[path] = clip
    return SetAnimation(Animation(clips, default_framerate=fps), play=True, repetitions=1).lower()


def scene_commands(view: PlanView, motion: Motion, source: str = "visual") -> tuple[list[dict], dict]:
    """The static scene and the animation of ``motion``: (commands in order, the
    ``set_animation`` command)."""
    soups = plan_soups(view, source, max_faces=MAX_FACES)
    frames = key_frames(view)
    b = np.array([bounds(frame_soup(view, soups, kf.q, kf.X_WO)) for kf in frames])
    lo, hi = b[:, 0].min(axis=0), b[:, 1].max(axis=0)
    centre = (lo + hi) / 2
    radius = float(np.linalg.norm(hi - lo)) / 2

    cmds = [_set_property(_path("Grid"), "visible", False), _set_property(_path("Axes"), "visible", False),
            _set_property(_path("Background"), "top_color", BACKGROUND[0]),
            _set_property(_path("Background"), "bottom_color", BACKGROUND[1])]
    X_shift = np.eye(4)
    X_shift[:3, 3] = -centre
    cmds.append(_set_transform(X_shift, _path("plan")))
    # camera: a narrower field of view than MeshCat's 75 degrees (less distortion), far
    # enough to hold the motion; MeshCat's camera node is turned so that its y is W's z
    camera = _path("Cameras", "default", "rotated", "<object>")
    d = CAMERA_DISTANCE * radius * VIEW_DIRECTION
    cmds.append(_set_property(camera, "fov", CAMERA_FOV))
    cmds.append(_set_property(camera, "position", [float(d[0]), float(d[2]), float(-d[1])]))
    cmds.append(_lines(_floor_grid(lo, hi), _path("plan", "floor"), colour=0xb0b0b0))
    axes = np.array([[0, 0, 0], [0.2, 0, 0], [0, 0, 0], [0, 0.2, 0], [0, 0, 0], [0, 0, 0.2]], dtype=float)
    rgb = np.repeat(np.eye(3), 2, axis=0)
    cmds.append(_lines(axes, _path("plan", "axes"), rgb))

    for s in obstacle_shapes(view.inputs.obstacles):
        cmds += shape_commands(s, _path("plan", "obstacles", s.name))
    obj = mesh_shape("mesh", view.inputs.mesh)
    cmds += shape_commands(obj, _path("plan", "object", "mesh"))
    goal = view.plan.placement("goal")
    if goal is not None:
        cmds += shape_commands(obj, _path("plan", "goal", "mesh"), opacity=GOAL_OPACITY)
        cmds.append(_set_transform(goal.X_WO, _path("plan", "goal")))

    X_WL = np.array([link_poses(view.kin, soups.links, q) for q in motion.q])  # (m, L, 4, 4)
    tracks = {}
    for i, ls in enumerate(soups.links):
        node = _path("plan", "robot", ls.link)
        for s in ls.shapes:
            cmds += shape_commands(s, _path("plan", "robot", ls.link, s.name))
        cmds.append(_set_transform(X_WL[0, i], node))
        tracks[node] = pose_keys(motion.t, X_WL[:, i], FPS_UNIT)
    node = _path("plan", "object")
    cmds.append(_set_transform(motion.X_WO[0], node))
    tracks[node] = pose_keys(motion.t, motion.X_WO, FPS_UNIT)
    return cmds, animation_command(tracks, FPS_UNIT)


def _encode(command: dict, single: bool = False) -> str:
    import umsgpack

    data = umsgpack.packb(command, force_float_precision="single") if single else umsgpack.packb(command)
    return base64.b64encode(data).decode("ascii")


def viewer_bundle() -> tuple[str, str]:
    """(MeshCat's viewer JavaScript, the meshcat package version)."""
    import meshcat

    path = Path(meshcat.viewer_assets_path()) / "dist" / "main.min.js"
    try:
        return path.read_text(encoding="utf-8"), version("meshcat")
    except OSError as exc:
        raise RegraspError(f"MeshCat's viewer bundle is missing ({path}: {exc.strerror or exc}); "
                           "reinstall the meshcat package") from None


# ------------------------------------------------------------------ the page


def _json_for_script(obj) -> str:
    """JSON safe inside a <script> element (no ``<`` at all: ``\\u003c`` is the same string)."""
    return json.dumps(obj, separators=(",", ":")).replace("<", "\\u003c")


def plan_page(view: PlanView, fps: float = 25.0, source: str = "visual") -> str:
    """The HTML page (a string) animating the plan; see the module docstring."""
    motion = sample_motion(view, fps)
    cmds, anim = scene_commands(view, motion, source)
    bundle, meshcat_version = viewer_bundle()
    plan = view.plan
    phases = [{"name": p.name, "start": float(p.times[0]), "end": float(p.times[-1]),
               "kind": p.kind.value, "holding": list(p.holding),
               "text": f"{holding_text(p.holding, p.touching, p.kind)} ({p.kind.value})"} for p in plan.phases]
    scene_name = Path(str(plan.scene.get("file", ""))).name or view.file.name
    data = {
        "title": f"{view.file.name}: {scene_name}, {plan.planner} planner, seed {plan.seed}",
        "duration": view.duration,
        "phases": phases,
        "keyframes": [{"name": kf.name, "t": kf.t} for kf in key_frames(view)],
        "commands": [_encode(c) for c in cmds] + [_encode(anim, single=True)],
    }
    # "</script" cannot occur in MeshCat's bundle outside strings and regular expressions,
    # where "<\\/script" means the same; escaped so that it never closes the element early
    bundle = bundle.replace("</script", "<\\/script")
    return PAGE.format(title=html_escape.escape(data["title"]), meshcat_version=html_escape.escape(meshcat_version),
                       bundle=bundle, data=_json_for_script(data), script=SCRIPT, style=STYLE)


def write_plan_html(view: PlanView, path: str | Path, fps: float = 25.0, source: str = "visual") -> Path:
    """Write the page atomically; returns its path."""
    path = Path(path)
    atomic_write_text(path, plan_page(view, fps, source))
    return path


STYLE = """
body { margin: 0; font-family: system-ui, sans-serif; overflow: hidden; }
#meshcat-pane { width: 100vw; height: 100vh; overflow: hidden; }
#hud { position: absolute; left: 12px; top: 10px; padding: 8px 12px; background: rgba(255,255,255,0.85);
       border-radius: 6px; font-size: 13px; color: #222; max-width: 60vw; pointer-events: none; }
#hud .phase { font-size: 20px; font-weight: 600; }
#bar { position: absolute; left: 0; right: 0; bottom: 0; padding: 8px 12px 10px; background: rgba(255,255,255,0.9);
       font-size: 13px; }
#row { display: flex; align-items: center; gap: 10px; }
#time { flex: 1; }
#play { width: 70px; }
#strip { display: flex; margin-top: 6px; height: 22px; border-radius: 4px; overflow: hidden; cursor: pointer; }
#strip div { overflow: hidden; white-space: nowrap; text-overflow: ellipsis; font-size: 11px; line-height: 22px;
             text-align: center; border-right: 1px solid #fff; color: #111; }
#strip div.active { outline: 2px solid #222; outline-offset: -2px; font-weight: 600; }
"""

SCRIPT = r"""
(function () {
  const data = JSON.parse(document.getElementById("plan-data").textContent);
  const viewer = new MeshCat.Viewer(document.getElementById("meshcat-pane"));
  window.viewer = viewer;
  for (const b64 of data.commands) {
    const bin = atob(b64);
    const bytes = new Uint8Array(bin.length);
    for (let i = 0; i < bin.length; i++) bytes[i] = bin.charCodeAt(i);
    viewer.handle_command_bytearray(bytes);
  }
  viewer.set_3d_pane_size();  // applies the camera's field of view
  const anim = viewer.animator, T = data.duration, phases = data.phases;
  const colours = {"": "#d9d9d9", "right": "#9ecae1", "left": "#fdae6b"};
  const slider = document.getElementById("time"), clock = document.getElementById("clock");
  const play = document.getElementById("play"), strip = document.getElementById("strip");
  const hudPhase = document.getElementById("phase"), hudText = document.getElementById("phase-text");
  document.getElementById("title").textContent = data.title;
  slider.max = T;
  phases.forEach((p, i) => {
    const d = document.createElement("div");
    d.style.flexGrow = Math.max(p.end - p.start, T / 200);
    d.style.background = p.holding.length > 1 ? "#c7a6d6" : colours[p.holding[0] || ""] || "#d9d9d9";
    d.textContent = p.name;
    d.title = p.name + " (" + p.start.toFixed(2) + " to " + p.end.toFixed(2) + " s): object " + p.text;
    d.addEventListener("click", () => seek(p.start));
    strip.appendChild(d);
  });
  function phaseAt(t) {
    let k = 0;
    for (let i = 0; i < phases.length; i++) if (phases[i].start <= t) k = i;
    return k;
  }
  function seek(t) {
    t = Math.max(0, Math.min(T, t));
    anim.seek(t);
    anim.display_progress(t);
  }
  function toggle() {
    if (anim.playing) { anim.pause(); return; }
    if (anim.time >= T - 1e-3) seek(0);
    anim.play();
  }
  play.addEventListener("click", toggle);
  slider.addEventListener("input", () => { if (anim.playing) anim.pause(); seek(parseFloat(slider.value)); });
  document.getElementById("speed").addEventListener("change", (e) => { anim.mixer.timeScale = parseFloat(e.target.value); });
  document.addEventListener("keydown", (e) => {
    if (e.target.tagName === "INPUT" && e.target.type !== "range") return;
    if (e.code === "Space") { toggle(); e.preventDefault(); }
    const k = phaseAt(anim.time);
    if (e.code === "ArrowRight" && k + 1 < phases.length) { anim.pause(); seek(phases[k + 1].start); }
    if (e.code === "ArrowLeft") { anim.pause(); seek(anim.time - phases[k].start > 0.05 || k === 0 ? phases[k].start : phases[k - 1].start); }
  });
  let shown = -1;
  function update() {
    const t = anim.time || 0;
    if (document.activeElement !== slider) slider.value = t;
    clock.textContent = t.toFixed(2) + " / " + T.toFixed(2) + " s";
    play.textContent = anim.playing ? "pause" : "play";
    const k = phaseAt(t);
    if (k !== shown) {
      shown = k;
      hudPhase.textContent = (k + 1) + "/" + phases.length + " " + phases[k].name;
      hudText.textContent = "object " + phases[k].text;
      Array.from(strip.children).forEach((d, i) => d.classList.toggle("active", i === k));
    }
    requestAnimationFrame(update);
  }
  update();
})();
"""

PAGE = """<!DOCTYPE html>
<html>
<head>
<meta charset="utf-8">
<title>{title}</title>
<!-- Made by regrasp show.  Viewer: MeshCat {meshcat_version} (MIT licence), with three.js
     and the other libraries of its bundle (their licences: the meshcat Python package,
     viewer/dist/main.min.js.LICENSE.txt).  Everything is in this file: no server, no network. -->
<style>{style}</style>
</head>
<body>
<div id="meshcat-pane"></div>
<div id="hud"><div id="title"></div><div class="phase" id="phase"></div><div id="phase-text"></div></div>
<div id="bar">
  <div id="row">
    <button id="play">play</button>
    <input id="time" type="range" min="0" max="1" step="0.01" value="0">
    <span id="clock"></span>
    <label>speed <select id="speed"><option value="0.25">0.25x</option><option value="0.5">0.5x</option>
      <option value="1" selected>1x</option><option value="2">2x</option><option value="4">4x</option></select></label>
  </div>
  <div id="strip"></div>
</div>
<script>
{bundle}
</script>
<script id="plan-data" type="application/json">{data}</script>
<script>
{script}
</script>
</body>
</html>
"""
