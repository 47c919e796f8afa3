"""The object's exchange position: Saut et al. 2010, §V-C and Fig. 6.

The exchange position is the collision-free node of a 3-D grid that minimises the summed
lengths of the wrist paths of Fig. 6: the grasping hand carries the object from its start
position to the exchange position, the other hand comes from where it rests, takes it
there and carries it to the goal.  The terms that do not depend on the exchange position
x are constant, so the cost is the sum of the distances from x to a few fixed points
(``anchors``: the object's start and goal positions and the receiving wrist's initial
position), a Fermat–Weber problem solved on the grid, as in the paper.  The planner's grid
is the cubes of the arms' reach maps that both hands get to (:mod:`model.reachmap`,
:func:`manip.tasks.handover.exchange_pose`); :func:`grid_nodes` makes a box's.
"""

from __future__ import annotations

from typing import Callable

import numpy as np


def grid_nodes(lower: np.ndarray, upper: np.ndarray, step: float) -> np.ndarray:
    """Nodes (m, 3) of a regular grid covering the box [lower, upper] (m) with ``step``."""
    lower, upper = np.asarray(lower, float), np.asarray(upper, float)
    if step <= 0 or np.any(upper < lower):
        raise ValueError(f"expected step > 0 and upper >= lower, found step={step}, box {lower}..{upper}")
    axes = [np.arange(lo, hi + 1e-9, step) for lo, hi in zip(lower, upper)]
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)


def wrist_path_cost(nodes: np.ndarray, anchors: np.ndarray, weights: np.ndarray | None = None) -> np.ndarray:
    """Sum of the (weighted) distances from each node (m, 3) to the anchors (k, 3): (m,)."""
    d = np.linalg.norm(nodes[:, None, :] - np.asarray(anchors, float)[None], axis=2)
    return d @ (np.ones(len(anchors)) if weights is None else np.asarray(weights, float))


def exchange_position(nodes: np.ndarray, anchors: np.ndarray, is_free: Callable[[np.ndarray], bool],
                      weights: np.ndarray | None = None) -> tuple[np.ndarray | None, int]:
    """The collision-free grid node of least cost and the number of nodes tested (cheapest
    first, so usually few); None when no node is free."""
    cost = wrist_path_cost(nodes, anchors, weights)
    for tested, i in enumerate(np.argsort(cost, kind="stable"), start=1):
        if is_free(nodes[i]):
            return nodes[i].copy(), tested
    return None, len(nodes)


def exchange_orientation(a_right_O: np.ndarray, a_left_O: np.ndarray, d_right_W: np.ndarray,
                         d_left_W: np.ndarray) -> np.ndarray:
    """R_WO (3, 3) turning the hands' approach directions in the object frame (3,) as close
    as possible (least squares, Wahba's problem) to the directions (3,) from which each
    arm reaches the exchange point: the paper's orientation "determined by the selected
    double grasp directions and the object position wrt. the robot torso"."""
    from scipy.spatial.transform import Rotation

    unit = lambda v: np.asarray(v, float) / max(float(np.linalg.norm(v)), 1e-12)  # noqa: E731
    R, _ = Rotation.align_vectors(np.array([unit(d_right_W), unit(d_left_W)]),
                                  np.array([unit(a_right_O), unit(a_left_O)]))
    return R.as_matrix()
