"""Pictures of a plan's key frames and of a grasp list, drawn with matplotlib (Agg, no
display needed).

Viewing only (not a paper section).  A scene is one :class:`~.geometry.Soup` of triangles
in the robot base frame W, drawn as a single ``Poly3DCollection`` so that matplotlib's
painter's algorithm sorts every triangle against every other (separate collections would
be sorted as wholes and overlap wrongly).  Faces are shaded by a fixed light (Lambert
with an ambient term), and every key frame of a plan uses the same camera: the view
direction of :data:`~.geometry.VIEW_DIRECTION` and limits that hold the whole motion.

Sizes are pixels; files are written atomically (:func:`regrasp_cli.store.atomic_write_bytes`).
"""

from __future__ import annotations

import io
from pathlib import Path
from typing import Sequence

import numpy as np

from regrasp_cli.model.robot import Kinematics
from regrasp_cli.show.geometry import (VIEW_DIRECTION, Soup, bounds, hand_links, link_poses, mesh_shape,
                                       robot_links, robot_soup, shapes_soup)
from regrasp_cli.show.motion import KeyFrame, PlanView, frame_soup, holding_text, key_frames, plan_soups
from regrasp_cli.store import atomic_write_bytes

DPI = 100
LIGHT = np.array([0.4, -0.3, 0.85]) / np.linalg.norm([0.4, -0.3, 0.85])  # towards the light, in W
AMBIENT = 0.45
FLOOR_RGBA = (0.93, 0.93, 0.93, 1.0)
CONTACT_COLOUR = "#d01c8b"  # magenta: apart from the frame axes' red, green and blue
NORMAL_LENGTH = 0.03  # m, drawn contact normals
AXIS_LENGTH = 0.04  # m, drawn grasp frame axes
MAX_EDGE = 0.1  # m: longer triangles are cut so that depth sorting works
MAX_FACES = 1500  # triangles of one robot mesh (more are decimated: matplotlib draws every one)


def _matplotlib():
    """matplotlib's Figure and 3D collections, without pyplot: no global figure state and
    no backend switch in the caller's process (a Figure renders to PNG with Agg itself)."""
    from matplotlib.figure import Figure
    from mpl_toolkits.mplot3d.art3d import Line3DCollection, Poly3DCollection

    return Figure, Poly3DCollection, Line3DCollection


def view_angles(direction: np.ndarray = VIEW_DIRECTION) -> tuple[float, float]:
    """matplotlib's (elevation, azimuth) in degrees for a camera looking from ``direction``
    (3,) (from the scene towards the camera, in W)."""
    d = np.asarray(direction, dtype=float)
    return float(np.degrees(np.arctan2(d[2], np.hypot(d[0], d[1])))), float(np.degrees(np.arctan2(d[1], d[0])))


def shade(soup: Soup, light: np.ndarray = LIGHT, ambient: float = AMBIENT) -> np.ndarray:
    """Face colours (n, 4): each triangle's colour scaled by ``ambient + (1 - ambient) |n . l|``
    (two-sided, so meshes of either winding look the same)."""
    tri = soup.triangles
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    norm = np.linalg.norm(n, axis=1, keepdims=True)
    n = np.divide(n, norm, out=np.zeros_like(n), where=norm > 0)
    k = ambient + (1.0 - ambient) * np.abs(n @ light)
    out = soup.rgba.copy()
    out[:, :3] = np.clip(out[:, :3] * k[:, None], 0.0, 1.0)
    return out


def _cube(ax, lo: np.ndarray, hi: np.ndarray, margin: float = 0.03) -> None:
    """Equal scales on the three axes, holding the box [lo, hi] (m)."""
    centre, half = (lo + hi) / 2, (hi - lo).max() / 2 * (1 + margin)
    ax.set_xlim(centre[0] - half, centre[0] + half)
    ax.set_ylim(centre[1] - half, centre[1] + half)
    ax.set_zlim(centre[2] - half, centre[2] + half)
    ax.set_box_aspect((1, 1, 1), zoom=1.4)


def _draw_soup(ax, Poly3DCollection, soup: Soup, zorder: int = 1, edges: bool = True) -> None:
    colours = shade(soup)
    pc = Poly3DCollection(soup.triangles, facecolors=colours, edgecolors=colours if edges else "none",
                          linewidths=0.15 if edges else 0.0)
    pc.set_zorder(zorder)
    pc.set_clip_on(False)  # the 3D box is drawn in a square; let a wide scene use the whole picture
    ax.add_collection3d(pc)


def _floor(lo: np.ndarray, hi: np.ndarray, z: float = 0.0, margin: float = 0.2) -> Soup:
    """A floor rectangle under the scene's bounds [lo, hi] at height z, ``margin`` wider (m)."""
    x0, y0, x1, y1 = lo[0] - margin, lo[1] - margin, hi[0] + margin, hi[1] + margin
    quad = np.array([[[x0, y0, z], [x1, y0, z], [x1, y1, z]], [[x0, y0, z], [x1, y1, z], [x0, y1, z]]])
    return Soup(quad, np.tile(FLOOR_RGBA, (2, 1))).subdivided(4 * MAX_EDGE)


def _png_bytes(fig) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=DPI)
    return buf.getvalue()


# ------------------------------------------------------------------ a plan's key frames


def key_frame_pngs(view: PlanView, size: tuple[int, int] = (960, 720), source: str = "visual",
                   frames: Sequence[KeyFrame] | None = None) -> list[tuple[str, bytes]]:
    """PNG images of the key frames: ``[(file name, bytes)]`` with names ``01_start.png``,
    ``02_pick.png``, ...  ``size`` is (width, height) in pixels."""
    Figure, Poly3DCollection, _ = _matplotlib()
    frames = key_frames(view) if frames is None else frames
    soups = plan_soups(view, source, MAX_EDGE, MAX_FACES)
    scenes = [frame_soup(view, soups, kf.q, kf.X_WO) for kf in frames]
    b = np.array([bounds(s) for s in scenes])
    lo, hi = b[:, 0].min(axis=0), b[:, 1].max(axis=0)
    lo[2] = min(lo[2], 0.0)  # the floor: at z = 0, or under the lowest point (a robot rooted at its pelvis)
    elev, azim = view_angles()
    scene_name = Path(str(view.plan.scene.get("file", view.file.name))).name
    out = []
    for i, (kf, scene) in enumerate(zip(frames, scenes), start=1):
        fig = Figure(figsize=(size[0] / DPI, size[1] / DPI), dpi=DPI)
        ax = fig.add_axes((0.0, 0.0, 1.0, 0.9), projection="3d")
        ax.computed_zorder = False
        ax.set_axis_off()
        _draw_soup(ax, Poly3DCollection, _floor(lo, hi, lo[2]), zorder=0, edges=False)
        _draw_soup(ax, Poly3DCollection, scene, zorder=1)
        _cube(ax, lo, hi)
        ax.view_init(elev=elev, azim=azim)
        phase = view.plan.phases[kf.phase]
        when = "start of" if kf.name == "start" else "end of"
        fig.suptitle(f"{i}/{len(frames)} {kf.name}: {when} {phase.name}, t = {kf.t:.2f} s of {view.duration:.2f} s",
                     y=0.975, fontsize=13)
        fig.text(0.5, 0.915, f"{scene_name}: object {holding_text(phase.holding, phase.touching, phase.kind)}",
                 ha="center", fontsize=10, color="0.3")
        out.append((f"{i:02d}_{kf.name}.png", _png_bytes(fig)))
    return out


def write_key_frames(view: PlanView, directory: str | Path, size: tuple[int, int] = (960, 720),
                     source: str = "visual") -> list[Path]:
    """Write the key frame pictures into ``directory`` (created); returns their paths."""
    directory = Path(directory)
    paths = []
    for name, data in key_frame_pngs(view, size, source):
        atomic_write_bytes(directory / name, data)
        paths.append(directory / name)
    return paths


# ------------------------------------------------------------------ a grasp list


def hand_soup_in_grasp_frame(robot, hand: str, finger_q: np.ndarray, source: str = "visual") -> Soup:
    """The hand's links (palm and fingers) with its finger joints at ``finger_q``
    (n_hand_joints,) (robot.yaml order), in the hand's grasp frame G."""
    from regrasp_cli.spatial import inverse

    links = hand_links(robot, robot_links(robot, source, MAX_FACES), hand)
    h = robot.hands[hand]
    q = robot.q_rest.copy()
    q[h.idx] = finger_q
    kin = Kinematics(robot)
    X_GW = inverse(kin.fk(q, h.grasp_frame))
    return robot_soup(links, X_GW @ link_poses(kin, links, q))


def grasps_png(glist, object_mesh, best: int = 10, robot=None, size_per_grasp: int = 320,
               title: str = "") -> bytes:
    """A grid picture of the ``best`` first grasps of a grasp list, in the object frame O:
    the object, the hand (when ``robot`` is given) at the grasp's finger values, the grasp
    frame's axes (x red, y green, z blue), the contacts and their outward normals (magenta).

    Args:
        glist: a :class:`~regrasp_cli.grasp.build.GraspList` (best first).
        object_mesh: the object's ``trimesh.Trimesh`` in frame O (m).
        best: how many grasps (the first ones of the list); at least 1.
        robot: the :class:`~regrasp_cli.model.robot.Robot` the list is for, or None.
        size_per_grasp: pixels of one cell of the grid (square).
    """
    Figure, Poly3DCollection, Line3DCollection = _matplotlib()
    n = max(0, min(best, len(glist)))
    cols = max(1, min(5, n))
    rows = max(1, -(-n // cols))
    obj = shapes_soup([mesh_shape("object", object_mesh, rgba=(0.85, 0.85, 0.85, 1.0))])
    lo, hi = bounds(obj)
    reach = float(np.linalg.norm(hi - lo)) * 0.45 + 0.03  # the hand around the object
    centre = (lo + hi) / 2
    elev, azim = view_angles()
    header = 0.6  # inches for the title
    fig = Figure(figsize=(cols * size_per_grasp / DPI, rows * size_per_grasp / DPI + header), dpi=DPI)
    fig.suptitle(title or f"best {n} of {len(glist)} grasps, {glist.hand} hand", fontsize=13)
    if n == 0:
        fig.text(0.5, 0.5, "the list is empty", ha="center")
    top = 1.0 - header / (rows * size_per_grasp / DPI + header)
    for i in range(n):
        r, c = divmod(i, cols)
        ax = fig.add_axes((c / cols, top - (r + 1) * top / rows, 1 / cols, top / rows * 0.92), projection="3d")
        ax.computed_zorder = False
        ax.set_axis_off()
        X_OG = glist.X_OG[i]
        parts = [obj]
        if robot is not None:
            hand = hand_soup_in_grasp_frame(robot, glist.hand, glist.finger_q[i])
            parts.append(hand.moved(X_OG))
        _draw_soup(ax, Poly3DCollection, Soup.join(parts), zorder=1)
        axes = [[X_OG[:3, 3], X_OG[:3, 3] + AXIS_LENGTH * X_OG[:3, k]] for k in range(3)]
        ax.add_collection3d(Line3DCollection(axes, colors=["#e41a1c", "#4daf4a", "#377eb8"], linewidths=2.0,
                                             zorder=3))
        touch = glist.in_contact[i]
        p, nrm = glist.points[i][touch], glist.normals[i][touch]
        if len(p):
            ax.scatter(p[:, 0], p[:, 1], p[:, 2], color=CONTACT_COLOUR, s=14, depthshade=False, zorder=4)
            ax.add_collection3d(Line3DCollection(np.stack([p, p + NORMAL_LENGTH * nrm], axis=1),
                                                 colors=CONTACT_COLOUR, linewidths=1.5, zorder=4))
        ax.set_xlim(centre[0] - reach, centre[0] + reach)
        ax.set_ylim(centre[1] - reach, centre[1] + reach)
        ax.set_zlim(centre[2] - reach, centre[2] + reach)
        ax.set_box_aspect((1, 1, 1), zoom=1.45)
        ax.view_init(elev=elev, azim=azim)
        fingers = ",".join(f for f, t in zip(glist.finger_names, touch) if t)
        ax.set_title(f"#{i}  score {glist.scores[i, -1]:.3f}\n{fingers}", fontsize=9, y=0.98)
    return _png_bytes(fig)



def placements_png(object_mesh, placements, counts: Sequence[int] | None = None, size_per_placement: int = 320,
                   title: str = "") -> bytes:
    """A grid picture of an object's stable placements, most stable first: the object
    resting at X_SO on a grey support (z = 0 of S), its resting facet outlined (magenta)
    and the mass centre's projection marked.

    Args:
        object_mesh: the object's ``trimesh.Trimesh`` in frame O (m).
        placements: :class:`~regrasp_cli.placement.stable.StablePlacement` list.
        counts: per placement, how many fits a scene has for it (printed), or None.
        size_per_placement: pixels of one cell of the grid (square).
    """
    Figure, Poly3DCollection, Line3DCollection = _matplotlib()
    n = len(placements)
    cols = max(1, min(4, n))
    rows = max(1, -(-n // cols))
    obj = shapes_soup([mesh_shape("object", object_mesh, rgba=(0.85, 0.85, 0.85, 1.0))])
    elev, azim = view_angles()
    header = 0.6
    fig = Figure(figsize=(cols * size_per_placement / DPI, rows * size_per_placement / DPI + header), dpi=DPI)
    fig.suptitle(title or f"{n} stable placements", fontsize=13)
    if n == 0:
        fig.text(0.5, 0.5, "no stable placement", ha="center")
    top = 1.0 - header / (rows * size_per_placement / DPI + header)
    for i, p in enumerate(placements):
        r, c = divmod(i, cols)
        ax = fig.add_axes((c / cols, top - (r + 1) * top / rows, 1 / cols, top / rows * 0.92), projection="3d")
        ax.computed_zorder = False
        ax.set_axis_off()
        resting = obj.moved(p.X_SO)
        lo, hi = bounds(resting)
        resting = resting.subdivided(0.15 * float((hi - lo).max()))  # small triangles sort right
        _draw_soup(ax, Poly3DCollection, _floor(lo, hi, 0.0, margin=0.2 * float((hi - lo).max())), zorder=0,
                   edges=False)
        _draw_soup(ax, Poly3DCollection, resting, zorder=1)
        ring = np.vstack([p.footprint, p.footprint[:1]])
        ax.plot(ring[:, 0], ring[:, 1], np.zeros(len(ring)), color=CONTACT_COLOUR, linewidth=2.0, zorder=2)
        ax.scatter([0.0], [0.0], [0.0], color=CONTACT_COLOUR, s=18, depthshade=False, zorder=3)
        _cube(ax, lo, hi)
        ax.view_init(elev=elev, azim=azim)
        fits = "" if counts is None else f", {counts[i]} fits"
        ax.set_title(f"#{i}  tips at {np.degrees(p.tipping_angle):.0f} deg{fits}", fontsize=9, y=0.98)
    return _png_bytes(fig)
