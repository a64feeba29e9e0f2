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


def cluster_contacts(ptr: np.ndarray, entry_cluster: np.ndarray) -> np.ndarray:
    """(2, P) array of every distinct (cluster id, reading position) contact of an index whose
    entries lie in clusters ``entry_cluster`` (0 = none), sorted by cluster then reading."""
    c, t = _contacts(ptr, np.ascontiguousarray(entry_cluster, dtype=np.int64))
    order = np.lexsort((t, c))
    return np.stack([c[order], t[order]])
