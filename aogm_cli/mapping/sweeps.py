"""EM's sweeps as ``run_em`` runs them: the grid's column bands (``sweep_bands``) colour by colour, a colour's bands
at once on threads (``Sweeps``), each a tile-kernel call resumed after every pause and every growth of its scratch."""

from __future__ import annotations

import queue
import threading
import time
from dataclasses import dataclass

import numpy as np

from aogm_cli.core.budget import active_limits, in_parts
from aogm_cli.mapping.em_kernels import layout as L
from aogm_cli.mapping.em_kernels import listing, tiles
from aogm_cli.sensor_models.cone import flat_offsets

# bytes of slack around a scratch's small arrays: two threads' control words and tile sums, written at every
# tile, must not share a cache line wherever the allocator puts them (docs/algorithms.md)
SLACK = 128


def _apart(shape, dtype=np.int64) -> np.ndarray:
    """Zeros of ``shape`` (C-contiguous) with SLACK bytes of their own before and after."""
    n, size = int(np.prod(shape)), np.dtype(dtype).itemsize
    return np.zeros(n * size + 2 * SLACK, dtype=np.uint8)[SLACK:SLACK + n * size].view(dtype).reshape(shape)


def _work(readings: L.EMReadings, n_seg: int) -> L.TileWork:
    n_readings = readings.ints.shape[0]
    pairs, room, listed = 1 << 16, 1 << 14, max(1024, n_readings // 8)
    none = np.zeros(0, dtype=np.int64)  # the band's readings, set per band (``Sweeps._band``)
    return L.TileWork(
        ctl=_apart(1, L.CONTROL), active=_apart(n_readings // 64 + 1, np.uint64), seg_ptr=_apart(n_seg + 1),
        seg_list=np.empty(listed, dtype=np.int64), count=_apart(L.SEGMENT + 1),
        pair_pos=np.empty(pairs, dtype=np.int64), pair_j=np.empty(pairs, dtype=np.int64), pair_g=np.empty(pairs),
        obs_j=np.empty(room, dtype=np.int64), obs_g=np.empty(room), pre=np.empty(room), seg_fill=_apart(n_seg),
        tile_t=_apart(1024), far_lo=_apart(1024), far_hi=_apart(1024),
        far_sum=_apart((2, L.SEGMENT + 1), np.float64),
        spans=np.empty(listed, dtype=listing.SPAN), seg_mask=_apart(n_seg), members=none, enter=none, leave=none,
        window_leave=none)


# A sweep visits column bands colour by colour (``sweep_bands``): bands of one colour lie further apart than
# any cone reaches, so they are swept at once on threads with the result of one after the other, in an order
# set by the problem alone (the same map on any thread count). Below BAND_READINGS readings a problem is one
# band: the band order would move small maps for little gain (docs/algorithms.md, "EM's sweep on several threads").
BAND_READINGS = 10000


@dataclass(frozen=True)
class Band:
    """Tile segments [seg_lo, seg_hi) of every row, and the readings whose cones reach them."""

    seg_lo: int
    seg_hi: int
    members: np.ndarray  # int64 readings
    enter: np.ndarray  # int64 positions in members by their readings' row_lo (stable)
    leave: np.ndarray  # ... by row_hi
    window_leave: np.ndarray  # ... by window_hi


def sweep_bands(rd: L.EMReadings, width: int) -> tuple[list[list[Band]], np.ndarray | None]:
    """The bands of one sweep by colour (those between two of one colour span any cone), and the readings' order
    (None: as they are): by middle column's band (threads seldom share a cache line), then by first row."""
    n_read = rd.ints.shape[0]
    n_seg = -(-width // L.SEGMENT)
    box = rd.extent.T
    live = box[0] <= box[1]
    whole = [[Band(0, n_seg, np.arange(n_read, dtype=np.int64), rd.enter.astype(np.int64),
                   rd.leave.astype(np.int64), rd.window_leave.astype(np.int64))]]
    if n_read < BAND_READINGS or not live.any():
        return whole, None
    span = int((box[3] - box[2] + 1)[live].max())
    w = -(-span // (2 * L.SEGMENT))
    colours = 1 + -(-span // (w * L.SEGMENT))
    n_bands = n_seg // w
    if n_bands <= colours:
        return whole, None
    middle = np.where(live, (box[2].astype(np.int64) + box[3]) // (2 * w * L.SEGMENT), -1)
    order = np.lexsort((box[0], middle))
    box, live, window_hi = box[:, order], live[order], rd.ints["window_hi"][order]
    edges = [i * w for i in range(n_bands)] + [n_seg]
    bands = []
    for lo, hi in zip(edges[:-1], edges[1:], strict=True):
        members = np.flatnonzero(live & (box[2] < hi * L.SEGMENT) & (box[3] >= lo * L.SEGMENT)).astype(np.int64)
        orders = (np.argsort(key[members], kind="stable").astype(np.int64) for key in (box[0], box[1], window_hi))
        bands.append(Band(lo, hi, members, *orders))
    return [bands[c::colours] for c in range(colours)], order


def _permuted(rd: L.EMReadings, order: np.ndarray) -> L.EMReadings:
    """Copies of ``rd``'s tables, state and extents in ``order`` (no reading order: a band has its own)."""
    none = rd.enter[:0]
    return L.EMReadings(ints=rd.ints[order], floats=rd.floats[order], extent=rd.extent[order], enter=none, leave=none,
                        window_leave=none)


def _grown(work: L.TileWork) -> L.TileWork:
    """``work`` with every buffer the kernel asked for (ctl's need_* sizes) half as large again."""
    ctl = work.ctl[0]
    grow = {}
    if ctl["need_list"] > work.seg_list.shape[0]:
        grow["seg_list"] = np.empty(int(ctl["need_list"] * 1.5) + 1, dtype=np.int64)
    if ctl["need_list"] > work.spans.shape[0]:
        grow["spans"] = np.empty(int(ctl["need_list"] * 1.5) + 1, dtype=listing.SPAN)
    if ctl["need_list"] > work.far_lo.shape[0]:
        size = int(ctl["need_list"] * 1.5) + 1
        grow |= {name: np.empty(size, dtype=np.int64) for name in ("tile_t", "far_lo", "far_hi")}
    if ctl["need_pairs"] > work.pair_pos.shape[0]:
        size = int(ctl["need_pairs"] * 1.5) + 1
        grow |= {"pair_pos": np.empty(size, dtype=np.int64), "pair_j": np.empty(size, dtype=np.int64),
                 "pair_g": np.empty(size)}
    if ctl["need_room"] > work.obs_j.shape[0]:
        need = int(ctl["need_room"])
        size = max(need, min(int(need * 1.5) + 1, L.ARENA_ENTRIES))
        used = int(ctl["bump"])  # live slots keep their places
        for name in ("obs_j", "obs_g", "pre"):
            old = getattr(work, name)
            grow[name] = np.empty(size, dtype=old.dtype)
            grow[name][:used] = old[:used]
    ctl["need_list"] = ctl["need_pairs"] = ctl["need_room"] = 0
    ctl["listed"] = -1  # the row is listed again (into the new buffers)
    return work._replace(**grow)


def _scratch_bytes(work: L.TileWork) -> int:
    return int(sum(a.nbytes for a in work))


class Sweeps:
    """The sweeps of one EM run over ``cand``; as a context manager, leaves the tables in the problem's order."""

    def __init__(self, problem, cand: L.Candidates):  # problem: an em.EMProblem (the layer above)
        rd = problem.readings
        self.problem, self.cand, self.model = problem, cand, problem.model
        self.kernel_args = (problem.templates.kernel_arrays, flat_offsets(problem.templates, problem.shape[1]),
                            L.row_groups(problem.templates))
        self.phases, self.order = sweep_bands(rd, problem.shape[1])
        # the readings and their state by column while the bands sweep (put back on leaving)
        self.tables = rd if self.order is None else _permuted(rd, self.order)
        self.threads = min(active_limits().thread_count(), max(len(bands) for bands in self.phases))
        self.works = queue.SimpleQueue()  # one scratch per thread
        for _ in range(self.threads):
            self.works.put(_work(self.tables, cand.tile_clock.shape[1]))
        self.peak = [0, 0]  # the most pairs of a tile, the bytes of a thread's scratch
        self.clock = 0  # accepted flips so far: a band starts at the clock its colour starts at
        self.seconds: dict[int, float] = {}  # each band's (by seg_lo) time in the last pass: their order
        self.band_seconds = 0.0  # the bands' times added up: against the wall time, how busy the threads were

    def __enter__(self) -> Sweeps:
        return self

    def __exit__(self, *exc) -> None:
        if self.order is not None:
            self.problem.readings.ints[self.order] = self.tables.ints
            self.problem.readings.floats[self.order] = self.tables.floats

    def one_pass(self, mode: int) -> tuple[int, int, int]:
        """One sweep (``mode`` SWEEP) or scoring pass (SCORE): (flips, candidates scored, pairs generated)."""
        totals = [0, 0, 0]
        for bands in self.phases:
            # the costliest bands first, so that the threads end together (the order changes nothing computed)
            by_cost = sorted(bands, key=lambda band: -self.seconds.get(band.seg_lo, 0.0))
            done = in_parts(len(by_cost), lambda k, stop, by_cost=by_cost: self._band(by_cost[k], mode, stop))
            for i in range(3):
                totals[i] += sum(d[i] for d in done)
            self.band_seconds += sum(self.seconds[band.seg_lo] for band in bands)
            self.clock = max(d[3] for d in done)
        return tuple(totals)

    def _band(self, band: Band, mode: int, stop: threading.Event) -> tuple[int, int, int, int]:
        """Sweep one band with a scratch of the pool: (flips, scored, pairs, the clock after)."""
        work = self.works.get()
        t0 = time.perf_counter()
        try:
            work.ctl.fill(0)
            ctl = work.ctl[0]
            ctl["mode"], ctl["clock"] = mode, self.clock
            ctl["sg_lo"], ctl["sg_hi"], ctl["listed"] = band.seg_lo, band.seg_hi, -1
            work = work._replace(members=band.members, enter=band.enter, leave=band.leave,
                                 window_leave=band.window_leave)
            work.active.fill(0)
            self.peak[1] = max(self.peak[1], _scratch_bytes(work))
            while not stop.is_set():
                ctl["budget"] = L.PAUSE_WORK
                status = tiles._sweep_tiles(*self.kernel_args, self.tables, self.model, self.cand, work)
                if status == L.DONE:
                    break
                if status == L.NEED_BUFFERS:
                    work = _grown(work)
                    self.peak[1] = max(self.peak[1], _scratch_bytes(work))
                # PAUSED: back in Python, where a pending signal's handler runs (core.interrupts); resume
            self.peak[0] = max(self.peak[0], work.pair_pos.shape[0])
            return tuple(int(ctl[name]) for name in ("flips", "scored", "pairs", "clock"))
        finally:
            self.seconds[band.seg_lo] = time.perf_counter() - t0
            self.works.put(work)
