"""Standard occupancy-grid mapping (Elfes 1989, Moravec 1988): each cell on its own, in log-odds.

``standard_map`` streams a log's scans chunk by chunk through one compiled kernel that, for
every reading and every cell of its cone, adds ``inverse_model - l0`` and clamps.

Choices (documented)
--------------------
* Clamping after every update (OctoMap's clamping update): a cell's log-odds never leaves
  [clamp_min, clamp_max], so a long run of identical evidence does not make a cell too
  confident to change back. The result depends on the order of readings, which is the
  log's order (scans in time, sensors in mount order), so it is reproducible.
* A reading visits each cell of its cone once (the templates hold each cell once).
* ``observed`` marks every cell that some reading's cone covered up to min(z + alpha/2,
  max_range), or up to max_range for a max-range reading, including the blind zone next
  to the sensor, where the reading gives no evidence.
* Arithmetic on the grid is float32 in a fixed order, so a map made chunk by chunk equals,
  bit for bit, the map made in one pass.

Speed: the kernel never evaluates a transcendental function per cell. Per template entry it
stores a = w_angle (E_a, or 1 for the constant model) and b = a * (d - Rmin)^2, so the free
increment is c_free * a * (1 - (d - Rmin)^2 / span^2) = A a - B b with per-reading A, B; the
occupied increment is c_occ * a. The region boundaries of a reading are binary searches in
its template's sorted ranges.
"""

from __future__ import annotations

from collections.abc import Iterable

import numba
import numpy as np

from aogm_cli.grid import GridSpec
from aogm_cli.logfile import SensorSpec
from aogm_cli.mapping.cone import ConeTemplates, build_cone_templates, sensor_cells
from aogm_cli.mapping.inverse_model import InverseModelConfig, angular_profile


def probability_from_log_odds(log_odds, observed=None) -> np.ndarray:
    """Occupancy probability p = 1 - 1 / (1 + exp(l)) as float32; 0.5 where not ``observed``."""
    lo = np.asarray(log_odds, dtype=np.float64)
    with np.errstate(over="ignore"):
        p = 1.0 - 1.0 / (1.0 + np.exp(lo))
    if observed is not None:
        p = np.where(np.asarray(observed, dtype=bool), p, 0.5)
    return p.astype(np.float32)


def template_profiles(
    templates: ConeTemplates, config: InverseModelConfig, sensor: SensorSpec
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-entry profile values (a, b) as float32 and, per stored bin, the blind-zone length.

    a = E_a(theta) ("elfes") or 1 ("constant"); b = a (d - min_range)^2 ("elfes", 0 in the
    blind zone) or 0 ("constant"). ``blind_end[b]`` counts the stored bin's entries nearer
    than min_range.
    """
    if config.model == "elfes":
        a = angular_profile(templates.bearings, sensor.beam_width)
        u = np.maximum(templates.ranges - sensor.min_range, 0.0)
        b = a * u * u
    else:
        a = np.ones_like(templates.ranges)
        b = np.zeros_like(templates.ranges)
    n_base = templates.offsets.size - 1
    blind_end = np.empty(n_base, dtype=np.int64)
    for i in range(n_base):
        s, e = templates.offsets[i], templates.offsets[i + 1]
        blind_end[i] = np.searchsorted(templates.ranges[s:e], sensor.min_range, side="left")
    return a.astype(np.float32), b.astype(np.float32), blind_end


def standard_map(
    chunks: Iterable[tuple[int, np.ndarray, np.ndarray, np.ndarray]],
    sensor: SensorSpec,
    grid: GridSpec,
    config: InverseModelConfig,
    *,
    templates: ConeTemplates | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Standard log-odds map of the scans in ``chunks``: (log_odds float32 (H, W), observed bool (H, W)).

    ``chunks`` yields (start, time, pose (T, 3), ranges (T, S)) like ``LogReader.chunks()``;
    memory is the grid, the templates and one chunk. Unobserved cells hold the prior l0.
    ``templates`` defaults to ``build_cone_templates(grid.resolution, sensor.beam_width,
    sensor.max_range)``.
    """
    config.validate()
    if templates is None:
        templates = build_cone_templates(grid.resolution, sensor.beam_width, sensor.max_range)
    if templates.resolution != grid.resolution or templates.beam_width != sensor.beam_width:
        raise ValueError("cone templates do not match the grid resolution and the sensor's beam width")
    if templates.reach < sensor.max_range:
        raise ValueError("cone templates do not reach the sensor's max_range")
    prof_a, prof_b, blind_end = template_profiles(templates, config, sensor)
    log_odds = np.full(grid.shape, config.l0, dtype=np.float32)
    observed = np.zeros(grid.shape, dtype=np.bool_)
    state = StandardKernelArgs(templates, prof_a, prof_b, blind_end, config, sensor, grid)
    for _start, _time, pose, ranges in chunks:
        update_standard(log_odds, observed, pose, ranges, sensor, grid, templates, state)
    return log_odds, observed


class StandardKernelArgs:
    """The per-run constants of the standard kernel, computed once per map."""

    def __init__(self, templates, prof_a, prof_b, blind_end, config, sensor, grid):
        self.tpl = templates.kernel_arrays
        self.prof_a = prof_a
        self.prof_b = prof_b
        self.blind_end = blind_end
        self.scalars = np.array(
            [
                0.5 * config.alpha,
                sensor.min_range,
                sensor.max_range,
                config.l_free - config.l0,
                config.l_occ - config.l0,
                config.clamp_min,
                config.clamp_max,
            ],
            dtype=np.float64,
        )
        self.extent = int(templates.extent)
        self.shape = grid.shape


def update_standard(log_odds, observed, pose, ranges, sensor, grid, templates, args: StandardKernelArgs) -> None:
    """Apply one chunk of scans (pose (T, 3), ranges (T, S)) to ``log_odds`` and ``observed`` in place."""
    rows, cols, bins, valid = sensor_cells(pose, sensor, grid, templates)
    z = np.where(valid, np.asarray(ranges, dtype=np.float32), np.float32(np.nan)).astype(np.float32)
    _standard_kernel(
        log_odds.reshape(-1),
        observed.reshape(-1),
        grid.height,
        grid.width,
        rows.reshape(-1),
        cols.reshape(-1),
        bins.reshape(-1),
        z.reshape(-1),
        args.tpl,
        args.prof_a,
        args.prof_b,
        args.blind_end,
        args.scalars,
        args.extent,
    )


@numba.njit(cache=True)
def _standard_kernel(g, obs, height, width, rows, cols, bins, z, tpl, prof_a, prof_b, blind_end, scalars, ext):
    """Compiled log-odds update of readings t = 0.. in order; ``g``/``obs`` are the flat grids."""
    offsets, dcol, drow, ranges, base_bin, transform = tpl
    half_alpha = scalars[0]
    min_range = scalars[1]
    max_range = scalars[2]
    c_free = scalars[3]
    c_occ = np.float32(scalars[4])
    lo = np.float32(scalars[5])
    hi = np.float32(scalars[6])
    for t in range(z.size):
        zt = np.float64(z[t])
        if not zt >= 0.0:  # NaN or negative: no information
            continue
        row0 = rows[t]
        col0 = cols[t]
        if row0 + ext < 0 or row0 - ext >= height or col0 + ext < 0 or col0 - ext >= width:
            continue  # the cone cannot touch the grid
        k = bins[t]
        b = base_bin[k]
        s = offsets[b]
        e = offsets[b + 1]
        r = ranges[s:e]
        if zt >= max_range:  # max-range reading: free space only, up to max_range
            free_end = np.searchsorted(r, max_range, side="right")
            arc_end = free_end
            span = max_range - min_range
        else:
            z_free = zt - half_alpha
            free_end = np.searchsorted(r, z_free, side="left")
            arc_end = np.searchsorted(r, min(zt + half_alpha, max_range), side="right")
            span = z_free - min_range
        blind = blind_end[b]
        fa = np.float32(c_free)
        fb = np.float32(0.0)
        if span > 0.0:
            fb = np.float32(max(c_free / (span * span), -1e30))
        ta = transform[k, 0]
        tb = transform[k, 1]
        tc = transform[k, 2]
        td = transform[k, 3]
        j_blind = s + min(blind, free_end)
        j_free0 = s + blind
        j_free1 = s + free_end
        j_arc1 = s + arc_end
        if row0 - ext >= 0 and row0 + ext < height and col0 - ext >= 0 and col0 + ext < width:
            # the whole cone lies inside the grid: no bounds checks
            p = tc * width + ta
            q = td * width + tb
            base = row0 * width + col0
            for j in range(s, j_blind):
                obs[base + p * dcol[j] + q * drow[j]] = True
            for j in range(j_free0, j_free1):
                i = base + p * dcol[j] + q * drow[j]
                x = g[i] + (fa * prof_a[j] - fb * prof_b[j])
                g[i] = min(max(x, lo), hi)
                obs[i] = True
            for j in range(j_free1, j_arc1):
                i = base + p * dcol[j] + q * drow[j]
                x = g[i] + c_occ * prof_a[j]
                g[i] = min(max(x, lo), hi)
                obs[i] = True
        else:
            for j in range(s, j_arc1):
                dc = np.int64(dcol[j])
                dr = np.int64(drow[j])
                rr = row0 + tc * dc + td * dr
                cc = col0 + ta * dc + tb * dr
                if rr < 0 or rr >= height or cc < 0 or cc >= width:
                    continue
                i = rr * width + cc
                obs[i] = True
                if j < j_free0 and j < j_free1:
                    continue  # blind zone
                if j < j_free1:
                    x = g[i] + (fa * prof_a[j] - fb * prof_b[j])
                else:
                    x = g[i] + c_occ * prof_a[j]
                g[i] = min(max(x, lo), hi)
