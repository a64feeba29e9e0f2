"""Readings on a grid, as every model takes them: the range convention (``echo_ranges``), the cone
templates every mode uses, each reading's sensor cell, heading bin and template range
(``readings_of``, ``lay_out_readings``), and the bands of readings' cones (``cone_bands``)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import NamedTuple

import numba
import numpy as np

from aogm_cli.core.budget import in_parts
from aogm_cli.core.grid import GridSpec
from aogm_cli.core.log import SensorSpec
from aogm_cli.sensor_models.cone import ConeTemplates, cone_cells, flat_offsets, reading_geometry
from aogm_cli.sensor_models.cone_build import build_cone_templates
from aogm_cli.sensor_models.ray import is_narrow_beam

# readings per call of the kernels that walk every reading's cone once (``reading_spans``)
READINGS_PER_CALL = 1 << 14


def echo_ranges(ranges: np.ndarray, grid: GridSpec) -> np.ndarray:
    """Ranges as the cone mappers use them: half a cell longer (the one place this shift is made).
    A cell is occupied when its centre lies inside an obstacle, so the first occupied cell along a
    beam has its centre on average half a cell beyond the surface; without this, walls come half a
    cell too near. Rays take ranges as logged."""
    return np.asarray(ranges, dtype=np.float64) + 0.5 * grid.resolution


def cone_templates(grid: GridSpec, sensor: SensorSpec) -> ConeTemplates:
    """The cone templates every mode uses on ``grid``: reach max_range plus one cell (for the axis
    offset); a narrow beam's cones also hold every cell their ray crosses, as ray tracing does."""
    return build_cone_templates(grid.resolution, sensor.beam_width, sensor.max_range, margin=grid.resolution,
                                ray=is_narrow_beam(sensor, grid.resolution))


def forward_templates(grid: GridSpec, sensor: SensorSpec) -> ConeTemplates:
    """The forward model's templates: the standard mapper's, with their flat offsets built now."""
    templates = cone_templates(grid, sensor)
    flat_offsets(templates, grid.width)
    return templates


def readings_of(pose: np.ndarray, ranges: np.ndarray, sensor: SensorSpec, grid: GridSpec, templates):
    """All readings as flat arrays: rows, cols, heading bins, and template ranges."""
    rows, cols, bins, valid, offset = reading_geometry(pose, sensor, grid, templates)
    z = np.where(valid, echo_ranges(ranges, grid), np.nan) + offset
    return rows.reshape(-1), cols.reshape(-1), bins.reshape(-1), z.reshape(-1)


def reading_spans(n: int) -> list[tuple[int, int]]:
    """(start, stop) spans of ``READINGS_PER_CALL`` readings: Python (signal handlers) runs between them."""
    return [(a, min(a + READINGS_PER_CALL, n)) for a in range(0, n, READINGS_PER_CALL)]


# fixed parts of the readings for threads (``reading_parts``): results the same for any thread count
READING_PARTS = 4


def reading_parts(n: int, call: Callable[[int, tuple[int, int]], None]) -> None:
    """``call(part, span)`` over readings in ``READING_PARTS`` fixed parts on threads (kernels: ``nogil``)."""
    parts = READING_PARTS
    bounds = np.linspace(0, n, parts + 1).astype(np.int64)

    def part(k: int, stop) -> None:
        first = int(bounds[k])
        for start, end in reading_spans(int(bounds[k + 1]) - first):
            if stop.is_set():  # the main thread's signal handler raised
                return
            call(k, (first + start, first + end))

    in_parts(parts, part)


def summed_in_parts(n: int, out: np.ndarray, call: Callable[[int, np.ndarray, tuple[int, int]], None]) -> None:
    """``reading_parts``, each part summing into its own zeros, added in part order: any thread count."""
    sums = [np.zeros_like(out) for _ in range(READING_PARTS)]
    reading_parts(n, lambda k, span: call(k, sums[k], span))
    for part in sums:
        out += part


@dataclass
class LaidOutReadings:
    """Every reading of a log laid out for the forward model (what EM and adaptive map from)."""

    grid: GridSpec
    sensor: SensorSpec
    templates: ConeTemplates
    ranges: np.ndarray  # (T, S) as logged
    rows: np.ndarray
    cols: np.ndarray
    bins: np.ndarray
    z: np.ndarray
    # per reading, the range where a surface deflected its beam (+inf: none; None: no beam deflected)
    shadow: np.ndarray | None = None

    @property
    def cones(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(rows, cols, bins, z): where each reading's cone sits."""
        return self.rows, self.cols, self.bins, self.z

    @property
    def cuts(self) -> np.ndarray | None:
        """``shadow`` per scan and sonar (as ``ranges``), where the standard mapper cuts a deflected beam."""
        return None if self.shadow is None else self.shadow.reshape(self.ranges.shape)


def lay_out_readings(pose: np.ndarray, ranges: np.ndarray, sensor: SensorSpec, grid: GridSpec,
                     chunk: int = 4096) -> LaidOutReadings:
    """The readings as ``LaidOutReadings`` on ``grid``, ``chunk`` scans at a time (small temporaries)."""
    templates = forward_templates(grid, sensor)
    n = ranges.size
    rows, cols, bins = (np.empty(n, dtype=np.int64) for _ in range(3))
    z = np.empty(n)
    width = ranges.shape[1] if ranges.ndim == 2 else 1
    for start in range(0, pose.shape[0], chunk):
        stop = min(start + chunk, pose.shape[0])
        part = slice(start * width, stop * width)
        rows[part], cols[part], bins[part], z[part] = readings_of(pose[start:stop], ranges[start:stop], sensor, grid,
                                                                  templates)
    return LaidOutReadings(grid, sensor, templates, ranges, rows, cols, bins, z)


class BandReadings(NamedTuple):
    """``_band``'s readings: flat arrays of one length."""

    rows: np.ndarray  # the sensor's cell (int64; may lie outside the grid)
    cols: np.ndarray
    bins: np.ndarray  # heading bin (int64)
    lower: np.ndarray  # float64 template ranges of the band (upper NaN or < 0: no band)
    upper: np.ndarray


class BandGrid(NamedTuple):
    """``_band``'s grid: its shape, the mask it counts cells of, and the union it marks."""

    height: int
    width: int
    cell_mask: np.ndarray  # flat bool (H * W)
    swept: np.ndarray  # flat bool (H * W): set on every cell of some band


@numba.njit(cache=True)
def _band(tpl, grid, readings, counts, span):
    """Mark each reading's band in ``grid.swept`` and count its cells of ``grid.cell_mask`` into ``counts``."""
    scratch_cell = np.empty(tpl.offsets[-1], dtype=np.int64)
    scratch_range = np.empty(tpl.offsets[-1], dtype=np.float64)
    for t in range(span[0], span[1]):
        if not readings.upper[t] >= 0.0:  # no band (max-range or invalid reading)
            continue
        n = cone_cells(tpl, grid.height, grid.width, readings.rows[t], readings.cols[t], readings.bins[t],
                       readings.upper[t], scratch_cell, scratch_range, readings.lower[t])
        count = 0
        for i in range(n):
            cell = scratch_cell[i]
            grid.swept[cell] = True
            if grid.cell_mask[cell]:
                count += 1
        counts[t] = count


def cone_bands(grid: GridSpec, templates, cones, below: float, above: float,
               cell_mask: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Each reading's band, the cells of its cone with template range in [z - below, z + above]
    (none for a non-finite z): ((H, W) union of the bands, (N,) cells of ``cell_mask`` on each)."""
    rows, cols, bins, z_model = cones
    z = np.asarray(z_model, dtype=np.float64).reshape(-1)
    finite = np.isfinite(z)
    lower = np.where(finite, z - below, np.inf)
    upper = np.where(finite, z + above, -1.0)
    if cell_mask is None:
        mask = np.zeros(grid.height * grid.width, dtype=np.bool_)
    else:
        mask = np.ascontiguousarray(np.asarray(cell_mask, dtype=np.bool_).reshape(-1))
    counts = np.zeros(z.shape[0], dtype=np.int64)
    swept = np.zeros(grid.height * grid.width, dtype=np.bool_)
    readings = BandReadings(*(np.ascontiguousarray(a, np.int64).reshape(-1) for a in (rows, cols, bins)), lower, upper)
    for span in reading_spans(z.shape[0]):
        _band(templates.kernel_arrays, BandGrid(grid.height, grid.width, mask, swept), readings, counts, span)
    return swept.reshape(grid.shape), counts
