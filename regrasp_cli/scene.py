"""A loaded planning problem: scene.yaml resolved into robot, object, obstacles and task.

The :class:`Problem` is immutable: planning stages build the collision worlds they need
from it (object static at a pose, or held by a hand) with :meth:`Problem.world`.  It is
the problem of every task: a pick-and-place scene's (``spec`` a :class:`SceneSpec`) or an
in-hand scene's (``spec`` an :class:`~regrasp_cli.config.InhandSpec` whose obstacles are
posed in W, the robot holding its wrist at ``q_start == q_goal``;
:func:`regrasp_cli.dexterous.task.load_inhand_problem`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from regrasp_cli.config import InhandSpec, ObstacleSpec, SceneSpec, load_scene_spec
from regrasp_cli.errors import InputError
from regrasp_cli.model.collision import CollisionOptions, CollisionWorld, ObjectPlacement, collision_world
from regrasp_cli.model.objects import ObjectMesh, load_object_mesh
from regrasp_cli.model.robot import Robot, load_robot
from regrasp_cli.model.selfcollision import DisabledPairs, PairProgress, disabled_pairs
from regrasp_cli.store import sha256_file, sha256_params


@dataclass(frozen=True)
class Problem:
    spec: SceneSpec | InhandSpec  # obstacles posed in W
    robot: Robot
    object: ObjectMesh
    disabled: DisabledPairs
    q_start: np.ndarray  # (nq,) robot start configuration
    q_goal: np.ndarray  # (nq,) robot goal configuration
    cache_dir: Path | None = None  # where the robot's artefacts (self-collision, reach maps) are cached

    @property
    def collision_options(self) -> CollisionOptions:
        tol = self.spec.planning.contact_tolerance
        return CollisionOptions(contact_tolerance=tol, support_tolerance=tol)

    def world(self, obj: ObjectPlacement | None = None) -> CollisionWorld:
        """Self-collision + static obstacles (+ the object placed as given)."""
        return collision_world(self.robot, self.spec.obstacles, self.disabled.links(), obj, self.collision_options)

    def object_at(self, X_WO: np.ndarray) -> ObjectPlacement:
        """The object resting at X_WO (4, 4), as a static obstacle."""
        return ObjectPlacement(self.object.mesh, X_WO)


def scene_object(spec: SceneSpec) -> ObjectMesh:
    """The scene's object mesh, scaled.

    Raises:
        InputError: it cannot be read, or it is flat (field ``object.mesh``).
    """
    obj = load_object_mesh(spec.object.mesh, base_dir=spec.file.parent, scale=spec.object.scale,
                           file=str(spec.file), field="object.mesh")
    ext = obj.extents
    if not ext.min() > 1e-6 * ext.max():
        # a flat object (a sheet, or a box with a zero side) has area but no volume: no
        # mass centre, no inside, nothing for the fingers to close on
        flat = "xyz"[int(np.argmin(ext))]
        raise InputError(spec.file, "object.mesh",
                         f"mesh {obj.name} has no thickness along {flat} (bounding box "
                         f"{' x '.join(f'{e:g}' for e in ext)} m), so it has no volume to grasp")
    return obj


def load_problem(path: str | Path, cache_dir: Path | None, progress: PairProgress | None = None) -> Problem:
    """The scene at ``path`` loaded, the robot's self-collision matrix read from
    ``cache_dir`` or computed (reporting to ``progress(done, total)``, if given)."""
    spec = load_scene_spec(path)
    robot = load_robot(spec.robot)
    if not any(len(robot.groups[a]) for a in ("right_arm", "left_arm")):
        raise InputError(spec.file, "robot", f"{spec.robot} is a hand alone (its groups are empty): it has no arm "
                                             "to pick and place with (hands alone are for in-hand planning)")
    obj = scene_object(spec)
    for i, ob in enumerate(spec.obstacles):  # fail here, naming the scene file and field
        if ob.shape == "mesh":
            load_object_mesh(str(ob.mesh), base_dir=ob.mesh.parent, scale=ob.size[0],
                             file=str(spec.file), field=f"obstacles[{i}].mesh.file")
    q = {}
    for key, value in (("robot_start", spec.task.robot_start), ("robot_goal", spec.task.robot_goal)):
        if value == "rest":
            q[key] = robot.q_rest.copy()
        else:
            try:
                q[key] = robot.configuration(value, f"task.{key}")
            except InputError as exc:
                raise InputError(spec.file, exc.field, exc.message) from None
    return Problem(spec, robot, obj, disabled_pairs(robot, cache_dir, progress), q["robot_start"], q["robot_goal"],
                   None if cache_dir is None else Path(cache_dir))


def obstacles_sha256(obstacles: tuple[ObstacleSpec, ...]) -> str:
    """SHA-256 of the obstacles as the planner sees them (names, shapes, sizes, poses, mesh files)."""
    items = [{"name": o.name, "shape": o.shape, "size": list(o.size), "pose": np.round(o.X_WO, 12).tolist(),
              "mesh": sha256_file(o.mesh) if o.mesh is not None else None} for o in obstacles]
    return sha256_params(items)
