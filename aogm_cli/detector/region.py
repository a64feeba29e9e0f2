"""Where a flagged reading's cluster lies: the band of its cone near its range, next to the walls
the standard map draws. Also counts a cell mask along such bands (the occupied arcs of labels rule (c)).
"""

from __future__ import annotations

import numba
import numpy as np

from aogm_cli.grid import GridSpec
from aogm_cli.mapping.cone import cone_cells

BAND_BELOW = 0.2  # m: a flagged cone's cluster starts this far before its range (z - 0.2 m) ...
# ... and ends at z + alpha (the obstacle thickness); a max-range reading has no band.
NEAR_OCCUPIED = 1  # cells: the band is kept within this many cells (8-connected) of a cell the standard map holds occupied


@numba.njit(cache=True)
def _band(tpl, height, width, rows, cols, bins, lower, upper, cell_mask, counts, swept):
    offsets = tpl[0]
    scratch_cell = np.empty(offsets[-1], dtype=np.int64)
    scratch_range = np.empty(offsets[-1], dtype=np.float64)
    for t in range(rows.shape[0]):
        if not upper[t] >= 0.0:  # no band (max-range or invalid reading)
            continue
        n = cone_cells(tpl, height, width, rows[t], cols[t], bins[t], upper[t], scratch_cell, scratch_range)
        count = 0
        for i in range(n):
            if scratch_range[i] >= lower[t]:
                cell = scratch_cell[i]
                swept[cell] = True
                if cell_mask[cell]:
                    count += 1
        counts[t] = count


def cone_bands(grid: GridSpec, templates, rows, cols, bins, z_model, below: float, above: float,
               cell_mask: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Each reading's band, the cells of its cone with template range in [z - below, z + above].

    ``rows, cols, bins, z_model`` as ``mapper.readings_of`` gives them (z in template ranges); a
    non-finite z has no band. Returns ((H, W) bool union of the bands, (N,) int64 cells of
    ``cell_mask`` (H, W) on each reading's band; zeros without a mask).
    """
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
    _band(templates.kernel_arrays, grid.height, grid.width, np.asarray(rows, np.int64).reshape(-1),
          np.asarray(cols, np.int64).reshape(-1), np.asarray(bins, np.int64).reshape(-1), lower, upper, mask, counts, swept)
    return swept.reshape(grid.shape), counts


def near_occupied(log_odds: np.ndarray, cells: int = NEAR_OCCUPIED) -> np.ndarray:
    """(H, W) bool: cells within ``cells`` steps (8-connected) of a cell with log-odds > 0."""
    from scipy import ndimage

    occupied = np.asarray(log_odds) > 0
    if cells <= 0:
        return occupied
    return ndimage.binary_dilation(occupied, structure=np.ones((3, 3), dtype=bool), iterations=cells)
