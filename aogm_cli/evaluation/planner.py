"""What a planner sees in a map: where a disk robot starting at the trajectory can drive. ``leak``,
``block`` and ``surface_recall`` against a simulated truth; ``walls_kept``, ``leak_vs_standard`` and
``far_leak`` against the standard map of the same log and grid (CONTRACT.md, Metrics)."""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from aogm_cli.core.grid import GridSpec
from aogm_cli.core.scores import STANDARD_KEYS as STANDARD_KEYS  # without truth, against the standard map
from aogm_cli.core.scores import TRUTH_KEYS as TRUTH_KEYS  # against a simulated log's truth

STANDARD_ITSELF = {"walls_kept": 1.0, "leak_vs_standard": 0.0, "far_leak": 0.0}  # the standard map's own values
ROBOT_RADIUS = 0.2  # m: aogm compare's default --robot-radius
START_DISTANCE = 0.3  # m: the planner starts anywhere this close to the trajectory
SURFACE_DISTANCE = 0.1  # m: a truth wall surface is found when a map cell above 0.5 is this close
WALL_DISTANCE = 0.15  # m: a standard map's confident wall is kept when a cell above 0.5 is this close
CONFIDENT = 0.9  # the standard map's confident walls: cells at p >= this
EIGHT = np.ones((3, 3), dtype=bool)


def drivable(free: np.ndarray, resolution: float, robot_radius: float) -> np.ndarray:
    """Cells of ``free`` (bool (H, W)) farther than ``robot_radius`` from every cell that is not
    free; cells outside the grid count as not free (as the world's ``passable`` checks have it)."""
    padded = np.pad(np.asarray(free, dtype=bool), 1, constant_values=False)
    clearance = ndimage.distance_transform_edt(padded)[1:-1, 1:-1] * resolution
    return free & (clearance > robot_radius)


def map_free(probability: np.ndarray, observed: np.ndarray) -> np.ndarray:
    """Cells a planner may drive on: observed and believed free (p < 0.5)."""
    return np.asarray(observed, dtype=bool) & (np.asarray(probability) < 0.5)


def near_trajectory(grid: GridSpec, poses: np.ndarray, distance: float = START_DISTANCE) -> np.ndarray:
    """Bool (H, W): cells whose centre lies within ``distance`` of the cell of some pose's (x, y)."""
    poses = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
    return grid.cells_near(poses[:, 0], poses[:, 1], distance)


def reachable(drive: np.ndarray, start: np.ndarray) -> np.ndarray:
    """Cells of ``drive`` 8-connected to a cell of ``drive & start``."""
    labels, _ = ndimage.label(drive, structure=EIGHT)
    seeds = np.unique(labels[drive & start])
    seeds = seeds[seeds > 0]
    return np.isin(labels, seeds)


def map_reach(grid: GridSpec, probability, observed, poses, robot_radius: float) -> np.ndarray:
    """Where the planner drives in a map: observed cells below 0.5 with room for the robot,
    connected to the cells near the trajectory."""
    drive = drivable(map_free(probability, observed), grid.resolution, robot_radius)
    return reachable(drive, near_trajectory(grid, poses))


def truth_reach(grid: GridSpec, truth_occupancy, poses, robot_radius: float) -> np.ndarray:
    """Where the robot can really drive: truth-free cells with room for it, connected to the
    cells near the trajectory."""
    drive = drivable(np.asarray(truth_occupancy) == 0, grid.resolution, robot_radius)
    return reachable(drive, near_trajectory(grid, poses))


def wall_surface(truth_occupancy, observed) -> np.ndarray:
    """Truth-occupied cells with an 8-neighbour that is observed and truth-free."""
    occupied = np.asarray(truth_occupancy) != 0
    seen_free = np.asarray(observed, dtype=bool) & ~occupied
    return occupied & ndimage.binary_dilation(seen_free, structure=EIGHT)


def _share(part: int, whole: int) -> float:
    return float(part / whole) if whole else float("nan")


def planner_metrics(grid: GridSpec, probability, observed, truth_occupancy, poses, robot_radius: float) -> dict:
    """``leak``, ``block`` and ``surface_recall`` of a map against the truth (CONTRACT.md), and
    the cell counts behind them."""
    observed = np.asarray(observed, dtype=bool)
    in_map = map_reach(grid, probability, observed, poses, robot_radius)
    in_truth = truth_reach(grid, truth_occupancy, poses, robot_radius) & observed
    surface = wall_surface(truth_occupancy, observed)
    found = grid.within(np.asarray(probability) > 0.5, SURFACE_DISTANCE)
    n_truth = int(in_truth.sum())
    return {
        "leak": _share(int(np.sum(in_map & ~in_truth)), n_truth),
        "block": _share(int(np.sum(in_truth & ~in_map)), n_truth),
        "surface_recall": _share(int(np.sum(surface & found)), int(surface.sum())),
        "reachable_cells": int(in_map.sum()),
        "truth_reachable_cells": n_truth,
    }


def against_standard(grid: GridSpec, probability, observed, standard_probability, standard_observed, poses,
                     robot_radius: float) -> dict:
    """``walls_kept``, ``leak_vs_standard`` and ``far_leak`` of a map against the standard map of the
    same log and grid (for logs without truth). ``far_leak`` counts only the cells reached farther
    than ``robot_radius`` from every cell reached in the standard map: a thinner wall lets the
    robot a little closer to it, and that band beside the standard map's reach is no leak."""
    standard_probability = np.asarray(standard_probability)
    walls = np.asarray(standard_observed, dtype=bool) & (standard_probability >= CONFIDENT)
    kept = grid.within(np.asarray(probability) > 0.5, WALL_DISTANCE)
    in_map = map_reach(grid, probability, observed, poses, robot_radius)
    in_standard = map_reach(grid, standard_probability, standard_observed, poses, robot_radius)
    n_standard = int(in_standard.sum())
    far = ~grid.within(in_standard, robot_radius)
    return {
        "walls_kept": _share(int(np.sum(walls & kept)), int(walls.sum())),
        "leak_vs_standard": _share(int(np.sum(in_map & ~in_standard)), n_standard),
        "far_leak": _share(int(np.sum(in_map & far)), n_standard),
    }
