"""The layout of EM's kernels' arrays: the readings' int and float columns, the control
words of a sweep, the named tuples the kernels take (``RowGroups``, ``ReadingTables``, ``EMModel``,
``Candidates``, ``TileWork``) and those they take apart (``EMReadings``, ``EMState``), and the
templates grouped by row."""

from __future__ import annotations

import functools
from typing import NamedTuple

import numba
import numpy as np
from llvmlite import ir
from numba import types
from numba.extending import intrinsic

__all__ = [  # what the package re-exports: the layout every caller of the kernels needs
    "ARENA_ENTRIES", "CTL_BUDGET", "CTL_BUMP", "CTL_CLOCK", "CTL_ENTER", "CTL_FLIPS", "CTL_LEAVE",
    "CTL_LISTED", "CTL_MODE", "CTL_NEED_LIST", "CTL_NEED_PAIRS", "CTL_NEED_ROOM", "CTL_PAIRS", "CTL_ROW",
    "CTL_SCORED", "CTL_SEG", "CTL_SG_HI", "CTL_SG_LO", "CTL_SIZE", "CTL_WINDOW_LEAVE", "Candidates", "DONE", "EMModel", "EMReadings",
    "EMState", "FLOATS", "F_CONST", "F_G0", "F_LOG", "F_RATIO", "F_S", "F_WSUM", "F_Z", "INTS", "I_BIN",
    "I_BOX", "I_COL0", "I_INSIDE", "I_JLO", "I_M", "I_NFAR", "I_NOBS", "I_REACH2", "I_ROW0", "I_SLOT",
    "I_STAMP", "I_WINDOW_HI", "NEED_BUFFERS", "PAUSED", "PAUSE_WORK", "ReadingTables", "RowGroups", "SCORE",
    "SEGMENT", "SWEEP", "TileWork", "reading_tables", "row_groups",
]

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
CTL_SG_LO, CTL_SG_HI = 16, 17  # the band's segments: the sweep visits tiles sg_lo <= sg < sg_hi
CTL_SIZE = 18
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

    rows: np.ndarray  # (2, n_base, 2 ext + 1, 4) int32: group v's first entry, entry count, least and
    # greatest other offset, at [kind, b, v + ext]: what a sweep's listing reads of a reading's row, in one
    # 16-byte record (three arrays cost three cache misses per reading and row on the intel log's
    # 163 800 readings: the listing's largest cost)
    j: np.ndarray  # (2, E) int32: entry index within its stored bin (range order)
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


class ReadingTables(NamedTuple):
    """What the kernels take of an ``EMReadings`` (``reading_tables``): its two tables and its
    orders, from which they take the columns (``_columns``).

    A column of a table is strided, unless the table has one row (or none): numpy calls such a
    column contiguous and numba would compile every kernel again for it (for a cluster that one
    reading reaches). A table is contiguous whatever its rows, so the kernels have one signature,
    and their columns, taken in compiled code, are the strided arrays they were compiled for.
    """

    ints: np.ndarray  # (R, INTS) int32
    floats: np.ndarray  # (R, FLOATS) float64
    enter: np.ndarray  # int32 EMReadings' orders
    leave: np.ndarray
    window_leave: np.ndarray


def reading_tables(rd: EMReadings) -> ReadingTables:
    """The ``ReadingTables`` of ``rd`` (its columns must be those of its tables, as
    ``em.em_readings`` and ``em.em_problem`` make them)."""
    return ReadingTables(rd.ints, rd.floats, rd.enter, rd.leave, rd.window_leave)


@numba.njit(cache=True, inline="always")
def _columns(tables):
    """Compiled: the ``EMReadings`` and ``EMState`` of ``tables`` (``ReadingTables``), views of
    its columns."""
    ints, floats = tables.ints, tables.floats
    rd = EMReadings(ints[:, I_ROW0], ints[:, I_COL0], ints[:, I_BIN], floats[:, F_Z], floats[:, F_G0],
                    floats[:, F_CONST], ints[:, I_M], ints[:, I_JLO], ints[:, I_BOX:I_BOX + 4].T,
                    ints[:, I_REACH2:I_REACH2 + 2].T, ints[:, I_INSIDE], ints[:, I_WINDOW_HI], tables.enter,
                    tables.leave, tables.window_leave, ints, floats)
    state = EMState(floats[:, F_S], floats[:, F_WSUM], ints[:, I_NOBS], ints[:, I_NFAR],
                    floats[:, F_RATIO:F_RATIO + 2], floats[:, F_LOG:F_LOG + 2], ints[:, I_STAMP])
    return rd, state


@numba.njit(cache=True, inline="always")
def _tile_work(scratch, slot):
    """Compiled: ``scratch`` (a ``TileWork`` whose ``slot`` is a stand-in) with ``slot``, the
    column of the readings' int table (``ReadingTables``) that holds their arena slots."""
    s = scratch
    return TileWork(s.ctl, s.active, s.seg_ptr, s.seg_list, s.count, s.pair_pos, s.pair_j, s.pair_g, slot, s.obs_j,
                    s.obs_g, s.pre, s.seg_fill, s.tile_t, s.far_lo, s.far_hi, s.far_sum, s.spans, s.seg_mask, s.members,
                    s.enter, s.leave, s.window_leave)


class Candidates(NamedTuple):
    """The cells EM may flip, in flat-id order, and what the sweeps remember of each."""

    cell: np.ndarray  # (C,) int64 sorted flat ids
    of_cell: np.ndarray  # (H * W,) int32 candidate position of each cell, -1 for none
    row_first: np.ndarray  # (H + 1,) int64 row r's candidates are row_first[r]:row_first[r + 1]
    occupied: np.ndarray  # (H * W,) bool the map
    stamp: np.ndarray  # (C,) int64 the clock when last scored (-1: never)
    last_gain: np.ndarray  # (C,) float64 the last data gain of flipping
    tile_clock: np.ndarray  # (H, n_seg) int64, Fortran order, the clock when each tile was last visited (-1: never)


class TileWork(NamedTuple):
    """The tiles' scratch; ``ctl`` holds the control words (CTL_*), the rest grows on demand."""

    ctl: np.ndarray  # (CTL_SIZE,) int64
    active: np.ndarray  # (R / 64 + 1,) uint64 bit set of the band's readings (positions) active at the row
    seg_ptr: np.ndarray  # (n_seg + 1,) int64
    seg_list: np.ndarray  # int64 readings of each segment, ascending
    count: np.ndarray  # int64 pairs per candidate of the tile (+1)
    pair_pos: np.ndarray  # int64 listing (position in the tile's reading list) of each window pair
    pair_j: np.ndarray  # int64 template entry
    pair_g: np.ndarray  # float64 its Gaussian (0 before the window)
    slot: np.ndarray  # (R,) int32 where each active reading's window obstacles are in the arena (-1: none);
    # a column of the readings' int table (I_SLOT), which the sweep takes itself (``_tile_work``)
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
    # the band's readings (``mapping.sweeps``): those whose cones reach its columns, by position i;
    # ``active`` is a bit set of positions
    members: np.ndarray  # int64 position -> reading
    enter: np.ndarray  # int64 positions by their readings' row_lo (stable; ``EMReadings.enter`` for all)
    leave: np.ndarray  # by row_hi
    window_leave: np.ndarray  # by window_hi


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
    if total >= 2**31:
        raise ValueError(f"{total} template entries: more than an int32 row table holds")
    rows = np.zeros((2, n_base, 2 * ext + 1, 4), dtype=np.int32)
    rows[..., 3] = -1
    j_all = np.empty((2, total), dtype=np.int32)
    box = np.empty((4, total), dtype=np.int32)
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
            sorted_other = other[order]
            counts = np.bincount(key + ext, minlength=2 * ext + 1)
            stops = s + np.cumsum(counts)
            starts = stops - counts
            filled = counts > 0
            rows[kind, b, :, 0] = starts
            rows[kind, b, :, 1] = counts
            rows[kind, b, filled, 2] = sorted_other[starts[filled] - s]
            rows[kind, b, filled, 3] = sorted_other[stops[filled] - 1 - s]
            # a row of a cone (a convex set) is a run of consecutive cells: entry positions follow
            # from the other offset by arithmetic
            if np.any(rows[kind, b, filled, 3] - rows[kind, b, filled, 2] + 1 != counts[filled]):
                raise AssertionError("a template row is not a run of consecutive cells")
    groups = RowGroups(rows, j_all, box)
    for a in groups:
        a.setflags(write=False)
    return groups
