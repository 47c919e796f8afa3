"""Per-query scratch of the online planner: options, collision worlds, segment checks.

The problem, the grasp lists and the roadmap are immutable inputs; a :class:`Scratch` is
built for one `regrasp plan` run and holds what the run learns: collision worlds (built
once per attachment of the object, ~35 ms each, and moved to each placement) and check
counters.  Random generators are arguments of the functions that draw, never kept here.

Segments that the roadmap did not certify (connections to key configurations, repairs,
escape trees, approach lines, finger motions) are checked densely: no joint moves more than
``resolution`` and no robot (or held-object) point more than ``cartesian_step`` between two
checked configurations (the Cartesian bound of :class:`motion.local.LocalPlanner`).

The worlds of the four queries are *certified* (``certify``): every pair except a hand's
own links keeps ``cartesian_step / 2`` of clearance (a coal security margin) at the checked
configurations, so every point between them is free too, up to the contact and support
tolerances the pairs allow, and a finer check such as `regrasp validate` agrees.  The
query ends (the far ends of the approach, lift and retreat lines) are chosen free with
that clearance.  The short lines near contact (approach, lift, descent, finger motions)
cannot keep a clearance from what they touch and stay sampled checks.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from regrasp_cli.model.collision import CollisionWorld, ObjectPlacement, collision_world, mesh_geometry
from regrasp_cli.model.ik import IKOptions
from regrasp_cli.model.robot import Kinematics
from regrasp_cli.model.handshape import palm_and_finger_links
from regrasp_cli.model.reachmap import ReachMap, reach_map
from regrasp_cli.roadmap.compose import margin_rule
from regrasp_cli.motion.local import LocalPlanner, arm_chains, held_reach, joint_reach
from regrasp_cli.motion.rrt import RRTOptions
from regrasp_cli.scene import Problem


@dataclass(frozen=True)
class OnlineOptions:
    """Options of `regrasp plan` (metres, radians, seconds)."""

    planner: str = "roadmap"  # or "rrt-connect": the single-query baseline of §VI, or its OMPL peer
    # "ompl-rrtconnect" (optional extra; see manip/ompl_peer.py)
    jobs: int = 2  # processes for the four queries (the result does not depend on it)
    approach_distance: float = 0.08  # pre-grasp offset of the hand before it closes
    lift_height: float = 0.06  # the object is lifted (and lowered) vertically by this
    line_steps: int = 4  # IK waypoints of an approach, retreat or lift line
    preshape: tuple[float, ...] = (1.0, 0.6, 0.35, 0.2)  # finger opening tried, open = 1
    backoff: tuple[float, ...] = (0.015, 0.008)  # m: then fingertips backed off their contacts by these
    single_per_hand: int = 6  # single-grasp configurations kept per hand (§IV-B)
    grasp_attempts: int = 40  # grasps of a list tried before giving up
    key_samples: int = 6  # samples of the non-grasping joints per grasp (§V-C)
    sample_sigma: float = 0.3  # rad: spread of those samples around the rest configuration
    ik_seeds: int = 2  # arm IK from random postures when those from the sample give no grasp
    base_draws: int = 4  # draws of a sample until the non-grasping joints are collision-free
    exchange_samples: int = 16  # Gaussian samples of the exchange pose per double grasp
    exchange_sigma: float = 0.04  # m, position spread of those samples
    exchange_angle_sigma: float = 0.15  # rad, orientation spread
    double_grasps_tried: int = 10
    double_grasps_wanted: int = 6  # fewer pairs than this: each hand searched again among the other's partners
    key_attempts: int = 3  # double grasps (with their exchange) tried in turn when a query fails
    resolution: float = 0.02  # rad: dense segment check
    cartesian_step: float = 0.01  # m: dense segment check
    k_connect: int = 40  # nearest Super Graph nodes tried when connecting a configuration
    connections: int = 2  # ... until this many are joined
    retreat_distance: float = 0.15  # m: a hand backed straight out when no node sees an end (a cage)
    retreat_lift: float = 0.02  # m: ... after rising this far, when it cannot back out straight at once
    escape_iterations: int = 1500  # tree growth from an end that no node sees
    repairs: int = 30  # graph re-searches per query before RRT-Connect takes over
    rrt: RRTOptions = RRTOptions(step=0.4, max_iterations=3000)
    ompl_time: float = 60.0  # s: wall-clock guard of an ompl-rrtconnect query; its budget is rrt.max_iterations,
    # like rrt-connect's, and 10 s cut it short on seeds where ours gets its full 3000
    certify: bool = True  # query worlds keep cartesian_step / 2 of clearance (module docstring)
    coarse_checks: int = 4  # certified checks step this many times farther where the clearance allows
    # (motion.local.tiered_free): same certificate, fewer checks
    shortcut_iterations: int = 36
    probe_step: int = 16  # fine intervals between the samples of the shortcuts' cheap probe (queries.smooth)
    partial_shortcuts: int = 30  # checks of one joint group's straight line at a time (motion.rrt.partial_shortcut)
    final_shortcuts: int = 24  # random shortcuts after the partial ones
    blend: bool = True  # cut the corners where the curve is free, and time without stopping there (motion.blend)
    prune: bool = True  # then drop the waypoints their neighbours see past: each is a stop of the motion
    acceleration: float = 3.0  # rad/s^2 for every joint (URDFs carry no acceleration limits)
    # a held object moves at most this share of the arms' speed (velocity limits times it,
    # accelerations times its square: the object's inertial load times its square); at full
    # speed 3 of 20 default plans kept the statuette in MuJoCo, at half speed 18 (the fingertip
    # grasps slip under the carry's 0.5 g and 3 rad/s, not under its weight)
    held_speed: float = 0.5
    ik: IKOptions = IKOptions(restarts=2, max_iters=40)


@dataclass
class Scratch:
    """Mutable state of one planning run."""

    problem: Problem
    options: OnlineOptions
    unchecked: tuple[str, ...] = ()  # obstacles the roadmap was not built with (Roadmap.unchecked)
    worlds: dict = field(default_factory=dict)
    local: LocalPlanner | None = None
    kin: Kinematics | None = None  # FK scratch of this run

    def __post_init__(self) -> None:
        self.kin = Kinematics(self.problem.robot)
        self._held: dict = {}  # local planners for a held object, by hand and placement
        self.workable: dict = {}  # grasps clear of the obstacles and reached, by hand and pose (doublegrasp)
        self.backed_off: dict = {}  # pre-shapes backed off the contacts, by hand, grasp, distance and lift (keyconf)
        self.local = LocalPlanner(self.options.resolution, self.options.cartesian_step / 2,
                                  joint_reach(self.problem.robot), self.options.coarse_checks)
        self.chains = arm_chains(self.problem.robot)  # the displacement bound per class of pairs
        self.object_geometry = mesh_geometry(self.problem.object.mesh)  # one BVH for the run's worlds
        self._reach: dict[str, ReachMap] = {}

    def reach(self, hand: str) -> ReachMap:
        """The hand's reachable workspace (:mod:`model.reachmap`), from the robot's cache."""
        if hand not in self._reach:
            self._reach[hand] = reach_map(self.problem.robot, hand, self.problem.cache_dir)
        return self._reach[hand]

    def world(self, X_PO: np.ndarray | None, attached: str | None = None, touching: tuple[str, ...] = (),
              pair_filter=None, key: str = "", certified: bool = False) -> "Placed":
        """Self-collision + obstacles + the object at X_PO (in W, or in the grasp frame of
        ``attached``).  Worlds are built once per attachment, touching hands, pair filter
        (``key`` names the filter) and clearance, and moved to each placement on use.
        ``certified`` worlds keep the clearance of the module docstring when
        ``options.certify`` is on."""
        certified = certified and self.options.certify
        k = (X_PO is None, attached, tuple(sorted(touching)), key, certified)
        w = self.worlds.get(k)
        if w is None:
            p = self.problem
            obj = None if X_PO is None else ObjectPlacement(p.object.mesh, X_PO, attached, tuple(touching),
                                                            self.object_geometry)
            # the holding hand and the object move as one (its fingers do not move while it
            # holds): those pairs were checked when it closed, and cost the most
            rigid = palm_and_finger_links(p.robot, attached) if attached is not None else set()
            base = pair_filter or (lambda a, b: True)

            def keep(a, b):
                return base(a, b) and not ("object" in (a, b) and (a in rigid or b in rigid))

            margin = margin_rule(p.robot, self.local.margin) if certified else None
            w = collision_world(p.robot, p.spec.obstacles, p.disabled.links(), obj, p.collision_options,
                                pair_filter=keep, margin=margin)
            self.worlds[k] = w
        return Placed(w, X_PO, (X_PO, attached, tuple(touching), pair_filter, key))

    def certified(self, world: "Placed") -> "Placed":
        """The certified counterpart of ``world`` (itself when certification is off)."""
        return self.world(*world.spec, certified=True)

    def _local(self, world: "Placed") -> LocalPlanner:
        obj = world.world.object
        if obj is None or obj.attached_to is None:
            return self.local
        # a held object reaches farther than the robot: denser samples for its Cartesian bound
        k = (obj.attached_to, np.round(world.X_PO, 12).tobytes())
        local = self._held.get(k)
        if local is None:
            reach = held_reach(self.problem.robot, self.local.reach, obj.attached_to,
                               np.asarray(self.problem.object.mesh.vertices), world.X_PO)
            local = self._held[k] = LocalPlanner(self.local.resolution, self.local.margin, reach, self.local.coarse)
        return local

    def segment_free(self, world: "Placed", q0: np.ndarray, q1: np.ndarray, limit: int | None = None) -> bool:
        """Certified check; with ``limit``, only the coarsest samples (False proves a collision)."""
        return self._local(world).segment_free(world, q0, q1, self.chains, limit)

    def probe_free(self, world: "Placed", q0: np.ndarray, q1: np.ndarray) -> bool:
        """The cheap test of :meth:`LocalPlanner.probe_free`: False proves a collision."""
        return self._local(world).probe_free(world, q0, q1, self.options.probe_step, self.chains)

    def blend_free(self, world: "Placed", A: np.ndarray, C: np.ndarray, B: np.ndarray) -> bool:
        """The blend curve A, C, B of :mod:`motion.blend`, checked like a segment."""
        return self._local(world).blend_free(world, A, C, B, self.chains)

    def path_free(self, world: CollisionWorld, path: np.ndarray) -> bool:
        return all(self.segment_free(world, a, b) for a, b in zip(path[:-1], path[1:]))

    @property
    def checks(self) -> int:
        return sum(w.n_checks for w in self.worlds.values())


class Placed:
    """A collision world with the object at a given placement: the interface of
    :class:`CollisionWorld` the planners use, moving the run's world's object first
    when another placement used it last."""

    def __init__(self, world: CollisionWorld, X_PO: np.ndarray | None, spec: tuple = ()):
        self.world, self.X_PO = world, X_PO
        self.spec = spec  # the arguments of Scratch.world that made it

    def _place(self) -> CollisionWorld:
        w = self.world
        if self.X_PO is not None and w.X_PO is not self.X_PO and not np.array_equal(w.X_PO, self.X_PO):
            w.set_object_pose(self.X_PO)
        return w

    def is_free(self, q: np.ndarray, scale: float = 1.0) -> bool:
        return self._place().is_free(q, scale)

    @property
    def certified(self) -> bool:
        return self.world.certified

    def colliding_pairs(self, q: np.ndarray) -> list[tuple[str, str]]:
        return self._place().colliding_pairs(q)

    def segment_free(self, q0: np.ndarray, q1: np.ndarray, resolution: float, min_steps: int = 1,
                     limit: int | None = None) -> bool:
        return self._place().segment_free(q0, q1, resolution, min_steps, limit)
