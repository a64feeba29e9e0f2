"""A narrow beam as a ray: which sensors are traced as rays rather than cones (``is_narrow_beam``)
and which grid cells a ray crosses (Amanatides & Woo 1987: ``ray_cells``, and the compiled steps
``ray_start`` and ``next_cell`` that ``mapping.beam`` walks); per cell, how many echoes end in it
on their sensor's axis and how many axes cross it before (``axis_counts``)."""

from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np

from aogm_cli.core.frames import sensor_poses
from aogm_cli.core.grid import GridSpec, dda_steps
from aogm_cli.core.log import SensorSpec

# a ray that stays in a cell for at most this many cells' length only touches it (a corner)
TOUCH = 1e-9
AXIS_SHORT = 2  # cells: an echo's axis counts as crossing the cells up to this many cells short of it


class Ray(NamedTuple):
    """One ray from (px, py) (m, from the grid's origin) along the unit vector (ux, uy)."""

    px: float
    py: float
    ux: float
    uy: float
    length: float


class RayCells(NamedTuple):
    """Outputs of ``_ray_cells_kernel``, each with room for every cell of a ray."""

    rows: np.ndarray  # int64
    cols: np.ndarray  # int64
    t_enter: np.ndarray  # float64 (m)
    t_exit: np.ndarray  # float64 (m)


class RayGrid(NamedTuple):
    """A grid's shape as the traversal takes it."""

    height: int
    width: int
    resolution: float


def is_narrow_beam(sensor: SensorSpec, resolution: float) -> bool:
    """Does standard mapping trace this sensor's readings as rays rather than cones? Yes for a laser
    (its return is near the axis, its beam no wider than their spacing) and a cone under a cell wide."""
    return sensor.kind == "laser" or float(sensor.beam_width) * float(sensor.max_range) < float(resolution)


def ray_cells(grid: GridSpec, x: float, y: float, yaw: float, length: float):
    """Cells (rows, cols, t_enter, t_exit) that the ray from (x, y) along ``yaw`` crosses up to ``length``."""
    n_max = int(grid.height + grid.width + 2)
    rows = np.empty(n_max, dtype=np.int64)
    cols = np.empty(n_max, dtype=np.int64)
    t0 = np.empty(n_max, dtype=np.float64)
    t1 = np.empty(n_max, dtype=np.float64)
    ray = Ray(float(x) - grid.origin_x, float(y) - grid.origin_y, math.cos(yaw), math.sin(yaw), float(length))
    n = _ray_cells_kernel(ray, RayGrid(grid.height, grid.width, float(grid.resolution)), RayCells(rows, cols, t0, t1))
    return rows[:n], cols[:n], t0[:n], t1[:n]


@numba.njit(cache=True, inline="always")
def _slab(p, u, size, t_lo, t_hi):
    """[t_lo, t_hi] clipped to where p + t u lies in [0, size) along one axis (t_hi -1: nowhere)."""
    if u > 0.0:
        return max(t_lo, -p / u), min(t_hi, (size - p) / u)
    if u < 0.0:
        return max(t_lo, (size - p) / u), min(t_hi, -p / u)
    if not (0.0 <= p < size):
        return t_lo, -1.0
    return t_lo, t_hi


@numba.njit(cache=True)
def ray_start(px, py, ux, uy, begin, end, height, width, res):
    """Set-up of the traversal of [begin, end] along one ray (t_start >= t_stop: it misses the grid)."""
    inf = np.inf
    if not (np.isfinite(px) and np.isfinite(py) and np.isfinite(ux) and np.isfinite(uy)):
        return 0, 0, 1.0, 0.0, inf, inf, inf, inf, 0, 0
    t_lo = max(begin, 0.0)
    t_hi = end
    x_max = width * res
    y_max = height * res
    t_lo, t_hi = _slab(px, ux, x_max, t_lo, t_hi)
    t_lo, t_hi = _slab(py, uy, y_max, t_lo, t_hi)
    if not t_lo < t_hi:
        return 0, 0, 1.0, 0.0, inf, inf, inf, inf, 0, 0
    col = min(max(int(math.floor((px + ux * t_lo) / res)), 0), width - 1)
    row = min(max(int(math.floor((py + uy * t_lo) / res)), 0), height - 1)
    # t of the next column / row edge, from the sensor's own position (no drift)
    step_col, step_row, t_max_col, t_max_row, t_delta_col, t_delta_row = dda_steps(col, row, px, py, ux, uy, 0.0,
                                                                                   0.0, res)
    return row, col, t_lo, t_hi, t_max_row, t_max_col, t_delta_row, t_delta_col, step_row, step_col


@numba.njit(cache=True)
def next_cell(row, col, t_max_row, t_max_col, d_row, d_col, s_row, s_col, height, width):
    """One Amanatides-Woo step; on a tie the row steps first (callers skip the zero-length cell)."""
    if t_max_col < t_max_row:
        col += s_col
        return row, col, t_max_row, t_max_col + d_col, 0 <= col < width
    row += s_row
    return row, col, t_max_row + d_row, t_max_col, 0 <= row < height


@numba.njit(cache=True)
def _ray_cells_kernel(ray, grid, out):
    """Write the cells of one ``Ray`` (``ray_cells``) to ``out``; return how many."""
    height = grid.height
    width = grid.width
    res = grid.resolution
    rows = out.rows
    cols = out.cols
    t_enter = out.t_enter
    t_exit = out.t_exit
    row, col, t0, t_stop, t_max_row, t_max_col, d_row, d_col, s_row, s_col = ray_start(
        ray.px, ray.py, ray.ux, ray.uy, 0.0, ray.length, height, width, res
    )
    tiny = TOUCH * res
    n = 0
    inside = True
    while inside and t0 < t_stop and n < rows.size:
        t1 = min(t_max_row, t_max_col)
        t1c = min(t1, t_stop)
        if t1c - t0 > tiny:
            rows[n] = row
            cols[n] = col
            t_enter[n] = t0
            t_exit[n] = t1c
            n += 1
        row, col, t_max_row, t_max_col, inside = next_cell(
            row, col, t_max_row, t_max_col, d_row, d_col, s_row, s_col, height, width
        )
        t0 = max(t0, t1)
    return n


def axis_counts(pose: np.ndarray, ranges: np.ndarray, sensor: SensorSpec, grid: GridSpec,
                short_cells: float = AXIS_SHORT) -> tuple[np.ndarray, np.ndarray]:
    """(ends, passes), each int32 (H, W), of the echoes: per cell, the echoes whose point on their
    sensor's axis lies in it, and those whose axis crosses it up to ``short_cells`` cells short of
    the range. The held-out AUC's labels and adaptive's evidence."""
    sp = sensor_poses(np.asarray(pose, dtype=np.float64).reshape(-1, 3), sensor.mount).reshape(-1, 3)
    z = np.asarray(ranges, dtype=np.float64).reshape(-1)
    with np.errstate(invalid="ignore"):
        echo = np.isfinite(z) & (z >= 0.0) & (z < sensor.max_range) & np.isfinite(sp).all(axis=1)
    sp, z = sp[echo], z[echo]
    n = grid.height * grid.width
    ux, uy = np.cos(sp[:, 2]), np.sin(sp[:, 2])
    rows, cols = grid.world_to_cell(sp[:, 0] + z * ux, sp[:, 1] + z * uy)
    inside = grid.contains(rows, cols)
    ends = np.bincount(rows[inside] * grid.width + cols[inside], minlength=n).astype(np.int32)
    passes = np.zeros(n, dtype=np.int32)
    m = grid.height + grid.width + 2
    cells = RayCells(np.empty(m, np.int64), np.empty(m, np.int64), np.empty(m), np.empty(m))
    _pass_counts(sp[:, 0] - grid.origin_x, sp[:, 1] - grid.origin_y, ux, uy, z - short_cells * grid.resolution,
                 RayGrid(grid.height, grid.width, float(grid.resolution)), cells, passes)
    return ends.reshape(grid.shape), passes.reshape(grid.shape)


@numba.njit(cache=True)
def _pass_counts(px, py, ux, uy, length, grid, cells, counts):
    """Add one to ``counts`` at every cell each ray crosses (nothing for length <= 0)."""
    for i in range(length.size):
        n = _ray_cells_kernel(Ray(px[i], py[i], ux[i], uy[i], length[i]), grid, cells)
        for j in range(n):
            counts[cells.rows[j] * grid.width + cells.cols[j]] += 1
