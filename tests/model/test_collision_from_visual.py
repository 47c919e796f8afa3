"""robot.yaml's ``collision_from_visual``: the named links are checked with their visual
geometry instead of the URDF's collision geometry (coarse boxes in many URDFs)."""

from __future__ import annotations

import coal
import numpy as np
import pytest
import yaml

from regrasp_cli.errors import InputError
from regrasp_cli.model.robot import load_robot
from regrasp_cli.model.selfcollision import cache_key

# A two-link finger: each link's collision geometry is a 4 cm box, its visual a 1 cm
# sphere 2 cm along x; the base has a collision box and no visual.
URDF = """<robot name="finger">
  <link name="base"><collision><geometry><box size="0.04 0.04 0.04"/></geometry></collision></link>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><origin xyz="0.05 0 0"/>
    <axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
  <link name="l1">
    <visual><origin xyz="0.02 0 0"/><geometry><sphere radius="0.01"/></geometry></visual>
    <collision><geometry><box size="0.04 0.04 0.04"/></geometry></collision></link>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/><origin xyz="0.05 0 0"/>
    <axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
  <link name="l2">
    <visual><origin xyz="0.02 0 0"/><geometry><sphere radius="0.01"/></geometry></visual>
    <collision><geometry><box size="0.04 0.04 0.04"/></geometry></collision></link>
</robot>
"""


def _robot(tmp_path, **changes):
    urdf = tmp_path / "finger.urdf"
    urdf.write_text(URDF)
    spec = {"format": "regrasp.robot/1", "urdf": str(urdf), "groups": {},
            "hands": {"right": {"grasp_frame": "base", "contact": "point", "kind": "fingertips", "fingers": [
                {"name": "f", "joints": ["j1", "j2"], "tip_link": "l2", "tip_radius": 0.01, "open": [0.0, 0.0]}]}}}
    spec.update(changes)
    path = tmp_path / "robot.yaml"
    path.write_text(yaml.safe_dump(spec, sort_keys=False))
    return load_robot(path)


def _shapes(robot) -> dict[str, list]:
    out: dict[str, list] = {}
    for go in robot.collision_model.geometryObjects:
        out.setdefault(robot.model.frames[go.parentFrame].name, []).append(go)
    return out


def test_named_links_take_their_visual_geometry(tmp_path):
    plain = _shapes(_robot(tmp_path))
    assert all(isinstance(g.geometry, coal.Box) for gs in plain.values() for g in gs)
    shapes = _shapes(_robot(tmp_path, collision_from_visual=["l2"]))
    (l2,) = shapes["l2"]
    assert isinstance(l2.geometry, coal.Sphere) and l2.geometry.radius == pytest.approx(0.01)
    assert np.allclose(l2.placement.translation, [0.02, 0.0, 0.0])  # the visual's origin, in the link frame
    assert [type(g.geometry) for g in shapes["l1"]] == [coal.Box]  # links not named keep theirs
    assert [type(g.geometry) for g in shapes["base"]] == [coal.Box]


def test_the_self_collision_key_follows_the_links(tmp_path):
    assert cache_key(_robot(tmp_path, collision_from_visual=["l2"])) != cache_key(_robot(tmp_path))


@pytest.mark.parametrize("value, expected", [
    (["l3"], "expected links of finger.urdf, found 'l3'"),
    (["j2"], "expected links of finger.urdf, found 'j2'"),
    (["base"], "link base has no visual geometry"),
    ("l2", "expected a list of names"),
])
def test_bad_links_are_refused_with_the_field(tmp_path, value, expected):
    with pytest.raises(InputError) as e:
        _robot(tmp_path, collision_from_visual=value)
    assert "collision_from_visual" in str(e.value) and expected in str(e.value)
