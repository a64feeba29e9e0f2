"""EM mapping with forward sensor models (Thrun 2003): hill climbing by single-cell flips, each scored exactly, the
E-step redone after every accepted flip (generalised EM: the objective never decreases, obstacles grow from an empty
start); cones regenerated tile by tile (``em_kernels``). ``run_em`` works on any cells, the others held fixed."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from aogm_cli.mapping.em_kernels import layout as L
from aogm_cli.mapping.em_kernels.extents import _box_of_cells, _far_gains, _reading_extent, _window_rows
from aogm_cli.mapping.em_kernels.likelihood import _init_state, _join_parents, _objective, _residual_from_gains
from aogm_cli.mapping.params import EMConfig
from aogm_cli.mapping.sweeps import Sweeps
from aogm_cli.sensor_models.cone import flat_offsets
from aogm_cli.sensor_models.forward_model import ForwardModelConfig, cone_limits, reading_constants
from aogm_cli.sensor_models.readings import (
    READING_PARTS,
    LaidOutReadings,
    forward_templates,
    reading_parts,
    summed_in_parts,
)


@dataclass
class EMResult:
    """What EM did: sweeps run, flips and objective per sweep, and each candidate's residual p."""

    sweeps: int
    flips: list[int]
    objective: list[float]  # after each sweep; objective[0] is the start
    candidates: np.ndarray  # flat cell ids EM was free to change
    residual: np.ndarray  # p(m_x = 1 | Z, m*) of each candidate
    scored: list[int]  # candidates scored per sweep (the rest were unchanged since)
    pairs: list[int]  # (candidate, reading) pairs generated per sweep
    peak_pairs: int  # the most pairs one tile held
    scratch_bytes: int  # the tiles' scratch (of one thread) at its largest
    threads: int = 1  # the sweeps' threads (mapping.sweeps: several where the grid holds bands)
    band_seconds: float = 0.0  # the sweeps' work, each band's time added up (on one thread: their wall time)


def em_readings(cones, templates, grid, z_max: float, config: ForwardModelConfig,
                select: np.ndarray | None = None, shadow: np.ndarray | None = None) -> L.EMReadings:
    """The readings ``cones`` (those ``select`` picks, taken a column at a time without copies) as EM's kernels
    take them: NaN left out, +inf a max-range reading, ``shadow`` cutting cones short (``cone_limits``)."""
    rows, cols, bins, z = cones
    pick = (lambda a: np.asarray(a).reshape(-1)) if select is None else (lambda a: np.asarray(a).reshape(-1)[select])
    z = pick(z).astype(np.float64, copy=False)
    if np.isnan(z).any():
        raise ValueError("NaN readings must be left out of EM's readings")
    z, limits = cone_limits(z, z_max, config, None if shadow is None else pick(shadow))
    n = z.shape[0]
    ints, floats = np.zeros(n, dtype=L.READING_INTS), np.zeros(n, dtype=L.READING_FLOATS)
    for name, a in (("row0", rows), ("col0", cols), ("bin", bins)):
        ints[name] = pick(a)
    z_eff = floats["z"]
    z_eff[:] = np.where(np.isfinite(z), np.minimum(z, z_max), z_max)
    # entries before this range are beyond the Gaussian's window (a margin against rounding)
    lower = z_eff - config.window * config.sigma - 1e-9
    no_order = np.zeros(0, dtype=np.int32)
    rd = L.EMReadings(ints=ints, floats=floats, extent=np.zeros((0, 4), dtype=np.int32), enter=no_order, leave=no_order,
                      window_leave=no_order)  # the extents and orders are not needed yet
    groups, gauss = L.row_groups(templates), (float(config.sigma), float(config.window))
    reading_parts(n, lambda _, span: _reading_extent(templates.kernel_arrays, groups, rd, (limits, lower), gauss,
                                                     grid.shape, span))
    g0, const, _ = reading_constants(z, z_max, config)
    floats["g0"] = g0
    floats["const"] = const
    # needs the fields above only
    reading_parts(n, lambda _, span: _window_rows(templates.kernel_arrays, rd, grid.height, span))
    return _with_extent(rd, np.ascontiguousarray(ints["box"]))._replace(window_leave=_order(ints["window_hi"]))


def _with_extent(rd: L.EMReadings, extent: np.ndarray) -> L.EMReadings:
    """``rd`` active over ``extent`` ((R, 4) int32, ``EMReadings.extent``), with its orders."""
    return rd._replace(extent=extent, enter=_order(extent[:, 0]), leave=_order(extent[:, 1]))


def _order(key: np.ndarray) -> np.ndarray:
    """The readings by ``key`` (stable), as int32."""
    return np.argsort(key, kind="stable").astype(np.int32)


@dataclass
class EMProblem:
    """EM's readings under a map, with their state (``em_problem``)."""

    readings: L.EMReadings
    model: L.EMModel
    state: L.EMState
    templates: object
    shape: tuple[int, int]
    seen: np.ndarray  # flat bool: cells some cone holds
    window: np.ndarray | None  # flat bool: cells in some reading's window (``_flippable``; None: not marked)
    parent: np.ndarray | None  # union-find over cluster ids (with labels): clusters sharing a reading


def em_problem(rd: L.EMReadings, templates, shape: tuple[int, int], occupied: np.ndarray, config: EMConfig,
               labels: np.ndarray | None = None) -> EMProblem:
    """Every reading's likelihood state under ``occupied`` and, with ``labels``, which clusters share a reading,
    extents narrowed to their cells. Writes into ``rd``'s tables: one problem per ``em_readings`` result."""
    fwd = config.forward
    p_hit = float(fwd.p_hit)
    n = rd.ints.shape[0]
    top = int(rd.ints["m"].max()) if n else 0
    model = L.EMModel(p_hit=p_hit, l_prior=float(config.l_prior),
                      qpow=(1.0 - p_hit) ** np.arange(top + 1, dtype=np.float64), w=1.0 - fwd.p_rand - fwd.p_max,
                      sigma=float(fwd.sigma), window=float(fwd.window))
    seen = np.zeros(shape[0] * shape[1], dtype=np.bool_)
    # the window cells ``_flippable`` asks for, marked in the same walk (a cluster problem holds none free)
    window = np.zeros_like(seen) if labels is None and config.l_prior < 0.0 else None
    if labels is None:
        marks = [(seen, seen[:0] if window is None else window, np.zeros(0, dtype=np.int64),
                  np.zeros(0, dtype=np.int64), np.zeros((0, 4), dtype=np.int32))]
        marks *= READING_PARTS
    else:
        labels = np.ascontiguousarray(labels, dtype=np.int64).reshape(-1)
        box = np.empty((n, 4), dtype=np.int32)
        # a union-find per part, joined after: one root (the least id) per group for any thread count
        marks = [(seen, seen[:0], labels, np.arange(int(labels.max(initial=0)) + 1, dtype=np.int64), box)
                 for _ in range(READING_PARTS)]
    flat, occupied = flat_offsets(templates, shape[1]), _flat_bool(occupied)
    reading_parts(n, lambda k, span: _init_state(templates.kernel_arrays, flat, rd, model, occupied, shape, marks[k],
                                                 span))  # into state
    parent = None
    if labels is not None:
        parent = marks[0][3]
        for other in marks[1:]:
            _join_parents(parent, other[3])
        rd = _with_extent(rd, box)
    return EMProblem(rd, model, L.em_state(rd), templates, shape, seen, window, parent)


def run_problem(run: LaidOutReadings, config: EMConfig, select: np.ndarray, occupied: np.ndarray,
                labels: np.ndarray | None = None) -> EMProblem:
    """EM's problem of ``run``'s readings ``select`` picks under ``occupied`` (``em_readings``, ``em_problem``)."""
    rd = em_readings(run.cones, run.templates, run.grid, run.sensor.max_range, config.forward, select=select,
                     shadow=run.shadow)
    return em_problem(rd, run.templates, run.grid.shape, occupied, config, labels=labels)


def _flat_bool(a: np.ndarray) -> np.ndarray:
    if a.dtype != np.bool_ or a.ndim != 1 or not a.flags.c_contiguous:
        raise ValueError("occupied must be a flat, contiguous bool array")
    return a


def _candidates(cells: np.ndarray, shape: tuple[int, int]) -> L.Candidates:
    height, width = shape
    cells = np.ascontiguousarray(cells, dtype=np.int64)
    if cells.size > 1 and not np.all(cells[1:] > cells[:-1]):
        cells = np.unique(cells)
    of_cell = np.full(height * width, -1, dtype=np.int32)
    of_cell[cells] = np.arange(cells.size, dtype=np.int32)
    row_first = np.searchsorted(cells, np.arange(height + 1, dtype=np.int64) * width)
    n_seg = -(-width // L.SEGMENT)
    return L.Candidates(cell=cells, of_cell=of_cell, row_first=row_first, occupied=np.zeros(0, dtype=np.bool_),
                        stamp=np.full(cells.size, -1, dtype=np.int64), last_gain=np.zeros(cells.size),
                        tile_clock=np.full((n_seg, height), -1, dtype=np.int64).T)  # a segment's clocks in one run
    # of memory: two bands' threads write apart


# the share of candidates held free (``_flippable``) at which EM leaves them out of its sweeps: their
# gains then cost one walk of every cone's far run, which pays when most go (docs/algorithms.md)
HELD_FREE_SHARE = 0.5


def run_em(problem: EMProblem, occupied: np.ndarray, candidates: np.ndarray, config: EMConfig,
           progress: Callable[[int, int, float], None] | None = None, final: bool = True) -> EMResult:
    """Hill-climb the binary map over ``candidates``, ``occupied`` in place; with ``final``, a run stopped by
    ``config.max_sweeps`` scores every candidate once more, so that its residuals describe its map."""
    occupied = _flat_bool(occupied)
    every = _candidates(candidates, problem.shape).cell
    swept, held_free = _flippable(problem, occupied, every)
    cand = _candidates(swept, problem.shape)._replace(occupied=occupied)
    flips, scored, pairs = [], [], []
    sweeps = Sweeps(_narrowed(problem, swept) if held_free.size else problem, cand)
    model, tables = problem.model, sweeps.tables
    objective = [_objective(tables, model, occupied, cand.cell)]
    with sweeps:
        for sweep in range(1, config.max_sweeps + 1):
            n_flips, n_scored, n_pairs = sweeps.one_pass(L.SWEEP)
            flips.append(n_flips)
            scored.append(n_scored)
            pairs.append(n_pairs)
            objective.append(_objective(tables, model, occupied, cand.cell))
            if progress:
                progress(sweep, n_flips, objective[-1])
            if n_flips == 0:
                break
        if final and not (flips and flips[-1] == 0):  # stopped by max_sweeps: score every candidate once more
            sweeps.one_pass(L.SCORE)
    peak = sweeps.peak
    gain = np.empty(every.size)
    gain[np.searchsorted(every, cand.cell)] = cand.last_gain
    if held_free.size:
        gain[np.searchsorted(every, held_free)] = _held_free_gains(problem, held_free)
    residual = _residual_from_gains(every, occupied, gain, model.l_prior)
    return EMResult(len(flips), flips, [float(v) for v in objective], every, residual, scored, pairs,
                    int(peak[0]), int(peak[1]), sweeps.threads, sweeps.band_seconds)


def _flippable(problem: EMProblem, occupied: np.ndarray, cells: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``cells`` (sorted) split into those EM sweeps and those it leaves free, when at least
    ``HELD_FREE_SHARE`` are such: free cells in no reading's window while the prior is below one half.
    There an obstacle only scales each echo's chance by 1 - p_hit, so occupancy can only lower the
    objective; their gains are one walk of the far runs (``_held_free_gains``). Not in a cluster
    problem, whose extents are narrowed already (no gain measured: docs/algorithms.md)."""
    if problem.window is None or cells.size == 0:  # none marked: a cluster problem, or a prior of 0.5 or more
        return cells, cells[:0]
    swept = problem.window[cells] | occupied[cells]
    if np.count_nonzero(~swept) < HELD_FREE_SHARE * cells.size:
        return cells, cells[:0]
    return cells[swept], cells[~swept]


def _narrowed(problem: EMProblem, swept: np.ndarray) -> EMProblem:
    """``problem`` with extents narrowed to the cells of ``swept`` (as a cluster problem's); the same tables."""
    rd = problem.readings
    mask = np.zeros(problem.shape[0] * problem.shape[1], dtype=np.bool_)
    mask[swept] = True
    box = np.empty((rd.ints.shape[0], 4), dtype=np.int32)
    tpl = problem.templates.kernel_arrays
    reading_parts(rd.ints.shape[0], lambda _, span: _box_of_cells(tpl, rd, problem.shape, mask, span, box))
    return dataclasses.replace(problem, readings=_with_extent(rd, box))


def _held_free_gains(problem: EMProblem, cells: np.ndarray) -> np.ndarray:
    """The gain of flipping each free, unwindowed cell of ``cells``, summed in fixed parts (any thread count alike)."""
    of_cell = np.full(problem.shape[0] * problem.shape[1], -1, dtype=np.int32)
    of_cell[cells] = np.arange(cells.size, dtype=np.int32)
    rd = problem.readings
    tpl = problem.templates.kernel_arrays
    out = np.zeros(cells.size)
    summed_in_parts(rd.ints.shape[0], out, lambda _, part, span: _far_gains(tpl, rd, problem.shape, of_cell, span, part))
    return out


@dataclass
class EMOutcome:
    """What EM's final run leaves: the model the map was made with, its result and problem."""

    config: EMConfig
    result: EMResult
    problem: EMProblem


# (EM config, flat occupied map, reading mask or None) -> (EM's problem under it, its candidates' flat ids)
ProblemFor = Callable[[EMConfig, np.ndarray, "np.ndarray | None"], tuple[EMProblem, np.ndarray]]


def em_step(problem_for: ProblemFor, on_sweep=None):
    """One EM run as calibration's rounds take it; on a subset of readings, not scored once more (``final``)."""
    def step(config: EMConfig, occ: np.ndarray, subset: np.ndarray | None):
        problem, candidates = problem_for(config, occ, subset)
        result = run_em(problem, occ, candidates, config, on_sweep, final=subset is None)
        return result.objective[-1], result.sweeps, result
    return step


def em_stats(outcome: EMOutcome | None) -> dict:
    """The map's statistics of EM's final run (zeros without one)."""
    if outcome is None:
        return {"sweeps": 0, "flips_per_sweep": [], "objective_per_sweep": [], "scored_per_sweep": [],
                "pairs_per_sweep": [], "candidate_cells": 0, "em_readings": 0, "index_entries": 0, "scratch_bytes": 0,
                "sweep_threads": 0, "band_seconds": 0.0}
    r = outcome.result
    return {"sweeps": r.sweeps, "flips_per_sweep": r.flips, "objective_per_sweep": r.objective,
            "scored_per_sweep": r.scored, "pairs_per_sweep": r.pairs, "candidate_cells": int(r.candidates.size),
            "em_readings": int(outcome.problem.readings.z.size), "index_entries": r.peak_pairs,
            "scratch_bytes": r.scratch_bytes, "sweep_threads": r.threads, "band_seconds": r.band_seconds}


def whole_log_problems(run: LaidOutReadings) -> ProblemFor:
    """The em mode's problems: every valid reading (of a subset, if given), every cell some cone holds."""
    keep = ~np.isnan(run.z)
    def problem_for(config: EMConfig, occ: np.ndarray, subset: np.ndarray | None):
        problem = run_problem(run, config, keep if subset is None else keep & subset, occ)
        return problem, np.flatnonzero(problem.seen)
    return problem_for


def prepared_templates(grid, sensor) -> None:
    """The forward templates of ``grid`` with their row groups, built or loaded before any clock starts."""
    L.row_groups(forward_templates(grid, sensor))
