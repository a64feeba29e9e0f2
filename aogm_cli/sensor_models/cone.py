"""Precomputed cone templates: which grid cells a sonar cone covers, in increasing range. The standard
mapper walks a template to apply the inverse model, EM finds its forward model's obstacles in range
order; ``reading_geometry`` places readings, ``cone_cells`` lists a reading's cells, ``range_search``."""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from typing import NamedTuple

import numba
import numpy as np

from aogm_cli.core.frames import sensor_poses
from aogm_cli.core.grid import GridSpec

TWO_PI = 2.0 * math.pi


class ConeArrays(NamedTuple):
    """A ``ConeTemplates`` as compiled kernels take it (``ConeTemplates.kernel_arrays``)."""

    offsets: np.ndarray  # (n_base + 1,) int64: stored bin b's entries are offsets[b]:offsets[b+1]
    dcol: np.ndarray  # (E,) int32: offsets in the stored bin's frame
    drow: np.ndarray  # (E,) int32
    ranges: np.ndarray  # (E,) float64, sorted within each stored bin
    base_bin: np.ndarray  # (n_bins,) int64: the stored bin of each heading bin
    transform: np.ndarray  # (n_bins, 4) int64: the lattice symmetry (a, b, c, d) of each heading bin
    range_index: np.ndarray  # (n_base, n_shells + 1) int64: see ``range_search``
    resolution: float  # m: the grid's cell size (and the shells' width of range_index)
    extent: int  # bound of |drow| and |dcol|
    heard: np.ndarray  # (E,) uint8: 1 where the sonar hears a surface (``heard.heard_templates``); empty: all


class FlatOffsets(NamedTuple):
    """Template offsets as flat index offsets for one grid width (``flat_offsets``)."""

    offsets: np.ndarray  # (4, E) int32: dr W + dc, dr W - dc, dc W + dr, dc W - dr per entry
    sel: np.ndarray  # (n_bins, 2) int64: per heading bin, which of the four, and its sign (+/-1)


NO_CUT = np.zeros(0, dtype=np.float32)  # ``ConeReadings.cut`` when no reading is cut
NO_CELLS = np.zeros(0, dtype=np.uint8)  # ``ConeTemplates.heard`` when every cell is heard


class ConeReadings(NamedTuple):
    """Readings as the compiled cone kernels take them: flat arrays of one length."""

    rows: np.ndarray  # the sensor's cell (int64; may lie outside the grid)
    cols: np.ndarray
    bins: np.ndarray  # heading bin (int64)
    z: np.ndarray  # the range (m; NaN or negative: no information, >= max_range: max-range reading)
    offset: np.ndarray  # the sensor's axis offset (m; see ``reading_geometry``)
    # the template range where a deflected beam stops (``surface.reading_shadows``; +inf: none);
    # empty: no reading is cut. Read by standard mapping only
    cut: np.ndarray


@dataclass(frozen=True, eq=False)
class ConeTemplates:
    """Cone templates in CSR form for the stored bins (0 .. n_bins/8), plus a per-bin symmetry:
    entries sorted by range (fields as ``ConeArrays``; quantisation: ``cone_build``)."""

    resolution: float
    beam_width: float
    reach: float
    n_bins: int
    offsets: np.ndarray  # (n_base + 1,) int64
    dcol: np.ndarray  # (E,) int32
    drow: np.ndarray  # (E,) int32
    ranges: np.ndarray  # (E,) float64
    bearings: np.ndarray  # (E,) float64
    base_bin: np.ndarray  # (n_bins,) int64
    transform: np.ndarray  # (n_bins, 4) int64
    extent: int
    range_index: np.ndarray  # (n_base, n_shells + 1) int64: entries with range < q * resolution
    # (E,) uint8: the cells whose surfaces the sonar hears (``heard.heard_templates``); empty: every cell.
    # EM, the exact inverse model and calibration leave the others out; the standard mapper draws them all
    heard: np.ndarray = field(default_factory=lambda: NO_CELLS)
    lobe: tuple[float, float] | None = None  # (lobe_deg, lobe_range) that ``heard`` was made of

    @property
    def kernel_arrays(self) -> ConeArrays:
        """The templates as compiled kernels take them."""
        return ConeArrays(self.offsets, self.dcol, self.drow, self.ranges, self.base_bin, self.transform,
                          self.range_index, float(self.resolution), int(self.extent), self.heard)

    def heading_bin(self, yaw):
        """Heading bin (int64 array) of each yaw (rad, any real): the bin whose centre is nearest."""
        k = np.floor(np.asarray(yaw, dtype=np.float64) * (self.n_bins / TWO_PI) + 0.5).astype(np.int64)
        return k % self.n_bins


@numba.njit(cache=True, inline="always")
def unheard(tpl, i):
    """True when template entry ``i`` is a cell the sonar does not hear (``ConeTemplates.heard``; empty: all heard):
    EM, the exact inverse model, calibration and the E-step leave it out of the reading."""
    return tpl.heard.shape[0] > 0 and tpl.heard[i] == 0


@numba.njit(cache=True)
def range_search(r, index_row, resolution, v, right):
    """Compiled ``np.searchsorted(r, v, side="right" if right else "left")``, narrowed by ``range_index``."""
    if not v >= 0.0:  # also NaN
        return 0
    # v lies in shell [qi, qi + 1) up to rounding: search shells qi - 1 .. qi + 1 to be safe
    last = index_row.size - 1
    qi = int(min(v / resolution, float(last)))
    lo = index_row[max(qi - 1, 0)]
    hi = index_row[qi + 2] if qi + 2 <= last else r.size
    while lo < hi:
        mid = (lo + hi) >> 1
        if r[mid] < v or (right and r[mid] == v):
            lo = mid + 1
        else:
            hi = mid
    return lo


@numba.njit(cache=True)
def cone_cells(tpl, height, width, row, col, k, limit, out_index, out_range, lower):
    """Compiled: write the grid cells of bin ``k``'s cone from cell (row, col), range from ``lower``
    (<= 0: all) to ``limit``, in range order, as flat indices to ``out_index`` and ranges to
    ``out_range`` (sized for the stored bin), cells off the grid left out. Returns how many."""
    offsets = tpl.offsets
    transform = tpl.transform
    b = tpl.base_bin[k]
    s = offsets[b]
    e = offsets[b + 1]
    ta = transform[k, 0]
    tb = transform[k, 1]
    tc = transform[k, 2]
    td = transform[k, 3]
    rng = tpl.ranges[s:e]
    dcs = tpl.dcol[s:e]
    drs = tpl.drow[s:e]
    first = np.searchsorted(rng, lower, side="left") if lower > 0.0 else 0  # the first entry at range >= lower
    n = 0
    for j in range(first, e - s):
        if rng[j] > limit:
            break
        dc = np.int64(dcs[j])
        dr = np.int64(drs[j])
        r = row + tc * dc + td * dr
        c = col + ta * dc + tb * dr
        if r < 0 or r >= height or c < 0 or c >= width:
            continue
        out_index[n] = r * width + c
        out_range[n] = rng[j]
        n += 1
    return n


def reading_geometry(pose: np.ndarray, sensor, grid: GridSpec, templates: ConeTemplates):
    """Each reading's sensor cell, heading bin, validity and axis offset, each (T, S). A pose that is
    not finite is invalid. Positions far off the grid are pulled in to just beyond the reach (they
    see no cell), so that indices never overflow. ``offset`` is the sensor's offset from its cell's
    centre along the beam (m; 0 when invalid): a reading z compares with template ranges at z + offset."""
    sp = sensor_poses(np.asarray(pose, dtype=np.float64).reshape(-1, 3), sensor.mount)
    xs, ys, yaws = sp[..., 0], sp[..., 1], sp[..., 2]
    valid = np.isfinite(sp).all(axis=-1)
    x_min, x_max, y_min, y_max = grid.extent
    pad = templates.reach + 2.0 * grid.resolution
    xs = np.clip(np.where(valid, xs, x_min - pad), x_min - pad, x_max + pad)
    ys = np.clip(np.where(valid, ys, y_min - pad), y_min - pad, y_max + pad)
    yaws = np.where(valid, yaws, 0.0)
    rows, cols = grid.world_to_cell(xs, ys)
    bins = templates.heading_bin(yaws)
    cx, cy = grid.cell_centre(rows, cols)
    offset = np.where(valid, (xs - cx) * np.cos(yaws) + (ys - cy) * np.sin(yaws), 0.0)
    return rows, cols, bins, valid, offset


@functools.lru_cache(maxsize=8)
def flat_offsets(templates: ConeTemplates, width: int) -> FlatOffsets:
    """Template offsets as flat index offsets on a grid ``width`` cells wide, without multiplies."""
    dc, dr = templates.dcol, templates.drow
    offs = np.empty((4, dc.size), dtype=np.int32)  # in int32 arithmetic: wraps as a cast from int64 would
    for i, (a, b) in enumerate(((dr, dc), (dc, dr))):
        np.multiply(a, np.int32(width), out=offs[2 * i])
        np.subtract(offs[2 * i], b, out=offs[2 * i + 1])
        offs[2 * i] += b
    # transform (a, b, c, d): dcol = a dc + b dr, drow = c dc + d dr; flat = drow W + dcol
    a, b, c, d = templates.transform.T
    from_dr = c == 0  # flat = d (dr W + (a/d) dc), else c (dc W + (b/c) dr)
    which = np.where(from_dr, np.where(a == d, 0, 1), np.where(b == c, 2, 3))
    sign = np.where(from_dr, d, c)
    sel = np.stack([which, sign], axis=1).astype(np.int64)
    offs.setflags(write=False)
    sel.setflags(write=False)
    return FlatOffsets(offs, sel)


# cone cells off the grid go to SPARE_MASK + 1 spare cells after it, in turn: their dummy updates
# form no long chain through one memory cell
SPARE_MASK = 255


@numba.njit(cache=True, inline="always")
def cone_flat_cells(ib, tpl, flat, k, m, row0, col0, height, width):
    """Compiled: the flat indices (int32) of the first ``m`` entries of heading bin ``k``'s cone
    from cell (row0, col0) into ``ib``, in template order; a cell off the grid gets a spare cell,
    height * width + (j & SPARE_MASK)."""
    ext = tpl.extent
    transform = tpl.transform
    s = tpl.offsets[tpl.base_bin[k]]
    base = row0 * width + col0
    x_off = flat.offsets[flat.sel[k, 0], s : s + m]
    positive = flat.sel[k, 1] > 0
    if row0 - ext >= 0 and row0 + ext < height and col0 - ext >= 0 and col0 + ext < width:
        if positive:
            for j in range(m):
                ib[j] = np.int32(base + x_off[j])
        else:
            for j in range(m):
                ib[j] = np.int32(base - x_off[j])
    else:  # near the border: the grid's bounds as bounds on the stored offsets (dc, dr)
        spare = height * width
        r_lo, r_hi = -row0, height - 1 - row0
        c_lo, c_hi = -col0, width - 1 - col0
        if transform[k, 2] != 0:  # drow = c dc, dcol = b dr
            dc_lo, dc_hi = (r_lo, r_hi) if transform[k, 2] > 0 else (-r_hi, -r_lo)
            dr_lo, dr_hi = (c_lo, c_hi) if transform[k, 1] > 0 else (-c_hi, -c_lo)
        else:  # drow = d dr, dcol = a dc
            dr_lo, dr_hi = (r_lo, r_hi) if transform[k, 3] > 0 else (-r_hi, -r_lo)
            dc_lo, dc_hi = (c_lo, c_hi) if transform[k, 0] > 0 else (-c_hi, -c_lo)
        dc = tpl.dcol[s : s + m]
        dr = tpl.drow[s : s + m]
        sign = 1 if positive else -1
        for j in range(m):
            inside = (dc[j] >= dc_lo) & (dc[j] <= dc_hi) & (dr[j] >= dr_lo) & (dr[j] <= dr_hi)
            ib[j] = np.int32(base + sign * x_off[j] if inside else spare + (j & SPARE_MASK))
