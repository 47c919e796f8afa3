"""The ompl-rrtconnect peer planner (manip/ompl_peer.py) on the default scene.

* one query around an obstacle: the statuette stands where the right hand rests and the
  right shoulder swings from one side of it to the other, so the straight segment is
  blocked; OMPL's path joins the exact ends and passes the plan checker's dense collision
  test, which is finer than the planner's own;
* the same seed gives the same path (OMPL's generator is seeded from ours);
* the iteration budget is OMPL's budget, and a failure names OMPL;
* without the optional extra, an InputError names it;
* the whole hand-over with `planner="ompl-rrtconnect"` runs its queries on OMPL, records
  OMPL's version, and fails only at a transition naming OMPL, or is solved and valid.

Grasp lists are the small ones of tests/manip/test_online.py (same options, same cache).
"""

from __future__ import annotations

import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("ompl")

from regrasp_cli.errors import InputError  # noqa: E402
from regrasp_cli.grasp.build import BuildOptions, GraspList, load_or_build  # noqa: E402
from regrasp_cli.grasp.single import GraspOptions  # noqa: E402
from regrasp_cli.model.collision import ObjectPlacement  # noqa: E402
from regrasp_cli.manip.context import OnlineOptions, Scratch  # noqa: E402
from regrasp_cli.manip.ompl_peer import ompl_query, ompl_version  # noqa: E402
from regrasp_cli.manip.modes import Kind  # noqa: E402
from regrasp_cli.manip.queries import QueryFailed, QueryStats  # noqa: E402
from regrasp_cli.manip.status import Stage  # noqa: E402
from regrasp_cli.manip.tasks.handover import TRANSITIONS, phase_worlds, plan  # noqa: E402
from regrasp_cli.model.robot import Kinematics
from regrasp_cli.motion.local import joint_reach, joint_weights  # noqa: E402
from regrasp_cli.motion.rrt import RRTOptions  # noqa: E402
from regrasp_cli.trajectory import Phase  # noqa: E402
from regrasp_cli.validate import collision_issues  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
SCENE_YAML = ROOT / "configs" / "scenes" / "desk_handover.yaml"
GRASP_TARGET = 40  # as tests/manip/test_online.py: the same cached lists
PLAN_SEED = 0
NO_CLOCK = float("inf")  # tests stop on the iteration budget only, never on the wall clock


@pytest.fixture(scope="module")
def lists(problem, cache_dir) -> dict[str, GraspList]:
    options = BuildOptions(grasp=replace(GraspOptions(), target=GRASP_TARGET), seed=problem.spec.planning.seed,
                           jobs=2)
    return {h: load_or_build(SCENE_YAML, cache_dir, h, options) for h in ("right", "left")}


def _q(problem, **offsets) -> np.ndarray:
    q = problem.robot.q_rest.copy()
    for name, v in offsets.items():
        q[problem.robot.joint_names.index(name)] += v
    return q


def dense_collisions(problem, X_WO: np.ndarray, path: np.ndarray) -> list:
    """Issues of the plan checker's dense test (0.01 rad, 5 mm) along ``path`` (k, nq)."""
    world = problem.world(ObjectPlacement(problem.object.mesh, X_WO, None, ()))
    phase = Phase("test", Kind.TRANSIT, {}, (), None, np.asarray(path), np.zeros(len(path)))
    issues, _ = collision_issues(phase, world, joint_reach(problem.robot), 0.01, 0.005)
    return issues


@pytest.fixture(scope="module")
def blocked(problem):
    """(X_WO, a, b): the statuette 11 cm under the right hand's grasp frame at rest; a and
    b swing the right shoulder (r_arm_j1) 0.5 rad either side, through the object."""
    robot = problem.robot
    X_WO = np.eye(4)
    X_WO[:3, 3] = Kinematics(robot).fk(robot.q_rest, robot.hands["right"].grasp_frame)[:3, 3] - [0, 0, 0.11]
    a, b = _q(problem, r_arm_j1=-0.5), _q(problem, r_arm_j1=0.5)
    assert not dense_collisions(problem, X_WO, [a]) and not dense_collisions(problem, X_WO, [b])
    assert dense_collisions(problem, X_WO, [a, b])
    return X_WO, a, b


def _query(problem, blocked, seed: int, **options) -> tuple[np.ndarray, QueryStats]:
    X_WO, a, b = blocked
    scratch = Scratch(problem, OnlineOptions(planner="ompl-rrtconnect", ompl_time=NO_CLOCK, **options))
    open_ = {h: problem.robot.hands[h].open for h in problem.robot.hands}
    stats = QueryStats()
    path = ompl_query(scratch, np.random.default_rng(seed), a, b, phase_worlds(scratch, X_WO, None, open_),
                      joint_weights(problem.robot), stats)
    return path, stats


@pytest.mark.parametrize("seed", [0, 1])
def test_ompl_query_goes_around_the_object(problem, blocked, seed):
    X_WO, a, b = blocked
    path, stats = _query(problem, blocked, seed)
    assert np.array_equal(path[0], a) and np.array_equal(path[-1], b)
    assert len(path) >= 3  # the straight segment is blocked
    assert not dense_collisions(problem, X_WO, path)
    moving = np.concatenate([problem.robot.groups[g] for g in ("torso", "right_arm", "left_arm")])
    fixed = np.setdiff1d(np.arange(problem.robot.nq), moving)
    assert np.array_equal(path[:, fixed], np.broadcast_to(a[fixed], (len(path), len(fixed))))
    assert stats.rrt_calls == 1 and stats.nodes >= 2 and stats.planning > 0


def test_the_same_seed_gives_the_same_path(problem, blocked):
    first, _ = _query(problem, blocked, 3)
    again, _ = _query(problem, blocked, 3)
    other, _ = _query(problem, blocked, 4)
    assert np.array_equal(first, again)
    assert first.shape != other.shape or not np.array_equal(first, other)


def test_a_one_iteration_budget_fails_naming_ompl(problem, blocked):
    with pytest.raises(QueryFailed, match="OMPL RRT-Connect .* budget of 1 iterations"):
        _query(problem, blocked, 0, rrt=RRTOptions(step=0.4, max_iterations=1))


def test_without_the_extra_the_error_names_it(monkeypatch):
    monkeypatch.setitem(sys.modules, "ompl", None)  # `import ompl` now raises ImportError
    with pytest.raises(InputError, match=r"pip install 'regrasp\[ompl\]'"):
        ompl_version()


def test_the_whole_plan_runs_on_ompl_and_a_solved_one_is_valid(problem, lists, cache_dir, tmp_path):
    """With the default budget (3000 iterations a query) OMPL's RRT-Connect often fails the
    place or rest query, so the plan either fails at a transition with OMPL named, or is
    solved and then must validate.  One attempt (one double grasp): OMPL ran its grasp and
    carry queries."""
    from regrasp_cli.manip.record import make_plan
    from regrasp_cli.trajectory import write_plan
    from regrasp_cli.validate import validate_plan

    options = OnlineOptions(planner="ompl-rrtconnect", jobs=1, ompl_time=NO_CLOCK, key_attempts=1)
    out = plan(problem, lists, None, options, PLAN_SEED)
    queries = out.transitions
    attempts = out.counts["key_attempts"]
    assert 1 <= attempts <= options.key_attempts
    assert queries["grasp"].rrt_calls == attempts and queries["carry"].rrt_calls == attempts
    plan_file = tmp_path / "ompl.json"
    written = make_plan(problem, lists, out, options, PLAN_SEED, plan_file, cache_dir, {}, timings=False)
    write_plan(plan_file, written)
    assert written.planner == "ompl-rrtconnect"
    assert written.stats["ompl_version"] == ompl_version() and ompl_version().startswith("2.")
    assert written.stats["counts"]["transitions"] == {q: s.counts() for q, s in queries.items()}
    if out.failure is not None:
        assert out.failure.stage == Stage.TRANSITION and out.failure.transition in TRANSITIONS, str(out.failure)
        assert "OMPL RRT-Connect found no path within its budget of 3000 iterations" in out.failure.reason
        assert written.status == "failed" and written.failure == out.failure.as_dict()
        return
    assert written.status == "solved" and written.failure is None
    report = validate_plan(plan_file)
    assert report.valid, [str(i) for i in report.issues]
