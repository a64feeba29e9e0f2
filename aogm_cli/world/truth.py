"""The truth raster: which cells of the truth grid the world's solids occupy (``truth_occupancy``:
polygons and circles by their cell centres, the centre lines of thin solids cell by cell, and the
floor plan's occupied pixels)."""

from __future__ import annotations

import math

import numba
import numpy as np

from aogm_cli.core.grid import GridSpec, dda_steps
from aogm_cli.world.config import World
from aogm_cli.world.solids import world_solids


@numba.njit(cache=True)
def _fill_polygons(occ, ox, oy, res, xy, start):
    """Mark the cells whose centre lies inside each polygon (even-odd rule, half-open edges).

    Polygon p has vertices ``xy[start[p]:start[p+1]]``; each is filled by scanlines through
    the cell centres over its bounding box only.
    """
    h, w = occ.shape
    for p in range(start.shape[0] - 1):
        a = start[p]
        n = start[p + 1] - a
        if n < 3:
            continue
        ymin = xy[a, 1]
        ymax = xy[a, 1]
        for k in range(a, a + n):
            ymin = min(ymin, xy[k, 1])
            ymax = max(ymax, xy[k, 1])
        r0 = max(0, int(math.ceil((ymin - oy) / res - 0.5)))
        r1 = min(h - 1, int(math.floor((ymax - oy) / res - 0.5)))
        xs = np.empty(n)
        for r in range(r0, r1 + 1):
            yc = oy + (r + 0.5) * res
            m = 0
            for k in range(n):
                x0, y0 = xy[a + k, 0], xy[a + k, 1]
                k1 = a + (k + 1) % n
                x1, y1 = xy[k1, 0], xy[k1, 1]
                if (y0 <= yc < y1) or (y1 <= yc < y0):
                    xs[m] = x0 + (yc - y0) * (x1 - x0) / (y1 - y0)
                    m += 1
            if m < 2:
                continue
            cross = np.sort(xs[:m])
            for q in range(0, m - 1, 2):
                c0 = max(0, int(math.ceil((cross[q] - ox) / res - 0.5)))
                c1 = min(w, int(math.ceil((cross[q + 1] - ox) / res - 0.5)))
                for c in range(c0, c1):
                    occ[r, c] = 1


@numba.njit(cache=True)
def _fill_circles(occ, ox, oy, res, circles):
    """Mark the cells whose centre lies inside each circle, and the cell holding its centre."""
    h, w = occ.shape
    for k in range(circles.shape[0]):
        cx, cy, rad = circles[k, 0], circles[k, 1], circles[k, 2]
        r0 = max(0, int(math.ceil((cy - rad - oy) / res - 0.5)))
        r1 = min(h - 1, int(math.floor((cy + rad - oy) / res - 0.5)))
        for r in range(r0, r1 + 1):
            dy = oy + (r + 0.5) * res - cy
            if dy * dy > rad * rad:
                continue
            half = math.sqrt(rad * rad - dy * dy)
            c0 = max(0, int(math.ceil((cx - half - ox) / res - 0.5)))
            c1 = min(w, int(math.ceil((cx + half - ox) / res - 0.5)))
            for c in range(c0, c1):
                occ[r, c] = 1
        cr = int(math.floor((cy - oy) / res))
        cc = int(math.floor((cx - ox) / res))
        if 0 <= cr < h and 0 <= cc < w:
            occ[cr, cc] = 1


@numba.njit(cache=True)
def _mark_lines(occ, ox, oy, res, lines):
    """Mark every cell each segment passes through (a 4-connected grid traversal).

    A segment ending exactly on a cell boundary does not mark the cell beyond it.
    """
    h, w = occ.shape
    for k in range(lines.shape[0]):
        x0, y0, x1, y1 = lines[k, 0], lines[k, 1], lines[k, 2], lines[k, 3]
        dx = x1 - x0
        dy = y1 - y0
        u0 = (x0 - ox) / res
        v0 = (y0 - oy) / res
        u1 = (x1 - ox) / res
        v1 = (y1 - oy) / res
        ix = int(math.floor(u0)) if dx >= 0 else int(math.ceil(u0)) - 1
        iy = int(math.floor(v0)) if dy >= 0 else int(math.ceil(v0)) - 1
        ex = int(math.ceil(u1)) - 1 if dx > 0 else int(math.floor(u1))
        ey = int(math.ceil(v1)) - 1 if dy > 0 else int(math.floor(v1))
        if dx > 0:
            ex = max(ex, ix)
        elif dx < 0:
            ex = min(ex, ix)
        if dy > 0:
            ey = max(ey, iy)
        elif dy < 0:
            ey = min(ey, iy)
        sx, sy, tx, ty, tdx, tdy = dda_steps(ix, iy, x0, y0, dx, dy, ox, oy, res)
        steps = abs(ex - ix) + abs(ey - iy)
        if 0 <= iy < h and 0 <= ix < w:
            occ[iy, ix] = 1
        for _ in range(steps):
            if (tx < ty and ix != ex) or iy == ey:
                ix += sx
                tx += tdx
            else:
                iy += sy
                ty += tdy
            if 0 <= iy < h and 0 <= ix < w:
                occ[iy, ix] = 1


def truth_occupancy(world: World) -> tuple[GridSpec, np.ndarray]:
    """The truth grid over ``world.bounds`` and its occupancy (H, W) uint8, 1 = occupied.

    A cell is occupied when a solid (wall piece, box, polygon, circle, occupied floor-plan
    pixel) covers its centre. Shapes thinner than a cell's diagonal also mark every cell their
    centre line crosses, a circle the cell holding its centre and a floor-plan pixel the cell
    holding the pixel's centre, so thin solids leave no gaps.
    """
    grid = GridSpec.covering(*world.bounds, world.truth_resolution)
    occ = np.zeros(grid.shape, dtype=np.uint8)
    ox, oy, res = grid.origin_x, grid.origin_y, grid.resolution
    solids = world_solids(world, res)
    if solids.polygons:
        xy = np.ascontiguousarray(np.concatenate([p for p, _ in solids.polygons]), dtype=np.float64)
        start = np.concatenate([[0], np.cumsum([len(p) for p, _ in solids.polygons])]).astype(np.int64)
        _fill_polygons(occ, ox, oy, res, xy, start)
    if solids.circles:
        _fill_circles(occ, ox, oy, res, np.array([c[:3] for c in solids.circles], dtype=np.float64))
    if len(solids.centre_lines):
        _mark_lines(occ, ox, oy, res, solids.centre_lines)
    if world.floorplan is not None:
        rosmap = world.floorplan.plan
        _mark_bitmap(occ, grid, np.asarray(rosmap.data) == 100, rosmap.grid_spec())
    return grid, occ


def _mark_bitmap(occ: np.ndarray, grid: GridSpec, occupied: np.ndarray, fgrid: GridSpec) -> None:
    """Mark truth cells whose centre lies in an occupied pixel, and cells holding an occupied pixel's centre."""
    xs = grid.origin_x + (np.arange(grid.width) + 0.5) * grid.resolution
    ys = grid.origin_y + (np.arange(grid.height) + 0.5) * grid.resolution
    fc = np.floor((xs - fgrid.origin_x) / fgrid.resolution).astype(np.int64)
    fr = np.floor((ys - fgrid.origin_y) / fgrid.resolution).astype(np.int64)
    cols = np.flatnonzero((fc >= 0) & (fc < fgrid.width))
    rows = np.flatnonzero((fr >= 0) & (fr < fgrid.height))
    if cols.size and rows.size:
        sub = occupied[np.ix_(fr[rows], fc[cols])]
        occ[np.ix_(rows, cols)] |= sub.astype(np.uint8)
    pr, pc = np.nonzero(occupied)
    if pr.size:
        x, y = fgrid.cell_centre(pr, pc)
        r, c = grid.world_to_cell(x, y)
        inside = grid.contains(r, c)
        occ[r[inside], c[inside]] = 1
