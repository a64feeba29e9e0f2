"""The sweep: candidates visited tile by tile (one grid row, SEGMENT columns), the active
readings listed per segment, their (candidate, reading) pairs generated from the templates,
each flip kept when it raises the objective (``_sweep_tiles``)."""


# How a tile works: readings whose cones cross row r are active there and list themselves under the
# segments they reach; a segment's (candidate, reading) pairs come from the templates, and each flip
# updates its readings' state. A reading's window obstacles (in range order, with prefix sums) are
# rebuilt into an arena when a tile needs them and dropped once the sweep is past the window.

from __future__ import annotations

import numba

from aogm_cli.mapping.em_kernels.layout import DONE, NEED_BUFFERS, PAUSED, SEGMENT, SWEEP, _columns
from aogm_cli.mapping.em_kernels.likelihood import _far_changed, _flip_gain, _set_sum, _update_reading
from aogm_cli.mapping.em_kernels.listing import (
    _active_words,
    _advance,
    _list_segments,
    _o_range,
    _row_unchanged,
    _span_at,
)
from aogm_cli.mapping.em_kernels.windows import _build_window, _make_room, _room
from aogm_cli.sensor_models.forward_model import gaussian_at


@numba.njit(cache=True, inline="always")
def _window_pairs(i, t, span, r, c0, c1, c_start, fill, tpl, groups, rd, model, cand, work):
    """Count (``fill`` False) or write reading t's window pairs in tile columns [c0, c1) of row r."""
    width = cand.of_cell.shape[0] // cand.tile_clock.shape[0]
    col0 = rd.col0[t]
    at = r * width + col0
    gj = groups.j[span.kind]
    s0 = tpl.offsets[tpl.base_bin[rd.bin[t]]]
    n = 0
    for side in range(2):
        if span.f_lo > span.f_hi:  # no far run: one run, the whole cone row
            if side == 1:
                break
            lo, hi = span.o_lo, span.o_hi
        elif side == 0:
            lo, hi = span.o_lo, span.f_lo - 1
        else:
            lo, hi = span.f_hi + 1, span.o_hi
        lo, hi = _o_range(span, col0, c0, c1, lo, hi)
        for o in range(lo, hi + 1):
            ci = cand.of_cell[at + span.sign * o]
            if ci < 0:
                continue
            n += 1
            local = ci - c_start
            if not fill:
                work.count[local + 1] += 1
                continue
            j = gj[span.first + o - span.o_first]
            pos = work.count[local]
            work.count[local] = pos + 1
            work.pair_pos[pos] = i
            work.pair_j[pos] = j
            work.pair_g[pos] = gaussian_at(rd.z[t], tpl.ranges[s0 + j], model.sigma, model.window)
    return n


@numba.njit(cache=True, inline="always")
def _count_pairs(tpl, groups, rd, model, cand, state, work, r, c0, c1, c_start, list_lo, list_hi, nc):
    """The tile's listing: far runs into ``far_sum``, window pairs counted; (pairs, arena entries needed)."""
    cnt = work.count
    for i in range(nc + 1):
        cnt[i] = 0
    for k in range(SEGMENT + 1):
        work.far_sum[0, k] = 0.0
        work.far_sum[1, k] = 0.0
    room = 0
    n_pairs = 0
    for i in range(list_lo, list_hi):
        span = _span_at(work, work.seg_list[i])
        t = work.spans[work.seg_list[i]].t
        li = i - list_lo
        work.tile_t[li] = t
        work.far_lo[li] = 1
        work.far_hi[li] = 0
        if span.o_hi < span.o_lo:
            continue
        f_lo, f_hi = _o_range(span, rd.col0[t], c0, c1, span.f_lo, span.f_hi)
        if f_lo <= f_hi:
            col0 = rd.col0[t]
            a, b = (col0 + f_lo, col0 + f_hi) if span.sign > 0 else (col0 - f_hi, col0 - f_lo)
            work.far_lo[li] = a - c0
            work.far_hi[li] = b - c0
            work.far_sum[0, a - c0] += state.far_log[t, 0]
            work.far_sum[0, b - c0 + 1] -= state.far_log[t, 0]
            work.far_sum[1, a - c0] += state.far_log[t, 1]
            work.far_sum[1, b - c0 + 1] -= state.far_log[t, 1]
        k = _window_pairs(li, t, span, r, c0, c1, c_start, False, tpl, groups, rd, model, cand, work)
        n_pairs += k
        if k > 0 and state.slot[t] < 0:
            room += _room(rd, t)
    for i in range(1, nc + 1):
        cnt[i] += cnt[i - 1]
    return n_pairs, room


@numba.njit(cache=True, inline="always")
def _flip(c, x, lo_pair, hi_pair, n_list, rd, model, cand, state, work):
    """Flip candidate c (tile column x) and update the tile's readings that hold it."""
    ctl = work.ctl[0]
    occupied = cand.occupied
    cell = cand.cell[c]
    occupied[cell] = not occupied[cell]
    cand.last_gain[c] = -cand.last_gain[c]  # flipping back undoes exactly this gain
    ctl.flips += 1
    ctl.clock += 1
    ctl.budget -= n_list + hi_pair - lo_pair
    adding = occupied[cell]
    now = ctl.clock
    for i in range(n_list):  # the readings that hold the cell before their windows
        if work.far_lo[i] <= x <= work.far_hi[i]:
            t = work.tile_t[i]
            old_add, old_rem = state.far_log[t, 0], state.far_log[t, 1]
            state.nfar[t] += 1 if adding else -1
            _set_sum(t, rd, model, state)
            _far_changed(i, t, x, old_add, old_rem, state, work)
            state.stamp[t] = now
    for p in range(lo_pair, hi_pair):
        i = work.pair_pos[p]
        t = work.tile_t[i]
        old_add, old_rem = state.far_log[t, 0], state.far_log[t, 1]
        _update_reading(t, work.pair_j[p], work.pair_g[p], adding, model, rd, state, work)
        _far_changed(i, t, x, old_add, old_rem, state, work)
        state.stamp[t] = now


@numba.njit(cache=True, inline="always")
def _visit(c, x, lo_pair, hi_pair, n_list, mode, tpl, flat, rd, model, cand, state, work):
    """Score candidate c into ``last_gain``; in SWEEP mode flip it when that raises the objective."""
    ctl = work.ctl[0]
    for p in range(lo_pair, hi_pair):
        t = work.tile_t[work.pair_pos[p]]
        if work.pair_g[p] != 0.0 and state.slot[t] < 0:
            _build_window(t, tpl, flat, rd, model, cand, state, work)
            ctl.budget -= _room(rd, t)
    ctl.scored += 1
    d = _flip_gain(c, x, lo_pair, hi_pair, rd, model, cand, state, work)
    cand.last_gain[c] = d
    if mode != SWEEP:
        return
    d += -model.l_prior if cand.occupied[cand.cell[c]] else model.l_prior
    if d > 1e-9:
        _flip(c, x, lo_pair, hi_pair, n_list, rd, model, cand, state, work)
    cand.stamp[c] = ctl.clock


@numba.njit(cache=True, inline="always")
def _tile(r, sg, c_start, c_stop, tpl, flat, groups, rd, model, cand, state, work):
    """Tile (r, sg): its candidates scored (and flipped, ``_visit``); skipped when none of its readings
    changed since its last visit (SWEEP). False, before any change, when the scratch is too small."""
    ctl = work.ctl[0]
    mode = ctl.mode
    width = cand.of_cell.shape[0] // cand.tile_clock.shape[0]
    c0 = sg * SEGMENT
    c1 = min(c0 + SEGMENT, width)
    list_lo = work.seg_ptr[sg]
    list_hi = work.seg_ptr[sg + 1]
    ctl.budget -= list_hi - list_lo
    clock0 = ctl.clock
    since = cand.tile_clock[r, sg] if mode == SWEEP else -1
    if since >= 0:  # skipped, its candidates stamped scored, when none of its readings changed since
        clean = True
        for i in range(list_lo, list_hi):
            if state.stamp[work.spans[work.seg_list[i]].t] > since:
                clean = False
                break
        if clean:
            for c in range(c_start, c_stop):
                cand.stamp[c] = clock0
            cand.tile_clock[r, sg] = clock0
            return True
    nc = c_stop - c_start
    n_list = list_hi - list_lo
    if n_list > work.far_lo.shape[0]:
        ctl.need_list = max(ctl.need_list, n_list)
        return False
    n_pairs, room = _count_pairs(tpl, groups, rd, model, cand, state, work, r, c0, c1, c_start, list_lo, list_hi, nc)
    if n_pairs > work.pair_pos.shape[0] or not _make_room(rd, state, work, room):
        ctl.need_pairs = n_pairs
        return False
    ctl.pairs += n_pairs
    ctl.budget -= n_pairs + 8 * nc
    for i in range(list_lo, list_hi):  # the window pairs counted, each candidate's in reading order
        span = _span_at(work, work.seg_list[i])
        if span.o_hi >= span.o_lo:
            _window_pairs(i - list_lo, work.spans[work.seg_list[i]].t, span, r, c0, c1, c_start, True, tpl, groups, rd,
                          model, cand, work)
    cnt = work.count
    for c in range(c_start, c_stop):
        li = c - c_start
        _visit(c, cand.cell[c] - r * width - c0, 0 if li == 0 else cnt[li - 1], cnt[li], n_list, mode, tpl, flat, rd,
               model, cand, state, work)
    if mode == SWEEP:
        cand.tile_clock[r, sg] = clock0
    return True


# _nrt=False: the sweep allocates nothing, and without reference counting its arrays cost nothing per call
@numba.njit(cache=True, _nrt=False, nogil=True)
def _sweep_tiles(tpl, flat, groups, readings, model, cand, work):
    """One pass over a band's candidates (segments ctl.sg_lo to ctl.sg_hi) in flat-id order, tile by
    tile; bands no reading joins may be swept at once, on threads. ctl.mode SWEEP keeps each flip
    that raises the objective, SCORE scores every candidate and flips none. Rows and tiles whose
    readings did not change since their last visit are skipped: the result equals a full sweep's.
    Starts at (ctl.row, ctl.seg); returns NEED_BUFFERS (sizes in ctl) when the scratch is too small,
    PAUSED once ctl.budget (in window pairs) is spent, else DONE; the caller grows or refills and
    calls again, and the pass resumes there. Where it pauses changes nothing."""
    rd, state = _columns(readings)
    ctl = work.ctl[0]
    height, n_seg = cand.tile_clock.shape
    width = cand.of_cell.shape[0] // height
    fresh = True  # nothing done yet in this call: no pause
    for r in range(ctl.row, height):
        ca = cand.row_first[r]
        cb = cand.row_first[r + 1]
        if ca == cb:
            continue
        if ctl.seg == 0 and ctl.budget <= 0 and not fresh:
            ctl.row = r
            return PAUSED
        ctl.row = r
        _advance(readings.extent, rd, state, work, r)
        if ctl.mode == SWEEP and ctl.seg == 0:
            ctl.budget -= _active_words(work)
            if _row_unchanged(rd, cand, state, work, r):
                fresh = False
                continue
        if ctl.listed != r:  # else listed before a pause, and still so
            if not _list_segments(tpl, groups, readings.extent, rd, cand, work, r, n_seg):
                return NEED_BUFFERS
            ctl.listed = r
        c_pos = ca
        row_base = r * width
        for sg in range(max(ctl.seg, ctl.sg_lo), ctl.sg_hi):
            c0 = sg * SEGMENT
            c1 = min(c0 + SEGMENT, width)
            while c_pos < cb and cand.cell[c_pos] < row_base + c0:
                c_pos += 1
            c_start = c_pos
            while c_pos < cb and cand.cell[c_pos] < row_base + c1:
                c_pos += 1
            if c_start == c_pos:
                continue
            if ctl.budget <= 0 and not fresh:
                ctl.seg = sg
                return PAUSED
            fresh = False
            if not _tile(r, sg, c_start, c_pos, tpl, flat, groups, rd, model, cand, state, work):
                ctl.seg = sg
                return NEED_BUFFERS
        ctl.seg = 0
    return DONE
