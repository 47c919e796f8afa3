"""Generate the HiroNX-like robot: a fixed body, a waist yaw and two 6-DoF arms with jaws.

The kinematic layout is that of Kawada's HiroNX / NEXTAGE as published in its URDF
(joint names, axes, origins and position limits): the body stands on the floor, the
chest turns about a vertical waist axis (``CHEST_JOINT0``) and carries two arms of six
joints, ``{R,L}ARM_JOINT0..5``:

====== ================= ====== ========================================= ===============
joint  role              axis   origin in the parent joint's frame (m)    limits (deg)
====== ================= ====== ========================================= ===============
J0     shoulder yaw      z      (0, +-0.145, 0.370296), rolled 15 deg     -88 .. 88
J1     shoulder pitch    y      (0, 0, 0)                                 -140 .. 60
J2     elbow pitch       y      (0, +-0.095, -0.25)   upper arm           -158 .. 0
J3     wrist yaw         z      (-0.03, 0, 0)                             -165 .. 105 (R)
J4     wrist pitch       y      (0, 0, -0.235)        forearm             -100 .. 100
J5     wrist roll        x      (-0.047, 0, -0.09)    wrist               -163 .. 163
====== ================= ====== ========================================= ===============

(+ on the left arm, - on the right one; the left wrist yaw is mirrored, -105 .. 165.)
The shoulder yaw axes lean outwards by 15 deg about x, so that the hanging upper arms,
offset 9.5 cm outwards at the shoulder pitch, come back under the shoulders.  The head
(two joints on the real robot) is omitted: a fixed head sits on the chest.  The waist
yaw turns +-163 deg.  Velocity and effort limits are ours (the published URDF carries
placeholders), of the order of the real robot's.

At zero the arms hang down.  The wrist roll axis is perpendicular to the forearm, and the
hand sticks out along -x of the wrist roll link: with the forearm held horizontal (the
robot's usual working pose) the hand points down at the table.

Hands: a two-finger parallel jaw on each wrist flange, like Baxter's electric gripper:
two prismatic fingers sliding towards each other, the second following the first through
a URDF mimic joint (multiplier -1), each ending in a pad link.  Each finger travels 45 mm,
so the jaw opens from 4 mm to 94 mm between the pads.

Frames: the base frame ``base_link`` is on the floor under the waist axis, x forward, z
up; the waist (``CHEST_JOINT0``) is ``WAIST_HEIGHT`` above the floor, so a table top at
z = 0.72-0.75 m with its near edge 0.25 m in front is within reach of both arms.
Gripper frame ``{r,l}_gripper_base``: z out of the flange (the approach), y the jaw's
closing axis (the first finger, ``*_l_finger``, on +y), x = y x z.  The grasp frame
``{r,l}_grasp_frame`` has the gripper's orientation and sits between the pads' centres.

Collision and visual geometry are URDF primitives (boxes and cylinders) only, the same
for both.

Run ``python scripts/make_hironx_urdf.py`` to rewrite ``configs/robots/hironx/robot.urdf``
(``configs/robots`` is ``regrasp_cli/data/robots``).  The output depends on nothing but
this file: :func:`urdf_text` returns it, :func:`main` writes it.
"""

from __future__ import annotations

import math
from pathlib import Path

OUT = Path(__file__).resolve().parents[1] / "regrasp_cli" / "data" / "robots" / "hironx" / "robot.urdf"

# URDF materials, declared once at the top of the file
COLOURS = {"white": "0.92 0.92 0.9 1", "grey": "0.6 0.6 0.63 1", "dark": "0.25 0.25 0.28 1", "pad": "0.12 0.12 0.12 1"}
WHITE, GREY, DARK, PAD_COLOUR = "white", "grey", "dark", "pad"

# Body
WAIST_HEIGHT = 0.85  # m: the waist yaw axis's origin above the floor
CHEST_LIMIT = 2.84489  # rad (163 deg)
CHEST_VELOCITY, CHEST_EFFORT = 1.0, 100.0

# Arms (published HiroNX layout).  Positions are for the left arm; the right one is
# mirrored in y (SHOULDER_Y, ELBOW_Y and the shoulder roll change sign).
SHOULDER_Y, SHOULDER_Z = 0.145, 0.370296  # J0 from the waist axis, m
SHOULDER_ROLL = 0.261799  # rad: J0's axis leans outwards by 15 deg
ELBOW_Y, UPPER_ARM = 0.095, 0.25  # J2 from J1: outwards and down, m
WRIST_YAW_X = -0.03  # J3 from J2, m
FOREARM = 0.235  # J4 from J3, m
ROLL_X, ROLL_Z = -0.047, -0.09  # J5 from J4, m
# (lower, upper) rad, per joint J0..J5 of the left arm; the right wrist yaw is mirrored
ARM_LIMITS = [(-1.53589, 1.53589), (-2.44346, 1.0472), (-2.75762, 0.0), (-1.8326, 2.87979),
              (-1.74533, 1.74533), (-2.84489, 2.84489)]
ARM_VELOCITY = [1.5, 1.5, 1.5, 2.0, 2.0, 2.5]  # rad/s
ARM_EFFORT = [60.0, 60.0, 40.0, 15.0, 15.0, 10.0]  # N m

# Jaw (gripper frame: z out of the flange, y the closing axis)
FLANGE = 0.015  # m: the flange disc, J5's origin to the gripper base
PALM = (0.05, 0.11, 0.05)  # m: the palm box (x, y, z), from the flange outwards
FINGER_TRAVEL = 0.045  # m: each finger's stroke, closed (0) to open
FINGER_GAP = 0.004  # m: between the pads, closed
FINGER = (0.022, 0.010, 0.045)  # m: each finger's body (x, y thickness, z length)
PAD = (0.022, 0.006, 0.040)  # m: each fingertip pad (x, y thickness, z length)
FINGER_VELOCITY, FINGER_EFFORT = 0.1, 40.0  # m/s, N


def num(x: float) -> str:
    x = float(x)
    return f"{x + 0.0:.9g}" if abs(x) > 1e-15 else "0"


def vec(v) -> str:
    return " ".join(num(x) for x in v)


class Urdf:
    def __init__(self, name: str, colours: dict[str, str]):
        self.parts = [f'<?xml version="1.0"?>\n<robot name="{name}">']
        self.parts += [f'  <material name="{c}"><color rgba="{rgba}"/></material>' for c, rgba in colours.items()]

    def link(self, name: str, shapes=(), mass: float = 0.2) -> None:
        """shapes: list of (geometry xml, xyz, rpy, colour)."""
        body = [f'  <link name="{name}">',
                f'    <inertial><mass value="{num(mass)}"/><origin xyz="0 0 0"/>'
                f'<inertia ixx="1e-3" ixy="0" ixz="0" iyy="1e-3" iyz="0" izz="1e-3"/></inertial>']
        for geom, xyz, rpy, colour in shapes:
            origin = f'<origin xyz="{vec(xyz)}" rpy="{vec(rpy)}"/>'
            body.append(f'    <visual>{origin}<geometry>{geom}</geometry><material name="{colour}"/></visual>')
            body.append(f"    <collision>{origin}<geometry>{geom}</geometry></collision>")
        body.append("  </link>")
        self.parts.append("\n".join(body))

    def joint(self, name: str, parent: str, child: str, xyz, rpy=(0, 0, 0), axis=None, limits=None,
              vel: float = 1.0, effort: float = 10.0, kind: str | None = None, mimic: tuple[str, float] | None = None):
        kind = kind or ("fixed" if axis is None else "revolute")
        s = [f'  <joint name="{name}" type="{kind}">',
             f'    <parent link="{parent}"/><child link="{child}"/>',
             f'    <origin xyz="{vec(xyz)}" rpy="{vec(rpy)}"/>']
        if axis is not None:
            s.append(f'    <axis xyz="{vec(axis)}"/>')
            s.append(f'    <limit lower="{num(limits[0])}" upper="{num(limits[1])}" effort="{num(effort)}" '
                     f'velocity="{num(vel)}"/>')
        if mimic is not None:
            s.append(f'    <mimic joint="{mimic[0]}" multiplier="{num(mimic[1])}" offset="0"/>')
        s.append("  </joint>")
        self.parts.append("\n".join(s))

    def text(self) -> str:
        return "\n".join(self.parts) + "\n</robot>\n"


HALF_PI = math.pi / 2


def box(size, xyz, colour, rpy=(0, 0, 0)):
    return (f'<box size="{vec(size)}"/>', xyz, rpy, colour)


def cylinder(radius: float, length: float, xyz, axis: str, colour):
    """A cylinder along the local axis ``axis`` ('x', 'y' or 'z') centred at ``xyz``."""
    rpy = {"x": (0, HALF_PI, 0), "y": (HALF_PI, 0, 0), "z": (0, 0, 0)}[axis]
    return (f'<cylinder radius="{num(radius)}" length="{num(length)}"/>', xyz, rpy, colour)


def body(u: Urdf) -> None:
    """The stand (on the floor, up to the waist), the waist yaw and the chest with the head."""
    u.link("base_link", [
        box([0.36, 0.44, WAIST_HEIGHT - 0.10], [-0.06, 0, (WAIST_HEIGHT - 0.10) / 2], DARK),  # stand
        box([0.26, 0.30, 0.10], [-0.04, 0, WAIST_HEIGHT - 0.05], WHITE),  # waist
    ], mass=40.0)
    u.joint("WAIST_JOINT", "base_link", "WAIST", [0, 0, WAIST_HEIGHT])
    u.link("WAIST", mass=0.01)
    u.joint("CHEST_JOINT0", "WAIST", "CHEST_JOINT0_Link", [0, 0, 0], axis=[0, 0, 1],
            limits=(-CHEST_LIMIT, CHEST_LIMIT), vel=CHEST_VELOCITY, effort=CHEST_EFFORT)
    u.link("CHEST_JOINT0_Link", [
        cylinder(0.10, 0.06, [0, 0, 0.03], "z", WHITE),  # waist bearing
        box([0.20, 0.20, 0.30], [-0.03, 0, 0.21], WHITE),  # trunk
        box([0.16, 0.26, 0.10], [-0.03, 0, 0.38], WHITE),  # shoulder girdle, between the J0 housings
        cylinder(0.035, 0.06, [0, 0, 0.46], "z", GREY),  # neck
        box([0.14, 0.16, 0.13], [0.0, 0, 0.555], WHITE),  # head (its two joints omitted)
    ], mass=15.0)


def arm_and_hand(u: Urdf, side: str) -> None:
    s = 1.0 if side == "l" else -1.0  # lateral sign: the left arm on +y
    P = "LARM" if side == "l" else "RARM"
    limits = list(ARM_LIMITS)
    if side == "r":  # the wrist yaw's range mirrored
        lo, hi = limits[3]
        limits[3] = (-hi, -lo)
    link = [f"{P}_JOINT{i}_Link" for i in range(6)]
    origins = [([0, s * SHOULDER_Y, SHOULDER_Z], (-s * SHOULDER_ROLL, 0, 0)),
               ([0, 0, 0], (0, 0, 0)),
               ([0, s * ELBOW_Y, -UPPER_ARM], (0, 0, 0)),
               ([WRIST_YAW_X, 0, 0], (0, 0, 0)),
               ([0, 0, -FOREARM], (0, 0, 0)),
               ([ROLL_X, 0, ROLL_Z], (0, 0, 0))]
    axes = [[0, 0, 1], [0, 1, 0], [0, 1, 0], [0, 0, 1], [0, 1, 0], [1, 0, 0]]
    shapes = [
        # J0: the shoulder yaw housing, on the chest's side
        [cylinder(0.05, 0.08, [0, 0, 0.0], "z", WHITE)],
        # J1: the shoulder pitch housing (outboard of J0) and the upper arm down to the elbow
        [cylinder(0.05, 0.09, [0, s * 0.085, 0], "y", WHITE),
         cylinder(0.04, 0.16, [0, s * ELBOW_Y, -0.13], "z", WHITE)],
        # J2: the elbow housing
        [cylinder(0.045, 0.08, [0, 0, 0], "y", GREY)],
        # J3: the forearm, from the elbow housing to the wrist
        [cylinder(0.038, 0.14, [0, 0, -0.115], "z", WHITE)],
        # J4: the wrist pitch hub and the wrist roll housing below it
        [cylinder(0.04, 0.08, [0, 0, 0], "y", GREY),
         box([0.07, 0.07, 0.05], [0, 0, -0.045], GREY),
         cylinder(0.04, 0.06, [ROLL_X + 0.03, 0, ROLL_Z], "x", GREY)],
        # J5: the flange disc (the hand follows, along -x)
        [cylinder(0.04, FLANGE, [-FLANGE / 2, 0, 0], "x", DARK)],
    ]
    masses = [1.3, 1.2, 0.6, 0.5, 0.4, 0.3]
    parent = "CHEST_JOINT0_Link"
    for i in range(6):
        xyz, rpy = origins[i]
        u.joint(f"{P}_JOINT{i}", parent, link[i], xyz, rpy, axis=axes[i], limits=limits[i],
                vel=ARM_VELOCITY[i], effort=ARM_EFFORT[i])
        u.link(link[i], shapes[i], mass=masses[i])
        parent = link[i]
    jaw(u, side, link[5])


def jaw(u: Urdf, side: str, flange_link: str) -> None:
    """The gripper on the flange: the palm, two prismatic fingers (the second a mimic of
    the first) each with a pad link at its end, and the grasp frame between the pads."""
    p = f"{side}_"
    # gripper z = the roll link's -x, y = its y: a quarter turn about y
    u.joint(f"{p}gripper_base_joint", flange_link, f"{p}gripper_base", [-FLANGE, 0, 0], (0, -HALF_PI, 0))
    u.link(f"{p}gripper_base", [box(PALM, [0, 0, PALM[2] / 2], DARK)], mass=0.5)
    z0 = PALM[2]  # the fingers slide on the palm's outer face
    for name, sign in (("l", 1.0), ("r", -1.0)):  # finger l on +y, r on -y
        finger = f"{p}gripper_{name}_finger"
        u.joint(f"{finger}_joint", f"{p}gripper_base", finger, [0, 0, z0], axis=[0, 1, 0],
                limits=(0.0, FINGER_TRAVEL) if sign > 0 else (-FINGER_TRAVEL, 0.0),
                vel=FINGER_VELOCITY, effort=FINGER_EFFORT, kind="prismatic",
                mimic=None if sign > 0 else (f"{p}gripper_l_finger_joint", -1.0))
        # the finger's body is recessed 2 mm behind its pad's face
        y_body = sign * (FINGER_GAP / 2 + 0.002 + FINGER[1] / 2)
        u.link(finger, [box(FINGER, [0, y_body, FINGER[2] / 2], GREY)], mass=0.05)
        u.joint(f"{finger}_tip_joint", finger, f"{finger}_tip", [0, 0, FINGER[2]])
        y_pad = sign * (FINGER_GAP / 2 + PAD[1] / 2)
        u.link(f"{finger}_tip", [box(PAD, [0, y_pad, PAD[2] / 2], PAD_COLOUR)], mass=0.02)
    u.joint(f"{p}grasp_joint", f"{p}gripper_base", f"{p}grasp_frame", [0, 0, z0 + FINGER[2] + PAD[2] / 2])
    u.link(f"{p}grasp_frame", mass=0.001)


def urdf_text() -> str:
    """The robot's URDF (deterministic)."""
    u = Urdf("hironx", COLOURS)
    body(u)
    arm_and_hand(u, "r")
    arm_and_hand(u, "l")
    return u.text()


def write(out: Path, text: str) -> None:
    """Write a generated URDF (the robot scripts share this)."""
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(text)
    print(f"wrote {out}")


def main() -> None:
    write(OUT, urdf_text())


if __name__ == "__main__":
    main()
