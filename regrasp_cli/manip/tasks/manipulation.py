"""Pick and place with the fewest regrasps: the manipulation planner of Harada et al. 2014
(seed 001) over the manipulation graph of :mod:`manip.graph`.  It chooses between one-arm
pick-and-place, a hand-over in the air (Saut et al. 2010) and putting the object down at
intermediate placements to grasp it again (§IV, Fig. 5), or as many of those as needed.

Stages, each timed:

1. ``nodes`` (§IV-B): for each hand and placement (the initial and target ones, then the
   intermediate ones), single-grasp configurations (IK and collision, with their approach
   and lift lines: :func:`doublegrasp.single_configurations`), the grasps already reached
   at the start and at the goal tried first so that transfers can join them.  A hand whose
   grasp frame cannot get near the object (position-only IK) has no node there.
   Intermediate placements (:mod:`placement.supports`: stable placements fitted on the
   scene's supports) are added only once every path without a regrasp has failed: they
   cannot give fewer.  ``sampler`` "faces": one per resting face, where the hands that
   must use them rest, with a few grasps each; "vis-prm": the Visibility-PRM over
   CG_r∩CP and CG_l∩CP with Type-1 steering (§IV-B-2, :mod:`manip.visprm`), its guards,
   connectors and the corners of their Type-2 paths; a second one when every path
   through the first failed.
2. ``search`` and ``motions`` (§IV-C), in turn: the path of fewest regrasps and then least
   joint-space length among the edges not found infeasible; its edges' motions are solved
   (transit and transfer queries by the planner's path solver; a hand-over edge first
   needs an exchange configuration, :func:`handover.exchange_near`); an edge that fails is
   blocked and the search runs again, ``graph_attempts`` times at most.  The first path
   whose motions all succeed is the plan: as every path with fewer regrasps failed before
   it, its regrasp count is the least the graph's motions allow.
3. ``optimise`` (§V): :func:`graph.optimise`'s merges, each solved before it is kept.
4. ``timing``, as the hand-over's.

Type-1 edges (§III-D) are not in the graph: each is the Type-2 pair transfer + regrasp it
expands to (:func:`graph.type2`), so the search returns realizable paths directly.
:func:`plan` runs the styles in order of the regrasps they need (see there).
"""

from __future__ import annotations

import itertools
import time
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.spatial import cKDTree

from regrasp_cli.grasp.build import GraspList
from regrasp_cli.manip import steps as moves
from regrasp_cli.manip.context import OnlineOptions, Scratch
from regrasp_cli.manip.doublegrasp import DoubleGrasp, cheap_order, empty_list_reason, single_configurations, workable
from regrasp_cli.dexterous.gsn import GsConfig
from regrasp_cli.dexterous.motions import piece_motions
from regrasp_cli.dexterous.roadmap import GaitTreeOptions
from regrasp_cli.dexterous.task import gs_scratch, turn_in_hand
from regrasp_cli.manip.graph import GOAL, START, STYLES, Edge, EdgeKind, Node, fewest_regrasps, optimise, ruled_out, \
    search, style_of, successors
from regrasp_cli.manip.keyconf import OTHER, ExchangeConfig, SingleConfig, shoulder, single_configuration
from regrasp_cli.manip.queries import Roadmap
from regrasp_cli.manip.solve import Outcome, Query, Step, TransitionStats, check_ends, solve_queries, time_steps
from regrasp_cli.manip.status import PlanningFailed, Stage
from regrasp_cli.manip.tasks import handover
from regrasp_cli.manip.visprm import VisOptions, visibility_roadmap
from regrasp_cli.manip.tasks.handover import blend_check, exchange_near, exchange_pose, grasp_id, object_shape, \
    phase_worlds, tick
from regrasp_cli.model.handshape import hand_shapes, hands_collide, static_geometry
from regrasp_cli.model.ik import IKOptions, solve_position
from regrasp_cli.motion.local import joint_reach, joint_weights
from regrasp_cli.placement.stable import StablePlacement
from regrasp_cli.placement.supports import FitOptions, Fitted, fit_placements, scene_supports
from regrasp_cli.scene import Problem
from regrasp_cli.spatial import inverse, rotation_angle

TASK = "manipulation graph"
STAGES = ("nodes", "search", "motions", "optimise", "timing")
HANDS = ("right", "left")


@dataclass(frozen=True)
class GraphOptions:
    style: str = "auto"  # a key of manip.graph.STYLES
    intermediate: int = 6  # intermediate placements at most (one per resting face)
    graph_attempts: int = 12  # paths whose motions are tried before giving up
    reach_factor: float = 1.0  # a hand has no node where the object is farther than this x its arm's reach
    intermediate_nodes: int = 4  # configurations per hand at an intermediate placement ...
    intermediate_attempts: int = 12  # ... from this many grasps at most, the arm alone (IK that fails is slow)
    sampler: str = "faces"  # intermediate placements: "faces" (one per resting face) or "vis-prm" (§IV-B-2)
    vis: VisOptions = field(default_factory=VisOptions)
    vis_pool: int = 200  # fits nearest a hand's rest its Visibility-PRM samples from
    vis_rounds: int = 2  # Visibility-PRMs at most, each when every path through the last ones failed
    fit: FitOptions = field(default_factory=FitOptions)
    inhand_nodes: int = 4000  # GS_n expansions an in-hand regrasp may take (seed 003's two trees) ...
    inhand_attempts: int = 3  # ... and turns searched per run (on one edge or several): a failure costs up to a minute
    turn_cost: float = 20.0  # weighted joint distance one radian of an in-hand turn counts as: finger gaiting
    # turns the object about this many times slower than the arm moves (docs/DESIGN-NOTES.md), so that among
    # in-hand moves the search tries the smallest turns first, as their motion is the shortest


class _Graph:
    """The nodes found so far (their configurations), the edges' motions solved so far,
    and the blocked edges, for one planning run."""

    def __init__(self, scratch: Scratch, lists: dict[str, GraspList], roadmap: Roadmap | None,
                 placements: dict[str, np.ndarray], options: GraphOptions, seed: int):
        p = scratch.problem
        self.scratch, self.lists, self.placements, self.options, self.seed = scratch, lists, placements, options, seed
        self.roadmap = roadmap
        self.query_weights = roadmap.weights if roadmap is not None else joint_weights(p.robot)
        self.env = static_geometry(p.spec.obstacles)
        self.shapes = {h: hand_shapes(p.robot, h, lists[h].finger_q, p.spec.planning.contact_tolerance) for h in HANDS}
        self.configs: dict[Node, SingleConfig] = {}
        self.searched: set[tuple[str, str]] = set()  # (hand, placement) searched in full
        self.searched_turnable: set[tuple[str, str]] = set()  # ... for grasps of every finger (in-hand moves)
        self.singles: dict = {}  # (hand, start or goal) -> the hand-over task's single configurations, stats
        self.blocked: set[Edge] = set()
        self.why: dict[Edge, str] = {}
        self.exchanges: dict[Edge, ExchangeConfig] = {}
        self.inhands: dict[Edge, list] = {}  # an in-hand edge's finger motions (dexterous.motions.FingerMotion)
        self.gaits = frozenset(h for h in HANDS if p.robot.hands[h].kind == "fingertips"
                               and len(p.robot.hands[h].finger_idx) >= 3)  # hands that can finger-gait
        self.paths: dict[str, np.ndarray] = {}
        self.table: dict[str, TransitionStats] = {}
        self.counts = {"single_checks": 0, "query_checks": 0, "paths_tried": 0, "queries": 0, "exchanges_tried": 0,
                       "inhand_tried": 0}
        reach = joint_reach(p.robot)
        self.reach = {h: options.reach_factor * reach[p.robot.hands[h].arm_idx[0]] for h in HANDS}
        self.shoulder = {h: shoulder(scratch, h, p.robot.q_rest) for h in HANDS}
        self.shoulders = {h: cKDTree(shoulder_positions(scratch, h)) for h in HANDS}
        self.rest = {h: scratch.kin.fk(p.robot.q_rest, p.robot.hands[h].grasp_frame)[:3, 3] for h in HANDS}
        self.weights = joint_weights(p.robot)
        self.rounds = 0  # intermediate placements added so many times
        self.names = itertools.count(1)  # of the Visibility-PRMs' placements: p1, p2...
        self.fitted: Fitted | None = None  # the stable placements fitted on the scene's supports

    # ---------------------------------------------------------------- nodes

    def add_nodes(self, pids: list[str], intermediate: bool = False, hands: tuple[str, ...] = HANDS) -> None:
        """Single-grasp configurations of the ``hands`` at each placement of ``pids``
        (fewer, from fewer grasps and without the torso's help, at ``intermediate``
        ones), each (hand, placement) searched once."""
        o = self.options
        limits = dict(wanted=o.intermediate_nodes, attempts=o.intermediate_attempts, lean=False) if intermediate \
            else {}
        for pid in pids:
            for hand in hands:
                if (hand, pid) in self.searched:
                    continue
                self.searched.add((hand, pid))
                if not self._reachable(hand, self.placements[pid], pid):
                    continue
                if pid in (START, GOAL):
                    # the hand-over task's own search of the hand at that end, which it reuses
                    rng = np.random.default_rng(handover.single_stream(self.seed, hand))
                    self.singles[(hand, pid)] = self._search(hand, pid, rng)
                    continue
                rng = np.random.default_rng([self.seed, 30, HANDS.index(hand), list(self.placements).index(pid)])
                found = self._grasps_at(hand, pid)
                # grasps reached at the start, then at the goal, first: transfers can join them
                for end in (START, GOAL):
                    known = np.setdiff1d(self._grasps_at(hand, end), found)
                    if len(known):
                        more, _ = self._search(hand, pid, rng, known, **limits)
                        found = np.union1d(found, [c.grasp for c in more])
                self._search(hand, pid, rng, np.setdiff1d(np.arange(len(self.lists[hand])), found), **limits)

    def add_turnable_nodes(self) -> None:
        """Nodes at the start and the goal of grasps the in-hand move can start or end
        with (every finger touching: GS_n), for the hands that can finger-gait, up to
        ``intermediate_nodes`` each; once per run."""
        o = self.options
        for hand in sorted(self.gaits):
            every = np.flatnonzero(self.lists[hand].in_contact.all(axis=1))
            for pid in (START, GOAL):
                if (hand, pid) in self.searched_turnable:
                    continue
                self.searched_turnable.add((hand, pid))
                have = [n.grasp for n in self.configs if n.hand == hand and n.placement == pid]
                only = np.setdiff1d(every, have)
                if len(only) and self._reachable(hand, self.placements[pid], pid):
                    rng = np.random.default_rng([self.seed, 31, HANDS.index(hand), (START, GOAL).index(pid)])
                    self._search(hand, pid, rng, only, wanted=o.intermediate_nodes, attempts=o.intermediate_attempts)

    def _search(self, hand: str, pid: str, rng: np.random.Generator, only: np.ndarray | None = None, **limits):
        """:func:`doublegrasp.single_configurations` of the hand at placement ``pid`` (the
        grasps ``only``), its configurations added as nodes; (configurations, stats)."""
        before = self.scratch.checks
        found, stats = single_configurations(self.scratch, rng, self.lists[hand], self.shapes[hand],
                                             self.placements[pid], self.env, only, **limits)
        self.counts["single_checks"] += self.scratch.checks - before
        self.configs.update({Node(hand, c.grasp, pid): c for c in found})
        return found, stats

    def usable(self) -> dict[tuple[str, str], frozenset]:
        """(hand, START or GOAL) -> the grasps (indices) whose hand clears the obstacles
        there and that the torso and arm reach (:func:`doublegrasp.workable`, one batched
        IK per hand and end, memoised for the searches that follow): the only grasps a
        node there can have."""
        return {(h, pid): frozenset(int(k) for k in workable(self.scratch, self.lists[h], self.shapes[h],
                                                            self.placements[pid], self.env)[1])
                for h in HANDS for pid in (START, GOAL)}

    def _grasps_at(self, hand: str, pid: str) -> np.ndarray:
        """The grasps (sorted indices) of the hand's nodes at placement ``pid``."""
        return np.array(sorted({n.grasp for n in self.configs if n.hand == hand and n.placement == pid}), dtype=int)

    def one_arm_nodes(self) -> None:
        """The nodes a one-arm path can use, cheaply: each hand with a grasp usable at
        both ends (:meth:`usable`) at the end nearer its shoulder (searched in full), then
        at the other end only with the grasps it has at the first (a transfer keeps the
        grasp), when it has any.  IK that fails is the slow part: a hand that cannot do
        both ends fails on a few grasps, not 80."""
        usable = self.usable()
        for hand in HANDS:
            if not usable[hand, START] & usable[hand, GOAL]:
                continue  # no grasp serves both ends: its nodes cannot make a one-arm path
            d = {pid: np.linalg.norm(self.placements[pid][:3, 3] - self.shoulder[hand]) for pid in (START, GOAL)}
            first, second = sorted(d, key=d.get)
            self.add_nodes([first], hands=(hand,))
            known = self._grasps_at(hand, first)
            if not len(known) or (hand, second) in self.searched or not self._reachable(
                    hand, self.placements[second], second):
                continue
            self._search(hand, second, np.random.default_rng([self.seed, 32, HANDS.index(hand)]), known,
                         wanted=len(known))

    def _reachable(self, hand: str, X_WO: np.ndarray, pid: str) -> bool:
        """Can the hand's grasp frame get to the grasp position nearest its shoulder at all
        (arm and torso, position only)?  When not, its grasps there are not searched: IK
        that fails is the slowest part of the nodes.  First, the object must be within the
        arm's reach of a shoulder position the torso allows (HiroNX's waist swings the
        shoulder round: from the shoulder at rest, goals it turns to looked out of reach)."""
        if not self.within_reach(hand, X_WO[None, :3, 3])[0]:
            return False
        robot = self.scratch.problem.robot
        p = X_WO[:3, :3] @ self.lists[hand].X_OG[:, :3, 3].T + X_WO[:3, 3:4]  # (3, n) grasp positions
        nearest = p[:, np.argmin(np.linalg.norm(p.T - self.shoulder[hand], axis=1))]
        idx = np.concatenate([robot.groups["torso"], robot.hands[hand].arm_idx])
        rng = np.random.default_rng([self.seed, 31, HANDS.index(hand), list(self.placements).index(pid)])
        return solve_position(robot, robot.hands[hand].grasp_frame, nearest, robot.q_rest, idx, rng,
                              IKOptions(restarts=8)).success

    def within_reach(self, hand: str, p: np.ndarray) -> np.ndarray:
        """(k,) bool: which points ``p`` (k, 3) are within the arm's reach of a shoulder
        position the torso allows."""
        return self.shoulders[hand].query(p)[0] <= self.reach[hand]

    def add_intermediate(self, stable: list[StablePlacement]) -> None:
        """Intermediate placements and their nodes, by ``options.sampler``: one fit per
        resting face with a few grasps each (:func:`intermediate_placements`), or the
        Visibility-PRM's guards, connectors and corners (:meth:`visibility_nodes`)."""
        spec, o = self.scratch.problem.spec, self.options
        if self.fitted is None:  # once: a second Vis-PRM samples the same fits
            self.fitted = fit_placements(stable, scene_supports(spec.obstacles, spec.supports, spec.file),
                                         self.scratch.problem.object.mesh, spec.obstacles, o.fit)
        fitted = self.fitted
        self.rounds += 1
        if o.sampler == "vis-prm":
            self.visibility_nodes(fitted)
        else:
            within = {h: self.within_reach(h, fitted.X_WO[:, :3, 3]) for h in HANDS}
            extra = intermediate_placements(fitted, len(stable), o, self.rest, within, self.ends())
            self.placements.update(extra)
            self.add_nodes(list(extra), intermediate=True)
        self.counts["intermediate_placements"] = len(set(self.placements) - {START, GOAL})

    def visibility_nodes(self, fitted: Fitted) -> None:
        """The Visibility-PRM of :mod:`manip.visprm` over CG_r∩CP and CG_l∩CP (§IV-B-2).
        A sample is a hand, a placement and a grasp.  The placement: half the time one
        sampled before (where the other hand may take over), else one of the ``vis_pool``
        fits on the supports nearest (horizontally) to where the hand rests, within its
        reach.  The grasp: half the time one the hand has at the start or the goal (a
        transfer joins it), else one of the ``intermediate_attempts`` grasps that clear the
        obstacles there with the best cheap score.  Uniform samples would mostly be poses
        a 6-DoF arm cannot take; this bias keeps the IK that fails, the slow part, rare.
        Only the roadmap's nodes join the graph, and only their placements."""
        o = self.options
        rng = np.random.default_rng([self.seed, 33, self.rounds])
        p = fitted.X_WO[:, :3, 3]
        pool = {}
        for h in HANDS:
            within = np.flatnonzero(self.within_reach(h, p))
            near = np.linalg.norm(p[within, :2] - self.rest[h][:2], axis=1)
            pool[h] = within[np.argsort(near, kind="stable")[:o.vis_pool]]
        ends = {h for h in HANDS for pid in (START, GOAL) if len(self._grasps_at(h, pid))}
        hands = [h for h in HANDS if h in ends and len(pool[h])]  # a hand at neither end joins nothing
        found: dict[Node, SingleConfig | None] = dict(self.configs)
        pid_of: dict[int, str] = {}  # fit index -> its placement id, once sampled
        order: dict[tuple[str, str], np.ndarray] = {}  # (hand, placement) -> free grasps, best first

        def grasps(h: str, pid: str) -> np.ndarray:
            if (h, pid) not in order:
                X_WO = self.placements[pid]
                _, reached = workable(self.scratch, self.lists[h], self.shapes[h], X_WO, self.env)
                order[(h, pid)] = cheap_order(self.scratch, self.lists[h], reached, X_WO)
            return order[(h, pid)]

        def sample() -> Node:
            h = hands[rng.integers(len(hands))]
            mine = [pid_of[i] for i in pool[h] if i in pid_of]
            if mine and rng.random() < 0.5:
                pid = mine[rng.integers(len(mine))]
            else:
                i = int(pool[h][rng.integers(len(pool[h]))])
                if i not in pid_of:
                    pid_of[i] = f"p{next(self.names)}"
                pid = pid_of[i]
                self.placements[pid] = fitted.X_WO[i]
            free = grasps(h, pid)
            known = np.intersect1d(np.union1d(self._grasps_at(h, START), self._grasps_at(h, GOAL)), free)
            best = free[:o.intermediate_attempts]
            if len(known) and (rng.random() < 0.5 or not len(best)):
                return Node(h, int(rng.choice(known)), pid)
            return Node(h, int(best[rng.integers(len(best))]) if len(best) else -1, pid)

        def valid(n: Node) -> bool:
            if n not in found:
                found[n] = None
                if n.grasp in grasps(n.hand, n.placement):
                    before = self.scratch.checks
                    X_WO, end = self.placements[n.placement], n.placement in (START, GOAL)
                    stream = np.random.default_rng([self.seed, 34, self.rounds, len(found)])
                    for lean in (False, True)[:1 + end]:  # the torso helps at the ends only, as there
                        found[n] = found[n] or single_configuration(self.scratch, stream, self.lists[n.hand],
                                                                    n.grasp, X_WO, lean)
                    self.counts["single_checks"] += self.scratch.checks - before
            return found[n] is not None

        at = {pid: [n for n in sorted(self.configs) if n.placement == pid] for pid in (START, GOAL)}
        roadmap = visibility_roadmap(at[START], at[GOAL], sample, valid, o.vis) if hands else None
        kept = roadmap.nodes if roadmap is not None else set()
        self.configs.update({n: found[n] for n in kept})
        for pid in set(pid_of.values()) - {n.placement for n in kept}:
            del self.placements[pid]
        self.counts.setdefault("vis_prm", []).append(dict(roadmap.counts() if roadmap else {},
                                                          configurations=len(found)))

    def ends(self) -> dict[str, set[str]]:
        """The hands with nodes at the start and at the goal."""
        return {pid: {n.hand for n in self.configs if n.placement == pid} for pid in (START, GOAL)}

    def handover_nodes(self) -> None:
        """The single grasps the hand-over task needs, in its order (the hand nearer the
        start picks, else the other), no more: a hand that reaches neither its end nor the
        other costs a failed search each, the slowest part."""
        guess = handover.picking_hand(self.scratch.problem, self.scratch)
        for g in (guess, OTHER[guess]):
            self.add_nodes([START], hands=(g,))
            if len(self._grasps_at(g, START)):
                self.add_nodes([GOAL], hands=(OTHER[g],))
                if len(self._grasps_at(OTHER[g], GOAL)):
                    return

    def no_handover(self) -> str:
        """Why no hand can pick at the start and the other place at the goal, from the
        nodes found there (the hand-over task would search the same configurations
        again), or "" when a pair exists or the nodes were not searched yet."""
        have = {(n.hand, n.placement) for n in self.configs if (n.hand, n.placement) in self.searched}
        maybe = have | ({(h, p) for h in HANDS for p in (START, GOAL)} - self.searched)  # not searched in full yet
        if any((h, START) in maybe and (OTHER[h], GOAL) in maybe for h in HANDS):
            return ""
        return "no hand reaches the start while the other reaches the goal (" + ", ".join(
            f"{h} hand: {', '.join(p for p in (START, GOAL) if (h, p) in have) or 'neither'}" for h in HANDS) + ")"

    def compatible(self, a: Node, b: Node) -> bool:
        """Can the two hands hold the object together with these grasps (hand shapes only)?"""
        la, lb = self.lists[a.hand], self.lists[b.hand]
        return not hands_collide(self.shapes[a.hand][a.grasp], la.X_OG[a.grasp], self.shapes[b.hand][b.grasp],
                                 lb.X_OG[b.grasp])

    def turnable(self, a: Node, b: Node) -> bool:
        """Can the hand turn the object in its fingers from ``a``'s grasp to ``b``'s?  A hand
        that can finger-gait, every finger touching in both grasps (GS_n: all n fingers)."""
        if a.hand != b.hand or a.hand not in self.gaits:
            return False
        touching = self.lists[a.hand].in_contact
        return bool(touching[a.grasp].all() and touching[b.grasp].all())

    def length(self, e: Edge) -> float:
        """Weighted joint distance the edge's motion covers at least (its queries' ends);
        an in-hand edge's counts its turn too (``turn_cost`` per radian)."""
        q = self.scratch.problem
        a = q.q_start if e.a is None else self.configs[e.a].lift[-1]
        b = q.q_goal if e.b is None else self.configs[e.b].lift[-1]
        arm = float(np.linalg.norm((a - b) * self.weights))
        return arm + self.options.turn_cost * self.turn_angle(e.a, e.b) if e.kind == EdgeKind.INHAND else arm

    def turn_angle(self, a: Node, b: Node) -> float:
        """The angle (rad) the object turns in the hand from ``a``'s grasp to ``b``'s."""
        X = self.lists[a.hand].X_OG
        return rotation_angle(X[a.grasp, :3, :3].T @ X[b.grasp, :3, :3])

    # ---------------------------------------------------------------- motions of edges

    def _queries(self, e: Edge, label: str) -> list[Query]:
        p, robot = self.scratch.problem, self.scratch.problem.robot
        open_ = {h: robot.hands[h].open for h in HANDS}
        ca = self.configs.get(e.a) if e.a is not None else None
        cb = self.configs.get(e.b) if e.b is not None else None
        if e.kind == EdgeKind.ARRIVE:
            return [Query(label, p.q_start, cb.approach[0], phase_worlds(self.scratch, self.placements[START], None,
                                                                         open_))]
        if e.kind == EdgeKind.LEAVE:
            return [Query(label, ca.approach[0], p.q_goal, phase_worlds(self.scratch, self.placements[GOAL], None,
                                                                        open_))]
        if e.kind == EdgeKind.REGRASP:
            return [Query(label, ca.approach[0], cb.approach[0],
                          phase_worlds(self.scratch, self.placements[e.a.placement], None, open_))]
        if e.kind == EdgeKind.TRANSFER:
            return [Query(label, ca.lift[-1], cb.lift[-1], self._held(e.a))]
        if e.kind == EdgeKind.INHAND:
            return [Query(label + ":place", self.turn_end(e), cb.lift[-1], self._held(e.b))]
        ex = self.exchanges[e]
        return [Query(label + ":carry", ca.lift[-1], ex.approach[0], self._held(e.a)),
                Query(label + ":place", ex.retreat[-1], cb.lift[-1], self._held(e.b))]

    def _held(self, n: Node):
        robot = self.scratch.problem.robot
        fingers = {h: robot.hands[h].open for h in HANDS}
        fingers[n.hand] = self.lists[n.hand].finger_q[n.grasp]
        return phase_worlds(self.scratch, inverse(self.lists[n.hand].X_OG[n.grasp]), n.hand, fingers)

    def _exchange(self, e: Edge) -> bool:
        """The exchange configuration of a hand-over edge (found once); False when none."""
        if e in self.exchanges:
            return True
        a, b = self.configs[e.a], self.configs[e.b]
        dg = DoubleGrasp(a, b, 0.0, 0.0, 0.0)
        obj = object_shape(self.scratch.problem)
        rng = np.random.default_rng([self.seed, 40, len(self.why), self.counts["exchanges_tried"]])
        self.counts["exchanges_tried"] += 1
        X_c = exchange_pose(self.scratch, dg, self.lists, self.env, obj)[0]
        for lean in (False, True):
            ex = None if X_c is None else exchange_near(self.scratch, rng, dg, self.lists, X_c, obj, self.env, lean)
            if ex is not None:
                self.exchanges[e] = ex
                return True
        return False

    def turn_end(self, e: Edge) -> np.ndarray:
        """Where an in-hand edge's turn ends (nq,): the arm still at the end of ``e.a``'s
        lift, the fingers at ``e.b``'s grasp (the turn ends at exactly that grasp)."""
        q = self.configs[e.a].lift[-1].copy()
        q[self.scratch.problem.robot.hands[e.a.hand].idx] = self.lists[e.a.hand].finger_q[e.b.grasp]
        return q

    def _inhand(self, e: Edge) -> bool:
        """The finger motions of an in-hand edge (found once): the object lifted with
        ``e.a``'s grasp, the arm held at the lift's end, the fingers turning it to exactly
        ``e.b``'s grasp (:func:`dexterous.task.turn_in_hand`); False when they do not.
        A failed search is tried again from another stream while the run has turns left:
        it is asked only once the edge's carry and the path's other motions exist, and
        the same turn fails or succeeds by the draw (a budget that ends it in 9 runs of 10)."""
        if e in self.inhands:
            return True
        p, hand = self.scratch.problem, e.a.hand
        grasps, names = self.lists[hand], [f.name for f in p.robot.hands[hand].spec.fingers]
        q_a, q_b = self.configs[e.a].lift[-1], self.turn_end(e)
        for k in range(self.options.inhand_attempts - self.counts["inhand_tried"]):
            rng = np.random.default_rng([self.seed, 60, len(self.why), len(self.inhands)] + [k] * (k > 0))
            s = gs_scratch(p.robot, hand, p.object.mesh, p.disabled.links(), q_a, tuple(p.spec.obstacles),
                           p.spec.object.friction, p.cache_dir, rng, p.collision_options.contact_tolerance)
            start, goal = (GsConfig(inverse(grasps.X_OG[j]), grasps.points[j], grasps.normals[j], q)
                           for j, q in ((e.a.grasp, q_a), (e.b.grasp, q_b)))
            pieces = turn_in_hand(s, start, goal, rng, GaitTreeOptions(nodes=self.options.inhand_nodes))
            self.counts["inhand_tried"] += 1
            if pieces:
                self.inhands[e] = piece_motions(pieces, names, s.X_WG)
                return True
        return False

    def solve(self, path: list[Edge], labels: list[str]) -> Edge | None:
        """Solve the motions of the path's edges not solved yet; the first edge that
        fails (then blocked, with why), or None when all have motions.  An in-hand edge's
        fingers turn the object last, once every query of the path has a motion: the
        turn is the dearest search, and its end is known before it (:meth:`turn_end`)."""
        for e, label in zip(path, labels):
            if e.kind == EdgeKind.HANDOVER and not self._exchange(e):
                self.why[e] = "no reachable collision-free exchange pose for the hand-over"
                self.blocked.add(e)
                return e
        queries = [q for e, label in zip(path, labels) for q in self._queries(e, label) if q.label not in self.paths]
        streams = [[self.seed, 50, self.counts["queries"] + i] for i in range(len(queries))]
        self.counts["queries"] += len(queries)
        results = solve_queries(self.scratch, self.roadmap, self.query_weights, queries, streams,
                                self.scratch.options.jobs)
        failed = None
        for q in queries:
            r = results[q.label]
            self.table[q.label] = self.table.get(q.label, TransitionStats()).plus(r.stats)
            self.counts["query_checks"] += r.checks
            if r.error is None:
                self.paths[q.label] = r.path
        for e, label in zip(path, labels):
            bad = [q for q in self._queries(e, label) if q.label not in self.paths]
            if bad and failed is None:
                failed = e
            if bad:
                self.blocked.add(e)
                self.why[e] = results[bad[0].label].error
        if failed is not None:
            return failed
        for e in (e for e in path if e.kind == EdgeKind.INHAND):
            spent = self.counts["inhand_tried"] >= self.options.inhand_attempts
            if not self._inhand(e):
                self.why[e] = (f"not tried: {self.options.inhand_attempts} in-hand moves a run at most, and "
                               "they failed" if spent else
                               f"the {e.a.hand} hand's fingers did not turn the object from one grasp to the "
                               f"other ({self.options.inhand_nodes} GS_n expansions, seed 003)")
                self.blocked.add(e)
                return e
        return None


def shoulder_positions(scratch: Scratch, hand: str, most: int = 729) -> np.ndarray:
    """(k, 3) positions of the hand's shoulder (its arm's first joint) over a grid of the
    torso's joint values (9 per joint up to three joints; ``most`` in all at most), the
    rest at rest."""
    robot = scratch.problem.robot
    torso = robot.groups["torso"]
    per_joint = max(2, min(9, int(round(most ** (1 / max(1, len(torso)))))))
    axes = [np.linspace(robot.lower[i], robot.upper[i], per_joint) for i in torso]
    q = np.repeat(robot.q_rest[None], max(1, per_joint ** len(torso)), axis=0)
    if len(torso):
        q[:, torso] = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, len(torso))
    return np.array([shoulder(scratch, hand, qk) for qk in q])


def _label(e: Edge) -> str:
    """A query label unique to the edge (its ends' hands, grasps and placements)."""
    def n(x: Node | None) -> str:
        return "robot" if x is None else f"{x.hand}-{x.grasp}@{x.placement}"
    return f"{e.kind.value} {n(e.a)} -> {n(e.b)}"


def intermediate_placements(fitted: Fitted, faces: int, options: GraphOptions, hands_at: dict[str, np.ndarray],
                            within: dict[str, np.ndarray], ends: dict[str, set[str]]) -> dict[str, np.ndarray]:
    """``p1``, ``p2``...: per resting face (``faces``, most stable first), one of the
    ``fitted`` placements on the scene's supports, ``intermediate`` at most, where the
    hands that must use it work most easily: nearest (horizontally) to where the hand
    rests (``hands_at``: its grasp frame at the rest configuration), for a hand with nodes
    at both the start and the goal (``ends``: the hands with nodes at each); else the fit
    whose farther distance to the rests of a hand of each end is least.  Within every such
    hand's reach (``within``: per hand, (k,) bool over the fits)."""
    if not len(fitted):
        return {}
    p = fitted.X_WO[:, :3, 3]
    near = {h: np.linalg.norm(p[:, :2] - hands_at[h][:2], axis=1) for h in HANDS}
    both = sorted(ends[START] & ends[GOAL])
    pairs = [(h, h) for h in both] or [(a, b) for a in ends[START] for b in ends[GOAL]] or [("right", "left")]
    score = np.min([np.where(within[a] & within[b], np.maximum(near[a], near[b]), np.inf) for a, b in pairs], axis=0)
    out = {}
    for face in range(faces):
        idx = np.flatnonzero((fitted.stable == face) & np.isfinite(score))
        if len(idx):
            out[f"p{len(out) + 1}"] = fitted.X_WO[idx[np.argmin(score[idx])]]
        if len(out) == options.intermediate:
            break
    return out


def steps_of(g: _Graph, path: list[Edge], labels: list[str]) -> list[Step]:
    """The path's transitions with their fixed pieces (approach, lift, exchange lines) and
    query labels, in order (each edge kind's in :mod:`manip.steps`)."""
    steps = []

    def gid(n: Node) -> str:
        return grasp_id(g.lists, n.hand, n.grasp)

    for e, label in zip(path, labels):
        ca = g.configs.get(e.a) if e.a is not None else None
        cb = g.configs.get(e.b) if e.b is not None else None
        if e.kind == EdgeKind.ARRIVE:
            steps += moves.arrive(label, cb, gid(e.b), START)
        elif e.kind == EdgeKind.TRANSFER:
            steps += moves.transfer(label, ca, cb, gid(e.a))
        elif e.kind == EdgeKind.REGRASP:
            steps += moves.regrasp(label, ca, gid(e.a), cb, gid(e.b), e.a.placement)
        elif e.kind == EdgeKind.HANDOVER:
            steps += moves.handover(label + ":carry", label + ":place", ca, gid(e.a), g.exchanges[e], cb, gid(e.b))
        elif e.kind == EdgeKind.INHAND:
            steps += moves.inhand(label, ca, gid(e.a), g.inhands[e], cb, gid(e.b))
        else:  # LEAVE
            steps += moves.leave(label, ca, gid(e.a), GOAL)
    return steps


def _search_and_solve(g: _Graph, style, clock: dict, stable: list[StablePlacement]):
    """The first path whose motions all succeed, with its labels; raises PlanningFailed."""
    o = g.options
    t0 = time.perf_counter()
    if style.handover or style.placements:
        g.add_nodes([START, GOAL])  # in full (each hand and end once per run)
    elif style.inhand:
        g.add_nodes([START, GOAL], hands=tuple(sorted(g.gaits)))  # the hands that can turn it
    else:
        g.one_arm_nodes()
    if style.inhand:
        g.add_turnable_nodes()
    t0 = tick(clock, "nodes", t0)
    rounds = (o.vis_rounds if o.sampler == "vis-prm" else 1) if style.placements and stable else 0
    out = successors(g.configs, style, g.compatible, g.turnable)
    last = None
    for attempt in range(o.graph_attempts):
        path = search(out, g.length, g.blocked)
        # every path without a regrasp failed: intermediate placements may help now; more
        # (another Visibility-PRM) when every path through them failed too
        while g.rounds < rounds and (path is None or (not g.rounds and sum(e.kind.regrasps for e in path))):
            t0 = tick(clock, "search", t0)
            g.add_intermediate(stable)
            t0 = tick(clock, "nodes", t0)
            out = successors(g.configs, style, g.compatible, g.turnable)
            path = search(out, g.length, g.blocked)
        t0 = tick(clock, "search", t0)
        if path is None:
            break
        g.counts["paths_tried"] = attempt + 1
        labels = [_label(e) for e in path]
        last = g.solve(path, labels)
        t0 = tick(clock, "motions", t0)
        if last is None:
            return _optimised(g, path, clock, t0)
    raise _no_path(g, style, last)


def _optimised(g: _Graph, path: list[Edge], clock: dict, t0: float) -> tuple[list[Edge], list[str]]:
    """The path after §V's merges (:func:`graph.optimise`), whose new edges' motions are
    solved here; regrasps and placements before and after in the counts."""
    def connect(edges: list[Edge]) -> bool:
        if any(e in g.blocked or any(n is not None and n not in g.configs for n in (e.a, e.b)) for e in edges):
            return False  # a node the graph has not, or an edge already failed
        return g.solve(edges, [_label(e) for e in edges]) is None

    before = (sum(e.kind.regrasps for e in path), len(_intermediate(path)))
    path = optimise(path, connect)
    g.counts["optimiser"] = {"regrasps": [before[0], sum(e.kind.regrasps for e in path)],
                             "placements": [before[1], len(_intermediate(path))]}
    tick(clock, "optimise", t0)
    return path, [_label(e) for e in path]


def _intermediate(path: list[Edge]) -> set[str]:
    return {n.placement for e in path for n in (e.a, e.b) if n is not None} - {START, GOAL}


def _ends_held(have: set[tuple[str, str]], hands) -> str:
    """"right hand: start, left hand: neither end": the ends where each hand has a node
    (``have``: (hand, START or GOAL) pairs)."""
    return ", ".join(f"{h} hand: " + (" and ".join(p for p in (START, GOAL) if (h, p) in have) or "neither end")
                     for h in hands)


def _no_path(g: _Graph, style, last: Edge | None) -> PlanningFailed:
    """Why no path was found: no node at the start or goal, or the last edge that failed."""
    for pid in (START, GOAL):
        if not any(n.placement == pid for n in g.configs) and all((h, pid) in g.searched for h in HANDS):
            return PlanningFailed(Stage.GRASPS, f"no hand reaches a collision-free grasp of the object at its {pid} "
                                                "pose")
    tried = g.counts["paths_tried"]
    if style.inhand and not (style.handover or style.placements) and last is None and not tried:
        every = {(n.hand, n.placement) for n in g.configs if n.hand in g.gaits
                 and g.lists[n.hand].in_contact[n.grasp].all()}
        ends = _ends_held(every, sorted(g.gaits))
        return PlanningFailed(Stage.GRASPS, f"no in-hand path: finger gaiting starts and ends with every finger on the "
                                            f"object, and no hand that can gait has such a grasp at both the start "
                                            f"and the goal ({ends})")
    if not (style.handover or style.placements) and last is None and not tried:
        ends = _ends_held({(n.hand, n.placement) for n in g.configs}, HANDS)
        return PlanningFailed(Stage.GRASPS, f"no one-arm path: no hand holds the object at both the start and the "
                                            f"goal with one grasp ({ends})")
    if last is None and not tried:
        none = " (no intermediate placement fits on the scene's supports)" if style.placements and \
            g.counts.get("intermediate_placements") == 0 else ""
        return PlanningFailed(Stage.GRASPS, f"no {style.name} path joins the start and the goal in the manipulation "
                                            f"graph ({len(g.configs)} grasp-placement nodes){none}")
    if last is None:
        return PlanningFailed(Stage.TRANSITION, f"every path of the manipulation graph failed ({tried} tried, "
                                                f"{len(g.blocked)} edges blocked)")
    return PlanningFailed(Stage.TRANSITION, f"{g.why.get(last, 'no path')} (the last of {tried} paths of the "
                                            f"manipulation graph tried, {len(g.blocked)} edges blocked)",
                          _label(last))


# auto: by regrasps, then by expected motion time: the fingers turn the object last (finger
# gaiting takes about TURN_S_PER_RAD seconds of motion per radian on top of the arm's moves,
# and a hand-over's or a place-and-regrasp's whole motion in our suites at most 37 s;
# docs/DESIGN-NOTES.md), and its search is the dearest (seconds to a minute), so it runs
# only when the arms' moves cannot do the task
LEVELS = {"auto": ("one-arm", "handover", "place-regrasp", "inhand"), "one-arm": ("one-arm",),
          "handover": ("handover",), "inhand": ("inhand",), "place-regrasp": ("place-regrasp",)}
TURN_S_PER_RAD = 36.0  # s of finger-gaiting motion per radian the object turns (the in-hand suite's median, 24-108)


def plan(problem: Problem, lists: dict[str, GraspList], roadmap: Roadmap | None, options: OnlineOptions, seed: int,
         stable: list[StablePlacement] = (), graph: GraphOptions = GraphOptions(), keep: dict | None = None) -> Outcome:
    """Plan the manipulation with the fewest regrasps in ``graph.style``; ``stable``: the
    object's stable placements (none: no intermediate placement).  A failure is the
    Outcome's ``failure``.

    ``auto`` tries the styles in order of the regrasps they need: one arm (none), then
    a hand-over (one; the hand-over task of Saut et al. 2010, whose double grasps and
    exchange search are tuned for it), then intermediate placements (one or more); the
    first that succeeds is the plan, and ``counts["styles"]`` says why the ones before
    it were not used.  A style that necessary conditions rule out (:func:`graph.ruled_out`
    over the grasps usable at each end, :meth:`_Graph.usable`: one batched IK per hand
    and end, ~50 ms) is not tried.  The manipulation graph (nodes, blocked edges) is
    shared by the styles; ``keep["graph"]`` receives it (for :func:`exhaustive_minimum`)."""
    task = problem.spec.task
    scratch = Scratch(problem, options, roadmap.unchecked if roadmap is not None else ())
    try:
        check_ends(scratch)
        for h in HANDS:
            if len(lists[h]) == 0:
                raise PlanningFailed(Stage.GRASPS, empty_list_reason(h))
    except PlanningFailed as exc:
        return failed(problem, exc, graph.style)
    g = _Graph(scratch, lists, roadmap, {START: task.X_WO_start, GOAL: task.X_WO_goal}, graph, seed)
    if keep is not None:
        keep["graph"] = g
    why, failures, clock, last = {}, {}, {}, None
    t0 = time.perf_counter()
    usable = g.usable()
    tick(clock, "styles: necessary conditions", t0)
    for name in LEVELS[graph.style]:
        cannot = ruled_out(STYLES[name], usable, bool(stable), g.gaits)
        if cannot:
            why[name] = cannot
            failures[name] = PlanningFailed(Stage.GRASPS, cannot)
            last = Outcome(TASK, placements=dict(g.placements), counts=dict(g.counts), failure=failures[name])
            continue
        if name == "handover":
            t0 = time.perf_counter()
            g.handover_nodes()
            nodes = {"nodes": time.perf_counter() - t0}
            if g.no_handover():
                out = Outcome(TASK, stages=nodes, failure=PlanningFailed(Stage.GRASPS, g.no_handover()))
            else:
                out = handover.plan(problem, lists, roadmap, options, seed, g.singles, scratch)
                out = replace(out, stages={**nodes, **out.stages})
            if out.failure is None:
                out = replace(out, counts=dict(out.counts, style="handover", regrasps=1, placements=0))
        else:
            out = _graph_plan(g, stable, STYLES[name])
        clock.update({f"{name}: {k}": v for k, v in out.stages.items()})
        if out.failure is None:
            why[name] = "chosen"
            for later in LEVELS[graph.style][LEVELS[graph.style].index(name) + 1:]:
                why[later] = ruled_out(STYLES[later], usable, bool(stable), g.gaits) or _not_needed(later, name)
            return replace(out, stages=clock, counts=dict(out.counts, styles=why))
        why[name], failures[name] = str(out.failure.reason), out.failure
        last = out
    if len(failures) == 1:
        return replace(last, stages=clock, counts=dict(last.counts, styles=why))
    # the stage of the style that got farthest; the reason names each style's stage
    far = max(failures.values(), key=lambda f: FARTHEST.index(f.stage) if f.stage in FARTHEST else -1)
    reason = "; ".join(f"{k} (stage {_where(f)}): {f.reason}" for k, f in failures.items())
    return replace(last, stages=clock, counts=dict(last.counts, styles=why),
                   failure=PlanningFailed(far.stage, reason, far.transition))


FARTHEST = (Stage.ENDS, Stage.GRASPS, Stage.KEYS, Stage.TRANSITION)  # how far a style got, in order


def _not_needed(later: str, chosen: str) -> str:
    """Why ``auto`` did not try ``later`` once ``chosen`` had succeeded."""
    if later == "inhand":
        return (f"not tried: {chosen} succeeded first; turning the object in the fingers is one regrasp too, but its "
                f"motion is the longest (about {TURN_S_PER_RAD:g} s of finger gaiting per radian of turn)")
    return f"not tried: {chosen} succeeded first with fewer or as few regrasps"


def _where(f: PlanningFailed) -> str:
    return f.stage.value + (f" ({f.transition})" if f.transition else "")


def failed(problem: Problem, failure: PlanningFailed, style: str) -> Outcome:
    """The outcome of a run of ``style`` that failed before planning (its ends, an empty
    grasp list or roadmap): no phases, the task's placements, the task that would have
    planned it (``seed000``: the hand-over task)."""
    if style == "seed000":
        return handover.failed(problem, failure)
    task = problem.spec.task
    return Outcome(TASK, placements={START: task.X_WO_start, GOAL: task.X_WO_goal}, failure=failure)


def plan_style(problem: Problem, lists: dict[str, GraspList], roadmap: Roadmap | None, options: OnlineOptions,
               seed: int, style: str, stable: list[StablePlacement] = (), keep: dict | None = None,
               sampler: str = GraphOptions.sampler) -> Outcome:
    """``regrasp plan --style --sampler``: ``seed000``, the hand-over task of Saut et al.
    2010 alone; any other, :func:`plan` in that style, its intermediate placements from
    ``sampler`` (``faces`` or ``vis-prm``, :class:`GraphOptions`)."""
    if style == "seed000":
        return handover.plan(problem, lists, roadmap, options, seed)
    return plan(problem, lists, roadmap, options, seed, stable, GraphOptions(style=style, sampler=sampler), keep)


def _graph_plan(g: _Graph, stable: list[StablePlacement], style) -> Outcome:
    """The manipulation graph's plan in one ``style`` (a :class:`graph.Style`), on the
    graph ``g`` (its nodes and blocked edges shared with the styles tried before)."""
    scratch, options = g.scratch, g.scratch.options
    problem = scratch.problem
    clock = dict.fromkeys(STAGES, 0.0)
    before = scratch.checks
    try:
        path, labels = _search_and_solve(g, style, clock, list(stable))
        t0 = time.perf_counter()
        steps = steps_of(g, path, labels)
        queries = [q for e, label in zip(path, labels) for q in g._queries(e, label)]
        phases = time_steps(steps, g.paths, problem.robot.velocity, np.full(problem.robot.nq, options.acceleration),
                            blend_check(scratch, queries) if options.blend else None, options.held_speed)
        tick(clock, "timing", t0)
    except PlanningFailed as exc:
        counts = dict(g.counts, checks=scratch.checks - before + _workers(g, options))
        return Outcome(TASK, placements=dict(g.placements), stages=clock, transitions=g.table, counts=counts,
                       failure=exc)
    used = [n for e in path for n in (e.a, e.b) if n is not None]
    grasps = tuple(dict.fromkeys((grasp_id(g.lists, n.hand, n.grasp), n.hand, n.grasp) for n in used))
    counts = dict(g.counts, style=style_of(path), regrasps=sum(e.kind.regrasps for e in path),
                  placements=len(_intermediate(path)), edges=[e.kind.value for e in path],
                  waypoints=int(sum(len(p.waypoints) for p in phases)),
                  checks=scratch.checks - before + _workers(g, options))
    kept = {pid: X for pid, X in g.placements.items() if pid in _intermediate(path) | {START, GOAL}}
    table = {q.label: g.table[q.label] for q in queries}
    return Outcome(TASK, phases, grasps, kept, clock, table, counts)


def fewer_regrasps(g: _Graph, stable: list[StablePlacement], regrasps: int, budget: int) -> tuple[bool | None, int]:
    """Is there a path of fewer than ``regrasps`` regrasps over the manipulation graph
    ``g`` of a run (every style; its intermediate placements added if the run had not)?
    (True, False, or None when ``budget`` edges were solved before it could tell; edges
    solved).  The benchmark's check that a plan's count is the least: the plain fix point
    of :func:`graph.fewest_regrasps` (apart from the search) over the edges not known to
    fail gives a path of fewer regrasps, if any; its edges are solved; one that fails is
    known to fail, and again, until a path's edges all succeed or none is left."""
    if regrasps == 0:
        return False, 0
    if stable and not g.rounds:  # a transfer through a placement may need no regrasp
        g.add_intermediate(stable)
    out = successors(g.configs, STYLES["auto"], g.compatible, g.turnable)
    solved = 0
    while True:
        least, path = fewest_regrasps(g.configs, out, lambda e: e not in g.blocked, limit=regrasps - 1, witness=True)
        if least is None:
            return False, solved
        for e in path:
            if _solved(g, e):
                continue
            if solved >= budget:
                return None, solved
            solved += 1
            if g.solve([e], [_label(e)]) is not None:
                break  # blocked now: look again
        else:
            return True, solved


def _solved(g: _Graph, e: Edge) -> bool:
    if (e.kind == EdgeKind.HANDOVER and e not in g.exchanges) or (e.kind == EdgeKind.INHAND and e not in g.inhands):
        return False
    return all(q.label in g.paths for q in g._queries(e, _label(e)))


def _workers(g: _Graph, options: OnlineOptions) -> int:
    return g.counts["query_checks"] if options.jobs > 1 else 0
