"""What mapping a log in a mode would cost (``map_estimate``), from the header, the poses and a sample of ranges;
``report.map_files.check_logs`` refuses a run over the budget."""

from __future__ import annotations

import math

import numpy as np

from aogm_cli.core.budget import Estimate, format_bytes
from aogm_cli.mapping.params import MapParams
from aogm_cli.mapping.pipeline import log_grid
from aogm_cli.sensor_models.ray import is_narrow_beam
from aogm_cli.sensor_models.readings import READING_PARTS

BYTES_PER_CELL = 40  # log-odds, probability, observed, EM state, the map file in memory
BYTES_PER_PADDED_CELL = 4  # the standard mapper's padded float32 state
# EM / adaptive: the readings laid out, EM's two tables of them, their orders, the set-up's temporaries
# and the log's ranges (docs/benchmarks.md: `make bench-scale`'s peak RSS)
BYTES_PER_READING = 300
# EM / adaptive on a sonar log: where beams were deflected (float64), and a cell's surface normal, echo
# sums and head-on passes (float32 x 6, one per part of the readings: ``sensor_models.surface``)
BYTES_PER_SHADOW = 8
BYTES_PER_SURFACE_CELL = 24 + 4 * READING_PARTS
BYTES_PER_TEMPLATE_CELL = 48  # the disc the cone templates are cut from (int64 offsets, ranges, angles)
# adaptive on a sonar log: the thinned map's state and evidence (float32 x 3), the final evidence's parts
BYTES_PER_THINNED_CELL = 12 + 8 * READING_PARTS
# the em mode's candidates held free (``em._flippable``): two masks, the cells' numbers and their gains
# in parts; each reading's narrowed extent and its orders (int64 x 4, int32 x 6)
BYTES_PER_HELD_CELL = 6 + 8 * READING_PARTS
BYTES_PER_HELD_READING = 56
SAMPLE_BLOCKS, BLOCK_SCANS = 32, 64  # ranges read to estimate the cones' mean size


def cone_area_cells(reach_cells: np.ndarray, beam_width: float) -> np.ndarray:
    """Cells of a cone of ``reach_cells`` cells' radius: its area, at least a ray's length."""
    return np.maximum(0.5 * beam_width * reach_cells**2, reach_cells) + 1.0


def mean_reach(reader, params: MapParams, resolution: float) -> float:
    """The mean reach (m) of a reading's cone, from up to SAMPLE_BLOCKS blocks of scans over the log."""
    n = reader.n_scans
    sensor = reader.sensor
    starts = np.unique(np.linspace(0, max(0, n - BLOCK_SCANS), min(SAMPLE_BLOCKS, max(1, n))).astype(np.int64))
    blocks = [reader.scan_ranges(int(s), int(min(n, s + BLOCK_SCANS))) for s in starts] if n else []
    if not blocks:
        return 0.0
    z = np.concatenate([b.reshape(-1) for b in blocks]).astype(np.float64)
    beyond = max(params.em.forward.window * params.em.forward.sigma, params.inverse_model.alpha) + resolution
    reach = np.where(np.isnan(z), 0.0, np.minimum(np.where(np.isinf(z), sensor.max_range, z + beyond),
                                                  sensor.max_range + resolution))
    return float(reach.mean()) if reach.size else 0.0


def map_estimate(reader, mode: str, params: MapParams) -> Estimate:
    """Memory (bytes) and work (cone cell updates) of mapping the open log ``reader`` in ``mode``."""
    sensor = reader.sensor
    grid = log_grid(reader, params.resolution)
    res = grid.resolution
    cells = float(grid.height) * float(grid.width)
    readings = float(reader.n_scans) * float(sensor.count)
    reach_cells = (sensor.max_range + res) / res
    narrow = is_narrow_beam(sensor, res)
    pad = 0.0 if narrow and mode == "standard" else math.floor(reach_cells)
    padded = (grid.height + 2 * pad) * (grid.width + 2 * pad) if mode != "em" else 0.0
    templates = 0.0 if narrow and mode == "standard" else (2 * pad + 1) ** 2
    per_reading = float(cone_area_cells(np.array(mean_reach(reader, params, res) / res), sensor.beam_width))
    entries = readings * per_reading
    grid_bytes = cells * BYTES_PER_CELL + padded * BYTES_PER_PADDED_CELL + templates * BYTES_PER_TEMPLATE_CELL
    reading_bytes = 0.0
    work = entries
    if mode != "standard":
        reading_bytes = readings * BYTES_PER_READING
        if mode == "em":  # adaptive's problems are its clusters', which hold no cell free (``em._flippable``)
            reading_bytes += readings * BYTES_PER_HELD_READING
            grid_bytes += cells * BYTES_PER_HELD_CELL
        if not narrow and params.em.forward.specular_deg < 90.0:  # the angle of incidence (``plan.incidence``)
            reading_bytes += readings * BYTES_PER_SHADOW
            grid_bytes += cells * BYTES_PER_SURFACE_CELL
        if not narrow and mode == "adaptive":
            grid_bytes += cells * BYTES_PER_THINNED_CELL
        work += entries * params.em.max_sweeps
    memory = grid_bytes + reading_bytes
    detail = (f"a {grid.height} x {grid.width} grid at {res:g} m, {readings:.3g} readings, "
              f"about {per_reading:.3g} cone cells each")
    # what else makes it fit: a coarser grid (the square); the readings' share only standard or fewer scans
    advice = f"a coarser --resolution (the grid's share is {format_bytes(grid_bytes)}, a quarter of it at {2 * res:g} m)"
    if reading_bytes:
        advice += (f"; the readings' share ({format_bytes(reading_bytes)}) no resolution changes: map part of the "
                   f"log at a time, or in the standard mode")
    return Estimate(f"the {mode} map of this log", memory, work, "cell updates", detail, advice)
