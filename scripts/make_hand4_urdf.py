"""Generate the in-hand test hand of seed 003's experiment: four identical 3-DoF fingers
standing round a palm, a hand alone (no arm; the wrist is the fixed base).

Saut, Sahbani and Perdereau simulate "four fingers. Each finger has 3 degrees of
freedom" and reorient a sphere held by all four.  Finger gaiting needs every three of the
four fingers to hold the object (§IV), which a thumb opposing three side-by-side fingers
cannot do (docs/DESIGN-NOTES.md, "In-hand manipulation"); fingers spaced round the object
can.  The dimensions are ours:

* palm: a disc of radius 5 cm, 2 cm thick, its top at z = 0 of ``palm`` (the base link);
  z is the palm's normal, the fingers stand along +z;
* finger k (k = 0..3) stands at 4.5 cm from the axis, at azimuth 90 k deg.  In its base
  frame x points away from the axis (radial), z up, y = z x x;
  ``f{k}_abd`` about x (sideways, +-0.5 rad), ``f{k}_prox`` about -y (towards the axis,
  -0.6 .. 1.6 rad), a 5 cm phalanx, ``f{k}_dist`` about -y (0 .. 1.6 rad), a 4 cm
  phalanx ending in the fingertip sphere (radius 8 mm) whose centre is the link
  ``f{k}_tip``;
* grasp frame ``grasp_frame``: on the axis, 7 cm above the palm, the palm's orientation.

Collision and visual geometry: URDF primitives.  Run ``python scripts/make_hand4_urdf.py``
to rewrite ``regrasp_cli/data/robots/hand4/robot.urdf``; the output depends on nothing but
this file and the URDF writer of ``make_hironx_urdf.py``.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from make_hironx_urdf import Urdf, cylinder, write  # noqa: E402  (the same URDF writer)

OUT = Path(__file__).resolve().parents[1] / "regrasp_cli" / "data" / "robots" / "hand4" / "robot.urdf"
COLOURS = {"grey": "0.6 0.6 0.63 1", "dark": "0.25 0.25 0.28 1", "tip": "0.12 0.12 0.12 1"}
PALM_RADIUS, PALM_THICKNESS = 0.05, 0.02
BASE_RADIUS = 0.045  # m: the fingers' bases from the palm's axis
PROXIMAL, DISTAL, TIP_RADIUS, FINGER_RADIUS = 0.05, 0.04, 0.008, 0.007
GRASP_HEIGHT = 0.07


def finger(u: Urdf, k: int) -> None:
    a = math.radians(90 * k)
    c, s = math.cos(a), math.sin(a)
    f = f"f{k}"
    u.link(f"{f}_base")
    u.joint(f"{f}_mount", "palm", f"{f}_base", (BASE_RADIUS * c, BASE_RADIUS * s, 0.0), (0, 0, a))
    u.link(f"{f}_knuckle", mass=0.02)
    u.joint(f"{f}_abd", f"{f}_base", f"{f}_knuckle", (0, 0, 0), axis=(1, 0, 0), limits=(-0.5, 0.5))
    u.link(f"{f}_proximal", [cylinder(FINGER_RADIUS, PROXIMAL, (0, 0, PROXIMAL / 2), "z", "grey")], mass=0.03)
    u.joint(f"{f}_prox", f"{f}_knuckle", f"{f}_proximal", (0, 0, 0), axis=(0, -1, 0), limits=(-0.6, 1.6))
    u.link(f"{f}_distal", [cylinder(FINGER_RADIUS, DISTAL, (0, 0, DISTAL / 2), "z", "grey")], mass=0.02)
    u.joint(f"{f}_dist", f"{f}_proximal", f"{f}_distal", (0, 0, PROXIMAL), axis=(0, -1, 0), limits=(0.0, 1.6))
    u.link(f"{f}_tip", [(f'<sphere radius="{TIP_RADIUS}"/>', (0, 0, 0), (0, 0, 0), "tip")], mass=0.005)
    u.joint(f"{f}_tip_joint", f"{f}_distal", f"{f}_tip", (0, 0, DISTAL))


def urdf_text() -> str:
    """The hand's URDF (deterministic)."""
    u = Urdf("hand4", COLOURS)
    u.link("palm", [cylinder(PALM_RADIUS, PALM_THICKNESS, (0, 0, -PALM_THICKNESS / 2), "z", "dark")], mass=0.3)
    u.link("grasp_frame", mass=0.001)
    u.joint("grasp_frame_joint", "palm", "grasp_frame", (0, 0, GRASP_HEIGHT))
    for k in range(4):
        finger(u, k)
    return u.text()


def main() -> None:
    write(OUT, urdf_text())


if __name__ == "__main__":
    main()
