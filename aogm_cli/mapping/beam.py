"""Standard mapping of narrow-beam sensors (lasers, ``ray.is_narrow_beam``): ``BeamMapper``, the log-odds
update along rays (``sensor_models.ray``) with the state and clamping of ``standard``."""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np

from aogm_cli.core.frames import sensor_poses
from aogm_cli.core.grid import GridSpec
from aogm_cli.core.log import SensorSpec
from aogm_cli.sensor_models.inverse_model import (
    UNOBSERVED,
    InverseModelConfig,
    float32_update,
    inverse_update,
    observed_log_odds,
    occupied_arc,
)
from aogm_cli.sensor_models.ray import TOUCH, next_cell, ray_start


class BeamGrid(NamedTuple):
    """``_beam_kernel``'s grid: the flat (height * width) state and the hit stamps."""

    state: np.ndarray  # float32 log-odds, -inf = unobserved
    hit_scan: np.ndarray  # int32: the last scan whose hit band covered the cell (-1: none)
    height: int
    width: int


class Rays(NamedTuple):
    """``_beam_kernel``'s readings, flat arrays of one length, scan after scan."""

    px: np.ndarray  # sensor position (m, from the grid's origin)
    py: np.ndarray
    ux: np.ndarray  # unit beam direction
    uy: np.ndarray
    z: np.ndarray  # float32 range as logged (NaN or negative: nothing; >= max_range: max-range)


# The model along a ray (Amanatides & Woo 1987, from the sensor's true position): for a reading z, cells
# overlapping the hit band [z - alpha/2, min(z + alpha/2, max_range)] are occupied (always the endpoint's:
# OctoMap's and GMapping's convention), those before it past min_range free, the blind zone observed only;
# a max-range reading only clears. Increments are the constant model's whatever the config names (a ray has
# no angular profile; Elfes' range profile models a sonar's fading cone). Within a scan a hit band's cells
# get no free evidence (OctoMap's insertPointCloud: occupied wins, more endpoints on occupied cells).
# A cell crossed for less than ``TOUCH`` cells is skipped (a ray through a corner steps diagonally).
class BeamMapper:
    """Incremental standard mapping of a narrow beam, as ``StandardMapper``, plus each cell's last hit-band scan."""

    def __init__(self, sensor: SensorSpec, grid: GridSpec, config: InverseModelConfig):
        config.validate()
        self.sensor = sensor
        self.grid = grid
        self.config = config
        self.update_constants = inverse_update(config, sensor, grid.resolution)
        self.state = np.full(grid.shape, UNOBSERVED, dtype=np.float32)
        self._grid = BeamGrid(self.state.reshape(-1), np.full(grid.height * grid.width, -1, dtype=np.int32),
                              grid.height, grid.width)
        self.scans_done = 0

    def update(self, pose: np.ndarray, ranges: np.ndarray) -> None:
        """Apply scans (pose (T, 3), ranges (T, S)) in order: every reading's ray, clamped."""
        pose = np.asarray(pose, dtype=np.float64).reshape(-1, 3)
        z = np.ascontiguousarray(ranges, dtype=np.float32).reshape(-1)
        if z.size != pose.shape[0] * self.sensor.count:
            raise ValueError(f"expected {pose.shape[0]} x {self.sensor.count} ranges, got {z.size}")
        sp = sensor_poses(pose, self.sensor.mount).reshape(-1, 3)
        rays = Rays(
            np.ascontiguousarray(sp[:, 0] - self.grid.origin_x),
            np.ascontiguousarray(sp[:, 1] - self.grid.origin_y),
            np.cos(sp[:, 2]),
            np.sin(sp[:, 2]),
            z,
        )
        _beam_kernel(self._grid, rays, self.update_constants, self.sensor.count, self.scans_done)
        self.scans_done += pose.shape[0]

    def result(self) -> tuple[np.ndarray, np.ndarray]:
        """(log_odds float32 (H, W), observed bool (H, W)); unobserved cells hold the prior l0."""
        return observed_log_odds(self.state, self.config.l0)


@numba.njit(cache=True, _nrt=False)
def _beam_kernel(grid, rays, update, n_beams, first_scan):
    """Compiled update of the ``Rays`` scan by scan: stamp hit bands in ``hit_scan``, then update (stamped: no free)."""
    state = grid.state
    hit_scan = grid.hit_scan
    height = grid.height
    width = grid.width
    z = rays.z
    min_range = update.min_range
    max_range = update.max_range
    c_free = np.float32(update.l_free_minus_l0)
    c_occ, lo, hi, l0 = float32_update(update)
    res = update.resolution
    tiny = TOUCH * res
    for k in range(z.size // n_beams):
        scan = first_scan + k
        first = k * n_beams
        # pass 1: the hit bands of this scan
        for t in range(first, first + n_beams):
            zt = np.float64(z[t])
            if not (zt >= 0.0 and zt < max_range):
                continue
            arc_start, arc_end = occupied_arc(zt, update.half_alpha, max_range)
            row, col, t0, t_stop, t_max_row, t_max_col, d_row, d_col, s_row, s_col = ray_start(
                rays.px[t], rays.py[t], rays.ux[t], rays.uy[t], arc_start, arc_end, height, width, res
            )
            inside = True
            while inside and t0 < t_stop:  # False for a NaN pose
                t1 = min(t_max_row, t_max_col)
                if min(t1, t_stop) - t0 > tiny:
                    hit_scan[row * width + col] = scan
                row, col, t_max_row, t_max_col, inside = next_cell(
                    row, col, t_max_row, t_max_col, d_row, d_col, s_row, s_col, height, width
                )
                t0 = max(t0, t1)
        # pass 2: every ray's update, clamped
        for t in range(first, first + n_beams):
            zt = np.float64(z[t])
            if not zt >= 0.0:  # NaN or negative: no information
                continue
            if zt >= max_range:  # max-range reading: free space only, up to max_range
                end = max_range
                z_free = np.inf
            else:
                z_free, end = occupied_arc(zt, update.half_alpha, max_range)
            row, col, t0, t_stop, t_max_row, t_max_col, d_row, d_col, s_row, s_col = ray_start(
                rays.px[t], rays.py[t], rays.ux[t], rays.uy[t], 0.0, end, height, width, res
            )
            inside = True
            while inside and t0 < t_stop:
                t1 = min(t_max_row, t_max_col)
                t1c = min(t1, t_stop)
                if t1c - t0 > tiny:
                    i = row * width + col
                    x = state[i]
                    x = l0 if x < lo else x
                    if t1c > z_free:
                        x = min(x + c_occ, hi)
                    elif t1c > min_range and hit_scan[i] != scan:
                        x = max(x + c_free, lo)
                    state[i] = x
                row, col, t_max_row, t_max_col, inside = next_cell(
                    row, col, t_max_row, t_max_col, d_row, d_col, s_row, s_col, height, width
                )
                t0 = max(t0, t1)
