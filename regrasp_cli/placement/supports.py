"""Where the object's stable placements fit in a scene: on the flat tops of its obstacles
(Harada et al. 2014, §III-C: "the object placement planner generates multiple object
postures stably placed on the environment surface"; the placements p_j of CP).

A support is the top face of a box with an axis along the world's vertical, or of a
cylinder standing upright (its disc approximated by an inscribed polygon, so that a fit
is never wrong).  A scene may name its supports (``supports: [table, shelf]``); otherwise
every such top is one.  A stable placement (:mod:`placement.stable`) fits at a position
and turn on a support when its whole resting facet lies on the top, ``edge_margin`` in
from the top's edges (so the mass centre's projection lies on the support as well), and the
object, lifted by ``lift`` off the top, touches no obstacle.  Candidates lie on a grid of
``step`` over each top, at ``yaws`` turns about the vertical.

Frames: W the scene's (z up); T a support's top, z up, origin at the top's centre; S the
frame of a stable placement (its origin under the mass centre, on the surface).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from regrasp_cli.config import ObstacleSpec
from regrasp_cli.errors import InputError
from regrasp_cli.model.collision import mesh_geometry
from regrasp_cli.model.handshape import hand_hits_static, may_hit_static, single_shape, static_geometry
from regrasp_cli.placement.stable import StablePlacement

VERTICAL_COS = 1.0 - 1e-6  # an axis is vertical when its cosine with z is above this
DISC_SIDES = 24  # sides of the polygon inscribed in a cylinder's top


@dataclass(frozen=True)
class FitOptions:
    step: float = 0.04  # m: grid spacing of candidate positions on a top
    yaws: int = 8  # turns about the vertical, evenly spaced
    edge_margin: float = 0.005  # m: the resting facet this far inside the top's edges
    lift: float = 0.002  # m: the object is checked against obstacles this far above the top


@dataclass(frozen=True)
class Support:
    """A flat top: ``X_WT`` (4, 4) its frame (z up, origin at its centre), ``outline``
    (k, 2) its convex outline in T's xy plane, counter-clockwise, m."""

    name: str
    X_WT: np.ndarray
    outline: np.ndarray


@dataclass(frozen=True)
class Fitted:
    """Placements in the scene, n of them: ``X_WO`` (n, 4, 4) object poses, ``stable``
    (n,) index of the stable placement, ``support`` (n,) index of the support, ``yaw``
    (n,) turn about the vertical, rad."""

    X_WO: np.ndarray
    stable: np.ndarray
    support: np.ndarray
    yaw: np.ndarray

    def __len__(self) -> int:
        return len(self.stable)


def _rectangle(hx: float, hy: float) -> np.ndarray:
    return np.array([[-hx, -hy], [hx, -hy], [hx, hy], [-hx, hy]])


def top_of(ob: ObstacleSpec) -> Support | None:
    """The obstacle's flat top, or None when it has none facing up (a sphere, a mesh, a
    tilted box)."""
    R, p = ob.X_WO[:3, :3], ob.X_WO[:3, 3]
    if ob.shape == "box":
        up = np.flatnonzero(np.abs(R[2]) > VERTICAL_COS)
        if not len(up):
            return None
        i = int(up[0])
        j, k = (i + 1) % 3, (i + 2) % 3
        X = np.eye(4)
        X[:3, 0] = R[:, j]
        X[:3, 1] = np.cross([0.0, 0.0, 1.0], R[:, j])
        X[:3, 3] = p + np.sign(R[2, i]) * R[:, i] * ob.size[i] / 2
        return Support(ob.name, X, _rectangle(ob.size[j] / 2, ob.size[k] / 2))
    if ob.shape == "cylinder" and abs(R[2, 2]) > VERTICAL_COS:
        r, length = ob.size
        X = np.eye(4)
        X[:3, 3] = p + np.array([0.0, 0.0, length / 2])
        a = 2 * np.pi * np.arange(DISC_SIDES) / DISC_SIDES
        return Support(ob.name, X, r * np.stack([np.cos(a), np.sin(a)], axis=1))
    return None


def scene_supports(obstacles: tuple[ObstacleSpec, ...], names: tuple[str, ...] | None = None,
                   file=None) -> list[Support]:
    """The supports of a scene: the tops of the obstacles ``names`` (each must have one),
    or of every obstacle with a flat top facing up.

    Raises:
        InputError: a named obstacle has no top facing up (field ``supports[i]``).
    """
    by_name = {ob.name: ob for ob in obstacles}
    if names is None:
        return [s for s in map(top_of, obstacles) if s is not None]
    out = []
    for i, name in enumerate(names):
        s = top_of(by_name[name])
        if s is None:
            raise InputError(file, f"supports[{i}]", f"obstacle {name!r} has no flat top facing up (a box with "
                                                     "an axis along z, or an upright cylinder, is expected)")
        out.append(s)
    return out


def resting_gap(vertices: np.ndarray, X_WO: np.ndarray, obstacles: tuple[ObstacleSpec, ...],
                tol: float = 0.001) -> float | None:
    """How far (m) the object (``vertices`` (n, 3) in O, at ``X_WO`` (4, 4)) hangs above the
    highest obstacle top under its lowest point (negative: into it), or None when no flat
    top is under it.  The planner has no gravity: an object placed 5 cm above its table
    is planned as if it stood there (PR2's scene did, until `regrasp simulate` dropped it).
    The lowest point is the mean of the vertices within ``tol`` of the lowest."""
    v = np.asarray(vertices, float) @ X_WO[:3, :3].T + X_WO[:3, 3]
    low = v[v[:, 2] <= v[:, 2].min() + tol]
    foot = np.r_[low[:, :2].mean(axis=0), v[:, 2].min()]
    best = None
    for top in filter(None, map(top_of, obstacles)):
        p_T = np.linalg.inv(top.X_WT) @ np.r_[foot, 1.0]
        if _inside(top.outline, p_T[None, None, :2], 0.0)[0] and p_T[2] > -0.05:  # a top under it, or just above
            best = p_T[2] if best is None else min(best, float(p_T[2]), key=abs)
    return None if best is None else float(best)


def _inside(outline: np.ndarray, points: np.ndarray, margin: float) -> np.ndarray:
    """Is every point of each set at least ``margin`` inside the convex ``outline`` (k, 2)?
    ``points`` (..., m, 2) -> (...,) bool."""
    a = outline
    e = np.roll(a, -1, axis=0) - a
    n = np.stack([e[:, 1], -e[:, 0]], axis=1) / np.linalg.norm(e, axis=1, keepdims=True)  # outward
    off = np.einsum("kd,kd->k", n, a)
    s = points @ n.T - off  # (..., m, k): signed distance outside each edge
    return (s.max(axis=(-1, -2)) <= -margin)


def _turn(yaw: float) -> np.ndarray:
    c, s = np.cos(yaw), np.sin(yaw)
    X = np.eye(4)
    X[:2, :2] = [[c, -s], [s, c]]
    return X


def fit_placements(stable: list[StablePlacement], supports: list[Support], mesh, obstacles: tuple[ObstacleSpec, ...],
                   options: FitOptions = FitOptions()) -> Fitted:
    """Every candidate (support, stable placement, position, turn) where the placement fits
    (module docstring), in that order; ``mesh`` the object's trimesh in O."""
    env = static_geometry(obstacles)
    shape = single_shape(mesh_geometry(mesh))
    hull = np.asarray(mesh.convex_hull.vertices)  # (v, 3) in O: where the object's lowest point is
    yaws = 2 * np.pi * np.arange(options.yaws) / options.yaws
    poses, which, where, turns = [], [], [], []
    for si, sup in enumerate(supports):
        lo, hi = sup.outline.min(axis=0), sup.outline.max(axis=0)
        xs = np.arange(lo[0] + options.step / 2, hi[0], options.step)
        ys = np.arange(lo[1] + options.step / 2, hi[1], options.step)
        grid = np.stack(np.meshgrid(xs, ys, indexing="ij"), axis=-1).reshape(-1, 2)
        lifted = sup.X_WT @ _offset(options.lift)
        for pi, sp in enumerate(stable):
            for yaw in yaws:
                c, s = np.cos(yaw), np.sin(yaw)
                foot = sp.footprint @ np.array([[c, s], [-s, c]])  # turned, (m, 2)
                ok = _inside(sup.outline, grid[:, None, :] + foot[None], options.edge_margin)
                X_TO = np.repeat(_turn(yaw)[None], int(ok.sum()), axis=0)
                X_TO[:, :2, 3] = grid[ok]
                X_TO = X_TO @ sp.X_SO
                X_WO = lifted @ X_TO
                # what does not reach above the lifted object's lowest point (the support
                # itself, the desk under it) cannot touch it
                low = float((X_WO[:, 2, :3] @ hull.T + X_WO[:, 2, 3:]).min()) if len(X_WO) else 0.0
                env_up = env.reaching_above(low - 1e-6)
                near = may_hit_static(shape, X_WO, env_up)
                for k in range(len(X_TO)):
                    if near[k] and hand_hits_static(shape, X_WO[k], env_up):
                        continue
                    poses.append(sup.X_WT @ X_TO[k])
                    which.append(pi)
                    where.append(si)
                    turns.append(yaw)
    return Fitted(np.array(poses).reshape(-1, 4, 4), np.array(which, dtype=np.int64),
                  np.array(where, dtype=np.int64), np.array(turns, dtype=float))


def _offset(z: float) -> np.ndarray:
    X = np.eye(4)
    X[2, 3] = z
    return X
