"""What every mode shares between a log and its map: the grid of a log, the range convention
(``echo_ranges``), the readings laid out as flat arrays, and timing that leaves out reading I/O.

A *log source* is an open ``io.logfile.LogReader`` or an in-memory ``core.log.Log``: both
have ``sensor``, ``n_scans``, ``truth_grid()``, ``poses()``, ``chunks()``, ``scan_ranges()`` and ``read()``.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from aogm_cli.core.errors import InputError
from aogm_cli.core.grid import GridSpec
from aogm_cli.core.log import SensorSpec
from aogm_cli.mapping.params import MapParams
from aogm_cli.mapping.sensor_models.cone import ConeTemplates, build_cone_templates, flat_offsets, reading_geometry

Progress = Callable[[str, int, int], None]  # (phase, done, total)
# readings per call of the kernels that walk every reading's cone once (``reading_spans``)
READINGS_PER_CALL = 1 << 14


def log_grid(log, resolution: float) -> GridSpec:
    """The truth grid of a simulated log; otherwise the poses' bounds plus max range."""
    grid = log.truth_grid()
    if grid is not None:
        return grid
    pose = log.poses()
    finite = np.isfinite(pose).all(axis=1)
    if not finite.any():
        raise InputError("no finite pose; cannot place a grid", file=log.path, key="/scans/pose")
    sensor = log.sensor
    reach = sensor.max_range + float(np.max(np.hypot(sensor.mount[:, 0], sensor.mount[:, 1]), initial=0.0))
    lo = pose[finite, :2].min(axis=0) - reach
    hi = pose[finite, :2].max(axis=0) + reach
    # snap the origin to the resolution so that maps of one log at one resolution align
    lo = np.floor(lo / resolution) * resolution
    return GridSpec.covering(lo[0], lo[1], hi[0], hi[1], resolution)


def echo_ranges(ranges: np.ndarray, grid: GridSpec) -> np.ndarray:
    """Ranges as the cone mappers use them: half a cell longer (the one place this shift is made).

    A truth (and map) cell is occupied when its centre lies inside an obstacle, so the first
    occupied cell along a beam has its centre between 0 and 1 cell beyond the surface that
    echoed: half a cell on average. Without this, standard and EM maps put walls half a cell
    too near the robot. Narrow beams (rays) take ranges as logged (see ``mapping.standard``)."""
    return np.asarray(ranges, dtype=np.float64) + 0.5 * grid.resolution


def is_narrow_beam(sensor: SensorSpec, resolution: float) -> bool:
    """Does standard mapping trace this sensor's readings as rays rather than cones?

    Yes for a laser (``kind == "laser"``: its reading is the first return near the beam's
    axis, and its beam, 0.5 deg or less, is no wider than the spacing of its beams), and for
    any sensor whose cone is under a cell wide at max range (beam_width * max_range < resolution).
    """
    return sensor.kind == "laser" or float(sensor.beam_width) * float(sensor.max_range) < float(resolution)


def cone_templates(grid: GridSpec, sensor: SensorSpec) -> ConeTemplates:
    """The cone templates every mode uses on ``grid``: reach max_range plus one cell (for the
    axis-offset correction of ``cone.reading_geometry``); cached, one-time set-up. A narrow
    beam's cones (EM's forward model of a laser) also hold every cell their ray crosses, as the
    ray tracing of standard mapping and of the held-out scores does (``build_cone_templates``)."""
    return build_cone_templates(grid.resolution, sensor.beam_width, sensor.max_range, margin=grid.resolution,
                                ray=is_narrow_beam(sensor, grid.resolution))


def forward_templates(grid: GridSpec, sensor: SensorSpec) -> ConeTemplates:
    """The forward model's templates: the standard mapper's (one cache for both), with their
    flat offsets for this grid's width built (and cached) now, as one-time set-up."""
    templates = cone_templates(grid, sensor)
    flat_offsets(templates, grid.width)
    return templates


class Timed:
    """Wraps a chunk iterator and adds up the time spent reading (to subtract it)."""

    def __init__(self, chunks):
        self._chunks = iter(chunks)
        self.io_seconds = 0.0

    def __iter__(self):
        return self

    def __next__(self):
        t0 = time.perf_counter()
        try:
            return next(self._chunks)
        finally:
            self.io_seconds += time.perf_counter() - t0


def readings_of(pose: np.ndarray, ranges: np.ndarray, sensor: SensorSpec, grid: GridSpec, templates):
    """All readings as flat arrays: sensor cell rows, cols, heading bins, and ranges shifted
    into template ranges: ``echo_ranges`` plus the sensor's offset from its cell's centre
    along the beam (``cone.reading_geometry``)."""
    rows, cols, bins, valid, offset = reading_geometry(pose, sensor, grid, templates)
    z = np.where(valid, echo_ranges(ranges, grid), np.nan) + offset
    return rows.reshape(-1), cols.reshape(-1), bins.reshape(-1), z.reshape(-1)


def reading_spans(n: int) -> list[tuple[int, int]]:
    """(start, stop) of readings 0 .. n - 1 in spans of ``READINGS_PER_CALL``: the kernels that
    walk every reading's cone once take a span per call and so return to Python between spans,
    where a signal's handler runs (``core.interrupts``): a signal ends a run within a second
    whatever the log's size."""
    return [(a, min(a + READINGS_PER_CALL, n)) for a in range(0, n, READINGS_PER_CALL)]


@dataclass
class Readings:
    """Every reading of a log laid out for the forward model (what EM and adaptive map from)."""

    grid: GridSpec
    sensor: SensorSpec
    templates: ConeTemplates
    ranges: np.ndarray  # (T, S) as logged
    rows: np.ndarray
    cols: np.ndarray
    bins: np.ndarray
    z: np.ndarray

    @property
    def cones(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(rows, cols, bins, z): where each reading's cone sits, as ``em_readings`` and
        ``cluster.cone_bands`` take them."""
        return self.rows, self.cols, self.bins, self.z


def lay_out_readings(pose: np.ndarray, ranges: np.ndarray, sensor: SensorSpec, grid: GridSpec,
                     chunk: int = 4096) -> Readings:
    """The readings of (pose (T, 3), ranges (T, S)) as ``Readings`` on ``grid``, laid out
    ``chunk`` scans at a time (the placement's temporaries stay small at any log size)."""
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
    return Readings(grid, sensor, templates, ranges, rows, cols, bins, z)


def params_json(params: MapParams, mode: str, grid: GridSpec) -> dict:
    """The parameters a map of ``mode`` records: every parameter, defaults included, and the
    grid it was derived onto (the truth's, or the poses' bounds)."""
    d = params.as_dict()
    d["mode"] = mode
    d["grid"] = {"origin": [grid.origin_x, grid.origin_y], "resolution": grid.resolution,
                 "shape": [grid.height, grid.width]}
    return d
