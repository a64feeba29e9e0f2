"""Clusters: where the readings the detector flags disagree with the standard map, grouped.

A flagged reading's cluster cells are the band of its cone near its range (z - 0.2 m to
z + alpha; none for a max-range reading), kept where the standard map is observed, not at
its free clamp, and holds the cell occupied (or, with ``near_occupied`` = n, within n cells
of one it holds occupied); 8-connected components of the union are the clusters, numbered
1..K (0 outside every cluster).
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np

from aogm_cli.core.grid import GridSpec
from aogm_cli.mapping.pipeline import reading_spans
from aogm_cli.mapping.sensor_models.cone import cone_cells


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
    """Mark the band of each reading span[0] <= t < span[1] in ``grid.swept`` and count its
    cells of ``grid.cell_mask`` into ``counts``; ``tpl`` is ``ConeTemplates.kernel_arrays``."""
    height = grid.height
    width = grid.width
    cell_mask = grid.cell_mask
    swept = grid.swept
    rows = readings.rows
    cols = readings.cols
    bins = readings.bins
    lower = readings.lower
    upper = readings.upper
    offsets = tpl.offsets
    scratch_cell = np.empty(offsets[-1], dtype=np.int64)
    scratch_range = np.empty(offsets[-1], dtype=np.float64)
    for t in range(span[0], span[1]):
        if not upper[t] >= 0.0:  # no band (max-range or invalid reading)
            continue
        n = cone_cells(tpl, height, width, rows[t], cols[t], bins[t], upper[t], scratch_cell, scratch_range,
                       lower[t])
        count = 0
        for i in range(n):
            cell = scratch_cell[i]
            swept[cell] = True
            if cell_mask[cell]:
                count += 1
        counts[t] = count


def cone_bands(grid: GridSpec, templates, cones, below: float, above: float,
               cell_mask: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Each reading's band, the cells of its cone with template range in [z - below, z + above].

    ``cones``: (rows, cols, bins, z) as ``pipeline.readings_of`` gives them (z in template ranges); a
    non-finite z has no band. Returns ((H, W) bool union of the bands, (N,) int64 cells of
    ``cell_mask`` (H, W) on each reading's band; zeros without a mask).
    """
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


def grown(mask: np.ndarray, cells: int) -> np.ndarray:
    """(H, W) bool: cells within ``cells`` steps (8-connected) of a cell of ``mask``."""
    mask = np.asarray(mask, dtype=bool)
    if cells <= 0 or not mask.any():
        return mask
    from scipy import ndimage  # not at start-up (``core.grid.GridSpec.cells_near``)

    return ndimage.binary_dilation(mask, structure=np.ones((3, 3), dtype=bool), iterations=cells)


def near_occupied(log_odds: np.ndarray, cells: int = 1) -> np.ndarray:
    """(H, W) bool: cells within ``cells`` steps (8-connected) of a cell with log-odds > 0."""
    return grown(np.asarray(log_odds) > 0, cells)


def label_clusters(region: np.ndarray) -> tuple[np.ndarray, int]:
    """8-connected components of ``region``: (int32 ids, 0 outside; number of clusters)."""
    from scipy import ndimage

    labels, n = ndimage.label(region, structure=np.ones((3, 3), dtype=int))
    return labels.astype(np.int32), int(n)


@numba.njit(cache=True)
def _contacts(ptr, entry_cluster):
    n_read = ptr.shape[0] - 1
    out_c = np.empty(entry_cluster.shape[0], dtype=np.int64)
    out_t = np.empty(entry_cluster.shape[0], dtype=np.int64)
    n = 0
    for t in range(n_read):
        start = n
        for e in range(ptr[t], ptr[t + 1]):
            k = entry_cluster[e]
            if k <= 0:
                continue
            seen = False
            for j in range(start, n):
                if out_c[j] == k:
                    seen = True
                    break
            if not seen:
                out_c[n] = k
                out_t[n] = t
                n += 1
    return out_c[:n], out_t[:n]


def readings_near_clusters(clusters, rows, cols, z, grid: GridSpec, z_max: float, forward) -> np.ndarray:
    """Positions of the readings whose forward cone could reach a cluster: the square of the
    cone's reach around the sensor's cell holds a cluster cell (counted in O(1) per reading
    from a summed-area table of the cluster mask)."""
    reach = np.where(np.isfinite(z), np.minimum(z + forward.window * forward.sigma, z_max), z_max)
    reach = np.where(np.isnan(z), -1.0, reach)
    r = np.ceil(reach / grid.resolution).astype(np.int64) + 1
    height, width = clusters.shape
    table = np.zeros((height + 1, width + 1), dtype=np.int64)
    np.cumsum(np.cumsum(clusters > 0, axis=0), axis=1, out=table[1:, 1:])
    r0, r1 = np.clip(rows - r, 0, height), np.clip(rows + r + 1, 0, height)
    c0, c1 = np.clip(cols - r, 0, width), np.clip(cols + r + 1, 0, width)
    inside = table[r1, c1] - table[r0, c1] - table[r1, c0] + table[r0, c0]
    return np.flatnonzero((inside > 0) & (reach >= 0))
