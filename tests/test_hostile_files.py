"""Hostile and broken input at the files and options every command reads (issue 40): one
line naming the file and the field, the exit code the README promises, no traceback,
nothing overwritten, bounded work.  Grouped by surface:

* outputs that name an input (the same file by any path or link) are refused before any work;
* files that are not regular files (FIFO, device, folder), too large, nested too deeply,
  or YAML whose aliases expand to millions of values ("billion laughs") are refused by
  type, size or count, never read until memory runs out or formatted into a message;
* values that used to end in a traceback: a quaternion whose norm overflows, a URDF
  without collision geometry, an object scaled to nanometres, a phase lasting 1e7 s;
* messages: options named as the command spells them, mimic cycles and mimics naming a
  missing joint said at load, control characters of a path escaped, temp files of a
  killed writer removed.

The commands that would hang or exhaust memory without the fix run in a subprocess
under a memory limit and a guard (a hang fails the test instead of stalling the run).
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import threading
from pathlib import Path

import pytest
import yaml

from cli_helpers import ROOT, SCENE_YAML, assert_one_error_line, needs_separate_stderr, run, scene_dict, write_scene

pytestmark = needs_separate_stderr

HIRONX = ROOT / "configs" / "robots" / "hironx"
GUARD_S = 120  # a hang is a failure, not a stalled run (the fixed commands answer in about 2 s)


def _cli(*args, cwd: Path | None = None) -> subprocess.CompletedProcess:
    """`regrasp ARGS` in a process limited to 3 GiB of address space."""
    code = ("import resource, sys; resource.setrlimit(resource.RLIMIT_AS, (3 << 30, 3 << 30)); "
            "from regrasp_cli.cli import main; sys.argv = ['regrasp'] + sys.argv[1:]; main()")
    env = dict(os.environ, COLUMNS="250", PYTHONPATH=str(ROOT))
    return subprocess.run([sys.executable, "-c", code, *map(str, args)], capture_output=True, text=True, env=env,
                          timeout=GUARD_S, cwd=cwd)


def _one_line(p: subprocess.CompletedProcess, *words: str, exit_code: int = 2) -> str:
    assert p.returncode == exit_code, (p.returncode, p.stdout[-2000:], p.stderr[-2000:])
    assert "Traceback" not in p.stderr + p.stdout
    errors = [ln for ln in p.stderr.splitlines() if ln.startswith("error:")]
    assert len(errors) == 1, p.stderr
    for w in words:
        assert w in errors[0], (w, errors[0])
    return errors[0]


def _bomb(levels: int = 9) -> str:
    """A YAML flow list of ``levels + 1`` items whose last expands to 9**(levels + 1) numbers."""
    items = ["&a0 [1, 1, 1, 1, 1, 1, 1, 1, 1]"] + [
        f"&a{i} [{', '.join([f'*a{i - 1}'] * 9)}]" for i in range(1, levels + 1)]
    return f"[{', '.join(items)}]"


# ------------------------------------------------------------------ outputs naming an input


def test_plan_output_equal_to_the_scene_is_refused_before_any_work(tmp_path):
    scene = write_scene(tmp_path / "scene.yaml", scene_dict())
    before = scene.read_bytes()
    result = run("--cache-dir", tmp_path / "cache", "plan", scene, "-o", scene)
    assert_one_error_line(result, "--output", "input", str(scene))
    assert scene.read_bytes() == before
    assert not (tmp_path / "cache").exists()  # refused before anything was loaded or built


def test_plan_output_through_a_link_to_the_scene_is_refused(tmp_path):
    scene = write_scene(tmp_path / "scene.yaml", scene_dict())
    (tmp_path / "link.json").symlink_to(scene)
    before = scene.read_bytes()
    result = run("--cache-dir", tmp_path / "cache", "plan", scene, "-o", tmp_path / "link.json")
    assert_one_error_line(result, "--output", "input")
    assert scene.read_bytes() == before


def test_plan_output_equal_to_the_robots_urdf_is_refused(tmp_path):
    urdf = tmp_path / "robot.urdf"
    urdf.write_bytes((ROOT / "configs/robots/humanoid43/robot.urdf").read_bytes())
    robot = yaml.safe_load((ROOT / "configs/robots/humanoid43/robot.yaml").read_text())
    (tmp_path / "robot.yaml").write_text(yaml.safe_dump(dict(robot, urdf="robot.urdf")))
    scene = write_scene(tmp_path / "scene.yaml", dict(scene_dict(), robot="robot.yaml"))
    before = urdf.read_bytes()
    result = run("--cache-dir", tmp_path / "cache", "plan", scene, "-o", urdf)
    assert_one_error_line(result, "--output", "input", str(urdf))
    assert urdf.read_bytes() == before


def test_show_html_equal_to_the_plan_is_refused(default_plan, tmp_path):
    plan = tmp_path / "plan.json"
    plan.write_bytes(default_plan.read_bytes())
    result = run("show", plan, "--html", plan)
    assert_one_error_line(result, "--html", "input")
    assert plan.read_bytes() == default_plan.read_bytes()


def test_placements_png_equal_to_the_artefact_is_refused(cache_dir, tmp_path):
    result = run("--cache-dir", cache_dir, "placements", "build", SCENE_YAML)
    assert result.exit_code == 0, result.output
    built = sorted((Path(cache_dir) / "placements").glob("*.h5"))[0]
    artefact = tmp_path / built.name
    artefact.write_bytes(built.read_bytes())
    result = run("placements", "show", artefact, "--scene", SCENE_YAML, "--png", artefact)
    assert_one_error_line(result, "--png", "input")
    assert artefact.read_bytes() == built.read_bytes()


# ------------------------------------------------------------------ bounded work


@pytest.mark.parametrize("key, field", [("object_start", "xyz"), ("object_goal", "rpy")])
def test_a_yaml_alias_bomb_in_a_scene_is_refused_at_once(tmp_path, key, field):
    d = scene_dict()
    d["task"][key][field] = "BOMB"
    scene = tmp_path / "scene.yaml"
    scene.write_text(yaml.safe_dump(d, sort_keys=False).replace("BOMB", _bomb()))
    p = _cli("--cache-dir", tmp_path / "cache", "plan", scene, "-o", tmp_path / "plan.json")
    _one_line(p, str(scene), "aliases")
    assert not (tmp_path / "plan.json").exists()


def test_a_yaml_alias_bomb_in_robot_rest_is_refused_at_once(tmp_path):
    robot = yaml.safe_load((ROOT / "configs/robots/humanoid43/robot.yaml").read_text())
    robot["urdf"] = str(ROOT / "configs/robots/humanoid43/robot.urdf")
    robot["rest"] = "BOMB"
    (tmp_path / "robot.yaml").write_text(yaml.safe_dump(robot, sort_keys=False).replace("BOMB", _bomb()))
    scene = write_scene(tmp_path / "scene.yaml", dict(scene_dict(), robot="robot.yaml"))
    p = _cli("--cache-dir", tmp_path / "cache", "info", scene)
    _one_line(p, "robot.yaml", "aliases")


def test_a_yaml_alias_bomb_in_a_suites_seeds_is_refused_at_once(tmp_path):
    suite = {"format": "regrasp.bench/1", "name": "bomb", "scenes": [str(SCENE_YAML)], "seeds": "BOMB"}
    path = tmp_path / "suite.yaml"
    path.write_text(yaml.safe_dump(suite, sort_keys=False).replace("BOMB", _bomb()))
    _one_line(_cli("bench", path, "-o", tmp_path / "out"), str(path), "aliases")
    assert not (tmp_path / "out").exists()


def test_a_recursive_yaml_document_is_refused_by_the_count():
    from regrasp_cli.errors import InputError
    from regrasp_cli.inputs import check_expansion

    loop: list = []
    loop.append(loop)  # what `a: &l [*l]` loads to
    with pytest.raises(InputError, match="recursive"):
        check_expansion({"a": loop}, Path("scene.yaml"))


def test_a_short_form_of_a_bad_value_in_the_message(tmp_path):
    """The message shows a bounded form of the value, not all of it."""
    d = scene_dict()
    d["task"]["object_goal"]["xyz"] = [[0.1] * 1000] * 3
    line = assert_one_error_line(run("info", write_scene(tmp_path / "scene.yaml", d)), "task.object_goal.xyz")
    assert len(line) < 400, line


def test_a_fifo_is_refused_by_type_not_read(tmp_path):
    """A writer is ready on the FIFO, so that a command that reads it gets a plan and
    finishes (a wrong exit code then, rather than a hang)."""
    fifo = tmp_path / "plan.json"
    os.mkfifo(fifo)

    def feed() -> None:
        try:
            fd = os.open(fifo, os.O_WRONLY | os.O_NONBLOCK)
        except OSError:  # no reader (the command refused it): nothing to feed
            return
        with os.fdopen(fd, "w") as f:
            f.write("{}")

    for command in (("validate", fifo), ("show", fifo, "--html", tmp_path / "p.html"), ("info", fifo)):
        t = threading.Timer(5.0, feed)
        t.start()
        try:
            assert_one_error_line(run(*command), str(fifo), "FIFO")
        finally:
            t.cancel()
            feed()  # unblock a reader, if one is stuck
        assert not (tmp_path / "p.html").exists()


def test_a_device_and_a_folder_are_refused_by_type(tmp_path):
    _one_line(_cli("validate", "/dev/zero"), "/dev/zero", "device")
    assert_one_error_line(run("validate", tmp_path), str(tmp_path), "folder")


def test_json_nested_200000_deep_is_one_line(tmp_path):
    plan = tmp_path / "plan.json"
    plan.write_text("[" * 200_000 + "]" * 200_000)
    assert_one_error_line(run("validate", plan), str(plan), "nested")


def test_a_timing_grid_of_1e7_seconds_is_refused_before_sampling(default_plan, tmp_path):
    d = json.loads(default_plan.read_text())
    ph = next(i for i, p in enumerate(d["phases"]) if p.get("timing") and p["kind"] == "transfer")
    d["phases"][ph]["timing"]["t"][-1] = 1e7
    plan = tmp_path / "plan.json"
    plan.write_text(json.dumps(d))
    _one_line(_cli("validate", plan), str(plan), f"phases[{ph}].timing.t")


# ------------------------------------------------------------------ values that were tracebacks


def test_a_quaternion_whose_norm_overflows_is_normalised(tmp_path):
    from regrasp_cli.config import load_inhand_spec, load_scene_spec

    d = scene_dict()
    d["task"]["object_goal"] = {"xyz": [0.62, 0.78, 0.74], "quat": [1e308, 1e308, 0.0, 0.0]}
    inhand = yaml.safe_load((ROOT / "regrasp_cli/data/scenes/inhand_ball.yaml").read_text())
    inhand["object_goal"] = {"quat": [1e308, 1e308, 0.0, 0.0]}
    for X in (load_scene_spec(write_scene(tmp_path / "scene.yaml", d)).task.X_WO_goal,
              load_inhand_spec(write_scene(tmp_path / "inhand.yaml", inhand)).X_GO_goal):
        R = X[:3, :3]
        assert abs(R[0, 1] - 1.0) < 1e-12 and abs(R[2, 2] + 1.0) < 1e-12  # a half turn about (1, 1, 0)


def test_a_urdf_without_collision_geometry_is_one_line(tmp_path):
    urdf = (ROOT / "configs/robots/humanoid43/robot.urdf").read_text()
    (tmp_path / "robot.urdf").write_text(re.sub(r"<collision>.*?</collision>", "", urdf, flags=re.S))
    robot = yaml.safe_load((ROOT / "configs/robots/humanoid43/robot.yaml").read_text())
    (tmp_path / "robot.yaml").write_text(yaml.safe_dump(robot))
    scene = write_scene(tmp_path / "scene.yaml", dict(scene_dict(), robot="robot.yaml"))
    assert_one_error_line(run("--cache-dir", tmp_path / "cache", "info", scene), "robot.yaml", "urdf",
                          "no <collision>")


def test_an_object_scaled_to_nanometres_is_one_line(tmp_path):
    d = scene_dict()
    d["object"]["scale"] = 1e-7
    scene = write_scene(tmp_path / "scene.yaml", d)
    assert_one_error_line(run("--cache-dir", tmp_path / "cache", "plan", scene, "-o", tmp_path / "p.json"),
                          str(scene), "object.scale", "m across")
    assert not (tmp_path / "p.json").exists()


def test_an_obstacle_at_1e308_is_one_line(tmp_path):
    """Found by tests/test_fuzz_inputs.py: coal refused the bounding volume with a traceback."""
    d = scene_dict()
    d["obstacles"][0]["pose"]["xyz"][1] = -1e308
    scene = write_scene(tmp_path / "scene.yaml", d)
    assert_one_error_line(run("info", scene), str(scene), "obstacles[0].pose.xyz", "within +-1000")


def test_a_waypoint_1e6_rad_away_is_a_limits_issue_not_1e8_samples(default_plan, tmp_path):
    """Found by tests/test_fuzz_inputs.py: the collision samples of a 1e6 rad segment did
    not fit in memory; a phase outside the joint limits is not sampled."""
    d = json.loads(default_plan.read_text())
    d["phases"][0]["waypoints"][1][5] = 1e6
    plan = default_plan.parent / "far-waypoint.json"  # beside it: the files it names are relative
    plan.write_text(json.dumps(d))
    p = _cli("validate", plan)
    assert p.returncode == 1 and "Traceback" not in p.stderr, p.stderr[-2000:]
    assert "limits" in p.stdout and "1e+06 outside" in p.stdout, p.stdout[-2000:]


def test_a_grasp_contact_at_1e308_is_one_line(default_plan):
    """Found by the fuzz (seed 11): the force-closure test's wrenches overflowed."""
    d = json.loads(default_plan.read_text())
    d["grasps"][0]["contacts"][0]["point"][0] = -1e308
    plan = default_plan.parent / "far-contact.json"
    plan.write_text(json.dumps(d))
    assert_one_error_line(run("validate", plan), str(plan), "grasps[0].contacts[0]", "within")


# ------------------------------------------------------------------ messages


@pytest.mark.parametrize("option, value", [("--roadmap-nodes", "0"), ("--grasp-target", "-5"), ("--held-speed", "0"),
                                           ("--held-speed", "1.5"), ("--held-speed", "nan")])
def test_plan_options_are_named_as_plan_spells_them(tmp_path, option, value):
    result = run("plan", SCENE_YAML, option, value, "-o", tmp_path / "p.json")
    assert_one_error_line(result, option)


def _hironx_copy(tmp_path: Path, edit) -> Path:
    urdf = (HIRONX / "robot.urdf").read_text()
    (tmp_path / "robot.urdf").write_text(edit(urdf))
    robot = yaml.safe_load((HIRONX / "robot.yaml").read_text())
    path = tmp_path / "robot.yaml"
    path.write_text(yaml.safe_dump(dict(robot, urdf="robot.urdf")))
    return path


def test_a_mimic_cycle_is_refused_at_load_naming_the_urdf(tmp_path):
    """The right gripper's leader made to follow its follower."""
    def cycle(urdf: str) -> str:
        head, sep, tail = urdf.partition('<joint name="r_gripper_l_finger_joint" type="prismatic">')
        return head + sep + '\n    <mimic joint="r_gripper_r_finger_joint" multiplier="-1" offset="0"/>' + tail

    robot = _hironx_copy(tmp_path, cycle)
    scene = yaml.safe_load((ROOT / "configs/scenes/hironx_handover.yaml").read_text())
    path = write_scene(tmp_path / "scene.yaml", dict(scene, robot=str(robot)))
    assert_one_error_line(run("--cache-dir", tmp_path / "cache", "info", path), "robot.urdf", "mimic", "cycle")


def test_a_mimic_naming_a_missing_joint_is_said_at_load(tmp_path):
    from regrasp_cli.model.robot import load_robot

    robot = _hironx_copy(tmp_path, lambda u: u.replace('<mimic joint="l_gripper_l_finger_joint"',
                                                       '<mimic joint="index_q1"', 1))
    with pytest.warns(UserWarning, match=r"l_gripper_r_finger_joint\.mimic names joint 'index_q1'"):
        r = load_robot(robot)
    assert len(r.mimic) == 1  # the right gripper's coupling stays


def test_a_path_with_a_newline_stays_one_line(tmp_path):
    d = scene_dict()
    d["object"]["mesh"] = "mesh.stl\nerror: something else"
    result = run("info", write_scene(tmp_path / "scene.yaml", d))
    line = assert_one_error_line(result, "object.mesh", "\\n")
    assert "something else" in line


def test_temp_files_of_a_killed_writer_are_removed(tmp_path):
    from regrasp_cli.store import atomic_write_text

    out = tmp_path / "plan.json"
    killed = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True,
                            text=True).stdout.strip()  # a process that is gone
    host = __import__("socket").gethostname().replace(".", "-")
    orphan = tmp_path / f".plan.json.{host}.{killed}.tmp"
    foreign = tmp_path / f".plan.json.otherhost.{killed}.tmp"  # another host's writer: not ours to judge
    alive = tmp_path / f".plan.json.{host}.{os.getppid()}.tmp"  # a writer still running
    for f in (orphan, foreign, alive):
        f.write_text("half")
    atomic_write_text(out, "{}")
    assert out.read_text() == "{}"
    assert not orphan.exists() and foreign.exists() and alive.exists()


def test_inhand_plan_output_equal_to_the_scene_is_refused(tmp_path):
    scene = tmp_path / "inhand.yaml"
    text = (ROOT / "configs/scenes/inhand_ball.yaml").read_text()
    scene.write_text(re.sub(r"(?m)^robot: \.\./", f"robot: {ROOT}/configs/", text))
    before = scene.read_bytes()
    result = run("--cache-dir", tmp_path / "cache", "inhand", "plan", scene, "-o", scene)
    assert_one_error_line(result, "--output", "input")
    assert scene.read_bytes() == before
