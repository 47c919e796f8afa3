"""A plan's motion for viewing: the robot's configuration and the object's pose over time,
and the key frames (start, pick, exchange, place, end).

Viewing only (not a paper section).  The plan is reloaded and the object followed through
the phases by :mod:`regrasp_cli.replay`, as the validator does: it rests at the phase's
placement while no hand holds it, otherwise ``X_WO = X_WG(q) @ X_GO`` with X_GO fixed at
the phase start.  Key frames come from the phases' kinds, never their names.  Between
waypoints the robot moves as each phase's own timing says (straight segments, or blends at
corners), evaluated by ``phase.evaluate`` at the plan's times.

Times are seconds from the plan start; configurations (nq,) in the plan's joint order
(rad or m); poses 4x4 in the robot base frame W (m).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from regrasp_cli.errors import InputError
from regrasp_cli.show.geometry import (LinkShapes, Soup, link_poses, mesh_shape, obstacle_shapes, robot_links,
                                       robot_soup, shapes_soup)
from regrasp_cli.manip.modes import Kind
from regrasp_cli.model.robot import Kinematics
from regrasp_cli.replay import Carry, Inputs, follow, load_inputs
from regrasp_cli.trajectory import Plan, read_plan

KEY_FRAMES = ("start", "pick", "exchange", "place", "end")  # kinds of key frame, see key_frames
MAX_FPS = 120


@dataclass(frozen=True, eq=False)
class PlanView:
    """A solved plan with what it refers to, loaded for drawing."""

    file: Path
    plan: Plan
    inputs: Inputs  # robot, object mesh (frame O), obstacles, timing limits
    carries: tuple[Carry, ...]  # per phase: the object static in W, or held by a hand
    kin: Kinematics  # FK scratch of this view (one pinocchio Data)

    @property
    def duration(self) -> float:
        return self.plan.duration

    def X_WO(self, phase: int, q: np.ndarray) -> np.ndarray:
        """Object pose (4, 4) during phase ``phase`` at configuration q (nq,)."""
        return self.carries[phase].X_WO(self.kin, q)


@dataclass(frozen=True, eq=False)
class Motion:
    """The motion sampled at times t (m,): configurations q (m, nq), the phase index of
    each sample (m,) and the object pose X_WO (m, 4, 4)."""

    t: np.ndarray
    q: np.ndarray
    phase: np.ndarray
    X_WO: np.ndarray


@dataclass(frozen=True, eq=False)
class KeyFrame:
    """A moment worth a picture: ``name`` (one of :data:`KEY_FRAMES`, with ``-2`` and so on
    for a repeat), the phase it ends (or starts, for ``start``), its time t (s), the
    configuration q (nq,) and X_WO (4, 4)."""

    name: str
    phase: int
    t: float
    q: np.ndarray
    X_WO: np.ndarray


def load_plan_view(path: str | Path) -> PlanView:
    """Read a plan and what it names.

    Raises:
        InputError: unreadable, malformed or stale plan (as ``regrasp validate``), a failed
            plan, or a plan without motion.
    """
    path = Path(path)
    plan = read_plan(path)
    if plan.status != "solved":
        f = plan.failure if isinstance(plan.failure, dict) else {}
        raise InputError(path, "status", f"the plan failed at stage {f.get('stage', '?')} "
                                         f"({f.get('reason', 'no reason given')}): there is no motion to show")
    if not plan.phases:
        raise InputError(path, "phases", "no phase: there is no motion to show")
    inputs = load_inputs(plan, path)
    kin = Kinematics(inputs.robot)
    carries, _ = follow(path, plan, kin)  # issues are the validator's business
    return PlanView(path, plan, inputs, tuple(carries), kin)


def sample_times(view: PlanView, fps: float) -> np.ndarray:
    """Times (s) at ``fps`` per second from 0 to the plan's end, plus every waypoint time
    (where the robot stops or passes a corner), sorted and without duplicates."""
    if not (np.isfinite(fps) and 0 < fps <= MAX_FPS):
        raise ValueError(f"fps must be in (0, {MAX_FPS}], got {fps}")
    T = view.duration
    t = np.concatenate([np.arange(0.0, T, 1.0 / fps), [T], *(p.times for p in view.plan.phases)])
    t = np.round(t, 9)  # rounding may move T by up to 0.5 ns either way: the end is T itself
    return np.unique(np.concatenate([t[(t >= 0.0) & (t < T - 1e-9)], [T]]))


def phase_at(view: PlanView, t: np.ndarray) -> np.ndarray:
    """Index of the phase each time (m,) falls in: the last phase starting at or before
    it.  A time on a boundary thus belongs to the phase that starts there (the
    configuration and the object pose agree there), and a phase of zero duration gets no
    time unless it is the last."""
    starts = np.array([p.times[0] for p in view.plan.phases])
    return np.clip(np.searchsorted(starts, t, side="right") - 1, 0, len(starts) - 1)


def sample_motion(view: PlanView, fps: float = 25.0) -> Motion:
    """The motion at the times of :func:`sample_times`.

    Raises:
        InputError: a phase's times do not fit its waypoints under the plan's limits.
    """
    t = sample_times(view, fps)
    k = phase_at(view, t)
    robot = view.inputs.robot
    q = np.empty((len(t), robot.nq))
    X_WO = np.empty((len(t), 4, 4))
    for i, phase in enumerate(view.plan.phases):
        rows = np.flatnonzero(k == i)
        if not len(rows):
            continue
        try:
            q[rows], _ = phase.evaluate(t[rows], view.inputs.velocity, view.inputs.acceleration)
        except ValueError as exc:
            raise InputError(view.file, f"phases[{i}].times", str(exc)) from None
        for r in rows:
            X_WO[r] = view.X_WO(i, q[r])
    return Motion(t, q, k, X_WO)


def _key_phases(phases) -> list[tuple[str, int]]:
    """(kind of key frame, index of the phase it ends) in order: ``pick`` ends a grasp (a
    hand closed on the resting object), ``exchange`` the first of consecutive hand-over
    phases (both hands on it), ``place`` a transfer followed by a release (the object set
    down, still held)."""
    out = []
    for i, p in enumerate(phases):
        nxt = phases[i + 1].kind if i + 1 < len(phases) else None
        prev = phases[i - 1].kind if i else None
        if p.kind == Kind.GRASP:
            out.append(("pick", i))
        elif p.kind == Kind.HANDOVER and prev != Kind.HANDOVER:
            out.append(("exchange", i))
        elif p.kind == Kind.TRANSFER and nxt == Kind.RELEASE:
            out.append(("place", i))
    return out


def key_frames(view: PlanView) -> tuple[KeyFrame, ...]:
    """The plan's key frames, in time order: ``start`` (first waypoint), then the pick,
    exchange and place moments of :func:`_key_phases` (a second one of a kind is named
    ``pick-2`` and so on, as in a regrasp through an intermediate placement), then ``end``
    (last waypoint)."""
    phases = view.plan.phases
    q0 = phases[0].waypoints[0]
    out = [KeyFrame("start", 0, float(phases[0].times[0]), q0, view.X_WO(0, q0))]
    seen: dict[str, int] = {}
    for kind, i in _key_phases(phases) + [("end", len(phases) - 1)]:
        seen[kind] = seen.get(kind, 0) + 1
        name = kind if seen[kind] == 1 else f"{kind}-{seen[kind]}"
        q = phases[i].waypoints[-1]
        out.append(KeyFrame(name, i, float(phases[i].times[-1]), q, view.X_WO(i, q)))
    return tuple(out)


# ------------------------------------------------------------------ geometry at a moment


@dataclass(frozen=True, eq=False)
class PlanSoups:
    """A plan's geometry triangulated once: the robot's links (each in its own frame),
    the obstacles in W and the object in its frame O."""

    links: tuple[LinkShapes, ...]
    link_soups: tuple[Soup, ...]
    obstacles: Soup
    object: Soup


def plan_soups(view: PlanView, source: str = "visual", max_edge: float | None = None,
               max_faces: int | None = None) -> PlanSoups:
    """Triangulate the plan's robot (``source``: visual or collision geometry; meshes
    decimated to ``max_faces`` triangles), obstacles and object; with ``max_edge`` (m),
    robot and obstacle triangles are cut to that size."""
    links = robot_links(view.inputs.robot, source, max_faces)
    cut = (lambda s: s) if max_edge is None else (lambda s: s.subdivided(max_edge))
    return PlanSoups(links, tuple(cut(shapes_soup(ls.shapes)) for ls in links),
                     cut(shapes_soup(obstacle_shapes(view.inputs.obstacles))),
                     shapes_soup([mesh_shape("object", view.inputs.mesh)]))


def frame_soup(view: PlanView, soups: PlanSoups, q: np.ndarray, X_WO: np.ndarray) -> Soup:
    """Everything in W at configuration q (nq,) with the object at X_WO (4, 4)."""
    X_WL = link_poses(view.kin, soups.links, q)
    return Soup.join([soups.obstacles, robot_soup(soups.links, X_WL, soups.link_soups), soups.object.moved(X_WO)])


def holding_text(holding: tuple[str, ...], touching: tuple[str, ...], kind: Kind | None = None) -> str:
    """Words for who has the object in a phase, e.g. ``held by the right hand``."""
    if kind is not None and kind.inhand:
        hands = " and ".join(dict.fromkeys(touching)) or "the"
        return (f"turned by the {hands} fingertips" if kind == Kind.INHAND_TRANSFER
                else f"held by the {hands} fingertips while one steps")
    if holding:
        hands = " and ".join(dict.fromkeys(holding))
        text = f"held by the {hands} hand" + ("s" if len(set(holding)) > 1 else "")
    else:
        text = "at rest"
    others = [h for h in dict.fromkeys(touching) if h not in holding]
    if others:
        text += f"; {' and '.join(others)} fingers on it"
    return text
