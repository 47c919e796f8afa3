"""Exchange position on a grid (Saut et al. 2010, §V-C, Fig. 6): cases known on paper."""

from __future__ import annotations

import numpy as np
import pytest

from regrasp_cli.manip.exchange import exchange_position, grid_nodes, wrist_path_cost


def test_grid_nodes_cover_the_box():
    n = grid_nodes([0, 0, 0], [0.2, 0.1, 0.0], 0.1)
    assert n.shape == (6, 3)
    assert np.allclose(n.min(axis=0), [0, 0, 0]) and np.allclose(n.max(axis=0), [0.2, 0.1, 0.0])


def test_bad_grid():
    with pytest.raises(ValueError):
        grid_nodes([0, 0, 0], [1, 1, 1], 0.0)
    with pytest.raises(ValueError):
        grid_nodes([1, 0, 0], [0, 1, 1], 0.1)


def test_cost_is_the_sum_of_distances():
    nodes = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    anchors = np.array([[0.0, 0.0, 0.0], [2.0, 0.0, 0.0]])
    assert np.allclose(wrist_path_cost(nodes, anchors), [2.0, 2.0])
    assert np.allclose(wrist_path_cost(nodes, anchors, [2.0, 1.0]), [2.0, 3.0])


def test_three_collinear_anchors_give_the_middle_one():
    # Fermat-Weber point of collinear points: the median
    nodes = grid_nodes([-1, -1, -1], [1, 1, 1], 0.25)
    anchors = np.array([[-1.0, 0.0, 0.0], [0.25, 0.0, 0.0], [1.0, 0.0, 0.0]])
    x, tested = exchange_position(nodes, anchors, lambda p: True)
    assert np.allclose(x, [0.25, 0.0, 0.0]) and tested == 1


def test_obstacle_moves_the_exchange_to_the_next_best_free_node():
    nodes = grid_nodes([-1, -1, 0], [1, 1, 0], 0.5)
    anchors = np.array([[-1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    # the unconstrained best node is (0, 0.5): cost 2*sqrt(1.25) + 0.5 (Fermat point (0, 0.577))
    assert np.allclose(exchange_position(nodes, anchors, lambda p: True)[0], [0.0, 0.5, 0.0])
    blocked = lambda p: np.linalg.norm(p - [0.0, 0.5, 0.0]) < 1e-9  # noqa: E731
    x, tested = exchange_position(nodes, anchors, lambda p: not blocked(p))
    assert not blocked(x) and tested == 2
    cost = wrist_path_cost(nodes, anchors)
    free_costs = [c for p, c in zip(nodes, cost) if not blocked(p)]
    assert wrist_path_cost(x[None], anchors)[0] == pytest.approx(min(free_costs))


def test_no_free_node():
    nodes = grid_nodes([0, 0, 0], [0.1, 0.1, 0.1], 0.1)
    x, tested = exchange_position(nodes, np.zeros((1, 3)), lambda p: False)
    assert x is None and tested == len(nodes)
