"""The aggregation of benchmark records (regrasp_cli.bench.aggregate and the tables of
regrasp_cli.bench.report) on fixed synthetic records with hand-computed answers: medians
and IQR over solved runs, success rates, per-seed ratios to the roadmap (only seeds both
solved, with the counts of the others), and Table I's layout."""

from __future__ import annotations

import math

import pytest

from regrasp_cli.bench.aggregate import (PLOT_PHASES, TABLE_ONE_COLUMNS, phase_medians, seed_ratios, spread,
                                         summarise, table_one)
from regrasp_cli.bench.report import markdown, ratio_rows, summary_rows

QUERY_A = {"grasp": (2, 0.1, 0, 0.05), "carry": (4, 0.2, 1, 0.1), "place": (6, 0.3, 0, 0.0),
           "rest": (8, 0.4, 2, 0.2)}  # n, planning T, invalid edges, validation T


def rec(planner: str, seed: int, solved: bool, total: float, scale: float = 1.0, queries=QUERY_A) -> dict:
    qs = {q: {"n": int(n * scale), "planning_s": p * scale, "invalid_edges": int(i * scale),
              "validation_s": v * scale, "rrt_calls": 0} for q, (n, p, i, v) in queries.items()}
    return {"scene": "desk", "planner": planner, "seed": seed, "solved": solved,
            "stage": None if solved else "transition", "transition": None if solved else "place",
            "reason": None if solved else "no path",
            "total_s": total, "planner_s": total / 2, "write_s": 0.01, "validation_s": total / 2 - 0.01,
            "stages_s": {"double grasps": 0.1, "exchange": 0.2, "queries": 1.5, "timing": 0.0},
            "queries": qs, "path_length": 10.0 + seed if solved else None, "regrasps": 1 if solved else None,
            "peak_rss_mb": 100.0 + seed}


# roadmap solves seeds 0-3 (1, 2, 3, 4 s) and fails 4, 5; rrt-connect solves 0, 1, 4 (3, 8, 6 s)
ROADMAP = [rec("roadmap", s, s < 4, t) for s, t in enumerate([1.0, 2.0, 3.0, 4.0, 9.0, 7.0])]
RRT = [rec("rrt-connect", s, s in (0, 1, 4), t) for s, t in enumerate([3.0, 8.0, 5.0, 4.0, 6.0, 2.0])]
RECORDS = ROADMAP + RRT


def test_spread_is_median_and_linear_quartiles():
    s = spread([4.0, 1.0, 3.0, 2.0])
    assert (s.n, s.median, s.q25, s.q75, s.min, s.max) == (4, 2.5, 1.75, 3.25, 1.0, 4.0)
    assert s.iqr == pytest.approx(1.5)
    empty = spread([])
    assert empty.n == 0 and math.isnan(empty.median)


def test_summary_counts_every_run_and_times_only_solved_ones():
    s = summarise(RECORDS, "desk", "roadmap")
    assert (s.runs, s.solved) == (6, 4)
    assert s.success_rate == pytest.approx(4 / 6)
    assert (s.total_s.median, s.total_s.q25, s.total_s.q75) == (2.5, 1.75, 3.25)  # failed 9 s and 7 s left out
    assert s.failures == {"transition (place)": 2}
    assert s.path_length.median == pytest.approx(11.5)
    assert s.peak_rss_mb.n == 6  # memory of every run
    r = summarise(RECORDS, "desk", "rrt-connect")
    assert (r.solved, r.total_s.median, r.total_s.q25, r.total_s.q75) == (3, 6.0, 4.5, 7.0)


def test_ratio_per_seed_only_where_both_solved():
    q = seed_ratios(RECORDS, "desk", "rrt-connect")
    assert q.per_seed == ((0, 3.0), (1, 4.0))
    assert q.ratio.median == pytest.approx(3.5)
    assert (q.only_reference, q.only_planner, q.neither) == (2, 1, 1)
    # the ratio of medians (6 / 2.5) is not what is reported
    assert q.ratio.median != pytest.approx(6.0 / 2.5)
    assert seed_ratios(RECORDS, "desk", "rrt-connect", key="planner_s").ratio.median == pytest.approx(3.5)
    row = ratio_rows(RECORDS)[0]
    assert row[:4] == ("desk", "rrt-connect", "2", "3.50x")
    assert row[-4:-1] == ("2", "1", "1")


def test_lower_bound_ratio_counts_failures_at_their_give_up_time():
    """Over the seeds the roadmap solved (0-3): 3/1 and 8/2 solved by both, then
    rrt-connect's failures at 5 s and 4 s against 3 s and 4 s: 3, 4, 5/3, 1."""
    q = seed_ratios(RECORDS, "desk", "rrt-connect")
    assert q.lower_bound.n == 4
    assert q.lower_bound.median == pytest.approx((5 / 3 + 3.0) / 2)
    assert (q.lower_bound.min, q.lower_bound.max) == (pytest.approx(1.0), pytest.approx(4.0))
    assert ratio_rows(RECORDS)[0][-1] == "2.33x (n=4)"
    # a run killed over its budget has no planner time: its total time counts
    killed = [dict(r, planner_s=None) if r["planner"] == "rrt-connect" and r["seed"] == 3 else r for r in RECORDS]
    assert seed_ratios(killed, "desk", "rrt-connect", key="planner_s").lower_bound.n == 4


def test_table_one_layout_and_medians():
    runs = [rec("roadmap", 0, True, 1.0), rec("roadmap", 1, True, 1.0, scale=3.0)]  # medians: twice run 0
    rows = table_one(runs)
    assert TABLE_ONE_COLUMNS == ("query", "planning n", "planning T (s)", "validation n", "validation T (s)",
                                 "total n", "total T (s)")
    assert [r[0] for r in rows] == ["grasp", "carry", "place", "rest", "total"]
    assert rows[0][1:] == pytest.approx((4, 0.2, 0, 0.1, 4, 0.3))
    assert rows[1][1:] == pytest.approx((8, 0.4, 2, 0.2, 10, 0.6))
    assert rows[4][1:] == pytest.approx((40, 2.0, 6, 0.7, 46, 2.7))  # per-run sums over the queries


def test_table_one_takes_each_query_over_the_runs_that_reached_it():
    short = rec("roadmap", 2, False, 1.0, queries={q: QUERY_A[q] for q in ("grasp", "carry")})
    rows = table_one([rec("roadmap", 0, True, 1.0), short])
    assert rows[0][1] == 2 and rows[3][1] == 8  # rest: the one run that got there
    assert all(math.isnan(v) for v in table_one([])[0][1:])


def test_phase_medians_split_the_queries_stage():
    m = phase_medians([rec("roadmap", 0, True, 1.0)])
    assert tuple(m) == PLOT_PHASES
    assert m["place"] == pytest.approx(0.3) and m["rest"] == pytest.approx(0.6)
    assert m["queries, other"] == pytest.approx(1.5 - 1.35)  # the stage minus the four queries (1.0 + 0.35)


def test_markdown_has_every_table():
    text = markdown(RECORDS, ["# t"], {"desk": {"grasp lists": {"s": 1.0, "status": "cached"}}})
    assert "| desk | roadmap | 4/6 | 67 % | 2.50 | 1.75–3.25 |" in text
    assert "| desk | rrt-connect | 2 | 3.50x |" in text
    assert "### desk, roadmap" in text and "| query | planning n | planning T (s) |" in text
    assert "## Failures (5)" in text  # 2 roadmap + 3 rrt-connect
    assert summary_rows(RECORDS)[1][10] == "transition (place) 3"


def test_the_paper_row_of_grasp_configurations_sums_the_hand_over_key_stages():
    """Stages named by style ("handover: nodes"), as the planner names them now: the
    hand-over's nodes, double grasps and exchange pose, not another style's nodes."""
    from regrasp_cli.bench.report import paper_rows

    stages = {"styles: necessary conditions": 0.1, "one-arm: nodes": 5.0, "handover: nodes": 0.5,
              "handover: double grasps": 0.01, "handover: exchange": 0.2, "handover: queries": 0.6}
    records = [dict(rec("roadmap", s, True, 2.0), stages_s=stages) for s in range(3)]
    rows = {name: ours for name, _, ours in paper_rows(records, {}, "desk")}
    assert rows["single + double grasp configurations (and exchange pose)"] == "0.71 s"
