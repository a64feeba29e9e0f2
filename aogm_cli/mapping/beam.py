"""Standard mapping of narrow-beam sensors (lasers): ``BeamMapper``, the log-odds update along rays
(traversed by ``sensor_models.ray``) with the state and clamping of ``standard``; which sensors count as
narrow is ``ray.is_narrow_beam``."""

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


# The model along a ray (Amanatides & Woo 1987, traversed from the sensor's true position). A cell is
# the stretch [t_enter, t_exit) of the ray inside it (t in metres from the sensor). For a reading z
# (the hit: the range as logged, see ``standard.standard_map``):
# * occupied: cells that overlap the hit band [z - alpha/2, min(z + alpha/2, max_range)], so the cell
#   holding the endpoint always (OctoMap's and GMapping's convention), and the cell before it when the
#   endpoint lies within alpha/2 of their common edge;
# * free: the cells before the band (t_exit <= z - alpha/2) that reach past min_range;
# * observed only: the blind zone (t_exit <= min_range), no evidence.
# A max-range reading (z >= max_range, or +inf) clears the cells that overlap [min_range, max_range]
# and marks nothing occupied; NaN or negative readings carry nothing. Increments are the constant
# model's (``l_free - l0``, ``l_occ - l0``) whichever model the ``InverseModelConfig`` names: a ray has
# no angular profile, and Elfes' range profile, which models a sonar's fading cone, is not applied to a
# laser. Within one scan (one row of the log's ranges), a cell in some reading's hit band gets no free
# evidence from the other readings of that scan (OctoMap's insertPointCloud: occupied wins; it puts
# more of a laser log's endpoints on occupied cells). Otherwise every reading updates its cells once
# each, clamped, in the log's order, exactly as ``standard.StandardMapper`` does. A ray through a
# lattice corner steps diagonally: a cell the ray crosses for less than ``TOUCH`` cells (zero, up to
# rounding) is skipped. Cost: O(cells on the ray) per reading, no set-up.
class BeamMapper:
    """Incremental standard mapping of a narrow-beam sensor: ``update`` with chunks, then ``result``.

    Same interface and state as ``standard.StandardMapper``: one float32 grid holding each
    cell's log-odds once some ray covered it and ``UNOBSERVED`` (-inf) before; plus, per cell,
    the last scan whose hit band covered it (for hit precedence within a scan).
    """

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
    """Compiled log-odds update of the ``Rays`` in order, scan by scan (``n_beams`` readings
    each, the first scan numbered ``first_scan``), on the ``BeamGrid``, with the constants of
    ``update`` (an ``InverseUpdate``). Reading t is a ray from (px[t], py[t]) (m, from the
    grid's origin) along (ux[t], uy[t]). First pass per scan: stamp the cells of every hit band
    with the scan's number in ``hit_scan``; second pass: update every ray's cells, with no free
    evidence for stamped cells.
    """
    state = grid.state
    hit_scan = grid.hit_scan
    height = grid.height
    width = grid.width
    px = rays.px
    py = rays.py
    ux = rays.ux
    uy = rays.uy
    z = rays.z
    half_alpha = update.half_alpha
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
            arc_start, arc_end = occupied_arc(zt, half_alpha, max_range)
            row, col, t0, t_stop, t_max_row, t_max_col, d_row, d_col, s_row, s_col = ray_start(
                px[t], py[t], ux[t], uy[t], arc_start, arc_end, height, width, res
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
                z_free, end = occupied_arc(zt, half_alpha, max_range)
            row, col, t0, t_stop, t_max_row, t_max_col, d_row, d_col, s_row, s_col = ray_start(
                px[t], py[t], ux[t], uy[t], 0.0, end, height, width, res
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
