"""Clusters: the regions swept by the readings the detector flags, as connected components.

A flagged reading sweeps the cells of its cone up to its range plus the obstacle thickness
(up to max range for a max-range reading); 8-connected components of the union are the
clusters, numbered 1..K (0 outside every cluster).
"""

from __future__ import annotations

import numba
import numpy as np
from scipy import ndimage

from aogm_cli.grid import GridSpec
from aogm_cli.mapping.cone import cone_cells


@numba.njit(cache=True)
def _sweep_cones(tpl, height, width, rows, cols, bins, limits, mask):
    offsets = tpl[0]
    scratch_cell = np.empty(offsets[-1], dtype=np.int64)
    scratch_range = np.empty(offsets[-1], dtype=np.float64)
    for t in range(rows.shape[0]):
        n = cone_cells(tpl, height, width, rows[t], cols[t], bins[t], limits[t], scratch_cell, scratch_range)
        for i in range(n):
            mask[scratch_cell[i]] = True


def swept_region(grid: GridSpec, templates, rows, cols, bins, z_model, max_range_model, alpha: float) -> np.ndarray:
    """(H, W) bool: cells in the cones of the given readings up to z + alpha (z in template
    ranges, see ``mapper.range_shift``), or ``max_range_model`` for max-range readings."""
    z = np.asarray(z_model, dtype=np.float64)
    keep = ~np.isnan(z)
    limits = np.where(np.isfinite(z[keep]), np.minimum(z[keep] + alpha, max_range_model), max_range_model)
    mask = np.zeros(grid.height * grid.width, dtype=np.bool_)
    _sweep_cones(templates.kernel_arrays, grid.height, grid.width, np.asarray(rows)[keep], np.asarray(cols)[keep],
                 np.asarray(bins)[keep], limits, mask)
    return mask.reshape(grid.shape)


def label_clusters(region: np.ndarray) -> tuple[np.ndarray, int]:
    """8-connected components of ``region``: (int32 ids, 0 outside; number of clusters)."""
    labels, n = ndimage.label(region, structure=np.ones((3, 3), dtype=int))
    return labels.astype(np.int32), int(n)
