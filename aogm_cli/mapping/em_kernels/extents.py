"""Where each reading's cone lies: its template entries, bounding box and Gaussian window
rows (compiled; the set-up of ``mapping.em.em_readings``)."""

from __future__ import annotations

import numba
import numpy as np

from aogm_cli.mapping.em_kernels.layout import _columns
from aogm_cli.sensor_models.cone import unheard
from aogm_cli.sensor_models.forward_model import cone_entries


@numba.njit(cache=True, inline="always")
def _entry_row_col(tpl, s, tr, j, row0, col0):
    """Grid row and column of entry j of a cone from (row0, col0), inside the grid or not."""
    dc = np.int64(tpl.dcol[s + j])
    dr = np.int64(tpl.drow[s + j])
    return row0 + tr[2] * dc + tr[3] * dr, col0 + tr[0] * dc + tr[1] * dr


@numba.njit(cache=True, inline="always")
def _entry_cell(tpl, s, tr, j, row0, col0, height, width):
    """Flat cell of entry j of a cone from (row0, col0), or -1 outside the grid (``_entry_row_col``)."""
    r, c = _entry_row_col(tpl, s, tr, j, row0, col0)
    if r < 0 or r >= height or c < 0 or c >= width:
        return -1
    return r * width + c


@numba.njit(cache=True, inline="always")
def _extend_box(box, t, r, c):
    """Reading t's box (``box`` (R, 4): row_lo, row_hi, col_lo, col_hi) grown to hold cell (r, c)."""
    box[t, 0] = min(box[t, 0], r)
    box[t, 1] = max(box[t, 1], r)
    box[t, 2] = min(box[t, 2], c)
    box[t, 3] = max(box[t, 3], c)


@numba.njit(cache=True, inline="always")
def _bin_transform(tpl, k):
    """Heading bin k's transform of its stored bin's offsets, as ``_entry_cell`` takes it."""
    return (np.int64(tpl.transform[k, 0]), np.int64(tpl.transform[k, 1]), np.int64(tpl.transform[k, 2]),
            np.int64(tpl.transform[k, 3]))


@numba.njit(cache=True, nogil=True)
def _reading_extent(tpl, groups, readings, bounds, gauss, grid_shape, span):
    """Per reading in ``span``, into its fields: entries m, first entry at range >= ``lower`` (jlo), box, reach2."""
    rd, _ = _columns(readings)
    rows, cols, bins, z = rd.row0, rd.col0, rd.bin, rd.z
    limits, lower = bounds
    height, width = grid_shape
    out_m, out_jlo, out_box, out_reach2, out_inside = rd.m, rd.jlo, rd.box, rd.reach2, rd.inside
    for t in range(span[0], span[1]):
        k = bins[t]
        b = tpl.base_bin[k]
        s = tpl.offsets[b]
        r = tpl.ranges[s : tpl.offsets[b + 1]]
        m = cone_entries(r, z[t], limits[t], gauss[0], gauss[1])
        out_m[t] = m
        out_jlo[t] = np.searchsorted(r, lower[t], side="left") if lower[t] >= 0.0 else 0
        out_box[0, t] = height  # none
        out_box[1, t] = -1
        out_box[2, t] = width
        out_box[3, t] = -1
        out_reach2[0, t] = -1
        out_reach2[1, t] = -1
        out_inside[t] = 0
        if m == 0:
            continue
        # ranges are resolution * sqrt(dr^2 + dc^2) and distinct squares give distinct ranges
        out_reach2[0, t] = np.int64(tpl.drow[s + m - 1]) ** 2 + np.int64(tpl.dcol[s + m - 1]) ** 2
        jlo = out_jlo[t]
        if jlo > 0:
            out_reach2[1, t] = np.int64(tpl.drow[s + jlo - 1]) ** 2 + np.int64(tpl.dcol[s + jlo - 1]) ** 2
        dr_lo, dr_hi = groups.box[0, s + m - 1], groups.box[1, s + m - 1]
        dc_lo, dc_hi = groups.box[2, s + m - 1], groups.box[3, s + m - 1]
        ta, tb, tc, td = tpl.transform[k, 0], tpl.transform[k, 1], tpl.transform[k, 2], tpl.transform[k, 3]
        if tc == 0:  # drow = td dr, dcol = ta dc
            r_lo, r_hi = (dr_lo, dr_hi) if td > 0 else (-dr_hi, -dr_lo)
            c_lo, c_hi = (dc_lo, dc_hi) if ta > 0 else (-dc_hi, -dc_lo)
        else:  # drow = tc dc, dcol = tb dr
            r_lo, r_hi = (dc_lo, dc_hi) if tc > 0 else (-dc_hi, -dc_lo)
            c_lo, c_hi = (dr_lo, dr_hi) if tb > 0 else (-dr_hi, -dr_lo)
        r_lo, r_hi, c_lo, c_hi = rows[t] + r_lo, rows[t] + r_hi, cols[t] + c_lo, cols[t] + c_hi
        out_inside[t] = 1 if r_lo >= 0 and r_hi < height and c_lo >= 0 and c_hi < width else 0
        r_lo, r_hi = max(r_lo, 0), min(r_hi, height - 1)
        c_lo, c_hi = max(c_lo, 0), min(c_hi, width - 1)
        if r_lo > r_hi or c_lo > c_hi:
            continue
        out_box[0, t] = r_lo
        out_box[1, t] = r_hi
        out_box[2, t] = c_lo
        out_box[3, t] = c_hi


@numba.njit(cache=True, nogil=True)
def _window_rows(tpl, readings, height, span):
    """Each reading's last grid row of window cells (entries jlo .. m - 1; -1: none), into ``window_hi``."""
    rd, _ = _columns(readings)
    out = rd.window_hi
    for t in range(span[0], span[1]):
        k = rd.bin[t]
        s0 = tpl.offsets[tpl.base_bin[k]]
        tc, td = tpl.transform[k, 2], tpl.transform[k, 3]
        hi = np.int64(-1)
        for j in range(rd.jlo[t], rd.m[t]):
            hi = max(hi, rd.row0[t] + tc * np.int64(tpl.dcol[s0 + j]) + td * np.int64(tpl.drow[s0 + j]))
        out[t] = min(hi, height - 1)


@numba.njit(cache=True, nogil=True)
def _far_gains(tpl, readings, grid_shape, of_cell, span, out):
    """Add each reading's ``far_log[t, 0]`` to the gain of every candidate (``of_cell``) before its window."""
    rd, state = _columns(readings)
    height, width = grid_shape
    for t in range(span[0], span[1]):
        k = rd.bin[t]
        s = tpl.offsets[tpl.base_bin[k]]
        tr = _bin_transform(tpl, k)
        v = state.far_log[t, 0]
        for j in range(0, min(rd.jlo[t], rd.m[t])):
            if unheard(tpl, s + j):  # no part of the reading
                continue
            c = _entry_cell(tpl, s, tr, j, np.int64(rd.row0[t]), np.int64(rd.col0[t]), height, width)
            if c >= 0 and of_cell[c] >= 0:
                out[of_cell[c]] += v


@numba.njit(cache=True, nogil=True)
def _box_of_cells(tpl, readings, grid_shape, mask, span, box):
    """Into ``box`` (R, 4): the bounds of each reading's cone cells that ``mask`` marks."""
    rd, _ = _columns(readings)
    height, width = grid_shape
    for t in range(span[0], span[1]):
        box[t, 0] = height
        box[t, 1] = -1
        box[t, 2] = width
        box[t, 3] = -1
        if rd.box[0, t] > rd.box[1, t]:
            continue
        k = rd.bin[t]
        s = tpl.offsets[tpl.base_bin[k]]
        tr = _bin_transform(tpl, k)
        row0, col0 = np.int64(rd.row0[t]), np.int64(rd.col0[t])
        for j in range(rd.m[t]):
            r, c = _entry_row_col(tpl, s, tr, j, row0, col0)
            if 0 <= r < height and 0 <= c < width and mask[r * width + c]:
                _extend_box(box, t, r, c)
