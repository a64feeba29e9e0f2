"""The compiled kernels of EM mapping (``mapping.em``) in bounded memory: each reading's
likelihood state in a few scalars, its cone cells regenerated from the templates row by row,
and the sweeps of single-cell flips run over tiles (one grid row, a few columns) in row-major
order, so that no array holds the (reading, cone cell) pairs of the whole log.

Pure functions on arrays, grouped into named tuples by meaning: the templates grouped by row
(``RowGroups``), the readings (``EMReadings``), the model's constants (``EMModel``), the
readings' state (``EMState``), the candidates (``Candidates``) and the tiles' scratch
(``TileWork``). ``mapping.em`` lays out their inputs and drives the sweeps.

How a tile works. The readings whose cones cross grid row r are *active* at r (a bit set,
updated as r grows); each lists itself under the column segments its cone's row-r cells can
reach. For one segment, the (candidate, reading) pairs are generated from the templates
(reading order within each candidate, as the sweep needs them), the candidates are visited
in order and each flip updates its readings' state. The obstacles of a reading inside its
Gaussian window (which a flip's score needs in range order, with prefix sums) are rebuilt
from the map into an arena when a tile first needs them and dropped once the sweep passes
the window's last row (or the arena reaches its cap); what a reading keeps otherwise is S_t,
the window's sum, its obstacle counts and the ratios of adding or removing a far obstacle.
"""

from __future__ import annotations

import functools
import math
from typing import NamedTuple

import numba
import numpy as np
from llvmlite import ir
from numba import types
from numba.extending import intrinsic

from aogm_cli.mapping.sensor_models.forward_model import cone_entries, gaussian_at

SWEEP = 0  # TileWork.ctl[CTL_MODE]: flip candidates that raise the objective
SCORE = 1  # score every candidate once (the residual pass), flip none
SEGMENT = 32  # columns per tile
# the window arena's largest size (entries of 24 bytes: 96 MB); beyond it slots are dropped
# and rebuilt (a slot lives while the sweep crosses its reading's window rows)
ARENA_ENTRIES = 1 << 22

# columns of EMReadings.ints and .floats (the readings, then their EMState and arena slot)
I_ROW0, I_COL0, I_BIN, I_M, I_JLO, I_REACH2, I_BOX, I_NOBS, I_NFAR, I_STAMP, I_SLOT, I_INSIDE, I_WINDOW_HI, INTS = (
    0, 1, 2, 3, 4, 5, 7, 11, 12, 13, 14, 15, 16, 17)
F_Z, F_G0, F_CONST, F_S, F_WSUM, F_RATIO, F_LOG, FLOATS = 0, 1, 2, 3, 4, 5, 7, 9

# TileWork.ctl slots
CTL_MODE, CTL_ROW, CTL_SEG = 0, 1, 2
CTL_NEED_LIST, CTL_NEED_PAIRS, CTL_NEED_ROOM = 3, 4, 5
CTL_ENTER, CTL_LEAVE, CTL_CLOCK, CTL_FLIPS, CTL_SCORED, CTL_PAIRS = 6, 7, 8, 9, 10, 11
CTL_BUMP, CTL_WINDOW_LEAVE = 12, 13
CTL_BUDGET, CTL_LISTED = 14, 15
CTL_SIZE = 16
DONE, NEED_BUFFERS, PAUSED = 0, 1, 2
# the work (in window pairs: see _sweep_tiles) after which a sweep pauses, so that the caller is
# back in Python, where a signal's handler runs, many times a second: on the 50k-scan office a
# call took 0.04 s (median; 0.1 s at the 99th percentile, 0.2 s at most: a tile is not divided)
PAUSE_WORK = 1 << 21


class RowGroups(NamedTuple):
    """Each stored template bin's entries grouped by one offset coordinate and sorted by the
    other (``row_groups``): ``kind`` 0 groups by dr (listing dc), 1 by dc (listing dr).

    A heading bin whose symmetry takes drow from dr uses kind 0, one that takes it from dc
    kind 1; either way a group is the cone's cells in one grid row, by column."""

    ptr: np.ndarray  # (2, n_base, 2 ext + 2) int64: group v's entries ptr[kind, b, v + ext]:..[v + ext + 1]
    j: np.ndarray  # (2, E) int32: entry index within its stored bin (range order)
    other: np.ndarray  # (2, E) int32: the other offset, ascending within a group
    lo: np.ndarray  # (2, n_base, 2 ext + 1) int32: least other offset of each group
    hi: np.ndarray  # (2, n_base, 2 ext + 1) int32: greatest
    zero: np.ndarray  # (2, n_base, 2 ext + 1) int64: each group's first entry with other offset >= 0
    box: np.ndarray  # (4, E) int32: min dr, max dr, min dc, max dc over a bin's entries 0..j


class EMReadings(NamedTuple):
    """The readings of an EM problem (arrays of one length, ``em.em_readings``).

    Every field is a column of two row-per-reading tables, ``ints`` and ``floats``, which
    also hold each reading's ``EMState``: what the tiles need of one reading shares a cache
    line or two, whichever pass of the robot it came from.
    """

    row0: np.ndarray  # int32 sensor cell (may lie outside the grid)
    col0: np.ndarray
    bin: np.ndarray  # int32 heading bin
    z: np.ndarray  # float64 range in template ranges (max-range readings: z_max)
    g0: np.ndarray  # float64 G0_t
    const: np.ndarray  # float64 C_t
    m: np.ndarray  # int32 template entries of the (truncated) cone
    jlo: np.ndarray  # int32 first entry that may lie inside the Gaussian window
    box: np.ndarray  # (4, R) int32 row_lo, row_hi, col_lo, col_hi of the cone in the grid (row_lo > row_hi: none)
    reach2: np.ndarray  # (2, R) int32 the cone's cells have dr^2 + dc^2 <= reach2[0], those before the window <= reach2[1]
    inside: np.ndarray  # int32 1 when every cell of the cone lies inside the grid (flat offsets serve)
    window_hi: np.ndarray  # int32 the last grid row of the cone's window cells (-1: none)
    enter: np.ndarray  # int32 readings by row_lo (stable)
    leave: np.ndarray  # int32 readings by row_hi (stable)
    window_leave: np.ndarray  # int32 readings by window_hi (stable): their window slots are dropped past it
    ints: np.ndarray  # (R, INTS) int32 the table of the integer columns (I_*): cells, bins, template entries
    # (< 2^31 for any template), counts, arena slots (< ARENA_ENTRIES but for one huge tile) and
    # the clock of stamps (accepted flips, < 2^31)
    floats: np.ndarray  # (R, FLOATS) float64 the table of the real ones (F_*)


class EMModel(NamedTuple):
    """The constants of the objective."""

    p_hit: float  # detection probability of each obstacle in a cone (q = 1 - p_hit)
    l_prior: float  # log-odds of the occupancy prior, added per occupied candidate
    qpow: np.ndarray  # float64 q^k for k = 0 .. the most entries of a reading
    w: float  # 1 - p_rand - p_max
    sigma: float
    window: float  # sigmas: the Gaussian is 0 beyond


class EMState(NamedTuple):
    """What every reading t keeps under the current map.

    Far obstacles (g = 0, before the window) come before the window's in range order, so
    S_t = q^nfar (wsum + q^nobs G0), wsum being the window obstacles' sum of
    q^(rank) p_hit g (``_set_sum``)."""

    s: np.ndarray  # (R,) float64 S_t
    wsum: np.ndarray  # (R,) float64
    nobs: np.ndarray  # (R,) int32 obstacles inside the window
    nfar: np.ndarray  # (R,) int32 obstacles before it
    far_ratio: np.ndarray  # (R, 2) float64 likelihood ratios of adding / removing a far obstacle
    far_log: np.ndarray  # (R, 2) float64 their logs
    stamp: np.ndarray  # (R,) int32 the clock when the reading last changed


class Candidates(NamedTuple):
    """The cells EM may flip, in flat-id order, and what the sweeps remember of each."""

    cell: np.ndarray  # (C,) int64 sorted flat ids
    of_cell: np.ndarray  # (H * W,) int32 candidate position of each cell, -1 for none
    row_first: np.ndarray  # (H + 1,) int64 row r's candidates are row_first[r]:row_first[r + 1]
    occupied: np.ndarray  # (H * W,) bool the map
    stamp: np.ndarray  # (C,) int64 the clock when last scored (-1: never)
    last_gain: np.ndarray  # (C,) float64 the last data gain of flipping
    tile_clock: np.ndarray  # (H, n_seg) int64 the clock when each tile was last visited (-1: never)


class TileWork(NamedTuple):
    """The tiles' scratch; ``ctl`` holds the control words (CTL_*), the rest grows on demand."""

    ctl: np.ndarray  # (CTL_SIZE,) int64
    active: np.ndarray  # (R / 64 + 1,) uint64 bit set of the readings active at the row
    seg_ptr: np.ndarray  # (n_seg + 1,) int64
    seg_list: np.ndarray  # int64 readings of each segment, ascending
    count: np.ndarray  # int64 pairs per candidate of the tile (+1)
    pair_pos: np.ndarray  # int64 listing (position in the tile's reading list) of each window pair
    pair_j: np.ndarray  # int64 template entry
    pair_g: np.ndarray  # float64 its Gaussian (0 before the window)
    slot: np.ndarray  # (R,) int32 where each active reading's window obstacles are in the arena (-1: none)
    obs_j: np.ndarray  # int64 arena: per slot its reading (header), then a bit per window entry (occupied or not)
    obs_g: np.ndarray  # float64 arena: the window obstacles' Gaussians, in range order
    pre: np.ndarray  # float64 arena: their prefix sums (one more than obstacles)
    seg_fill: np.ndarray  # (n_seg,) int64 scratch of the segment lists
    tile_t: np.ndarray  # int64 per listing: its reading
    far_lo: np.ndarray  # int64 per listing: the tile columns where the cone's cells lie before its window
    far_hi: np.ndarray  # (far_hi < far_lo: none)
    far_sum: np.ndarray  # (2, SEGMENT + 1) float64 differences of sum_t log far ratio along the tile (add, remove)
    spans: np.ndarray  # (11, n) int64 the row's active readings' ``RowSpan``s, readings and columns (seg_list points into it)
    seg_mask: np.ndarray  # (n_seg,) int64 bit k of segment s: column s * SEGMENT + k holds a candidate


@intrinsic
def _trailing_zeros(typingctx, x):
    """Compiled: the number of trailing zero bits of the uint64 x (LLVM's cttz; x != 0)."""
    sig = types.uint64(types.uint64)

    def codegen(context, builder, signature, args):
        return builder.cttz(args[0], ir.Constant(ir.IntType(1), 1))

    return sig, codegen


@functools.lru_cache(maxsize=4)
def row_groups(templates) -> RowGroups:
    """``RowGroups`` of ``templates`` (a ``cone.ConeTemplates``); cached, one-time set-up."""
    ext = templates.extent
    n_base = templates.offsets.shape[0] - 1
    total = int(templates.offsets[-1])
    ptr = np.zeros((2, n_base, 2 * ext + 2), dtype=np.int64)
    j_all = np.empty((2, total), dtype=np.int32)
    other_all = np.empty((2, total), dtype=np.int32)
    lo = np.zeros((2, n_base, 2 * ext + 1), dtype=np.int32)
    hi = np.full((2, n_base, 2 * ext + 1), -1, dtype=np.int32)
    box = np.empty((4, total), dtype=np.int32)
    zero = np.zeros((2, n_base, 2 * ext + 1), dtype=np.int64)
    for b in range(n_base):
        s, e = int(templates.offsets[b]), int(templates.offsets[b + 1])
        dr = templates.drow[s:e].astype(np.int64)
        dc = templates.dcol[s:e].astype(np.int64)
        box[0, s:e] = np.minimum.accumulate(dr)
        box[1, s:e] = np.maximum.accumulate(dr)
        box[2, s:e] = np.minimum.accumulate(dc)
        box[3, s:e] = np.maximum.accumulate(dc)
        for kind, (key, other) in enumerate(((dr, dc), (dc, dr))):
            order = np.lexsort((other, key))
            j_all[kind, s:e] = order
            other_all[kind, s:e] = other[order]
            counts = np.bincount(key + ext, minlength=2 * ext + 1)
            ptr[kind, b, 1:] = s + np.cumsum(counts)
            ptr[kind, b, 0] = s
            filled = counts > 0
            starts, stops = ptr[kind, b, :-1], ptr[kind, b, 1:]
            lo[kind, b, filled] = other_all[kind, starts[filled]]
            hi[kind, b, filled] = other_all[kind, stops[filled] - 1]
            for v in np.flatnonzero(filled):
                run = other_all[kind, starts[v]:stops[v]]
                # a row of a cone (a convex set) is a run of consecutive cells: entry positions
                # follow from the other offset by arithmetic
                if not np.array_equal(run, np.arange(run[0], run[0] + run.size)):
                    raise AssertionError("a template row is not a run of consecutive cells")
                zero[kind, b, v] = starts[v] + min(max(-int(run[0]), 0), run.size)
    groups = RowGroups(ptr, j_all, other_all, lo, hi, zero, box)
    for a in groups:
        a.setflags(write=False)
    return groups


@numba.njit(cache=True, inline="always")
def _entry_cell(tpl, k, j, row0, col0, height, width):
    """Flat cell of entry j of heading bin k's cone from (row0, col0), or -1 outside the grid."""
    s = tpl.offsets[tpl.base_bin[k]]
    dc = np.int64(tpl.dcol[s + j])
    dr = np.int64(tpl.drow[s + j])
    r = row0 + tpl.transform[k, 2] * dc + tpl.transform[k, 3] * dr
    c = col0 + tpl.transform[k, 0] * dc + tpl.transform[k, 1] * dr
    if r < 0 or r >= height or c < 0 or c >= width:
        return -1
    return r * width + c


@numba.njit(cache=True)
def _reading_extent(tpl, groups, readings, gauss, grid_shape, out, span):
    """Per reading span[0] <= t < span[1] of ``readings`` = (rows, cols, bins, z, limits,
    lower): the entries of its cone (m: up to ``limits``, and beyond z only while the
    Gaussian, ``gauss`` = (sigma, window), is not 0, as ``forward_model.cone_entries``), the
    first entry at range >= ``lower`` (jlo), the grid rows and columns its cone spans (row_lo >
    row_hi: none) and the squared offsets (cells) of entries m - 1 and jlo - 1
    (``EMReadings.reach2``)."""
    rows, cols, bins, z, limits, lower = readings
    sigma, window = gauss
    height, width = grid_shape
    out_m, out_jlo, out_box, out_reach2, out_inside = out
    for t in range(span[0], span[1]):
        k = bins[t]
        b = tpl.base_bin[k]
        s = tpl.offsets[b]
        r = tpl.ranges[s : tpl.offsets[b + 1]]
        m = cone_entries(r, z[t], limits[t], sigma, window)
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


@numba.njit(cache=True)
def _window_rows(tpl, rd, height, out, span):
    """The last grid row of the window cells (entries jlo .. m - 1; -1: none) of each reading
    span[0] <= t < span[1]."""
    for t in range(span[0], span[1]):
        k = rd.bin[t]
        s0 = tpl.offsets[tpl.base_bin[k]]
        tc, td = tpl.transform[k, 2], tpl.transform[k, 3]
        hi = np.int64(-1)
        for j in range(rd.jlo[t], rd.m[t]):
            hi = max(hi, rd.row0[t] + tc * np.int64(tpl.dcol[s0 + j]) + td * np.int64(tpl.drow[s0 + j]))
        out[t] = min(hi, height - 1)


@numba.njit(cache=True, inline="always")
def _set_sum(t, rd, model, state):
    """S_t from the state, and the likelihood ratios of adding / removing a far obstacle.

    A far cell has g = 0 and so have all obstacles before it (they are nearer), so adding
    it makes S_t -> q S_t and removing it S_t -> S_t / q, whatever its rank: one value per
    reading instead of a search per (cell, reading) pair.
    """
    qpow = model.qpow
    w = model.w
    q = 1.0 - model.p_hit
    value = qpow[state.nfar[t]] * (state.wsum[t] + qpow[state.nobs[t]] * rd.g0[t])
    state.s[t] = value
    c = rd.const[t]
    base = c + w * value
    state.far_ratio[t, 0] = (c + w * q * value) / base  # likelihood ratio of adding one
    state.far_ratio[t, 1] = (c + w * value / q) / base  # ... and of removing one
    state.far_log[t, 0] = math.log(state.far_ratio[t, 0])
    state.far_log[t, 1] = math.log(state.far_ratio[t, 1])


@numba.njit(cache=True, inline="always")
def _find(parent, x):
    """Union-find root of x (path halving)."""
    while parent[x] != x:
        parent[x] = parent[parent[x]]
        x = parent[x]
    return x


# _nrt=False (a private numba option): the kernel allocates nothing, and without numba's
# reference counting its tuples' arrays cost nothing per reading
@numba.njit(cache=True, _nrt=False)
def _init_state(tpl, flat, rd, model, occupied, grid_shape, marks, state, span):
    """The ``EMState`` of each reading span[0] <= t < span[1] under ``occupied`` (one walk of
    its cone, nearest first).

    ``marks`` = (seen, labels, parent, box): with a non-empty ``seen`` (flat bool) every
    cone cell is marked in it; with non-empty ``labels`` (flat int, 0 outside every cluster)
    clusters that share a reading are joined in the union-find ``parent``, and ``box`` (4, R)
    gets the rows and columns of each reading's cluster cells (row_lo > row_hi: none), the
    only ones EM may flip: the reading need only be active there.
    """
    seen, labels, parent, box = marks
    height, width = grid_shape
    qpow = model.qpow
    p_hit = model.p_hit
    mark = seen.shape[0] > 0
    join = labels.shape[0] > 0
    for t in range(span[0], span[1]):
        state.stamp[t] = 0
        far = 0
        k = 0
        acc = 0.0
        first = 0
        if join:
            box[0, t] = height
            box[1, t] = -1
            box[2, t] = width
            box[3, t] = -1
        if rd.box[0, t] <= rd.box[1, t]:
            k_bin = rd.bin[t]
            s0 = tpl.offsets[tpl.base_bin[k_bin]]
            inside = rd.inside[t] != 0
            x_off = flat.offsets[flat.sel[k_bin, 0]]
            sign = flat.sel[k_bin, 1]
            at = rd.row0[t] * width + rd.col0[t]
            for j in range(rd.m[t]):
                cell = at + sign * np.int64(x_off[s0 + j]) if inside else _entry_cell(tpl, k_bin, j, rd.row0[t],
                                                                                      rd.col0[t], height, width)
                if cell < 0:
                    continue
                if mark:
                    seen[cell] = True
                if join and labels[cell] > 0:
                    row = cell // width
                    col = cell - row * width
                    box[0, t] = min(box[0, t], row)
                    box[1, t] = max(box[1, t], row)
                    box[2, t] = min(box[2, t], col)
                    box[3, t] = max(box[3, t], col)
                    if first == 0:
                        first = labels[cell]
                    else:
                        a = _find(parent, first)
                        c = _find(parent, labels[cell])
                        if a != c:
                            parent[max(a, c)] = min(a, c)
                if not occupied[cell]:
                    continue
                g = 0.0 if j < rd.jlo[t] else gaussian_at(rd.z[t], tpl.ranges[s0 + j], model.sigma, model.window)
                if g == 0.0:
                    far += 1
                    continue
                acc += qpow[k] * p_hit * g
                k += 1
        state.nobs[t] = k
        state.nfar[t] = far
        state.wsum[t] = acc
        _set_sum(t, rd, model, state)


@numba.njit(cache=True, inline="always")
def _row_group(tpl, groups, k, v):
    """(kind, stored bin, group value, column sign) of row offset v of heading bin k's cone."""
    b = tpl.base_bin[k]
    if tpl.transform[k, 2] == 0:  # drow = d dr, dcol = a dc
        return 0, b, v * tpl.transform[k, 3], tpl.transform[k, 0]
    return 1, b, v * tpl.transform[k, 2], tpl.transform[k, 1]


@numba.njit(cache=True, inline="always")
def _room(rd, t):
    """Arena entries of reading t's slot: a header, and room for every window entry plus one."""
    return max(rd.m[t] - rd.jlo[t], 0) + 2


@numba.njit(cache=True, inline="always")
def _build_window(t, tpl, flat, rd, model, cand, work):
    """Reading t's window obstacles (entries ascending), their Gaussians and prefix sums into a
    new arena slot, from the map (the arena must have room: ``_make_room``)."""
    height = cand.tile_clock.shape[0]
    width = cand.of_cell.shape[0] // height
    qpow = model.qpow
    p_hit = model.p_hit
    k_bin = rd.bin[t]
    s0 = tpl.offsets[tpl.base_bin[k_bin]]
    head = work.ctl[CTL_BUMP]
    work.ctl[CTL_BUMP] = head + _room(rd, t)
    work.obs_j[head] = t
    base = head + 1
    work.slot[t] = base
    work.pre[base] = 0.0
    jlo = rd.jlo[t]
    for k in range((rd.m[t] - jlo + 63) >> 6):
        work.obs_j[base + k] = 0
    n = 0
    acc = 0.0
    inside = rd.inside[t] != 0
    x_off = flat.offsets[flat.sel[k_bin, 0]]
    sign = flat.sel[k_bin, 1]
    at = rd.row0[t] * width + rd.col0[t]
    for j in range(rd.jlo[t], rd.m[t]):
        cell = at + sign * np.int64(x_off[s0 + j]) if inside else _entry_cell(tpl, k_bin, j, rd.row0[t], rd.col0[t],
                                                                              height, width)
        if cell < 0 or not cand.occupied[cell]:
            continue
        g = gaussian_at(rd.z[t], tpl.ranges[s0 + j], model.sigma, model.window)
        if g == 0.0:
            continue
        q = j - jlo
        work.obs_j[base + (q >> 6)] |= np.int64(1) << np.int64(q & 63)
        work.obs_g[base + n] = g
        acc += qpow[n] * p_hit * g
        n += 1
        work.pre[base + n] = acc


@numba.njit(cache=True, inline="always")
def _make_room(rd, work, need):
    """Slide the live slots of the arena down over the dead ones (readings that left, in
    address order) when fewer than ``need`` entries are free. Past ARENA_ENTRIES the arena
    does not grow: every slot is dropped instead (called before a tile builds any, so none is
    in use; they are rebuilt from the map when needed). False when it must grow."""
    ctl = work.ctl
    top = ctl[CTL_BUMP]
    if top + need <= work.obs_j.shape[0]:
        return True
    a = 0
    out = 0
    while a < top:
        t = work.obs_j[a]
        size = _room(rd, t)
        if work.slot[t] == a + 1:  # live
            if out != a:
                for k in range(size):
                    work.obs_j[out + k] = work.obs_j[a + k]
                    work.obs_g[out + k] = work.obs_g[a + k]
                    work.pre[out + k] = work.pre[a + k]
                work.slot[t] = out + 1
            out += size
        a += size
    ctl[CTL_BUMP] = out
    size = work.obs_j.shape[0]
    if 2 * (out + need) <= size:  # half free at least, or compactions come too often
        return True
    if size < ARENA_ENTRIES:
        ctl[CTL_NEED_ROOM] = min(2 * (out + need), ARENA_ENTRIES)
        if ctl[CTL_NEED_ROOM] > size:
            return False
    a = 0  # the arena is as large as it gets: drop every slot
    while a < out:
        t = work.obs_j[a]
        work.slot[t] = -1
        a += _room(rd, t)
    ctl[CTL_BUMP] = 0
    if need <= size:
        return True
    ctl[CTL_NEED_ROOM] = need  # one tile needs more than the cap
    return False


@numba.njit(cache=True, inline="always")
def _popcount(x):
    """Set bits of the int64 x."""
    v = np.uint64(x)
    v = v - ((v >> np.uint64(1)) & np.uint64(0x5555555555555555))
    v = (v & np.uint64(0x3333333333333333)) + ((v >> np.uint64(2)) & np.uint64(0x3333333333333333))
    v = (v + (v >> np.uint64(4))) & np.uint64(0x0F0F0F0F0F0F0F0F)
    return np.int64((v * np.uint64(0x0101010101010101)) >> np.uint64(56))


@numba.njit(cache=True, inline="always")
def _rank(bits, base, q):
    """How many window obstacles lie before window entry q: set bits below q in the slot's
    bit map (a wall the standard map draws thick puts tens of obstacles in one window)."""
    n = 0
    w = q >> 6
    for k in range(w):
        n += _popcount(bits[base + k])
    return n + _popcount(bits[base + w] & ((np.int64(1) << np.int64(q & 63)) - 1))


@numba.njit(cache=True, inline="always")
def _flip_gain(c, x, lo_pair, hi_pair, rd, model, cand, state, work):
    """Exact change of sum_t log p(z_t | m) when candidate c (tile column x) flips (data part
    only): the readings whose cones hold it before their windows through the tile's sums of
    their log ratios (``far_sum``), the others over its pairs lo_pair:hi_pair, whose window
    obstacle lists must be built (``_build_window``)."""
    pair_pos = work.pair_pos
    pair_j = work.pair_j
    pair_g = work.pair_g
    const = rd.const
    w = model.w
    p_hit = model.p_hit
    qpow = model.qpow
    s = state.s
    q = 1.0 - p_hit
    adding = not cand.occupied[cand.cell[c]]
    far = 0 if adding else 1
    delta = 0.0
    for k in range(x + 1):
        delta += work.far_sum[far, k]
    ratio = 1.0
    for p in range(lo_pair, hi_pair):
        t = work.tile_t[pair_pos[p]]
        if pair_g[p] == 0.0:  # a window entry whose Gaussian underflows: as a far one
            ratio *= state.far_ratio[t, far]
            continue
        base = work.slot[t]
        r = _rank(work.obs_j, base, pair_j[p] - rd.jlo[t])
        qf = qpow[state.nfar[t]]
        a = qf * work.pre[base + r]
        term = qf * qpow[r] * p_hit * pair_g[p]
        st = s[t]
        if adding:
            s_new = a + term + q * (st - a)
        else:
            rest = st - a - term
            if rest < 0.0:
                rest = 0.0
            s_new = a + rest / q
        # one log per candidate instead of one per pair: multiply the ratios, taking the log
        # only when the product leaves a safe range
        ratio *= (const[t] + w * s_new) / (const[t] + w * st)
        if ratio > 1e100 or ratio < 1e-100:
            delta += math.log(ratio)
            ratio = 1.0
    return delta + math.log(ratio)


@numba.njit(cache=True, inline="always")
def _far_changed(li, t, x, old_add, old_rem, state, work):
    """Reading t (listing li) changed after a flip at tile column x: move its log far ratios
    in the tile's sums over its far columns beyond x (the columns still to be scored)."""
    lo = max(work.far_lo[li], x + 1)
    hi = work.far_hi[li]
    if lo > hi:
        return
    d_add = state.far_log[t, 0] - old_add
    d_rem = state.far_log[t, 1] - old_rem
    work.far_sum[0, lo] += d_add
    work.far_sum[0, hi + 1] -= d_add
    work.far_sum[1, lo] += d_rem
    work.far_sum[1, hi + 1] -= d_rem


@numba.njit(cache=True, inline="always")
def _update_reading(t, j, g, adding, model, rd, state, work):
    """Add (or remove) the obstacle at entry j (Gaussian g) of reading t: O(1) before the
    window, else an insertion into the window's list and its prefix sums from that rank on."""
    if g == 0.0:
        state.nfar[t] += 1 if adding else -1
        _set_sum(t, rd, model, state)
        return
    qpow = model.qpow
    p_hit = model.p_hit
    obs_j = work.obs_j
    obs_g = work.obs_g
    pre = work.pre
    base = work.slot[t]
    n = state.nobs[t]
    q = j - rd.jlo[t]
    r = _rank(obs_j, base, q)
    acc = pre[base + r]
    bit = np.int64(1) << np.int64(q & 63)
    if adding:
        obs_j[base + (q >> 6)] |= bit
        for k in range(n, r, -1):
            obs_g[base + k] = obs_g[base + k - 1]
        obs_g[base + r] = g
        n += 1
        for k in range(r, n):
            acc += qpow[k] * p_hit * obs_g[base + k]
            pre[base + k + 1] = acc
    else:  # shift down and redo the prefix sums in one pass
        obs_j[base + (q >> 6)] &= ~bit
        n -= 1
        for k in range(r, n):
            obs_g[base + k] = obs_g[base + k + 1]
            acc += qpow[k] * p_hit * obs_g[base + k]
            pre[base + k + 1] = acc
    state.nobs[t] = n
    state.wsum[t] = pre[base + n]
    _set_sum(t, rd, model, state)


@numba.njit(cache=True)
def _objective(rd, model, state, occupied, cand_cell):
    """sum_t log p(z_t | m) plus l_prior per occupied candidate."""
    const = rd.const
    w = model.w
    s = state.s
    total = 0.0
    for t in range(s.shape[0]):
        total += math.log(const[t] + w * s[t])
    for c in range(cand_cell.shape[0]):
        if occupied[cand_cell[c]]:
            total += model.l_prior
    return total


@numba.njit(cache=True)
def _logistic(x):
    """1 / (1 + exp(-x)) without overflow."""
    if x >= 0:
        return 1.0 / (1.0 + math.exp(-x))
    ex = math.exp(x)
    return ex / (1.0 + ex)


@numba.njit(cache=True)
def _residual_from_gains(cand_cell, occupied, last_gain, l_prior):
    """p(m_x = 1 | Z, m*) from each candidate's current data gain of flipping."""
    out = np.empty(cand_cell.shape[0])
    for c in range(cand_cell.shape[0]):
        out[c] = _logistic((-last_gain[c] if occupied[cand_cell[c]] else last_gain[c]) + l_prior)
    return out


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
    """One reading's cone in one grid row, as runs of the other offset o (``_row_span``): the
    cell at o has column col0 + sign * o and template entry j[kind, first + o - o_first]."""

    kind: int
    first: int
    o_first: int
    sign: int
    o_lo: int  # the cone's cells: o_lo <= o <= o_hi
    o_hi: int
    f_lo: int  # those before the window: f_lo <= o <= f_hi (f_hi < f_lo: none)
    f_hi: int


@numba.njit(cache=True, inline="always")
def _row_span(tpl, groups, rd, t, r):
    """``RowSpan`` of reading t's cone in grid row r (o_hi < o_lo: none there)."""
    kind, b, gv, sign = _row_group(tpl, groups, rd.bin[t], r - rd.row0[t])
    ext = tpl.extent
    if gv < -ext or gv > ext or rd.m[t] == 0:
        return RowSpan(0, 0, 0, 1, 1, 0, 1, 0)
    first = groups.ptr[kind, b, gv + ext]
    if first == groups.ptr[kind, b, gv + ext + 1]:
        return RowSpan(0, 0, 0, 1, 1, 0, 1, 0)
    o_first = np.int64(groups.lo[kind, b, gv + ext])
    o_last = np.int64(groups.hi[kind, b, gv + ext])
    # a template entry's range is resolution * sqrt(dr^2 + dc^2): entries < m (or < jlo) are
    # the cells of the row with o^2 <= reach2 - gv^2, exactly, in integers
    v = _isqrt(rd.reach2[0, t] - gv * gv)
    if v < 0:
        return RowSpan(0, 0, 0, 1, 1, 0, 1, 0)
    f = min(_isqrt(rd.reach2[1, t] - gv * gv), v)
    return RowSpan(kind, first, o_first, sign, max(o_first, -v), min(o_last, v), max(o_first, -f), min(o_last, f))


@numba.njit(cache=True, inline="always")
def _o_range(span, col0, c0, c1, lo, hi):
    """The o of [lo, hi] whose columns lie in [c0, c1)."""
    if span.sign > 0:
        return max(lo, c0 - col0), min(hi, c1 - 1 - col0)
    return max(lo, col0 - c1 + 1), min(hi, col0 - c0)


@numba.njit(cache=True, inline="always")
def _window_pairs(i, t, span, r, c0, c1, c_start, fill, tpl, groups, rd, model, cand, work):
    """Count (``fill`` False) or write reading t's window pairs in tile columns [c0, c1) of
    row r (the cone's cells beyond its far run: up to two runs of o); returns how many."""
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
def _advance(rd, work, r):
    """The active bit set at row r: readings whose cone rows reach r (repeatable)."""
    ctl = work.ctl
    active = work.active
    n_read = rd.z.shape[0]
    e = ctl[CTL_ENTER]
    while e < n_read and rd.box[0, rd.enter[e]] <= r:
        t = rd.enter[e]
        active[t >> 6] |= np.uint64(1) << np.uint64(t & 63)
        e += 1
    ctl[CTL_ENTER] = e
    k = ctl[CTL_LEAVE]
    while k < n_read and rd.box[1, rd.leave[k]] < r:
        t = rd.leave[k]
        active[t >> 6] &= ~(np.uint64(1) << np.uint64(t & 63))
        work.slot[t] = -1  # its arena slot (if any) is dead
        k += 1
    ctl[CTL_LEAVE] = k
    k = ctl[CTL_WINDOW_LEAVE]
    while k < n_read and rd.window_hi[rd.window_leave[k]] < r:
        work.slot[rd.window_leave[k]] = -1  # the sweep is past its window: no tile needs the slot again
        k += 1
    ctl[CTL_WINDOW_LEAVE] = k


@numba.njit(cache=True, inline="always")
def _span_at(work, k):
    """The ``RowSpan`` stored at ``work.spans[:, k]`` (its reading is spans[8, k])."""
    sp = work.spans
    return RowSpan(sp[0, k], sp[1, k], sp[2, k], sp[3, k], sp[4, k], sp[5, k], sp[6, k], sp[7, k])


@numba.njit(cache=True, inline="always")
def _span_mask(lo, hi, s):
    """Bits of columns lo..hi within segment s (bit k: column s * SEGMENT + k)."""
    a = max(lo - s * SEGMENT, 0)
    b = min(hi - s * SEGMENT, SEGMENT - 1)
    if a > b:
        return np.int64(0)
    return ((np.int64(1) << np.int64(b - a + 1)) - 1) << np.int64(a)


@numba.njit(cache=True, inline="always")
def _list_segments(tpl, groups, rd, cand, work, r, n_seg):
    """The row's active readings with their ``RowSpan`` in ``spans`` (one each), and each
    segment's (ascending) in seg_ptr / seg_list, as positions in ``spans``: a reading is
    listed where its cone holds a candidate of the row (``seg_mask``). False (with the size
    needed in ctl) when a buffer is too small."""
    active = work.active
    seg_ptr = work.seg_ptr
    fill = work.seg_fill
    sp = work.spans
    mask = work.seg_mask
    width = cand.of_cell.shape[0] // cand.tile_clock.shape[0]
    for s in range(n_seg + 1):
        seg_ptr[s] = 0
    for s in range(n_seg):
        mask[s] = 0
    for c in range(cand.row_first[r], cand.row_first[r + 1]):
        col = cand.cell[c] - r * width
        mask[col // SEGMENT] |= np.int64(1) << np.int64(col % SEGMENT)
    n = 0
    visited = 0
    for wi in range(active.shape[0]):
        word = active[wi]
        while word != np.uint64(0):
            t = (wi << 6) + np.int64(_trailing_zeros(word))
            word &= word - np.uint64(1)  # the lowest set bit off
            visited += 1
            span = _row_span(tpl, groups, rd, t, r)
            if span.o_hi >= span.o_lo:
                col0 = rd.col0[t]
                if span.sign > 0:
                    lo, hi = col0 + span.o_lo, col0 + span.o_hi
                else:
                    lo, hi = col0 - span.o_hi, col0 - span.o_lo
                lo, hi = max(lo, rd.box[2, t]), min(hi, rd.box[3, t])
                if lo <= hi:
                    if n >= sp.shape[1]:
                        work.ctl[CTL_NEED_LIST] = max(work.ctl[CTL_NEED_LIST], 2 * sp.shape[1])
                        return False
                    sp[0, n], sp[1, n], sp[2, n], sp[3, n] = span.kind, span.first, span.o_first, span.sign
                    sp[4, n], sp[5, n], sp[6, n], sp[7, n] = span.o_lo, span.o_hi, span.f_lo, span.f_hi
                    sp[8, n] = t
                    sp[9, n], sp[10, n] = lo, hi
                    listed = False
                    for s in range(lo // SEGMENT, hi // SEGMENT + 1):
                        if _span_mask(lo, hi, s) & mask[s]:
                            seg_ptr[s + 1] += 1
                            listed = True
                    if listed:
                        n += 1
    work.ctl[CTL_BUDGET] -= active.shape[0] + 2 * visited  # a listed reading costs about two window pairs
    for s in range(n_seg):
        seg_ptr[s + 1] += seg_ptr[s]
        fill[s] = seg_ptr[s]
    if seg_ptr[n_seg] > work.seg_list.shape[0]:
        work.ctl[CTL_NEED_LIST] = max(work.ctl[CTL_NEED_LIST], seg_ptr[n_seg])
        return False
    for k in range(n):
        lo, hi = sp[9, k], sp[10, k]
        for s in range(lo // SEGMENT, hi // SEGMENT + 1):
            if _span_mask(lo, hi, s) & mask[s]:
                work.seg_list[fill[s]] = k
                fill[s] += 1
    return True


@numba.njit(cache=True, inline="always")
def _row_unchanged(rd, cand, state, work, r, n_seg):
    """True (and every candidate of row r stamped as scored now) when no active reading
    changed since the row's tiles were last visited: a check of one stamp per reading
    instead of listing them (late sweeps change few readings)."""
    since = cand.tile_clock[r, 0]
    for s in range(1, n_seg):
        since = min(since, cand.tile_clock[r, s])
    if since < 0:
        return False
    active = work.active
    for wi in range(active.shape[0]):
        word = active[wi]
        while word != np.uint64(0):
            t = (wi << 6) + np.int64(_trailing_zeros(word))
            word &= word - np.uint64(1)
            if state.stamp[t] > since:
                return False
    now = work.ctl[CTL_CLOCK]
    for c in range(cand.row_first[r], cand.row_first[r + 1]):
        cand.stamp[c] = now
    for s in range(n_seg):
        cand.tile_clock[r, s] = now
    return True


# _nrt=False: the sweep allocates nothing (its scratch comes in ``work``), and without numba's
# reference-counting runtime the arrays it hands to the inlined helpers cost nothing per call
@numba.njit(cache=True, _nrt=False)
def _sweep_tiles(tpl, flat, groups, rd, model, cand, state, work):
    """One pass over the candidates in flat-id order, tile by tile (see the module docstring):
    ctl[CTL_MODE] SWEEP keeps each flip that raises the objective, SCORE scores every
    candidate into ``last_gain`` and flips none.

    A candidate none of whose readings changed since it was last scored keeps its (non-
    improving) gain and is skipped, and so is a whole tile none of whose readings changed
    since the tile's last visit: the result equals a full sweep's. The clock counts accepted
    flips. Starts at (ctl[CTL_ROW], ctl[CTL_SEG]); returns NEED_BUFFERS, with the sizes
    needed in ctl, before a tile's first change when the scratch is too small (grow it and
    call again: the pass resumes there), PAUSED before a row or a tile once the work done in
    this call (subtracted from ctl[CTL_BUDGET], in window pairs: a listed reading counts 2, a
    scored candidate 8, a window built its entries, a flip the tile's readings and the cell's
    pairs) exhausts the budget the caller set (set it again and call again: the pass resumes
    there, with the row's listing kept, ctl[CTL_LISTED]), else DONE. Every call does at least
    one tile or row before it pauses; where it pauses changes nothing computed.
    """
    ctl = work.ctl
    height, n_seg = cand.tile_clock.shape
    width = cand.of_cell.shape[0] // height
    mode = ctl[CTL_MODE]
    occupied = cand.occupied
    seg_list = work.seg_list
    cnt = work.count
    fresh = True  # nothing done yet in this call: no pause
    for r in range(ctl[CTL_ROW], height):
        ca = cand.row_first[r]
        cb = cand.row_first[r + 1]
        if ca == cb:
            continue
        if ctl[CTL_SEG] == 0 and ctl[CTL_BUDGET] <= 0 and not fresh:
            ctl[CTL_ROW] = r
            return PAUSED
        ctl[CTL_ROW] = r
        _advance(rd, work, r)
        if mode == SWEEP and ctl[CTL_SEG] == 0:
            ctl[CTL_BUDGET] -= work.active.shape[0]
            if _row_unchanged(rd, cand, state, work, r, n_seg):
                fresh = False
                continue  # no reading whose cone crosses the row changed since its last visit
        if ctl[CTL_LISTED] != r:  # else listed before a pause, and still so
            if not _list_segments(tpl, groups, rd, cand, work, r, n_seg):
                return NEED_BUFFERS
            ctl[CTL_LISTED] = r
        c_pos = ca
        row_base = r * width
        for sg in range(ctl[CTL_SEG], n_seg):
            c0 = sg * SEGMENT
            c1 = min(c0 + SEGMENT, width)
            while c_pos < cb and cand.cell[c_pos] < row_base + c0:
                c_pos += 1
            c_start = c_pos
            while c_pos < cb and cand.cell[c_pos] < row_base + c1:
                c_pos += 1
            c_stop = c_pos
            if c_start == c_stop:
                continue
            if ctl[CTL_BUDGET] <= 0 and not fresh:
                ctl[CTL_SEG] = sg
                return PAUSED
            fresh = False
            list_lo = work.seg_ptr[sg]
            list_hi = work.seg_ptr[sg + 1]
            ctl[CTL_BUDGET] -= list_hi - list_lo
            clock0 = ctl[CTL_CLOCK]
            if mode == SWEEP:
                since = cand.tile_clock[r, sg]
                dirty = since < 0
                if not dirty:
                    for i in range(list_lo, list_hi):
                        if state.stamp[work.spans[8, seg_list[i]]] > since:
                            dirty = True
                            break
                if not dirty:  # nothing the tile's candidates see changed: each keeps its gain
                    for c in range(c_start, c_stop):
                        cand.stamp[c] = clock0
                    cand.tile_clock[r, sg] = clock0
                    continue
            # the tile: each listed reading's far run (into the sums of log far ratios) and
            # window pairs (counted per candidate, then written in reading order)
            nc = c_stop - c_start
            n_list = list_hi - list_lo
            if n_list > work.far_lo.shape[0]:
                ctl[CTL_NEED_LIST] = max(ctl[CTL_NEED_LIST], n_list)
                ctl[CTL_SEG] = sg
                return NEED_BUFFERS
            for i in range(nc + 1):
                cnt[i] = 0
            for k in range(SEGMENT + 1):
                work.far_sum[0, k] = 0.0
                work.far_sum[1, k] = 0.0
            room = 0
            n_pairs = 0
            for i in range(list_lo, list_hi):
                span = _span_at(work, seg_list[i])
                t = work.spans[8, seg_list[i]]
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
                if k > 0 and work.slot[t] < 0:
                    room += _room(rd, t)
            for i in range(1, nc + 1):
                cnt[i] += cnt[i - 1]
            if n_pairs > work.pair_pos.shape[0] or not _make_room(rd, work, room):
                ctl[CTL_NEED_PAIRS] = n_pairs
                ctl[CTL_SEG] = sg
                return NEED_BUFFERS
            ctl[CTL_PAIRS] += n_pairs
            ctl[CTL_BUDGET] -= n_pairs + 8 * nc
            for i in range(list_lo, list_hi):
                span = _span_at(work, seg_list[i])
                t = work.spans[8, seg_list[i]]
                if span.o_hi >= span.o_lo:
                    _window_pairs(i - list_lo, t, span, r, c0, c1, c_start, True, tpl, groups, rd, model, cand, work)
            for c in range(c_start, c_stop):
                li = c - c_start
                lo_pair = 0 if li == 0 else cnt[li - 1]
                hi_pair = cnt[li]
                x = cand.cell[c] - row_base - c0  # the tile column
                for p in range(lo_pair, hi_pair):  # the window obstacles the score needs
                    t = work.tile_t[work.pair_pos[p]]
                    if work.pair_g[p] != 0.0 and work.slot[t] < 0:
                        _build_window(t, tpl, flat, rd, model, cand, work)
                        ctl[CTL_BUDGET] -= _room(rd, t)
                ctl[CTL_SCORED] += 1
                d = _flip_gain(c, x, lo_pair, hi_pair, rd, model, cand, state, work)
                cand.last_gain[c] = d
                if mode != SWEEP:
                    continue
                cell = cand.cell[c]
                d += -model.l_prior if occupied[cell] else model.l_prior
                if d > 1e-9:
                    occupied[cell] = not occupied[cell]
                    cand.last_gain[c] = -cand.last_gain[c]  # flipping back undoes exactly this gain
                    ctl[CTL_FLIPS] += 1
                    ctl[CTL_CLOCK] += 1
                    ctl[CTL_BUDGET] -= n_list + hi_pair - lo_pair
                    adding = occupied[cell]
                    now = ctl[CTL_CLOCK]
                    for i in range(n_list):  # the readings that hold the cell before their windows
                        if work.far_lo[i] <= x <= work.far_hi[i]:
                            t = work.tile_t[i]
                            old_add, old_rem = state.far_log[t, 0], state.far_log[t, 1]
                            state.nfar[t] += 1 if adding else -1
                            _set_sum(t, rd, model, state)
                            _far_changed(i, t, x, old_add, old_rem, state, work)
                            state.stamp[t] = now
                    for p in range(lo_pair, hi_pair):  # ... and inside them
                        i = work.pair_pos[p]
                        t = work.tile_t[i]
                        old_add, old_rem = state.far_log[t, 0], state.far_log[t, 1]
                        _update_reading(t, work.pair_j[p], work.pair_g[p], adding, model, rd, state, work)
                        _far_changed(i, t, x, old_add, old_rem, state, work)
                        state.stamp[t] = now
                cand.stamp[c] = ctl[CTL_CLOCK]
            if mode == SWEEP:
                cand.tile_clock[r, sg] = clock0
        ctl[CTL_SEG] = 0
    return DONE
