"""The layout of EM's kernels' arrays: a reading's records, a sweep's control words, the named tuples
the kernels take (``EMReadings``, ``RowGroups``, ``EMModel``, ``Candidates``, ``TileWork``) and take
apart (``Columns``, ``EMState``), and the templates grouped by row."""

from __future__ import annotations

import functools
from typing import NamedTuple

import numba
import numpy as np
from llvmlite import ir
from numba import types
from numba.extending import intrinsic

SWEEP = 0  # TileWork.ctl's mode: flip candidates that raise the objective
SCORE = 1  # score every candidate once (the residual pass), flip none
SEGMENT = 32  # columns per tile
# the window arena's largest size (entries of 24 bytes: 96 MB); beyond it slots are dropped and rebuilt
ARENA_ENTRIES = 1 << 22

# A reading's integers and reals, one record each: what the tiles need of a reading shares a cache
# line or two. Every integer fits an int32 (entries, slots, the clock of stamps < 2^31).
READING_INTS = np.dtype([
    ("row0", np.int32), ("col0", np.int32),  # sensor cell (may lie outside the grid)
    ("bin", np.int32),  # heading bin
    ("m", np.int32),  # template entries of the (truncated) cone
    ("jlo", np.int32),  # first entry that may lie inside the Gaussian window
    ("reach2", np.int32, (2,)),  # the cone's cells have dr^2 + dc^2 <= reach2[0], those before the window <= reach2[1]
    ("box", np.int32, (4,)),  # row_lo, row_hi, col_lo, col_hi of the cone in the grid (row_lo > row_hi: none)
    ("nobs", np.int32), ("nfar", np.int32), ("stamp", np.int32), ("slot", np.int32),  # its EMState
    ("inside", np.int32),  # 1 when every cell of the cone lies inside the grid (flat offsets serve)
    ("window_hi", np.int32),  # the last grid row of the cone's window cells (-1: none)
], align=True)
READING_FLOATS = np.dtype([
    ("z", np.float64),  # range in template ranges (max-range readings: z_max)
    ("g0", np.float64), ("const", np.float64),  # G0_t, C_t
    ("s", np.float64), ("wsum", np.float64), ("far_ratio", np.float64, (2,)), ("far_log", np.float64, (2,)),  # EMState
], align=True)

# TileWork.ctl: one record of a sweep's control words
CONTROL = np.dtype([(name, np.int64) for name in (
    "mode",  # SWEEP or SCORE
    "row", "seg",  # where the pass resumes
    "need_list", "need_pairs", "need_room",  # the sizes the scratch must grow to (NEED_BUFFERS)
    "enter", "leave",  # the band's readings entered and left so far (positions in its orders)
    "clock", "flips", "scored", "pairs",  # accepted flips' clock, and the pass's counts
    "bump",  # the window arena's top
    "window_leave",  # the band's readings whose window rows the sweep is past
    "budget",  # the work left before a pause (in window pairs: see _sweep_tiles)
    "listed",  # the row whose readings are listed (-1: none)
    "sg_lo", "sg_hi",  # the band's segments: the sweep visits tiles sg_lo <= sg < sg_hi
)], align=True)
DONE, NEED_BUFFERS, PAUSED = 0, 1, 2
# the work (window pairs) after which a sweep pauses, so that Python, where a signal's handler runs,
# is back many times a second (timings: docs/algorithms.md)
PAUSE_WORK = 1 << 21


class RowGroups(NamedTuple):
    """Each stored bin's entries grouped by grid row (``kind`` 0 by dr, 1 by dc: as the symmetry takes drow)."""

    rows: np.ndarray  # (2, n_base, 2 ext + 1, 6) int32: group v's first entry, count, least and greatest
    # other offset, least and greatest heard (``ConeTemplates.heard``; greatest < least: none): one record,
    # not several arrays' cache misses (docs/algorithms.md)
    j: np.ndarray  # (2, E) int32: entry index within its stored bin (range order)
    box: np.ndarray  # (4, E) int32: min dr, max dr, min dc, max dc over a bin's entries 0..j


class EMReadings(NamedTuple):
    """The readings of an EM problem (``em.em_readings``) and their ``EMState``: a record per reading
    in each table. Kernels take the tables whole (a column of a one-row table would be contiguous, and
    numba would compile every kernel again) and their fields in compiled code (``_columns``)."""

    ints: np.ndarray  # (R,) READING_INTS
    floats: np.ndarray  # (R,) READING_FLOATS
    extent: np.ndarray  # (R, 4) int32 row_lo, row_hi, col_lo, col_hi: where a sweep needs each reading
    enter: np.ndarray  # int32 readings by extent row_lo (stable)
    leave: np.ndarray  # int32 readings by extent row_hi (stable)
    window_leave: np.ndarray  # int32 readings by window_hi (stable): their window slots are dropped past it

    @property
    def z(self) -> np.ndarray:
        return self.floats["z"]


class Columns(NamedTuple):
    """Compiled: the fields of ``EMReadings``' tables but its state, as arrays (``_columns``)."""

    row0: np.ndarray
    col0: np.ndarray
    bin: np.ndarray
    z: np.ndarray
    g0: np.ndarray
    const: np.ndarray
    m: np.ndarray
    jlo: np.ndarray
    box: np.ndarray  # (4, R)
    reach2: np.ndarray  # (2, R)
    inside: np.ndarray
    window_hi: np.ndarray


class EMModel(NamedTuple):
    """The constants of the objective."""

    p_hit: float  # detection probability of each obstacle in a cone (q = 1 - p_hit)
    l_prior: float  # log-odds of the occupancy prior, added per occupied candidate
    qpow: np.ndarray  # float64 q^k for k = 0 .. the most entries of a reading
    w: float  # 1 - p_rand - p_max
    sigma: float
    window: float  # sigmas: the Gaussian is 0 beyond


class EMState(NamedTuple):
    """What each reading keeps under the map: S_t = q^nfar (wsum + q^nobs G0), far obstacles first."""

    s: np.ndarray  # (R,) float64 S_t
    wsum: np.ndarray  # (R,) float64
    nobs: np.ndarray  # (R,) int32 obstacles inside the window
    nfar: np.ndarray  # (R,) int32 obstacles before it
    far_ratio: np.ndarray  # (R, 2) float64 likelihood ratios of adding / removing a far obstacle
    far_log: np.ndarray  # (R, 2) float64 their logs
    stamp: np.ndarray  # (R,) int32 the clock when the reading last changed
    slot: np.ndarray  # (R,) int32 where its window obstacles are in a sweep's arena (-1: none)


def em_state(rd: EMReadings) -> EMState:
    """The ``EMState`` of ``rd``: views of its tables' fields."""
    return EMState(**{name: (rd.ints if name in READING_INTS.names else rd.floats)[name] for name in EMState._fields})


# Each field's word in a table seen as a plain (R, words) array, whose columns numba reads faster than
# field views (docs/algorithms.md, "EM's kernel tables")
_INT_WORDS, _FLOAT_WORDS = READING_INTS.itemsize // 4, READING_FLOATS.itemsize // 8
_ROW0, _COL0, _BIN, _M, _JLO, _REACH2, _BOX, _NOBS, _NFAR, _STAMP, _SLOT, _INSIDE, _WINDOW_HI = (
    READING_INTS.fields[name][1] // 4 for name in ("row0", "col0", "bin", "m", "jlo", "reach2", "box", "nobs", "nfar",
                                                   "stamp", "slot", "inside", "window_hi"))
_Z, _G0, _CONST, _S, _WSUM, _FAR_RATIO, _FAR_LOG = (
    READING_FLOATS.fields[name][1] // 8 for name in ("z", "g0", "const", "s", "wsum", "far_ratio", "far_log"))


@numba.njit(cache=True, inline="always")
def _columns(rd):
    """Compiled: the ``Columns`` and ``EMState`` of ``rd`` (``EMReadings``), views of its tables."""
    n = rd.ints.shape[0]
    ints = rd.ints.view(np.int32).reshape((n, _INT_WORDS))
    floats = rd.floats.view(np.float64).reshape((n, _FLOAT_WORDS))
    columns = Columns(row0=ints[:, _ROW0], col0=ints[:, _COL0], bin=ints[:, _BIN], z=floats[:, _Z], g0=floats[:, _G0],
                      const=floats[:, _CONST], m=ints[:, _M], jlo=ints[:, _JLO], box=ints[:, _BOX:_BOX + 4].T,
                      reach2=ints[:, _REACH2:_REACH2 + 2].T, inside=ints[:, _INSIDE], window_hi=ints[:, _WINDOW_HI])
    state = EMState(s=floats[:, _S], wsum=floats[:, _WSUM], nobs=ints[:, _NOBS], nfar=ints[:, _NFAR],
                    far_ratio=floats[:, _FAR_RATIO:_FAR_RATIO + 2], far_log=floats[:, _FAR_LOG:_FAR_LOG + 2],
                    stamp=ints[:, _STAMP], slot=ints[:, _SLOT])
    return columns, state


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
    """The tiles' scratch; ``ctl`` holds the control words, the rest grows on demand."""

    ctl: np.ndarray  # (1,) CONTROL
    active: np.ndarray  # (R / 64 + 1,) uint64 bit set of the band's readings (positions) active at the row
    seg_ptr: np.ndarray  # (n_seg + 1,) int64
    seg_list: np.ndarray  # int64 readings of each segment, ascending
    count: np.ndarray  # int64 pairs per candidate of the tile (+1)
    pair_pos: np.ndarray  # int64 listing (position in the tile's reading list) of each window pair
    pair_j: np.ndarray  # int64 template entry
    pair_g: np.ndarray  # float64 its Gaussian (0 before the window)
    obs_j: np.ndarray  # int64 arena: per slot its reading (header), then a bit per window entry (occupied or not)
    obs_g: np.ndarray  # float64 arena: the window obstacles' Gaussians, in range order
    pre: np.ndarray  # float64 arena: their prefix sums (one more than obstacles)
    seg_fill: np.ndarray  # (n_seg,) int64 scratch of the segment lists
    tile_t: np.ndarray  # int64 per listing: its reading
    far_lo: np.ndarray  # int64 per listing: the tile columns where the cone's cells lie before its window
    far_hi: np.ndarray  # (far_hi < far_lo: none)
    far_sum: np.ndarray  # (2, SEGMENT + 1) float64 differences of sum_t log far ratio along the tile (add, remove)
    spans: np.ndarray  # listing.SPAN the row's listed readings (seg_list points into it)
    seg_mask: np.ndarray  # (n_seg,) int64 bit k of segment s: column s * SEGMENT + k holds a candidate
    # the band's readings (``mapping.sweeps``), by position
    members: np.ndarray  # int64 position -> reading
    enter: np.ndarray  # int64 positions by their readings' extent row_lo (stable; ``EMReadings.enter`` for all)
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
    rows = np.zeros((2, n_base, 2 * ext + 1, 6), dtype=np.int32)
    rows[..., 3] = -1
    rows[..., 5] = -1
    heard = templates.heard.astype(bool) if templates.heard.size else np.ones(total, dtype=bool)
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
            # a row of a (convex) cone is a run of cells: positions follow from the other offset
            if np.any(rows[kind, b, filled, 3] - rows[kind, b, filled, 2] + 1 != counts[filled]):
                raise AssertionError("a template row is not a run of consecutive cells")
            h = heard[s:e]
            lo = np.full(2 * ext + 1, np.iinfo(np.int32).max, dtype=np.int64)
            hi = np.full(2 * ext + 1, np.iinfo(np.int32).min, dtype=np.int64)
            np.minimum.at(lo, key[h] + ext, other[h])
            np.maximum.at(hi, key[h] + ext, other[h])
            some = hi >= lo
            rows[kind, b, some, 4] = lo[some]
            rows[kind, b, some, 5] = hi[some]
            rows[kind, b, ~some, 4] = 1  # none heard: an empty run
            rows[kind, b, ~some, 5] = 0
    groups = RowGroups(rows, j_all, box)
    for a in groups:
        a.setflags(write=False)
    return groups
