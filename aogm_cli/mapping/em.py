"""EM mapping with forward sensor models (Thrun 2003): hill climbing by single-cell flips.

Each candidate flip is scored by the exact change of sum_t log p(z_t | m) over the readings
whose cones hold the cell, plus the occupancy prior: the E-step redone for those readings
after every accepted flip (generalised EM), so the objective never decreases and EM can
create obstacles from an empty start. ``run_em`` works on any set of cells with every other
cell held fixed, using only the readings of the given index: the adaptive mapper calls it
once per group of clusters. ``map_em`` is the em mode: every observed cell a candidate.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from aogm_cli.core.occupancy_map import OccupancyMap
from aogm_cli.mapping.em_kernels import (
    EMModel,
    PairIndex,
    SweepStamps,
    _init_state,
    _objective,
    _pair_index,
    _residual,
    _residual_from_gains,
    _sweep,
)
from aogm_cli.mapping.params import EMConfig, MapParams
from aogm_cli.mapping.pipeline import Progress, forward_templates, lay_out_readings, log_grid, params_json
from aogm_cli.mapping.sensor_models.forward_model import ForwardIndex, build_forward_index
from aogm_cli.mapping.standard import standard_pass


@dataclass
class EMResult:
    """What EM did: sweeps run, flips and objective per sweep, and each candidate's residual p."""

    sweeps: int
    flips: list[int]
    objective: list[float]  # after each sweep; objective[0] is the start
    candidates: np.ndarray  # flat cell ids EM was free to change
    residual: np.ndarray  # p(m_x = 1 | Z, m*) of each candidate


def pair_index(index: ForwardIndex, candidates: np.ndarray) -> PairIndex:
    """Cell -> readings index for ``candidates``: a ``PairIndex`` (cand_cell, cand_ptr, pair_t,
    pair_e, pair_g).

    Only the candidates appear (each with its (reading, entry) pairs in reading order, and
    each pair's Gaussian, stored along the pairs for the sweeps); other cells of the cones
    are held fixed by EM. The look-up table spans the candidates' range of flat ids only, so
    a small cluster costs little.
    """
    candidates = np.ascontiguousarray(candidates, dtype=np.int64)
    if candidates.size > 1 and not np.all(candidates[1:] > candidates[:-1]):
        candidates = np.unique(candidates)
    if candidates.size == 0:
        empty = np.zeros(0, dtype=np.int64)
        return PairIndex(candidates, np.zeros(1, dtype=np.int64), empty, empty, np.zeros(0))
    lo = int(candidates[0])
    lookup = np.full(int(candidates[-1]) - lo + 1, -1, dtype=np.int64)
    lookup[candidates - lo] = np.arange(candidates.size)
    return _pair_index(index.kernel_arrays, candidates, lookup, lo)


def run_em(
    index: ForwardIndex,
    occupied: np.ndarray,
    candidates: np.ndarray,
    config: EMConfig,
    progress: Callable[[int, int, float], None] | None = None,
) -> EMResult:
    """Hill-climb the binary map over ``candidates`` (flat ids); ``occupied`` (flat bool) is
    updated in place, every other cell stays as it is. Sweeps until no flip improves the
    objective or ``config.max_sweeps``; ``progress(sweep, flips, objective)`` after each."""
    if occupied.dtype != np.bool_ or occupied.ndim != 1:
        raise ValueError("occupied must be a flat bool array")
    p_hit = float(config.forward.p_hit)
    pairs = pair_index(index, candidates)
    fwd = index.kernel_arrays
    max_entries = int(np.max(np.diff(index.ptr))) if index.n_readings else 0
    model = EMModel(p_hit, float(config.l_prior), (1.0 - p_hit) ** np.arange(max_entries + 1, dtype=np.float64))
    state = _init_state(fwd, model, occupied)
    objective = [_objective(fwd, model, state, occupied, pairs.cand_cell)]
    flips: list[int] = []
    n_cand = pairs.cand_cell.shape[0]
    stamps = SweepStamps(np.zeros(index.n_readings, dtype=np.int64), np.full(n_cand, -1, dtype=np.int64),
                         np.zeros(1, dtype=np.int64), np.zeros(n_cand, dtype=np.float64))
    for sweep in range(1, config.max_sweeps + 1):
        n_flips, _ = _sweep(pairs, fwd, model, occupied, state, stamps)
        flips.append(int(n_flips))
        objective.append(_objective(fwd, model, state, occupied, pairs.cand_cell))
        if progress:
            progress(sweep, int(n_flips), objective[-1])
        if n_flips == 0:
            break
    if flips and flips[-1] == 0:
        residual = _residual_from_gains(pairs.cand_cell, occupied, stamps.last_gain, model.l_prior)
    else:  # stopped by max_sweeps: score every candidate once more
        residual = _residual(pairs, fwd, model, occupied, state)
    return EMResult(len(flips), flips, [float(v) for v in objective], pairs.cand_cell, residual)


def em_candidates(index: ForwardIndex, n_cells: int) -> np.ndarray:
    """The cells some reading's cone holds (sorted flat ids): a boolean mask, not a sort."""
    seen = np.zeros(n_cells, dtype=bool)
    seen[index.cell] = True
    return np.flatnonzero(seen)


def map_em(log, params: MapParams, progress: Progress | None = None) -> OccupancyMap:
    """The em mode: Thrun's EM map of a log source (``pipeline``); every observed cell is a
    candidate, started from the thresholded standard map (or empty, ``em.start``)."""
    config = params.em
    grid = log_grid(log, params.resolution)
    whole = log.read()  # EM needs every reading in memory: read the scans once
    log_odds, observed, t_standard = standard_pass(log, grid, params, chunks=[(0, whole.time, whole.pose, whole.ranges)])
    forward_templates(grid, log.sensor)  # one-time set-up, cached, outside the clock
    t0 = time.perf_counter()
    run = lay_out_readings(whole.pose, whole.ranges, log.sensor, grid)
    t_readings = time.perf_counter() - t0
    t0 = time.perf_counter()
    index = build_forward_index(run.rows, run.cols, run.bins, run.z, grid, run.templates, log.sensor.max_range,
                                config.forward)
    candidates = em_candidates(index, grid.height * grid.width)
    t_index = time.perf_counter() - t0
    occupied = (log_odds > 0).reshape(-1) if config.start == "standard" else np.zeros(grid.height * grid.width, bool)
    occupied = np.ascontiguousarray(occupied)

    def on_sweep(sweep, flips, objective):
        if progress:
            progress("em sweep", sweep, config.max_sweeps)

    t0 = time.perf_counter()
    result = run_em(index, occupied, candidates, config, on_sweep)
    probability = np.full(grid.height * grid.width, 1.0 / (1.0 + math.exp(-config.l_prior)), dtype=np.float32)
    probability[result.candidates] = result.residual
    probability = probability.reshape(grid.shape)
    probability[~observed] = 0.5
    t_em = time.perf_counter() - t0
    stats = {
        "sweeps": result.sweeps,
        "flips_per_sweep": result.flips,
        "objective_per_sweep": result.objective,
        "candidate_cells": int(result.candidates.size),
        "index_entries": int(index.cell.size),
        "phase_seconds": {"standard": t_standard, "readings": t_readings, "index": t_index, "em": t_em},
    }
    return OccupancyMap(
        grid=grid,
        probability=probability,
        observed=observed,
        mode="em",
        params=params_json(params, "em", grid),
        runtime_s=t_standard + t_readings + t_index + t_em,
        source_log=log.path,
        occupied=occupied.reshape(grid.shape) & observed,
        stats=stats,
    )
