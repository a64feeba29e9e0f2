"""Benchmark of the standard mapper's kernel against a compiled scatter-add ceiling.

Run as ``python bench/bench_standard.py``. It synthesises logs in memory (a lawn-mower of
corridors over a 100 m x 100 m grid at 0.05 m, a ring of 24 sonars, ranges uniform in
[0.3, 5] m with 10% max-range readings), compiles first, then prints cone-cell updates per
second for ``standard_map`` and for a scatter-add loop (``grid.flat[idx] += val`` in numba)
over exactly the same cells of the same readings, and their ratio.
"""

from __future__ import annotations

import argparse
import math
import time

import numba
import numpy as np

from aogm_cli.core.grid import GridSpec
from aogm_cli.core.log import SensorSpec
from aogm_cli.mapping.standard import standard_map
from aogm_cli.sensor_models.cone import cone_cells, reading_geometry
from aogm_cli.sensor_models.inverse_model import InverseModelConfig
from aogm_cli.sensor_models.readings import cone_templates as standard_templates
from aogm_cli.sensor_models.readings import echo_ranges

CHUNK = 4096  # scans per chunk, as LogReader.chunks() yields them


def synthetic_log(n_scans: int, seed: int = 0, size: float = 100.0, n_sonars: int = 24):
    """Poses along parallel corridors 10 m apart (back and forth), and random sonar ranges."""
    rng = np.random.default_rng(seed)
    lanes = np.arange(5.0, size, 10.0)
    lane_len = size - 4.0
    s = np.linspace(0.0, lanes.size * lane_len, n_scans, endpoint=False)
    lane = (s // lane_len).astype(int)
    along = s - lane * lane_len
    forward = lane % 2 == 0
    x = np.where(forward, 2.0 + along, size - 2.0 - along)
    y = lanes[lane] + rng.normal(0.0, 0.3, n_scans)
    yaw = np.where(forward, 0.0, math.pi) + rng.normal(0.0, 0.1, n_scans)
    pose = np.stack([x, y, yaw], axis=1)
    ranges = rng.uniform(0.3, 5.0, (n_scans, n_sonars)).astype(np.float32)
    ranges[rng.random((n_scans, n_sonars)) < 0.1] = np.inf
    a = np.arange(n_sonars) * (2.0 * math.pi / n_sonars)
    mount = np.stack([0.2 * np.cos(a), 0.2 * np.sin(a), a], axis=1)
    sensor = SensorSpec(mount=mount, beam_width=math.radians(30.0), min_range=0.15, max_range=5.0)
    return pose, ranges, sensor


def chunks_of(pose, ranges, size=CHUNK):
    for start in range(0, pose.shape[0], size):
        stop = min(pose.shape[0], start + size)
        yield start, np.zeros(stop - start), pose[start:stop], ranges[start:stop]


@numba.njit(cache=True)
def _reading_limits(z, offset, half_alpha, max_range):
    """Template range up to which the mapper visits each reading's cone (-1: skipped)."""
    out = np.empty(z.size, dtype=np.float64)
    for t in range(z.size):
        zt = np.float64(z[t])
        if not zt >= 0.0:
            out[t] = -1.0
        elif zt >= max_range:
            out[t] = max_range + offset[t]
        else:
            out[t] = min(zt + half_alpha, max_range) + offset[t]
    return out


@numba.njit(cache=True)
def _gather_cells(tpl, height, width, rows, cols, bins, limits, max_cells):
    """Flat indices (int32) of every cone cell the mapper visits, reading after reading."""
    idx = np.empty(rows.size * max_cells, dtype=np.int32)
    out_index = np.empty(max_cells, dtype=np.int64)
    out_range = np.empty(max_cells, dtype=np.float64)
    n = 0
    for t in range(rows.size):
        if limits[t] < 0.0:
            continue
        m = cone_cells(tpl, height, width, rows[t], cols[t], bins[t], limits[t], out_index, out_range, -1.0)
        for j in range(m):
            idx[n + j] = out_index[j]
        n += m
    return idx[:n]


@numba.njit(cache=True)
def scatter_add(flat, idx, val):
    """The ceiling: grid.flat[idx] += val, one update at a time."""
    for i in range(idx.size):
        flat[idx[i]] += val[i]


def ceiling(pose, ranges, sensor, grid, config, templates, block=500):
    """Seconds for scatter-add over the mapper's own cells; returns (seconds, updates)."""
    flat = np.zeros(grid.height * grid.width, dtype=np.float32)
    max_cells = int(np.diff(templates.offsets).max())
    seconds = 0.0
    updates = 0
    for start in range(0, pose.shape[0], block):
        stop = min(pose.shape[0], start + block)
        rows, cols, bins, valid, offset = reading_geometry(pose[start:stop], sensor, grid, templates)
        # the ranges as standard_map takes them (readings.echo_ranges, as float32)
        z = np.where(valid, echo_ranges(ranges[start:stop], grid).astype(np.float32), np.nan).astype(np.float32).reshape(-1)
        limits = _reading_limits(z, offset.reshape(-1), 0.5 * config.alpha, sensor.max_range)
        idx = _gather_cells(
            templates.kernel_arrays, grid.height, grid.width,
            rows.reshape(-1), cols.reshape(-1), bins.reshape(-1), limits, max_cells,
        )
        val = np.full(idx.size, 0.01, dtype=np.float32)
        t0 = time.perf_counter()
        scatter_add(flat, idx, val)
        seconds += time.perf_counter() - t0
        updates += idx.size
    return seconds, updates


def run(n_scans: int, grid: GridSpec, config: InverseModelConfig, repeat: int) -> None:
    pose, ranges, sensor = synthetic_log(n_scans)
    templates = standard_templates(grid, sensor)
    best_map = math.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        log_odds, observed = standard_map(chunks_of(pose, ranges), sensor, grid, config, templates=templates)
        best_map = min(best_map, time.perf_counter() - t0)
    best_ceiling = math.inf
    for _ in range(repeat):
        sec, updates = ceiling(pose, ranges, sensor, grid, config, templates)
        best_ceiling = min(best_ceiling, sec)
    map_rate = updates / best_map
    ceil_rate = updates / best_ceiling
    print(
        f"{n_scans:6d} scans x {sensor.count} sonars, grid {grid.height}x{grid.width} at {grid.resolution} m, "
        f"model {config.model}: {updates / 1e6:.1f} M cone-cell updates"
    )
    print(f"    standard_map   {best_map:7.3f} s  {map_rate / 1e9:6.3f} G updates/s  ({observed.mean():.1%} cells observed)")
    print(f"    scatter-add    {best_ceiling:7.3f} s  {ceil_rate / 1e9:6.3f} G updates/s  (ceiling)")
    print(f"    ratio          {map_rate / ceil_rate:7.1%}  (target >= 40%)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3, help="runs per measurement; the best is reported")
    parser.add_argument("--model", default="elfes", choices=["elfes", "constant"])
    args = parser.parse_args()
    grid = GridSpec(0.0, 0.0, 0.05, 2000, 2000)
    config = InverseModelConfig(model=args.model)
    # compile (and warm the template cache) on a tiny log first
    pose, ranges, sensor = synthetic_log(50)
    templates = standard_templates(grid, sensor)
    standard_map(chunks_of(pose, ranges), sensor, grid, config, templates=templates)
    ceiling(pose, ranges, sensor, grid, config, templates)
    print(f"numba {numba.__version__}, threads used: 1, templates: {templates.n_bins} heading bins, "
          f"{templates.offsets[-1]} stored entries")
    for n_scans in (5_000, 20_000):
        run(n_scans, grid, config, args.repeat)


if __name__ == "__main__":
    main()
