"""Generate the default robot: a 43-DoF humanoid torso with two anthropomorphic hands.

The layout follows the robot of Saut et al. 2010, §VI (DLR Justin with two SAH hands):
a 3-DoF torso (yaw, two pitches), two 7-DoF arms with the joint pattern of a KUKA/DLR
LWR (z y z y z y z, upper arm 0.40 m, forearm 0.39 m), and per hand four 3-DoF fingers
(abduction, proximal and middle flexion; the distal phalanx is rigid with the middle one,
which stands for the SAH's coupled distal joint) plus a 1-DoF thumb base:
3 + 2 x 7 + 2 x (4 x 3 + 1) = 43 DoF.

Collision and visual geometry are URDF primitives (cylinders, boxes, spheres), so any
URDF tool reads the file and collision checks are exact and fast.

Frames: the base frame is on the floor under the torso, x forward, z up.  Palm frame P:
x along the fingers, z the palm normal (fingers curl towards +z), y = z x x.  The grasp
frame G (``{r,l}_grasp_frame``) sits in front of the palm where the fingertip workspaces
overlap (§IV-A-1: "a grasp frame centred on the intersection of the finger workspaces").

Run ``python scripts/make_humanoid_urdf.py`` to rewrite ``configs/robots/humanoid43/robot.urdf``.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

OUT = Path(__file__).resolve().parents[1] / "configs" / "robots" / "humanoid43" / "robot.urdf"

GREY, DARK, SKIN = "0.75 0.75 0.78 1", "0.3 0.3 0.35 1", "0.85 0.7 0.6 1"

# Arm: (joint axis, offset of the next joint along the arm's z, link geometry)
ARM_JOINT_LIMITS = np.radians([170, 120, 170, 120, 170, 120, 170])
ARM_VELOCITY = [1.9, 1.9, 2.2, 2.2, 3.1, 3.1, 3.1]  # rad/s, LWR-class
ARM_OFFSETS = [0.06, 0.20, 0.20, 0.20, 0.19, 0.0, 0.07]  # a1..a7 -> next joint, metres
ARM_RADII = [0.075, 0.06, 0.06, 0.05, 0.05, 0.045, 0.04]

FINGER_PROX, FINGER_MID, TIP_RADIUS = 0.050, 0.055, 0.010
THUMB_PROX, THUMB_MID = 0.050, 0.060


def rpy(R: np.ndarray) -> str:
    with warnings.catch_warnings():  # gimbal lock: any valid decomposition will do
        warnings.simplefilter("ignore")
        r, p, y = Rotation.from_matrix(R).as_euler("xyz")
    return f"{r:.9g} {p:.9g} {y:.9g}"


def vec(v) -> str:
    return " ".join(f"{float(x):.9g}" for x in v)


class Urdf:
    def __init__(self, name: str):
        self.parts = [f'<?xml version="1.0"?>\n<robot name="{name}">']
        self.materials = {}

    def link(self, name: str, shapes=(), mass: float = 0.2) -> None:
        """shapes: list of (kind, size_attrs, xyz, R, colour)."""
        body = [f'  <link name="{name}">']
        body.append(
            f'    <inertial><mass value="{mass}"/><origin xyz="0 0 0"/>'
            f'<inertia ixx="1e-3" ixy="0" ixz="0" iyy="1e-3" iyz="0" izz="1e-3"/></inertial>'
        )
        for kind, size, xyz, R, colour in shapes:
            geom = f"<{kind} {size}/>"
            origin = f'<origin xyz="{vec(xyz)}" rpy="{rpy(R)}"/>'
            body.append(
                f"    <visual>{origin}<geometry>{geom}</geometry>"
                f'<material name="c{abs(hash(colour)) % 997}"><color rgba="{colour}"/></material></visual>'
            )
            body.append(f"    <collision>{origin}<geometry>{geom}</geometry></collision>")
        body.append("  </link>")
        self.parts.append("\n".join(body))

    def joint(self, name, parent, child, xyz, R=np.eye(3), axis=None, limits=None, vel=2.0, kind=None):
        kind = kind or ("fixed" if axis is None else "revolute")
        s = [f'  <joint name="{name}" type="{kind}">',
             f'    <parent link="{parent}"/><child link="{child}"/>',
             f'    <origin xyz="{vec(xyz)}" rpy="{rpy(R)}"/>']
        if axis is not None:
            s.append(f'    <axis xyz="{vec(axis)}"/>')
            s.append(f'    <limit lower="{limits[0]:.6g}" upper="{limits[1]:.6g}" effort="50" velocity="{vel}"/>')
        s.append("  </joint>")
        self.parts.append("\n".join(s))

    def text(self) -> str:
        return "\n".join(self.parts) + "\n</robot>\n"


def cyl_along(axis: int, length: float, radius: float, colour: str, start: float = 0.0):
    """A cylinder of ``length`` along local axis 0 (x) or 2 (z), starting at ``start``."""
    xyz = np.zeros(3)
    xyz[axis] = start + length / 2
    R = np.eye(3) if axis == 2 else Rotation.from_euler("y", np.pi / 2).as_matrix()
    return ("cylinder", f'radius="{radius}" length="{length}"', xyz, R, colour)


def sphere(radius, xyz, colour):
    return ("sphere", f'radius="{radius}"', np.asarray(xyz, float), np.eye(3), colour)


def box(size, xyz, colour):
    return ("box", f'size="{vec(size)}"', np.asarray(xyz, float), np.eye(3), colour)


def finger(u: Urdf, p: str, name: str, parent: str, xyz, R, s: float, prox: float, mid: float) -> None:
    """Abduction (about the root's z), then two flexions (about -y, curling x towards +z)."""
    u.joint(f"{p}{name}_abd", parent, f"{p}{name}_base", xyz, R, axis=[0, 0, s], limits=(-0.26, 0.26), vel=3.0)
    u.link(f"{p}{name}_base", mass=0.01)
    u.joint(f"{p}{name}_prox", f"{p}{name}_base", f"{p}{name}_proximal", [0, 0, 0], axis=[0, -1, 0],
            limits=(-0.15, 1.57), vel=3.0)
    u.link(f"{p}{name}_proximal", [cyl_along(0, prox, 0.009, SKIN)], mass=0.02)
    u.joint(f"{p}{name}_mid", f"{p}{name}_proximal", f"{p}{name}_middle", [prox, 0, 0], axis=[0, -1, 0],
            limits=(0.0, 1.57), vel=3.0)
    u.link(f"{p}{name}_middle", [cyl_along(0, mid, 0.008, SKIN)], mass=0.02)
    u.joint(f"{p}{name}_tip_joint", f"{p}{name}_middle", f"{p}{name}_tip", [mid, 0, 0])
    u.link(f"{p}{name}_tip", [sphere(TIP_RADIUS, [0, 0, 0], DARK)], mass=0.005)


def arm_and_hand(u: Urdf, side: str) -> None:
    p = f"{side}_"
    s = -1.0 if side == "r" else 1.0  # lateral sign: right arm on -y
    # Shoulder mount: the arm's z points outwards and 45 deg down.
    R_mount = Rotation.from_euler("x", -s * 3 * np.pi / 4).as_matrix()
    parent, xyz, R = "chest", [0.0, s * 0.22, 0.20], R_mount
    for i in range(7):
        axis = [0, 0, 1] if i % 2 == 0 else [0, 1, 0]
        child = f"{p}arm_link{i + 1}"
        lim = ARM_JOINT_LIMITS[i]
        u.joint(f"{p}arm_j{i + 1}", parent, child, xyz, R, axis=axis, limits=(-lim, lim), vel=ARM_VELOCITY[i])
        L, r = ARM_OFFSETS[i], ARM_RADII[i]
        if L == 0 or i == 0:
            shapes = [sphere(r, [0, 0, 0], GREY)]
        elif i == 6:  # flange: starts clear of the wrist sphere
            shapes = [cyl_along(2, L - 0.045, r, GREY, start=0.045)]
        else:  # stops short of the next joint so consecutive links only meet at joints
            shapes = [cyl_along(2, L - (0.05 if i == 4 else 0.025), r, GREY)]
        u.link(child, shapes, mass=1.0)
        parent, xyz, R = child, [0, 0, L], np.eye(3)
    # Palm: x along the arm (flange z), z the palm normal (flange x).
    R_FP = np.column_stack([[0, 0, 1], [0, -1, 0], [1, 0, 0]]).astype(float)
    u.joint(f"{p}palm_joint", f"{p}arm_link7", f"{p}palm", [0, 0, ARM_OFFSETS[6]], R_FP)
    u.link(f"{p}palm", [box([0.10, 0.09, 0.03], [0.05, 0, 0], SKIN)], mass=0.4)
    # Fingers: index next to the thumb.  Thumb on the -s side so the two hands mirror.
    t = -s
    for name, y in (("index", t * 0.03), ("middle", 0.0), ("ring", -t * 0.03)):
        finger(u, p, name, f"{p}palm", [0.10, y, 0.0], np.eye(3), t, FINGER_PROX, FINGER_MID)
    # Thumb: rooted at the side of the palm, pointing out of the palm and 30 deg forward,
    # curling forwards towards the finger pads (opposition); the base joint swings its
    # plane of flexion from the palm's side towards the palm's middle.
    u.joint(f"{p}thumb_base", f"{p}palm", f"{p}thumb_root", [0.03, t * 0.045, 0.0],
            axis=[t, 0, 0], limits=(0.0, 1.2), vel=2.0)
    u.link(f"{p}thumb_root", mass=0.02)
    a = np.radians(30)
    R_thumb = np.column_stack([[np.sin(a), 0, np.cos(a)], [0, -1, 0], [np.cos(a), 0, -np.sin(a)]])
    finger(u, p, "thumb", f"{p}thumb_root", [0, 0, 0], R_thumb, t, THUMB_PROX, THUMB_MID)
    u.joint(f"{p}grasp_joint", f"{p}palm", f"{p}grasp_frame", [0.135, 0.0, 0.065])
    u.link(f"{p}grasp_frame", mass=0.001)


def main() -> None:
    u = Urdf("humanoid43")
    u.link("base_link", [cyl_along(2, 0.65, 0.16, DARK)], mass=20.0)
    u.joint("torso_yaw", "base_link", "torso_1", [0, 0, 0.65], axis=[0, 0, 1], limits=(-0.5, 0.5), vel=1.0)
    u.link("torso_1", [cyl_along(2, 0.20, 0.13, GREY)], mass=5.0)
    u.joint("torso_pitch1", "torso_1", "torso_2", [0, 0, 0.20], axis=[0, 1, 0], limits=(-0.2, 0.6), vel=1.0)
    u.link("torso_2", [cyl_along(2, 0.20, 0.13, GREY)], mass=5.0)
    u.joint("torso_pitch2", "torso_2", "chest", [0, 0, 0.20], axis=[0, 1, 0], limits=(-0.4, 0.4), vel=1.0)
    u.link("chest", [box([0.20, 0.30, 0.26], [0, 0, 0.12], GREY), sphere(0.10, [0.0, 0, 0.40], GREY)], mass=8.0)
    arm_and_hand(u, "r")
    arm_and_hand(u, "l")
    OUT.parent.mkdir(parents=True, exist_ok=True)
    OUT.write_text(u.text())
    print(f"wrote {OUT}")


if __name__ == "__main__":
    main()
