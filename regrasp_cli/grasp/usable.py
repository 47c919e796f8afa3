"""The grasps of a list that a scene lets a hand use: Saut et al. 2010, §IV-B.

A grasp list is context independent (:mod:`.build`); the online stage "first filter[s]
L_1 and L_2" against the environment (§IV-B).  :func:`usable_at_ends` keeps the grasps
whose hand alone, at the grasp, clears the scene's obstacles with the object at its start
pose or at its goal pose (its fingertips may touch an obstacle as they touch the object,
within the contact tolerance): a grasp from under the object goes through its support at
both and no planner can use it.  The planners then work on the best of them, as many as
the list's build target, in the list's order (best first); their rows keep their index in
the stored list (:attr:`.build.GraspList.list_index`).
"""

from __future__ import annotations

import numpy as np

from regrasp_cli.grasp.build import GraspList
from regrasp_cli.model.handshape import hand_hits_static, hand_shapes, static_geometry
from regrasp_cli.scene import Problem


def usable_at_ends(problem: Problem, glist: GraspList, limit: int) -> GraspList:
    """The grasps of ``glist`` among the first ``limit`` (0: all) usable at the task's
    start pose or among the first ``limit`` usable at its goal pose, in the list's order."""
    env = static_geometry(problem.spec.obstacles)
    task, tolerance = problem.spec.task, problem.spec.planning.contact_tolerance
    poses = (task.X_WO_start, task.X_WO_goal)
    found = [0, 0]  # grasps usable at each pose so far
    keep = []
    shapes = hand_shapes(problem.robot, glist.hand, glist.finger_q, tolerance) if len(glist) else []
    for k, shape in enumerate(shapes):
        if limit and min(found) >= limit:
            break
        usable = [(not limit or found[i] < limit)
                  and not hand_hits_static(shape, X_WO @ glist.X_OG[k], env, touching=True)
                  for i, X_WO in enumerate(poses)]
        if any(usable):
            keep.append(k)
        found = [n + int(u) for n, u in zip(found, usable)]
    return glist.rows(np.array(keep, dtype=int))
