"""The GS_n roadmap, single-query (seed 003 §V): trees of GS_n configurations grown from
the start grasp and from a grasp at the goal pose, whose edges are linear paths in GS_n
reduced to transfers and regrasps, joined by transfer-regrasp sequences.

Nodes are sampled the RLG way (§V, :func:`rlg_sample`): with the object's pose given,
each finger's contact is drawn among the surface points inside the finger's workspace
whose normal faces the closing fingertip, and its joints follow by IK; a sample is kept
when the hand does not collide (finger-finger, finger-object, object-palm) and the
contacts are force closure.  The start's grasp is the best of such samples at the start
pose: most fingers that may let go, then the finger joints farthest from their limits;
the goal tree's root is chosen the same way at the goal pose.

An edge (:func:`slide`) turns and moves the object from a node towards a target pose by
at most ``step_rad`` and ``step_m``, each contact sliding along the geodesic to the
surface point nearest where its fingertip is (the fingers stay where they are in the hand
as far as the surface allows), every step checked by :func:`gsn.gs_path` (IK, joint step,
collisions, force closure of all fingers and of every n-1 of them whose contact moves).
Targets are the other tree's newest node (probability ``goal_bias``; with one tree, the
goal pose) or a random pose; the tree's node nearest the target extends.  The paper
builds a roadmap of GS_n's connected components and links them by regrasp-transfer
sequences: :func:`connect` is that link, between a node of each tree within
``connect_rad``; the goal tree's path is then run backwards.  The goal is a pose only:
any grasp at it will do, so a start-tree node at the goal pose ends the query too (seed
003 §IV's final grasp is the one the path arrives with).

Frames: the grasp frame G (fixed), the object frame O; metres, radians.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from regrasp_cli.config import InhandPlanning
from regrasp_cli.dexterous.gait import GaitOptions, Piece, Regrasp, carry, finger_step, reduce_path, regrasp_to, \
    reversed_path
from regrasp_cli.dexterous.gsn import GsConfig, GsScratch, gs_path
from regrasp_cli.dexterous.hand import reach, tip_targets
from regrasp_cli.spatial import inverse


FACING = 0.2  # cosine: a fingertip closes on its contact within 78 deg of its normal, as the grasp
# search asks (0.5 kept the cube's distal links off its faces a little more often, but cost
# the ball many more of its successes: docs/DESIGN-NOTES.md, "Trees")


@dataclass(frozen=True)
class GaitTreeOptions:
    step_rad: float = 0.35  # object rotation per edge
    step_m: float = 0.01  # object translation per edge
    goal_bias: float = 0.5  # probability that the goal pose is the target
    nodes: int = InhandPlanning.nodes  # budget of extensions tried
    start_samples: int = 60  # RLG samples at the start pose
    candidates: int = 40  # contact candidates per finger per sample
    box_m: float = 0.02  # random targets within this of the start position (each axis)
    goal_carries: tuple[float, ...] = (1.0,)  # fractions of an edge a carry towards the goal tries, in turn
    regrasp_carry: bool = False  # an aimed regrasp carries the object one edge on at once
    first_tree: int = 150  # >0: restart with a fresh tree (and start grasp) after this, then twice as many, ...
    goal_tree: bool = True  # grow a second tree from a grasp at the goal pose and join the two
    connect_rad: float = 0.35  # try to join nodes of the two trees this close (rad, :func:`_distance`)
    connect_orders: int = 6  # finger orders a join's regrasps try
    aim_newest: bool = True  # each tree aims at the other's newest node (RRT-Connect), not at its root


def tree_budgets(total: int, first: int) -> list[int]:
    """Expansions of each tree when ``total`` is spent on trees of ``first``, ``2 first``,
    ``4 first``, ... expansions (the last gets the rest; one tree when ``first`` is 0).  A
    tree that wandered into grasps it cannot turn the object from seldom recovers, while
    most runs end early: restarts cut the long tail (a Luby-like schedule, doubling)."""
    if first <= 0:
        return [total]
    out, b = [], first
    while total - sum(out) > b:
        out.append(b)
        b *= 2
    rest = total - sum(out)
    if out and rest < out[-1] // 2:  # too short a tree: the last one gets it
        out[-1] += rest
    else:
        out.append(rest)
    return out


@dataclass
class RoadmapStats:
    generated: int = 0  # configurations tried (RLG samples and edge ends)
    kept: int = 0  # nodes of the tree
    iterations: int = 0
    start_liftable: int = 0  # fingers of the start grasp that may let go


@dataclass
class Tree:
    nodes: list[GsConfig] = field(default_factory=list)
    parent: list[int] = field(default_factory=list)
    edge: list[list[Piece]] = field(default_factory=list)  # transfers and regrasps from the parent

    def add(self, c: GsConfig, parent: int, pieces: list[Piece]) -> int:
        self.nodes.append(c)
        self.parent.append(parent)
        self.edge.append(pieces)
        return len(self.nodes) - 1

    def path(self, i: int) -> list[Piece]:
        """The transfers and regrasps from the root to node ``i``."""
        out: list[Piece] = []
        while i > 0:
            out[:0] = self.edge[i]
            i = self.parent[i]
        return out


def _candidates(s: GsScratch, X_GO: np.ndarray, f: int) -> tuple[np.ndarray, np.ndarray]:
    """Contact candidates of finger ``f`` with the object at ``X_GO``: indices (c,) of
    surface samples whose fingertip centre lies in the finger's workspace, where the
    fingertip touches the surface only at the contact (:attr:`GsScratch.clear`) and whose
    normal faces the closing fingertip, and the nearest workspace sample of each (c,);
    memoised (a node is expanded, and its fingers step, many times)."""
    return s.memoised(("candidates", X_GO.tobytes(), f), lambda: _find_candidates(s, X_GO, f))


def _find_candidates(s: GsScratch, X_GO: np.ndarray, f: int) -> tuple[np.ndarray, np.ndarray]:
    ws, r = s.workspaces[f], s.hand.radii[f]
    c_G = (s.sampled.points + r * s.sampled.normals) @ X_GO[:3, :3].T + X_GO[:3, 3]
    inside = np.nonzero((s.hm.voxels(s.workspaces)[f].lookup(c_G) >= 0) & s.clear)[0]
    if inside.size == 0:
        return inside, inside
    near = ws.tree.query(c_G[inside])[1]
    n_G = s.sampled.normals[inside] @ X_GO[:3, :3].T
    facing = -np.einsum("ij,ij->i", n_G, ws.sample_closing[near]) > FACING
    return inside[facing], near[facing]


def _seed(s: GsScratch, q: np.ndarray, f: int, near: int) -> np.ndarray:
    q = q.copy()
    q[s.hm.hand.finger_idx[f]] = s.workspaces[f].sample_q[near]
    return q


def rlg_sample(s: GsScratch, X_GO: np.ndarray, rng: np.random.Generator, candidates: int = 40) -> GsConfig | None:
    """A random GS_n configuration with the object at ``X_GO`` (4, 4), or None (§V: the
    contacts are the free parameters, the joints follow by IK)."""
    s.generated += 1
    s.place(X_GO)
    n_f = len(s.hand.fingers)
    q = s.hm.q.copy()
    points, normals = np.zeros((n_f, 3)), np.zeros((n_f, 3))
    for f in map(int, rng.permutation(n_f)):
        idx, near = _candidates(s, X_GO, f)
        for k in rng.permutation(idx.size)[:candidates]:
            i = idx[k]
            p, n = s.sampled.points[i:i + 1], s.sampled.normals[i:i + 1]
            targets = np.zeros((n_f, 3))
            targets[f] = tip_targets(s.X_WG @ X_GO, p, n, s.hand.radii[f:f + 1])[0]
            q_try = reach(s.hand, _seed(s, q, f, near[k]), targets, rng, fingers=(f,), restarts=0, tol=s.options.tol,
                          kin=s.kin)
            if q_try is not None and not s.finger_collides(q_try, f):
                q, points[f], normals[f] = q_try, p[0], n[0]
                break
        else:
            return None
    return GsConfig(X_GO.copy(), points, normals, q) if s.holds(points, normals) else None


def comfort(s: GsScratch, c: GsConfig) -> float:
    """How far the finger joints are from their limits: the least margin, as a fraction
    of each joint's range (0 at a limit, 0.5 mid-range)."""
    idx = np.concatenate(s.hm.hand.finger_idx)
    lo, hi = s.hm.robot.lower[idx], s.hm.robot.upper[idx]
    return float(np.min(np.minimum(c.q[idx] - lo, hi - c.q[idx]) / (hi - lo)))


def start_config(s: GsScratch, X_GO: np.ndarray, rng: np.random.Generator, o: GaitTreeOptions) -> GsConfig | None:
    """The best of ``o.start_samples`` RLG samples at ``X_GO``: most fingers that may let
    go, then the finger joints farthest from their limits (room to gait)."""
    best, key = None, (-1, -1.0)
    for _ in range(o.start_samples):
        c = rlg_sample(s, X_GO, rng, o.candidates)
        if c is None:
            continue
        k = (len(s.liftable(c)), comfort(s, c))
        if k > key:
            best, key = c, k
    return best


def regrasp_one(s: GsScratch, c: GsConfig, rng: np.random.Generator, o: GaitTreeOptions,
                g: GaitOptions) -> Regrasp | None:
    """One finger that may let go moves to a random new contact (§IV's regrasping path;
    the RLG sampling of that finger's contact), or None."""
    liftable = s.liftable(c)
    if not liftable:
        return None
    f = int(rng.choice(liftable))
    idx, near = _candidates(s, c.X_GO, f)
    for k in rng.permutation(idx.size)[:max(1, o.candidates // 8)]:
        i = idx[k]
        step = finger_step(s, c, f, s.sampled.points[i], s.sampled.normals[i], rng, g, _seed(s, c.q, f, near[k]))
        if step is not None:
            return step
    return None


def _reach_ahead(s: GsScratch, f: int, p: np.ndarray, n: np.ndarray, poses: np.ndarray) -> np.ndarray:
    """(k, c) bool: is the fingertip centre of finger ``f`` on the contacts ``p`` (c, 3)
    with normals ``n`` (c, 3), object frame, inside its workspace with the object at each
    pose of ``poses`` (k, 4, 4)?"""
    c_O = p + s.hand.radii[f] * n
    c_G = np.einsum("kij,cj->kci", poses[:, :3, :3], c_O) + poses[:, None, :3, 3]
    return (s.hm.voxels(s.workspaces)[f].lookup(c_G.reshape(-1, 3)) >= 0).reshape(len(poses), len(p))


def _turns(inside: np.ndarray) -> np.ndarray:
    """(c,) how many of the first poses, in a row, have every finger inside: ``inside`` (k, c)."""
    return np.argmin(np.vstack([inside, np.zeros((1, inside.shape[1]), bool)]), axis=0)


def aimed_regrasp(s: GsScratch, c: GsConfig, X_goal: np.ndarray, rng: np.random.Generator, o: GaitTreeOptions,
                  g: GaitOptions, ahead: int = 3) -> list[Piece] | None:
    """A finger that may let go steps to the contact that lets the object turn furthest
    towards ``X_goal`` with every fingertip inside its workspace (up to ``ahead`` edges
    of ``o.step_rad``), farther than the grasp now does; with ``o.regrasp_carry`` the
    object is then carried one edge on (seed 003 §V's regrasp-transfer sequence; the
    first step is kept alone when no carry goes).  None when no finger can step.  On a
    flat face a random step seldom helps the next turn: the contacts the turn needs are
    where a fingertip has room to follow them."""
    liftable = s.liftable(c)
    if not liftable:
        return None
    poses = np.stack([step_towards(c.X_GO, X_goal, k * o.step_rad, k * o.step_m) for k in range(1, ahead + 1)])
    each = np.stack([_reach_ahead(s, f, c.p[f:f + 1], c.n[f:f + 1], poses)[:, 0] for f in range(len(c.p))], axis=1)
    now = int(_turns(each.all(axis=1)[:, None])[0])
    options = []  # (turns, tie-break, finger, candidate, workspace sample)
    for f in liftable:
        idx, near = _candidates(s, c.X_GO, f)
        if idx.size == 0:
            continue
        others = np.delete(each, f, axis=1).all(axis=1)
        turns = _turns(_reach_ahead(s, f, s.sampled.points[idx], s.sampled.normals[idx], poses) & others[:, None])
        for k in np.nonzero(turns > now)[0]:
            options.append((int(turns[k]), rng.random(), f, int(idx[k]), int(near[k])))
    options.sort(reverse=True)
    kept = None
    for _, _, f, i, near in options[:max(1, o.candidates // 8)]:
        step = finger_step(s, c, f, s.sampled.points[i], s.sampled.normals[i], rng, g, _seed(s, c.q, f, near))
        if step is None:
            continue
        t = carry(s, step.after, poses[0], rng, s.options.step_m, s.options.step_rad, g) if o.regrasp_carry else None
        if t is not None:
            return [step, t]
        kept = kept or [step]
    return kept


def step_towards(X_a: np.ndarray, X_b: np.ndarray, step_rad: float, step_m: float) -> np.ndarray:
    """The pose from X_a towards X_b, at most ``step_rad`` and ``step_m`` away (X_b when
    within both)."""
    angle = Rotation.from_matrix(X_a[:3, :3].T @ X_b[:3, :3]).magnitude()
    dist = np.linalg.norm(X_b[:3, 3] - X_a[:3, 3])
    t = min(1.0, step_rad / angle if angle > 0 else 1.0, step_m / dist if dist > 0 else 1.0)
    if t >= 1.0:
        return X_b.copy()
    X = np.eye(4)
    X[:3, :3] = Slerp([0.0, 1.0], Rotation.from_matrix(np.stack([X_a[:3, :3], X_b[:3, :3]])))([t]).as_matrix()[0]
    X[:3, 3] = (1 - t) * X_a[:3, 3] + t * X_b[:3, 3]
    return X


def slide(s: GsScratch, a: GsConfig, X_new: np.ndarray, rng: np.random.Generator,
          g: GaitOptions) -> list[Piece] | None:
    """The GS_n path from ``a`` to the object at ``X_new``, each contact of a finger that
    may let go sliding to the surface point nearest its fingertip there (the others keep
    theirs: a thumb opposing three fingers), reduced to transfers and regrasps; None when a
    step fails (:func:`gsn.gs_path`) or the reduction does (:func:`gait.reduce_path`)."""
    centres_G = inverse(s.X_WG) @ np.c_[s.hand.tips(s.kin, a.q), np.ones(len(a.p))].T
    b_p, _ = s.surface.nearest((inverse(X_new) @ centres_G)[:3].T)
    fixed = tuple(f for f in range(len(a.p)) if f not in s.liftable(a))
    b_p[list(fixed)] = a.p[list(fixed)]
    steps = gs_path(s, a, X_new, b_p, rng, fixed)
    if not steps:
        return None
    return reduce_path(s, [a] + steps, rng, g)


def _distance(X_a: np.ndarray, X_b: np.ndarray, rho: float) -> float:
    """Pose distance: rotation angle plus translation over the object's radius."""
    return Rotation.from_matrix(X_a[:3, :3].T @ X_b[:3, :3]).magnitude() + np.linalg.norm(X_b[:3, 3] - X_a[:3, 3]) / rho


def pose_distances(X_a: np.ndarray, X_b: np.ndarray, rho: float) -> np.ndarray:
    """:func:`_distance` from each pose of ``X_a`` (k, 4, 4) to ``X_b`` (4, 4), at once: the
    angle from the chord, ``|R_a - R_b|_F = 2 sqrt(2) sin(angle / 2)`` (exact near 0)."""
    chord = np.linalg.norm(X_a[:, :3, :3] - X_b[:3, :3], axis=(1, 2))
    angle = 2.0 * np.arcsin(np.minimum(chord / (2.0 * np.sqrt(2.0)), 1.0))
    return angle + np.linalg.norm(X_a[:, :3, 3] - X_b[:3, 3], axis=1) / rho


def random_pose(X_start: np.ndarray, box: float, rng: np.random.Generator) -> np.ndarray:
    X = np.eye(4)
    X[:3, :3] = Rotation.random(random_state=rng).as_matrix()
    X[:3, 3] = X_start[:3, 3] + rng.uniform(-box, box, 3)
    return X


def _expand(s: GsScratch, a: GsConfig, target: np.ndarray, to_goal: bool, rng: np.random.Generator,
            o: GaitTreeOptions, g: GaitOptions) -> list[Piece] | None:
    """Towards ``target``: slide the contacts (the GS_n path; first towards the goal, the
    fingers staying where they are), or carry the object with them fixed (towards the goal
    by each fraction of an edge in ``o.goal_carries`` in turn); when neither goes, one
    finger regrasps, aimed at the goal's next turns when the target is the goal."""
    X_new = step_towards(a.X_GO, target, o.step_rad, o.step_m)
    for how in (0, 1) if to_goal else rng.permutation(2):
        s.generated += 1
        if how == 0:
            pieces = slide(s, a, X_new, rng, g)
        else:
            for frac in o.goal_carries if to_goal else (1.0,):
                X = X_new if frac == 1.0 else step_towards(a.X_GO, target, frac * o.step_rad, frac * o.step_m)
                t = carry(s, a, X, rng, s.options.step_m, s.options.step_rad, g)
                if t is not None:
                    break
            pieces = None if t is None else [t]
        if pieces:
            return pieces
    s.generated += 1
    aimed = aimed_regrasp(s, a, target, rng, o, g) if to_goal else None
    if aimed:
        return aimed
    r = regrasp_one(s, a, rng, o, g)
    return None if r is None else [r]


def _extend(s: GsScratch, tree: Tree, target: np.ndarray, to_goal: bool, goal_fails: dict[int, int],
            rng: np.random.Generator, o: GaitTreeOptions, g: GaitOptions) -> int | None:
    """Expand the tree's node nearest ``target`` (towards the goal: of those that failed it
    less than twice; ties, a regrasp keeping the pose, broken at random) and add the node
    it reaches: its index, or None.  ``goal_fails`` counts the failures towards the goal."""
    d = pose_distances(np.array([c.X_GO for c in tree.nodes]), target, s.rho) + 1e-9 * rng.random(len(tree.nodes))
    if to_goal:
        d[[k for k, n in goal_fails.items() if n >= 2]] = np.inf
        if np.isinf(d).all():
            return None
    i = int(np.argmin(d))
    pieces = _expand(s, tree.nodes[i], target, to_goal, rng, o, g)
    if not pieces:
        if to_goal:
            goal_fails[i] = goal_fails.get(i, 0) + 1
        return None
    return tree.add(pieces[-1].end, i, pieces)


def grow(s: GsScratch, start: GsConfig, X_goal: np.ndarray, rng: np.random.Generator,
         o: GaitTreeOptions = GaitTreeOptions(), g: GaitOptions = GaitOptions(),
         progress: Callable[[], None] | None = None) -> tuple[list[Piece] | None, Tree, RoadmapStats]:
    """Grow the tree from ``start`` until a node is at ``X_goal`` (4, 4, grasp frame): the
    transfers and regrasps from the start to it, or None within ``o.nodes`` expansions.
    ``progress()`` is called after each expansion."""
    tree = Tree()
    tree.add(start, -1, [])
    stats = RoadmapStats(start_liftable=len(s.liftable(start)))
    goal_fails: dict[int, int] = {}  # node -> failed expansions towards the goal
    for it in range(o.nodes):
        stats.iterations = it + 1
        to_goal = rng.random() < o.goal_bias
        target = X_goal if to_goal else random_pose(start.X_GO, o.box_m, rng)
        j = _extend(s, tree, target, to_goal, goal_fails, rng, o, g)
        if progress is not None:
            progress()
        if j is None:
            continue
        if _distance(tree.nodes[j].X_GO, X_goal, s.rho) < 1e-9:
            stats.kept = len(tree.nodes)
            return tree.path(j), tree, stats
    stats.kept = len(tree.nodes)
    return None, tree, stats


def connect(s: GsScratch, a: GsConfig, b: GsConfig, rng: np.random.Generator, o: GaitTreeOptions,
            g: GaitOptions) -> list[Piece] | None:
    """Transfers and regrasps from ``a`` to ``b`` (seed 003 §V's transfer-regrasp and
    regrasp-transfer sequences that link two GS_n configurations): the object carried to
    b's pose on a's contacts, then each finger stepping to b's contact; or each finger
    stepping first, at a's pose, to b's contacts carried there, then the object carried to
    b.  None when neither goes."""
    t = carry(s, a, b.X_GO, rng, s.options.step_m, s.options.step_rad, g)
    if t is not None:
        steps = regrasp_to(s, t.end, b, rng, g, orders=o.connect_orders)
        if steps is not None:
            return [t] + steps
    back = carry(s, b, a.X_GO, rng, s.options.step_m, s.options.step_rad, g)
    if back is not None:
        steps = regrasp_to(s, a, back.end, rng, g, orders=o.connect_orders)
        if steps is not None:
            return steps + reversed_path([back])
    return None


def grow_connect(s: GsScratch, start: GsConfig, goal: GsConfig, rng: np.random.Generator,
                 o: GaitTreeOptions = GaitTreeOptions(), g: GaitOptions = GaitOptions(),
                 progress: Callable[[], None] | None = None, exact: bool = False
                 ) -> tuple[list[Piece] | None, tuple[Tree, Tree], RoadmapStats]:
    """Two trees, from ``start`` and from ``goal`` (a grasp at the goal pose), grown by
    :func:`join_trees`: the start tree's path to its node, the join and the goal tree's
    path reversed: the transfers and regrasps from the start to ``goal`` (or to another
    grasp at its pose); or None within ``o.nodes`` expansions.  (The single-query version
    of §V adds both configurations to the graph; our goal is a pose, any grasp there will
    do, so ``goal`` is one such grasp, and a start-tree node at the goal pose ends the
    search as in :func:`grow`; with ``exact``, the path ends at ``goal`` itself: the
    grasp a regrasp of the manipulation graph must end with.)  ``progress()`` is called
    after each expansion."""
    trees = (Tree(), Tree())
    trees[0].add(start, -1, [])
    trees[1].add(goal, -1, [])
    stats = RoadmapStats(start_liftable=len(s.liftable(start)))
    joined = join_trees(s, trees, rng, o, g, stats, at_goal=not exact, progress=progress)
    stats.kept = len(trees[0].nodes) + len(trees[1].nodes)
    if joined is None:
        return None, trees, stats
    a, b, link = joined
    return trees[0].path(a) + link + reversed_path(trees[1].path(b)), trees, stats


def join_trees(s: GsScratch, trees: tuple[Tree, Tree], rng: np.random.Generator, o: GaitTreeOptions,
               g: GaitOptions, stats: RoadmapStats, at_goal: bool = False,
               progress: Callable[[], None] | None = None) -> tuple[int, int, list[Piece]] | None:
    """Grow the two trees in turn as :func:`grow` grows one, each towards the other's
    newest node (RRT-Connect's aim; with ``o.aim_newest`` off, the other's root pose) or a
    random pose near its own root; a new node is joined to the other tree's two nearest
    nodes within ``o.connect_rad`` (:func:`connect`).  The first tree's node ``a``, the
    second's ``b`` and the pieces from a to b; or None within ``o.nodes`` expansions.
    With ``at_goal``, a first-tree node at the second tree's root pose ends it too: ``b``
    is then 0 and no pieces (any grasp at the goal pose will do).  ``progress()`` is
    called after each expansion."""
    aims = (trees[1].nodes[0].X_GO, trees[0].nodes[0].X_GO)
    goal_fails: tuple[dict[int, int], dict[int, int]] = ({}, {})
    for it in range(o.nodes):
        stats.iterations += 1
        k = it % 2
        tree, other = trees[k], trees[1 - k]
        to_goal = rng.random() < o.goal_bias
        aim = other.nodes[-1].X_GO if o.aim_newest else aims[k]
        target = aim if to_goal else random_pose(tree.nodes[0].X_GO, o.box_m, rng)
        j = _extend(s, tree, target, to_goal, goal_fails[k], rng, o, g)
        if progress is not None:
            progress()
        if j is None:
            continue
        new = tree.nodes[j]
        if at_goal and k == 0 and _distance(new.X_GO, aims[0], s.rho) < 1e-9:
            return j, 0, []
        d = pose_distances(np.array([c.X_GO for c in other.nodes]), new.X_GO, s.rho)
        for m in np.argsort(d)[:2]:
            if d[m] > o.connect_rad:
                break
            s.generated += 1
            a, b = (j, int(m)) if k == 0 else (int(m), j)
            link = connect(s, trees[0].nodes[a], trees[1].nodes[b], rng, o, g)
            if link is not None:
                return a, b, link
    return None
