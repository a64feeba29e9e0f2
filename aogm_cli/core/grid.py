"""The one place that converts between world (x, y) metres and grid (row, col) cells: index [row, col]
= [iy, ix], row 0 the lowest y (ROS OccupancyGrid order); cell [iy, ix] covers x in
[origin_x + ix*res, origin_x + (ix+1)*res), and likewise y."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np


@dataclass(frozen=True)
class GridSpec:
    """Origin (x, y of the outer corner of cell [0, 0]), resolution (m per cell), shape (H, W)."""

    origin_x: float
    origin_y: float
    resolution: float
    height: int
    width: int

    @property
    def shape(self) -> tuple[int, int]:
        return (self.height, self.width)

    @property
    def origin(self) -> tuple[float, float]:
        return (self.origin_x, self.origin_y)

    @property
    def extent(self) -> tuple[float, float, float, float]:
        """(x_min, x_max, y_min, y_max) of the whole grid in metres."""
        return (
            self.origin_x,
            self.origin_x + self.width * self.resolution,
            self.origin_y,
            self.origin_y + self.height * self.resolution,
        )

    @classmethod
    def covering(cls, x_min: float, y_min: float, x_max: float, y_max: float, resolution: float) -> GridSpec:
        """The smallest grid at ``resolution`` whose cells cover the box, origin on the box corner."""
        width = max(1, int(math.ceil((x_max - x_min) / resolution - 1e-9)))
        height = max(1, int(math.ceil((y_max - y_min) / resolution - 1e-9)))
        return cls(float(x_min), float(y_min), float(resolution), height, width)

    def world_to_cell(self, x, y):
        """(row, col) integer arrays of the cells holding points (x, y); may lie outside the grid."""
        col = np.floor((np.asarray(x, dtype=np.float64) - self.origin_x) / self.resolution).astype(np.int64)
        row = np.floor((np.asarray(y, dtype=np.float64) - self.origin_y) / self.resolution).astype(np.int64)
        return row, col

    def cell_centre(self, row, col):
        """(x, y) of the centres of cells (row, col)."""
        x = self.origin_x + (np.asarray(col, dtype=np.float64) + 0.5) * self.resolution
        y = self.origin_y + (np.asarray(row, dtype=np.float64) + 0.5) * self.resolution
        return x, y

    def centres(self):
        """(X, Y) arrays of shape (H, W) with every cell's centre."""
        xs = self.origin_x + (np.arange(self.width) + 0.5) * self.resolution
        ys = self.origin_y + (np.arange(self.height) + 0.5) * self.resolution
        return np.meshgrid(xs, ys)

    def contains(self, row, col):
        """Boolean array: which (row, col) lie inside the grid."""
        row = np.asarray(row)
        col = np.asarray(col)
        return (row >= 0) & (row < self.height) & (col >= 0) & (col < self.width)

    def cells_near(self, x, y, distance: float) -> np.ndarray:
        """Bool (H, W): cells whose centre lies within ``distance`` (m) of the cell of some point
        (x, y) (non-finite points and points outside the grid are left out)."""
        x = np.asarray(x, dtype=np.float64).reshape(-1)
        y = np.asarray(y, dtype=np.float64).reshape(-1)
        keep = np.isfinite(x) & np.isfinite(y)
        rows, cols = self.world_to_cell(x[keep], y[keep])
        inside = self.contains(rows, cols)
        marks = np.zeros(self.shape, dtype=bool)
        marks[rows[inside], cols[inside]] = True
        return self.within(marks, distance)

    def within(self, mask: np.ndarray, distance: float) -> np.ndarray:
        """Bool (H, W): cells whose centre lies within ``distance`` (m) of the centre of some cell
        of ``mask`` (bool (H, W)); none when the mask is empty. A few marked cells (a robot's
        poses) get the disc of offsets within ``distance`` stamped at each; many, a Euclidean
        distance transform of the grid: the same cells either way (the same test of the same
        distances), at the cost of the marked cells' discs or of the grid's cells."""
        mask = np.asarray(mask, dtype=bool)
        rows, cols = np.nonzero(mask)
        if rows.size == 0:
            return np.zeros(self.shape, dtype=bool)
        reach = int(distance / self.resolution) + 1
        dr, dc = np.mgrid[-reach:reach + 1, -reach:reach + 1]
        disc = np.sqrt((dr * dr + dc * dc).astype(np.float64)) * self.resolution <= distance + 1e-9
        if rows.size * int(disc.sum()) > mask.size:
            from scipy import ndimage  # here, not at start-up: importing scipy.ndimage takes about 0.2 s

            return ndimage.distance_transform_edt(~mask) * self.resolution <= distance + 1e-9
        out = np.zeros(self.shape, dtype=bool)
        for a, b in zip(dr[disc], dc[disc], strict=True):
            r, c = rows + a, cols + b
            inside = (r >= 0) & (r < self.height) & (c >= 0) & (c < self.width)
            out[r[inside], c[inside]] = True
        return out

    def attrs(self) -> dict:
        """Attributes written beside a grid in every file: resolution and origin."""
        return {"resolution": self.resolution, "origin": np.array([self.origin_x, self.origin_y])}


@numba.njit(cache=True, inline="always")
def dda_steps(ix, iy, ox, oy, dx, dy, gx0, gy0, cell):
    """Compiled Amanatides-Woo steps for the ray (ox, oy) + t (dx, dy) in column ix, row iy
    of a grid of ``cell``-sized cells whose corner is (gx0, gy0): (step in x, step in y, t of
    the next x face, t of the next y face, t per cell in x, t per cell in y); the t's are inf
    along an axis the ray does not move on. Shared by the simulator, the truth raster and the
    ray mapper, so that all three walk the grid's cells alike."""
    sx = 1 if dx > 0.0 else -1
    sy = 1 if dy > 0.0 else -1
    tx = ((ix + (1 if dx > 0.0 else 0)) * cell + gx0 - ox) / dx if dx != 0.0 else np.inf
    ty = ((iy + (1 if dy > 0.0 else 0)) * cell + gy0 - oy) / dy if dy != 0.0 else np.inf
    tdx = cell / abs(dx) if dx != 0.0 else np.inf
    tdy = cell / abs(dy) if dy != 0.0 else np.inf
    return sx, sy, tx, ty, tdx, tdy
