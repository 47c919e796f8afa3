"""regrasp_cli.roadmap.rejections and the roadmap build's emptiness checks, on tiny
hand-made inputs with exact answers."""

from __future__ import annotations

import numpy as np
import pytest

from regrasp_cli.errors import EmptyRoadmap
from regrasp_cli.roadmap.build import RoadmapOptions, _check_elementary
from regrasp_cli.roadmap.rejections import DIAGNOSED, Rejections, pairs_text, tallied
from regrasp_cli.roadmap.visprm import ElementaryRoadmap


def _world(free_below: float):
    """A 1-D world: q[0] < free_below is free; above, 'hand' hits 'obstacle:wall', and
    above 0.8 'elbow' hits 'torso' too."""
    looked = []

    def is_free(q):
        return q[0] < free_below

    def colliding_pairs(q):
        looked.append(float(q[0]))
        pairs = [("obstacle:wall", "hand")]  # obstacle first: the tally puts links first
        if q[0] > 0.8:
            pairs.append(("torso", "elbow"))
        return pairs

    return is_free, colliding_pairs, looked


def test_tallied_counts_every_rejection_and_lists_the_pairs_of_the_first_ones():
    is_free, pairs, looked = _world(0.5)
    tally = Rejections()
    check = tallied(is_free, pairs, tally)
    qs = [np.array([x]) for x in (0.1, 0.6, 0.9, 0.2, 0.95)]
    assert [check(q) for q in qs] == [True, False, False, True, False]
    assert (tally.checked, tally.collided, tally.diagnosed) == (5, 3, 3)
    assert looked == [0.6, 0.9, 0.95]  # only rejected configurations are looked at
    assert tally.top() == [(("hand", "obstacle:wall"), 3), (("elbow", "torso"), 2)]
    assert tally.describe() == ("3 of 5 configurations collide; the pairs in most of the 3 looked at: "
                                "hand–obstacle:wall 3, elbow–torso 2")


def test_tallied_stops_looking_after_the_first_diagnosed():
    is_free, pairs, looked = _world(-1.0)  # nothing is free
    tally = Rejections()
    check = tallied(is_free, pairs, tally)
    for _ in range(DIAGNOSED + 7):
        assert not check(np.array([0.9]))
    assert tally.collided == DIAGNOSED + 7 and tally.diagnosed == DIAGNOSED == len(looked)
    assert tally.pairs[("hand", "obstacle:wall")] == DIAGNOSED


def test_describe_without_pairs_and_pairs_text():
    assert Rejections(checked=4).describe("samples collide") == "0 of 4 samples collide"
    assert pairs_text([("a", "b"), ("c", "d"), ("a", "b")]) == "a–b, c–d"  # each pair once
    assert pairs_text([("a", str(i)) for i in range(5)], n=2) == "a–0, a–1 and 3 more"


def _roadmap(n: int) -> ElementaryRoadmap:
    return ElementaryRoadmap(np.zeros((n, 2)), np.zeros((0, 2), dtype=np.int64), np.zeros(0), np.ones(n, dtype=bool), 100)


def _tally() -> Rejections:
    t = Rejections(checked=100)
    for _ in range(3):
        t.record([("r_hand", "obstacle:cage")])
    t.collided = 97
    return t


def test_an_elementary_roadmap_without_node_is_an_error_naming_pairs_and_rest():
    options = RoadmapOptions(nodes=10)
    with pytest.raises(EmptyRoadmap) as e:
        _check_elementary(options, {"right": (_roadmap(0), _tally()), "left": (_roadmap(10), Rejections())},
                             [("head", "obstacle:cage")])
    msg = e.value.message
    assert msg.startswith("the roadmap is empty: R_r (torso + right arm) has no node: 97 of 100 samples collide or "
                          "come within 30 mm; the pairs in most of the 3 looked at: r_hand–obstacle:cage 3")
    assert "R_l" not in msg and msg.endswith("is in collision: head–obstacle:cage")
    assert e.value.exit_code == 1


def test_any_shortfall_warns_and_enough_do_not():
    """18 of 50 nodes went unsaid when the warning started below a fifth (issue 41)."""
    options = RoadmapOptions(nodes=10)
    warnings = _check_elementary(options, {"right": (_roadmap(9), _tally()), "left": (_roadmap(10), Rejections())},
                                    [])
    assert warnings == ["R_r (torso + right arm) has 9 of the 10 nodes asked for: 97 of 100 samples collide or "
                        "come within 30 mm; the pairs in most of the 3 looked at: r_hand–obstacle:cage 3"]