"""Metrics and passable / blocked checks on hand-made maps."""

import numpy as np
import pytest

from aogm_cli.core.grid import GridSpec
from aogm_cli.evaluation.metrics import expected_calibration_error, map_metrics, passable, run_checks


def test_metrics_on_a_hand_made_map():
    truth = np.array([[1, 0, 0], [1, 1, 0]], dtype=np.uint8)
    prob = np.array([[0.9, 0.6, 0.1], [0.2, 0.5, 0.3]])
    observed = np.array([[True, True, True], [True, True, False]])
    m = map_metrics(prob, observed, truth)
    # observed: (1,.9) TP, (0,.6) FP, (0,.1) TN, (1,.2) FN, (1,.5) FN (0.5 is not > 0.5)
    assert m["observed_cells"] == 5
    assert m["accuracy"] == pytest.approx(2 / 5)
    assert m["occupied_precision"] == pytest.approx(1 / 2)
    assert m["occupied_recall"] == pytest.approx(1 / 3)
    assert m["occupied_f1"] == pytest.approx(2 * 0.5 * (1 / 3) / (0.5 + 1 / 3))
    brier = np.mean([(0.9 - 1) ** 2, 0.6**2, 0.1**2, (0.2 - 1) ** 2, (0.5 - 1) ** 2])
    assert m["brier"] == pytest.approx(brier)
    # ECE: each observed cell alone in its bin (0.9, 0.6, 0.1, 0.2, 0.5 in bins 9, 6, 1, 2, 5)
    assert m["ece"] == pytest.approx((0.1 + 0.6 + 0.1 + 0.8 + 0.5) / 5)


def test_ece_pools_each_bins_cells_and_closes_the_last_bin():
    """Bin 0 (0.0, 0.05: mean 0.025, none occupied), bin 1 (0.15, occupied), bin 9 (1.0, 0.95,
    0.92: mean 0.9567, two of three occupied): (2 * 0.025 + 1 * 0.85 + 3 * (0.9567 - 2/3)) / 6."""
    p = [0.0, 0.05, 0.15, 1.0, 0.95, 0.92]
    t = [0, 0, 1, 1, 1, 0]
    assert expected_calibration_error(p, t) == pytest.approx((0.05 + 0.85 + (2.87 - 2)) / 6)
    assert expected_calibration_error([0.3, 0.3, 0.3], [1, 0, 0]) == pytest.approx(1 / 30)  # calibrated to 0.33
    assert expected_calibration_error([0.7, 0.2], [1, 0], bins=1) == pytest.approx(abs(0.45 - 0.5))
    assert np.isnan(expected_calibration_error([], []))


def door_map(gap_cells: int):
    """14 x 20 cells at 0.1 m: a wall across row 5 with a gap of ``gap_cells`` in the middle."""
    grid = GridSpec(0.0, 0.0, 0.1, 14, 20)
    prob = np.full(grid.shape, 0.1)
    prob[5, :] = 0.9
    lo = 10 - gap_cells // 2
    prob[5, lo : lo + gap_cells] = 0.1
    return grid, prob, np.ones(grid.shape, dtype=bool)


def test_passable_through_a_gap_depends_on_robot_radius():
    grid, prob, obs = door_map(gap_cells=6)  # 0.6 m gap
    start, goal = (1.05, 0.25), (1.05, 0.95)
    # the centre cells of a 6-cell gap are 3 cells (0.3 m) from the nearest wall cell
    assert passable(grid, prob, obs, start, goal, 0.25)
    assert not passable(grid, prob, obs, start, goal, 0.31)
    grid, prob, obs = door_map(gap_cells=0)
    assert not passable(grid, prob, obs, start, goal, 0.0)


def test_unobserved_cells_block_and_grid_edge_counts_as_obstacle():
    grid, prob, obs = door_map(gap_cells=6)
    obs[5, :] = False
    assert not passable(grid, prob, obs, (1.05, 0.25), (1.05, 0.95), 0.05)
    grid = GridSpec(0.0, 0.0, 0.1, 3, 10)
    free = np.zeros(grid.shape)
    # the middle row is 0.1 m from the outside; a 0.1 m robot does not fit, 0.05 m does
    assert not passable(grid, free, np.ones(grid.shape, bool), (0.05, 0.15), (0.95, 0.15), 0.1)
    assert passable(grid, free, np.ones(grid.shape, bool), (0.05, 0.15), (0.95, 0.15), 0.05)


def test_run_checks_reads_the_world_check_format():
    grid, prob, obs = door_map(gap_cells=8)
    checks = [{"name": "door", "passable": {"from": [1.05, 0.25], "to": [1.05, 0.95], "robot_radius": 0.25}}]
    assert run_checks(grid, prob, obs, checks) == [{"name": "door", "passed": True}]


def test_a_blocked_check_passes_when_there_is_no_path():
    checks = [{"name": "wall", "blocked": {"from": [1.05, 0.25], "to": [1.05, 0.95], "robot_radius": 0.25}},
              {"name": "door", "passable": {"from": [1.05, 0.25], "to": [1.05, 0.95], "robot_radius": 0.25}}]
    grid, prob, obs = door_map(gap_cells=8)  # the 0.8 m gap lets the robot through
    assert run_checks(grid, prob, obs, checks) == [{"name": "wall", "passed": False}, {"name": "door", "passed": True}]
    grid, prob, obs = door_map(gap_cells=0)  # the wall holds
    assert run_checks(grid, prob, obs, checks) == [{"name": "wall", "passed": True}, {"name": "door", "passed": False}]
