"""Clusters: where the readings the detector flags disagree with the standard map, grouped into
8-connected components numbered 1..K (0 outside every cluster); and the readings whose cones reach them."""

from __future__ import annotations

import numpy as np

from aogm_cli.core.grid import GridSpec

# A flagged reading's cluster cells: its cone's band near its range (``adaptive.find_clusters``); the
# components of their union are the clusters (``label_clusters``).


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


def readings_near_clusters(clusters, rows, cols, z, grid: GridSpec, z_max: float, forward) -> np.ndarray:
    """Positions of the readings whose cone's reach square holds a cluster cell (summed-area table: O(1) each)."""
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
