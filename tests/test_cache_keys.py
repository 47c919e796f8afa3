"""Each artefact hashes what determines it, and nothing else (seed 000's offline/online
split, §IV-A, §IV-B).  Both grasp lists of the default robot and statuette are built once
(small grids) with a copy of the robot; then one input changes at a time and each
artefact is checked as the planner checks it before use (the file its inputs name exists
and its provenance matches):

* the robot's rest posture, a comment in robot.yaml, an obstacle, the object's start and
  goal poses: both grasp lists are reused;
* an obstacle: the roadmap is rebuilt, the placements and self-collision pairs are not;
  a comment or an object pose keeps the roadmap too;
* the right thumb's tip radius: the right hand's list is rebuilt, the left hand's reused.
"""

from __future__ import annotations

import shutil
from dataclasses import replace
from pathlib import Path

import pytest
import yaml

from cli_helpers import scene_dict, write_scene

from regrasp_cli.grasp.build import BuildOptions, artefact_path, build_grasps, provenance
from regrasp_cli.grasp.single import GraspOptions
from regrasp_cli.model import selfcollision
from regrasp_cli.placement import artefact as placements
from regrasp_cli.placement.stable import PlacementOptions
from regrasp_cli.roadmap import build as roadmap
from regrasp_cli.roadmap.build import RoadmapOptions
from regrasp_cli.scene import load_problem
from regrasp_cli.store import is_fresh, sha256_params

ROBOT = Path(__file__).resolve().parents[1] / "configs" / "robots" / "humanoid43"
OPTIONS = BuildOptions(grasp=replace(GraspOptions(), n_positions=2, n_orientations=512, target=3, pinch_frames=0))
HANDS = ("right", "left")


@pytest.fixture(scope="module")
def base(tmp_path_factory, cache_dir, problem) -> Path:
    """A folder with a copy of the robot and the default scene using it; both lists built."""
    d = tmp_path_factory.mktemp("keys")
    shutil.copytree(ROBOT, d / "robot")
    s = scene_dict()
    s["robot"] = str(d / "robot" / "robot.yaml")
    write_scene(d / "scene.yaml", s)
    cache = d / "cache"
    shutil.copytree(cache_dir / "self_collision", cache / "self_collision")  # the same URDF: the run's pairs (problem)
    for hand in HANDS:
        assert len(build_grasps(d / "scene.yaml", cache, hand, OPTIONS)[0]) >= 1
    return d


def variant(base: Path, name: str, scene=None, robot_yaml=None) -> Path:
    """A copy of the base folder's robot and scene, changed by ``scene(dict)`` and
    ``robot_yaml(text) -> text``; the cache stays the base's."""
    d = base / name
    shutil.copytree(base / "robot", d / "robot")
    if robot_yaml:
        p = d / "robot" / "robot.yaml"
        p.write_text(robot_yaml(p.read_text()))
    s = yaml.safe_load((base / "scene.yaml").read_text())
    s["robot"] = str(d / "robot" / "robot.yaml")
    if scene:
        scene(s)
    return write_scene(d / "scene.yaml", s)


def keys(path: Path, cache: Path) -> dict:
    """Per artefact, whether it is reused (grasp lists: fresh in the cache) or its key."""
    p = load_problem(path, cache)
    out = {hand: (lambda f, prov: f.is_file() and is_fresh(f, prov))(artefact_path(cache, p, hand, OPTIONS),
                                                                       provenance(p, hand, OPTIONS))
           for hand in HANDS}
    rm = RoadmapOptions()
    out["roadmap"] = (roadmap.artefact_path(cache, p, rm), roadmap.provenance(p, rm).inputs)
    out["placements"] = placements.provenance(p.object, PlacementOptions()).inputs
    out["self_collision"] = sha256_params(selfcollision.cache_key(p.robot))
    return out


def _rest(text: str) -> str:
    return text.replace("r_arm_j1: 0.389", "r_arm_j1: 0.489")


def _comment(text: str) -> str:
    return "# a comment a user added\n" + text.replace("hands:", "hands:  # the two hands", 1)


def _move_vase(s: dict) -> None:
    vase = next(o for o in s["obstacles"] if o["name"] == "vase_body")
    vase["pose"]["xyz"][1] += 0.05


def _poses(s: dict) -> None:
    s["task"]["object_start"]["xyz"][0] += 0.03
    s["task"]["object_goal"]["rpy"][2] += 0.2


def _thumb_radius(text: str) -> str:
    right = text.index("  right:")
    i = text.index("tip_radius: 0.010", right)
    return text[:i] + "tip_radius: 0.011" + text[i + len("tip_radius: 0.010"):]


def test_the_base_lists_are_reused_as_they_are(base):
    k = keys(base / "scene.yaml", base / "cache")
    assert k["right"] and k["left"]


@pytest.mark.parametrize("name, scene, robot_yaml", [
    ("rest", None, _rest), ("comment", None, _comment), ("obstacle", _move_vase, None), ("poses", _poses, None)])
def test_no_grasp_list_is_rebuilt_for_the_scene_or_the_rest_of_the_robot(base, name, scene, robot_yaml):
    k = keys(variant(base, name, scene, robot_yaml), base / "cache")
    assert k["right"] and k["left"]


def test_an_obstacle_rebuilds_the_roadmap_only(base):
    before = keys(base / "scene.yaml", base / "cache")
    after = keys(variant(base, "obstacle2", scene=_move_vase), base / "cache")
    assert after["roadmap"][0] != before["roadmap"][0] and after["roadmap"][1] != before["roadmap"][1]
    assert after["placements"] == before["placements"] and after["self_collision"] == before["self_collision"]
    assert after["right"] and after["left"]


@pytest.mark.parametrize("name, scene, robot_yaml", [("comment2", None, _comment), ("poses2", _poses, None)])
def test_a_comment_or_a_pose_keeps_the_roadmap(base, name, scene, robot_yaml):
    before = keys(base / "scene.yaml", base / "cache")
    after = keys(variant(base, name, scene, robot_yaml), base / "cache")
    assert after["roadmap"] == before["roadmap"]


def test_a_tip_radius_rebuilds_that_hands_lists_only(base):
    k = keys(variant(base, "thumb", robot_yaml=_thumb_radius), base / "cache")
    assert not k["right"] and k["left"]
