"""Consistency of a finished map with its own log, for logs without truth (as OctoMap's
``eval_octree_accuracy``): every in-range reading is re-cast against the map (``log_consistency``,
``map_consistency``, over pure functions on arrays: ``reading_endpoints``, ``arc_status``, ``summarize``)."""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np
from scipy import ndimage

from aogm_cli.core.frames import sensor_poses
from aogm_cli.core.grid import GridSpec
from aogm_cli.core.log import SensorSpec
from aogm_cli.io.logfile import LogReader
from aogm_cli.sensor_models.cone import NO_CUT, ConeReadings, ConeTemplates, range_search, reading_geometry
from aogm_cli.sensor_models.inverse_model import InverseModelConfig, occupied_arc
from aogm_cli.sensor_models.ray import is_narrow_beam
from aogm_cli.sensor_models.readings import cone_templates, echo_ranges

# What is measured. A cell is believed occupied when observed and p > 0.5, believed free when observed
# and p < 0.5. A reading is in range when finite, >= 0 and below the sensor's max_range (max-range
# readings end nowhere). Each in-range reading is re-cast from its sensor's pose:
# * narrow beams (``ray.is_narrow_beam``): its endpoint, the point at the logged range along the
#   beam's axis. It agrees when the endpoint's cell is believed occupied, contradicts when that cell
#   is believed free; otherwise (unobserved, p = 0.5, outside the grid) neither.
# * cones (sonar): its occupied arc, the cells the standard mapper marks occupied for it (cone
#   templates, range band alpha around the reading as the mapper shifts it). It agrees when some arc
#   cell is believed occupied, contradicts when every arc cell in the grid is believed free.
# ``endpoint_occupied`` is the share of in-range readings that agree. ``endpoint_occupied_8`` is the
# same with each believed-occupied cell grown by its 8 neighbours: the share that lands within one
# cell of an occupied one, which forgives pose errors of up to a cell. Both are reported; the first
# is the headline (OctoMap's count, and the stricter). ``endpoint_free`` is the share that
# contradicts. ``free_contradicted`` is the share of believed-free cells on which some reading ends
# (its endpoint cell, or a believed-free cell of the arc of a reading with no believed-occupied arc
# cell): free space that the log itself says holds an obstacle.

# per-reading status
NOT_COUNTED = -1  # not in range (no echo, NaN, negative) or no finite pose
UNKNOWN = 0  # neither agrees nor contradicts
CONTRADICTS = 1  # ends on believed-free cells only
AGREES = 2  # ends on a believed-occupied cell


class ArcMaps(NamedTuple):
    """``_arc_kernel``'s grid: flat (H * W) bool beliefs, and the contradicted cells it marks."""

    occupied: np.ndarray
    free: np.ndarray
    contradicted: np.ndarray
    height: int
    width: int


def believed_occupied(probability, observed) -> np.ndarray:
    """Cells observed with p > 0.5, as bool (H, W)."""
    return np.asarray(observed, dtype=bool) & (np.asarray(probability) > 0.5)


def believed_free(probability, observed) -> np.ndarray:
    """Cells observed with p < 0.5, as bool (H, W)."""
    return np.asarray(observed, dtype=bool) & (np.asarray(probability) < 0.5)


def with_neighbours(mask: np.ndarray) -> np.ndarray:
    """``mask`` grown by the 8 neighbours of each of its cells."""
    return ndimage.binary_dilation(np.asarray(mask, dtype=bool), structure=np.ones((3, 3), dtype=bool))


def in_range(ranges, sensor: SensorSpec) -> np.ndarray:
    """Readings that end on something: finite, >= 0 and below max_range."""
    z = np.asarray(ranges, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        return np.isfinite(z) & (z >= 0.0) & (z < sensor.max_range)


def reading_endpoints(pose: np.ndarray, ranges: np.ndarray, sensor: SensorSpec, grid: GridSpec):
    """Each reading's endpoint cell: (rows, cols, counted), each (T, S).

    The endpoint is the sensor's position plus the logged range along the beam's axis;
    ``counted`` marks in-range readings with a finite pose (rows, cols are 0 elsewhere).
    Cells may lie outside the grid.
    """
    sp = sensor_poses(np.asarray(pose, dtype=np.float64).reshape(-1, 3), sensor.mount)
    z = np.asarray(ranges, dtype=np.float64).reshape(sp.shape[:2])
    counted = in_range(z, sensor) & np.isfinite(sp).all(axis=-1)
    zc = np.where(counted, z, 0.0)
    x = np.where(counted, sp[..., 0] + zc * np.cos(sp[..., 2]), grid.origin_x)
    y = np.where(counted, sp[..., 1] + zc * np.sin(sp[..., 2]), grid.origin_y)
    rows, cols = grid.world_to_cell(x, y)
    return rows, cols, counted


def endpoint_status(occupied: np.ndarray, free: np.ndarray, rows, cols, counted) -> np.ndarray:
    """Status (int8, like ``rows``) of readings ending in cells (rows, cols): AGREES on a
    believed-occupied cell, CONTRADICTS on a believed-free one, UNKNOWN elsewhere (outside the
    grid too), NOT_COUNTED where not ``counted``."""
    rows = np.asarray(rows)
    cols = np.asarray(cols)
    h, w = occupied.shape
    inside = (rows >= 0) & (rows < h) & (cols >= 0) & (cols < w) & np.asarray(counted, dtype=bool)
    r = np.where(inside, rows, 0)
    c = np.where(inside, cols, 0)
    status = np.where(occupied[r, c], AGREES, np.where(free[r, c], CONTRADICTS, UNKNOWN))
    status = np.where(inside, status, UNKNOWN)
    return np.where(counted, status, NOT_COUNTED).astype(np.int8)


def arc_status(
    occupied: np.ndarray,
    free: np.ndarray,
    scans: tuple[np.ndarray, np.ndarray],
    sensor: SensorSpec,
    grid: GridSpec,
    templates: ConeTemplates,
    alpha: float,
    contradicted: np.ndarray | None = None,
) -> np.ndarray:
    """Status (int8 (T, S)) of each reading of ``scans`` = (pose (T, 3), ranges (T, S))'s occupied arc: AGREES when some arc cell is
    believed occupied, CONTRADICTS when every arc cell in the grid is believed free, else
    UNKNOWN; NOT_COUNTED for readings out of range. The arc is the standard mapper's: template
    cells within alpha/2 of the reading shifted by ``readings.echo_ranges`` and the sensor's axis
    offset. When ``contradicted`` (bool (H, W)) is given, the believed-free arc cells of
    readings with no believed-occupied arc cell are set in it.
    """
    pose, ranges = scans
    rows, cols, bins, valid, offset = reading_geometry(pose, sensor, grid, templates)
    z = np.asarray(ranges, dtype=np.float64).reshape(rows.shape)
    counted = in_range(z, sensor) & valid
    zt = np.where(counted, echo_ranges(z, grid), np.nan)
    if contradicted is None:
        contradicted = np.zeros(grid.shape, dtype=bool)
    status = np.empty(z.size, dtype=np.int8)
    maps = ArcMaps(
        np.ascontiguousarray(occupied, dtype=np.bool_).reshape(-1),
        np.ascontiguousarray(free, dtype=np.bool_).reshape(-1),
        contradicted.reshape(-1),
        grid.height,
        grid.width,
    )
    readings = ConeReadings(rows.reshape(-1), cols.reshape(-1), bins.reshape(-1), zt.reshape(-1), offset.reshape(-1),
                            NO_CUT)
    _arc_kernel(maps, readings, templates.kernel_arrays, 0.5 * float(alpha), float(sensor.max_range), status)
    return status.reshape(z.shape)


@numba.njit(cache=True, _nrt=False)  # allocates nothing: as ``standard._standard_kernel``
def _arc_kernel(maps, readings, tpl, half_alpha, max_range, status):
    """Each reading's arc status into ``status``; ``maps`` is an ``ArcMaps``, ``readings``
    ``cone.ConeReadings`` and ``tpl`` ``ConeTemplates.kernel_arrays``."""
    height = maps.height
    width = maps.width
    free = maps.free
    for t in range(readings.z.size):
        zt = readings.z[t]
        if not zt >= 0.0:
            status[t] = -1
            continue
        k = readings.bins[t]
        b = tpl.base_bin[k]
        s = tpl.offsets[b]
        r = tpl.ranges[s : tpl.offsets[b + 1]]
        shift = readings.offset[t]
        arc_start, arc_end = occupied_arc(zt, half_alpha, max_range)
        f1 = range_search(r, tpl.range_index[b], tpl.resolution, arc_start + shift, False)
        m = range_search(r, tpl.range_index[b], tpl.resolution, arc_end + shift, True)
        ta, tb, tc, td = tpl.transform[k, 0], tpl.transform[k, 1], tpl.transform[k, 2], tpl.transform[k, 3]
        agree = False
        all_free = True
        for j in range(f1, m):
            dc = np.int64(tpl.dcol[s + j])
            dr = np.int64(tpl.drow[s + j])
            row = readings.rows[t] + tc * dc + td * dr
            col = readings.cols[t] + ta * dc + tb * dr
            if row < 0 or row >= height or col < 0 or col >= width:
                continue
            i = row * width + col
            if maps.occupied[i]:
                agree = True
                break
            if not free[i]:
                all_free = False
        if agree:
            status[t] = 2
            continue
        status[t] = 1 if all_free and m > f1 else 0
        for j in range(f1, m):
            dc = np.int64(tpl.dcol[s + j])
            dr = np.int64(tpl.drow[s + j])
            row = readings.rows[t] + tc * dc + td * dr
            col = readings.cols[t] + ta * dc + tb * dr
            if 0 <= row < height and 0 <= col < width and free[row * width + col]:
                maps.contradicted[row * width + col] = True


def summarize(status, status_8, contradicted: np.ndarray, free: np.ndarray, method: str) -> dict:
    """The consistency fields from per-reading statuses (exact and with 8 neighbours) and the
    contradicted cells: see the comment at the top. Shares are None when nothing was counted."""
    status = np.asarray(status).reshape(-1)
    n = int(np.sum(status != NOT_COUNTED))
    n_free = int(np.sum(free))
    n_contradicted = int(np.sum(contradicted & free))

    def share(count: int, total: int):
        return count / total if total else None

    return {
        "method": method,
        "readings": n,
        "endpoint_occupied": share(int(np.sum(status == AGREES)), n),
        "endpoint_occupied_8": share(int(np.sum(np.asarray(status_8).reshape(-1) == AGREES)), n),
        "endpoint_free": share(int(np.sum(status == CONTRADICTS)), n),
        "free_cells": n_free,
        "free_contradicted": share(n_contradicted, n_free),
    }


def log_consistency(reader: LogReader, grid: GridSpec, probability, observed, alpha: float | None = None,
                    chunk: int = 4096) -> dict:
    """Re-cast every in-range reading of the log open in ``reader`` against the map
    (``probability``, ``observed`` on ``grid``); returns ``summarize``'s fields.

    ``alpha`` (the arc's thickness, cones only) defaults to the inverse model's default.
    """
    sensor = reader.sensor
    occupied = believed_occupied(probability, observed)
    free = believed_free(probability, observed)
    occupied_8 = with_neighbours(occupied)
    contradicted = np.zeros(grid.shape, dtype=bool)
    narrow = is_narrow_beam(sensor, grid.resolution)
    if not narrow:
        templates = cone_templates(grid, sensor)
        alpha = InverseModelConfig().alpha if alpha is None else float(alpha)
    statuses, statuses_8 = [], []
    for _start, _time, pose, ranges in reader.chunks(chunk):
        if narrow:
            rows, cols, counted = reading_endpoints(pose, ranges, sensor, grid)
            status = endpoint_status(occupied, free, rows, cols, counted)
            status_8 = endpoint_status(occupied_8, free, rows, cols, counted)
            ends = status == CONTRADICTS
            contradicted[rows[ends], cols[ends]] = True
        else:
            status = arc_status(occupied, free, (pose, ranges), sensor, grid, templates, alpha, contradicted)
            status_8 = arc_status(occupied_8, free, (pose, ranges), sensor, grid, templates, alpha)
        statuses.append(status.reshape(-1))
        statuses_8.append(status_8.reshape(-1))
    empty = np.zeros(0, dtype=np.int8)
    return summarize(np.concatenate(statuses or [empty]), np.concatenate(statuses_8 or [empty]), contradicted, free,
                     "endpoint" if narrow else "arc")


def map_consistency(log_path, m) -> dict:
    """``log_consistency`` of map ``m`` (``mapfile.OccupancyMap``) against the log at
    ``log_path``, with the arc thickness alpha the map was made with."""
    alpha = (m.params.get("inverse_model") or {}).get("alpha") if isinstance(m.params, dict) else None
    with LogReader(log_path) as reader:
        return log_consistency(reader, m.grid, m.probability, m.observed, alpha)
