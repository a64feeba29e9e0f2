"""A sweep's row: the readings active at grid row r (``_advance``), each one's cells in that row as a
``RowSpan`` of its template, listed under the column segments they reach (``_list_segments``), and
whether anything a row's readings see changed since the row was last visited (``_row_unchanged``)."""

from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np

from aogm_cli.mapping.em_kernels.layout import SEGMENT, _trailing_zeros


@numba.njit(cache=True, inline="always")
def _isqrt(n):
    """The largest o >= 0 with o * o <= n (-1 for n < 0), exactly."""
    if n < 0:
        return np.int64(-1)
    o = np.int64(math.sqrt(float(n)))
    while o * o > n:
        o -= 1
    while (o + 1) * (o + 1) <= n:
        o += 1
    return o


class RowSpan(NamedTuple):
    """One reading's cone in one grid row: the cell at offset o has column col0 + sign * o."""

    kind: int
    first: int
    o_first: int
    sign: int
    o_lo: int  # the cone's cells: o_lo <= o <= o_hi
    o_hi: int
    f_lo: int  # those before the window: f_lo <= o <= f_hi (f_hi < f_lo: none)
    f_hi: int


# TileWork.spans: a listed reading's RowSpan in the row, the reading t and the columns lo..hi it is listed for
SPAN = np.dtype([(name, np.int64) for name in (*RowSpan._fields, "t", "lo", "hi")], align=True)


@numba.njit(cache=True, inline="always")
def _row_span(tpl, groups, rd, t, r):
    """``RowSpan`` of reading t's cone in grid row r (o_hi < o_lo: none there)."""
    k, b = rd.bin[t], tpl.base_bin[rd.bin[t]]
    if tpl.transform[k, 2] == 0:  # drow = d dr, dcol = a dc: the row's group is the stored bin's row dr
        kind, gv, sign = 0, (r - rd.row0[t]) * tpl.transform[k, 3], tpl.transform[k, 0]
    else:  # drow = c dc, dcol = b dr: its column dc
        kind, gv, sign = 1, (r - rd.row0[t]) * tpl.transform[k, 2], tpl.transform[k, 1]
    ext = tpl.extent
    if gv < -ext or gv > ext or rd.m[t] == 0:
        return RowSpan(0, 0, 0, 1, 1, 0, 1, 0)
    rows, at = groups.rows, gv + ext
    if rows[kind, b, at, 1] == 0:
        return RowSpan(0, 0, 0, 1, 1, 0, 1, 0)
    first = np.int64(rows[kind, b, at, 0])
    o_first = np.int64(rows[kind, b, at, 2])
    o_last = np.int64(rows[kind, b, at, 3])
    # entries < m (or < jlo) are the row's cells with o^2 <= reach2 - gv^2, exactly
    v = _isqrt(rd.reach2[0, t] - gv * gv)
    if v < 0:
        return RowSpan(0, 0, 0, 1, 1, 0, 1, 0)
    f = min(_isqrt(rd.reach2[1, t] - gv * gv), v)
    h_lo = max(o_first, np.int64(rows[kind, b, at, 4]))  # the heard run (``ConeTemplates.heard``)
    h_hi = min(o_last, np.int64(rows[kind, b, at, 5]))
    return RowSpan(kind, first, o_first, sign, max(h_lo, -v), min(h_hi, v), max(h_lo, -f), min(h_hi, f))


@numba.njit(cache=True, inline="always")
def _o_range(span, col0, c0, c1, lo, hi):
    """The o of [lo, hi] whose columns lie in [c0, c1)."""
    if span.sign > 0:
        return max(lo, c0 - col0), min(hi, c1 - 1 - col0)
    return max(lo, col0 - c1 + 1), min(hi, col0 - c0)


@numba.njit(cache=True, inline="always")
def _advance(extent, rd, state, work, r):
    """The active bit set at row r. A reading's arena slot is dropped when it enters (a slot left by
    another band's sweep points into that sweep's arena), leaves, and when the sweep is past its window."""
    ctl = work.ctl[0]
    active = work.active
    members = work.members
    n_read = members.shape[0]
    e = ctl.enter
    while e < n_read and extent[members[work.enter[e]], 0] <= r:
        i = work.enter[e]
        active[i >> 6] |= np.uint64(1) << np.uint64(i & 63)
        state.slot[members[i]] = -1
        e += 1
    ctl.enter = e
    k = ctl.leave
    while k < n_read and extent[members[work.leave[k]], 1] < r:
        i = work.leave[k]
        active[i >> 6] &= ~(np.uint64(1) << np.uint64(i & 63))
        state.slot[members[i]] = -1
        k += 1
    ctl.leave = k
    k = ctl.window_leave
    while k < n_read and rd.window_hi[members[work.window_leave[k]]] < r:
        state.slot[members[work.window_leave[k]]] = -1
        k += 1
    ctl.window_leave = k


@numba.njit(cache=True, inline="always")
def _active_words(work):
    """The words of the active bit set the band's readings use (the set is sized for all)."""
    return (work.members.shape[0] + 63) >> 6


@numba.njit(cache=True, inline="always")
def _span_at(work, k):
    """The ``RowSpan`` stored at ``work.spans[k]``."""
    e = work.spans[k]
    return RowSpan(e.kind, e.first, e.o_first, e.sign, e.o_lo, e.o_hi, e.f_lo, e.f_hi)


@numba.njit(cache=True, inline="always")
def _span_mask(lo, hi, s):
    """Bits of columns lo..hi within segment s (bit k: column s * SEGMENT + k)."""
    a = max(lo - s * SEGMENT, 0)
    b = min(hi - s * SEGMENT, SEGMENT - 1)
    if a > b:
        return np.int64(0)
    return ((np.int64(1) << np.int64(b - a + 1)) - 1) << np.int64(a)


@numba.njit(cache=True, inline="always")
def _list_segments(tpl, groups, extent, rd, cand, work, r, n_seg):
    """The row's active readings with their ``RowSpan`` in ``spans``, and each segment's in seg_ptr /
    seg_list, where their cone holds a candidate. False (size needed in ctl) when a buffer is too small."""
    active = work.active
    members = work.members
    seg_ptr = work.seg_ptr
    fill = work.seg_fill
    sp = work.spans
    mask = work.seg_mask
    ctl = work.ctl[0]
    width = cand.of_cell.shape[0] // cand.tile_clock.shape[0]
    for s in range(n_seg + 1):
        seg_ptr[s] = 0
    for s in range(n_seg):
        mask[s] = 0
    c_lo, c_hi = _band_columns(work, width)
    for c in range(cand.row_first[r], cand.row_first[r + 1]):
        col = cand.cell[c] - r * width
        if c_lo <= col < c_hi:
            mask[col // SEGMENT] |= np.int64(1) << np.int64(col % SEGMENT)
    n = 0
    visited = 0
    for wi in range(_active_words(work)):
        word = active[wi]
        while word != np.uint64(0):
            t = members[(wi << 6) + np.int64(_trailing_zeros(word))]
            word &= word - np.uint64(1)
            visited += 1
            span = _row_span(tpl, groups, rd, t, r)
            if span.o_hi >= span.o_lo:
                col0 = rd.col0[t]
                if span.sign > 0:
                    lo, hi = col0 + span.o_lo, col0 + span.o_hi
                else:
                    lo, hi = col0 - span.o_hi, col0 - span.o_lo
                lo, hi = max(lo, extent[t, 2], c_lo), min(hi, extent[t, 3], c_hi - 1)
                if lo <= hi:
                    if n >= sp.shape[0]:
                        ctl.need_list = max(ctl.need_list, 2 * sp.shape[0])
                        return False
                    e = sp[n]
                    e.kind, e.first, e.o_first, e.sign = span.kind, span.first, span.o_first, span.sign
                    e.o_lo, e.o_hi, e.f_lo, e.f_hi = span.o_lo, span.o_hi, span.f_lo, span.f_hi
                    e.t = t
                    e.lo, e.hi = lo, hi
                    listed = False
                    for s in range(lo // SEGMENT, hi // SEGMENT + 1):
                        if _span_mask(lo, hi, s) & mask[s]:
                            seg_ptr[s + 1] += 1
                            listed = True
                    if listed:
                        n += 1
    ctl.budget -= _active_words(work) + 2 * visited  # a listed reading costs about two window pairs
    for s in range(n_seg):
        seg_ptr[s + 1] += seg_ptr[s]
        fill[s] = seg_ptr[s]
    if seg_ptr[n_seg] > work.seg_list.shape[0]:
        ctl.need_list = max(ctl.need_list, seg_ptr[n_seg])
        return False
    for k in range(n):
        lo, hi = sp[k].lo, sp[k].hi
        for s in range(lo // SEGMENT, hi // SEGMENT + 1):
            if _span_mask(lo, hi, s) & mask[s]:
                work.seg_list[fill[s]] = k
                fill[s] += 1
    return True


@numba.njit(cache=True, inline="always")
def _band_columns(work, width):
    """The columns [c_lo, c_hi) of the band's tiles (ctl's sg_lo, sg_hi)."""
    ctl = work.ctl[0]
    return ctl.sg_lo * SEGMENT, min(ctl.sg_hi * SEGMENT, width)


@numba.njit(cache=True, inline="always")
def _row_unchanged(rd, cand, state, work, r):
    """True (and row r's candidates stamped scored) when no active reading changed since the row's last visit."""
    ctl = work.ctl[0]
    sg_lo, sg_hi = ctl.sg_lo, ctl.sg_hi
    since = cand.tile_clock[r, sg_lo]
    for s in range(sg_lo + 1, sg_hi):
        since = min(since, cand.tile_clock[r, s])
    if since < 0:
        return False
    active = work.active
    for wi in range(_active_words(work)):
        word = active[wi]
        while word != np.uint64(0):
            t = work.members[(wi << 6) + np.int64(_trailing_zeros(word))]
            word &= word - np.uint64(1)
            if state.stamp[t] > since:
                return False
    now = ctl.clock
    width = cand.of_cell.shape[0] // cand.tile_clock.shape[0]
    c_lo, c_hi = _band_columns(work, width)
    for c in range(cand.row_first[r], cand.row_first[r + 1]):
        if c_lo <= cand.cell[c] - r * width < c_hi:
            cand.stamp[c] = now
    for s in range(sg_lo, sg_hi):
        cand.tile_clock[r, s] = now
    return True
