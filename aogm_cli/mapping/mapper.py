"""Log file -> map, in each mode: the grid of a log, the standard and EM pipelines, timing.

``runtime_s`` counts the mapping work only: reading the log (I/O) is excluded, and the
compiled kernels are compiled (or loaded from numba's cache) by ``warm_up`` before timing.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from aogm_cli.grid import GridSpec
from aogm_cli.logfile import LogReader, SensorSpec
from aogm_cli.mapfile import OccupancyMap
from aogm_cli.mapping.beam import is_narrow_beam
from aogm_cli.mapping.cone import build_cone_templates, flat_offsets, reading_geometry, sensor_cells
from aogm_cli.mapping.em import EMConfig, run_em
from aogm_cli.mapping.forward_model import ForwardIndex, build_forward_index, select_readings
from aogm_cli.mapping.params import MapParams
from aogm_cli.mapping.standard import probability_from_log_odds, standard_map, standard_templates

Progress = Callable[[str, int, int], None]  # (phase, done, total)


def log_grid(reader: LogReader, resolution: float) -> GridSpec:
    """The truth grid of a simulated log; otherwise the poses' bounds plus max range."""
    grid = reader.truth_grid()
    if grid is not None:
        return grid
    pose = reader.poses()
    finite = np.isfinite(pose).all(axis=1)
    if not finite.any():
        from aogm_cli.errors import InputError

        raise InputError("no finite pose; cannot place a grid", file=reader.path, key="/scans/pose")
    sensor = reader.sensor
    reach = sensor.max_range + float(np.max(np.hypot(sensor.mount[:, 0], sensor.mount[:, 1]), initial=0.0))
    lo = pose[finite, :2].min(axis=0) - reach
    hi = pose[finite, :2].max(axis=0) + reach
    # snap the origin to the resolution so that maps of one log at one resolution align
    lo = np.floor(lo / resolution) * resolution
    return GridSpec.covering(lo[0], lo[1], hi[0], hi[1], resolution)


def echo_ranges(ranges: np.ndarray, grid: GridSpec) -> np.ndarray:
    """Ranges as both mappers use them: half a cell longer. A truth (and map) cell is
    occupied when its centre lies inside an obstacle, so the first occupied cell along a
    beam has its centre between 0 and 1 cell beyond the surface that echoed: half a cell on
    average. Without this, standard and EM maps put walls half a cell too near the robot."""
    return np.asarray(ranges, dtype=np.float64) + 0.5 * grid.resolution


class _Timed:
    """Wraps a chunk iterator and adds up the time spent reading (to subtract it)."""

    def __init__(self, chunks):
        self._chunks = iter(chunks)
        self.io_seconds = 0.0

    def __iter__(self):
        return self

    def __next__(self):
        t0 = time.perf_counter()
        try:
            return next(self._chunks)
        finally:
            self.io_seconds += time.perf_counter() - t0


def warm_up(sensor: SensorSpec, params: MapParams, em: bool = False) -> None:
    """Compile (or load from cache) the kernels on a tiny map, so that timing excludes it."""
    grid = GridSpec(0.0, 0.0, 0.5, 4, 4)
    tiny = SensorSpec(np.zeros((1, 3)), sensor.kind, sensor.beam_width, 0.0, 1.0, sensor.noise_sigma)
    pose = np.array([[1.0, 1.0, 0.0]])
    ranges = np.array([[0.9]], dtype=np.float32)
    log_odds, _ = standard_map([(0, np.zeros(1), pose, ranges)], tiny, grid, params.inverse_model)
    if em:
        templates = build_cone_templates(grid.resolution, tiny.beam_width, tiny.max_range)
        rows, cols, bins, _ = sensor_cells(pose, tiny, grid, templates)
        index = build_forward_index(rows, cols, bins, ranges, grid, templates, 1.0, params.em.forward)
        occupied = np.zeros(grid.height * grid.width, dtype=bool)
        run_em(index, occupied, np.unique(index.cell), EMConfig(params.em.forward, max_sweeps=1))
        from aogm_cli.mapping.cluster import cluster_contacts, cone_bands, coupled_groups

        region, _ = cone_bands(grid, templates, rows.reshape(-1), cols.reshape(-1), bins.reshape(-1),
                               ranges.reshape(-1).astype(np.float64), 0.2, 0.1, np.ones(grid.shape, dtype=bool))
        coupled_groups(cluster_contacts(index.ptr, region.reshape(-1)[index.cell].astype(np.int64)), 1)


def standard_pass(reader: LogReader, grid: GridSpec, params: MapParams, chunk: int = 4096, chunks=None):
    """(log_odds, observed, seconds of mapping work) for the whole log, streamed in chunks
    (``reader.chunks(chunk)``, or ``chunks`` when the caller already holds the scans).

    One-time set-up is done before the clock starts, like compilation: the cone templates
    and their per-grid-width tables are built (or found in their caches) by mapping no scans.
    Narrow beams (``beam.is_narrow_beam``) are traced as rays and need no templates; their
    readings go in as logged, not through ``echo_ranges``: a ray's hit is the cell holding its
    endpoint (OctoMap's convention; on the intel log 0.892 of endpoints land on occupied
    cells this way, 0.819 with the half-cell shift).
    """
    narrow = is_narrow_beam(reader.sensor, grid.resolution)
    templates = None if narrow else standard_templates(grid, reader.sensor)
    standard_map([], reader.sensor, grid, params.inverse_model, templates=templates)

    def prepared(r):  # the ranges as the mapper takes them
        return np.asarray(r, dtype=np.float32) if narrow else echo_ranges(r, grid).astype(np.float32)

    source = reader.chunks(chunk) if chunks is None else chunks
    timed = _Timed((s, t, p, prepared(r)) for s, t, p, r in source)
    t0 = time.perf_counter()
    log_odds, observed = standard_map(timed, reader.sensor, grid, params.inverse_model, templates=templates)
    seconds = time.perf_counter() - t0 - timed.io_seconds
    return log_odds, observed, seconds


def map_standard(path: str | Path, params: MapParams, progress: Progress | None = None) -> OccupancyMap:
    """The standard log-odds map of the log at ``path``."""
    with LogReader(path) as reader:
        grid = log_grid(reader, params.resolution)
        warm_up(reader.sensor, params)
        log_odds, observed, seconds = standard_pass(reader, grid, params)
        n_scans = reader.n_scans
    return OccupancyMap(
        grid=grid,
        probability=probability_from_log_odds(log_odds, observed),
        observed=observed,
        mode="standard",
        params=_params_json(params, "standard"),
        runtime_s=seconds,
        source_log=str(path),
        log_odds=log_odds,
        stats={"scans": n_scans, "phase_seconds": {"standard": seconds}},
    )


def readings_of(pose: np.ndarray, ranges: np.ndarray, sensor: SensorSpec, grid: GridSpec, templates):
    """All readings as flat arrays: sensor cell rows, cols, heading bins, and ranges shifted
    into template ranges: ``echo_ranges`` plus the sensor's offset from its cell's centre
    along the beam (``cone.reading_geometry``)."""
    rows, cols, bins, valid, offset = reading_geometry(pose, sensor, grid, templates)
    z = np.where(valid, echo_ranges(ranges, grid), np.nan) + offset
    return rows.reshape(-1), cols.reshape(-1), bins.reshape(-1), z.reshape(-1)


@dataclass
class _EMInputs:
    """What EM and adaptive mapping read from a log before their own work starts."""

    grid: GridSpec
    sensor: SensorSpec
    log_odds: np.ndarray
    observed: np.ndarray
    t_standard: float
    templates: object
    ranges: np.ndarray  # (T, S) as logged
    rows: np.ndarray
    cols: np.ndarray
    bins: np.ndarray
    z: np.ndarray


def _em_inputs(path: str | Path, params: MapParams) -> _EMInputs:
    """Read the log, compile, run the (timed) standard pass, and lay out every reading."""
    with LogReader(path) as reader:
        grid = log_grid(reader, params.resolution)
        sensor = reader.sensor
        warm_up(sensor, params, em=True)
        log = reader.read()  # EM needs every reading in memory: read the scans once
        pose, ranges = log.pose, log.ranges
        log_odds, observed, t_standard = standard_pass(reader, grid, params, chunks=[(0, log.time, pose, ranges)])
    templates = em_forward_templates(grid, sensor)
    rows, cols, bins, z = readings_of(pose, ranges, sensor, grid, templates)
    return _EMInputs(grid, sensor, log_odds, observed, t_standard, templates, ranges, rows, cols, bins, z)


def em_forward_templates(grid: GridSpec, sensor: SensorSpec):
    """The forward model's cone templates: the standard mapper's (one cache for both), with
    their flat offsets for this grid's width built (and cached) now, as one-time set-up."""
    templates = standard_templates(grid, sensor)
    flat_offsets(templates, grid.width)
    return templates


def map_em(path: str | Path, params: MapParams, progress: Progress | None = None) -> OccupancyMap:
    """Thrun's EM map of the log at ``path``: every observed cell is a candidate."""
    config = params.em
    run = _em_inputs(path, params)
    grid, sensor, log_odds, observed, t_standard = run.grid, run.sensor, run.log_odds, run.observed, run.t_standard
    templates, rows, cols, bins, z = run.templates, run.rows, run.cols, run.bins, run.z
    t0 = time.perf_counter()
    index = build_forward_index(rows, cols, bins, z, grid, templates, sensor.max_range, config.forward)
    t_index = time.perf_counter() - t0
    occupied = (log_odds > 0).reshape(-1) if config.start == "standard" else np.zeros(grid.height * grid.width, bool)
    occupied = np.ascontiguousarray(occupied)
    candidates = np.unique(index.cell)

    def on_sweep(sweep, flips, objective):
        if progress:
            progress("em sweep", sweep, config.max_sweeps)

    t0 = time.perf_counter()
    result = run_em(index, occupied, candidates, config, on_sweep)
    t_em = time.perf_counter() - t0
    probability = np.full(grid.height * grid.width, 1.0 / (1.0 + math.exp(-config.l_prior)), dtype=np.float32)
    probability[result.candidates] = result.residual
    probability = probability.reshape(grid.shape)
    probability[~observed] = 0.5
    stats = {
        "sweeps": result.sweeps,
        "flips_per_sweep": result.flips,
        "objective_per_sweep": result.objective,
        "candidate_cells": int(result.candidates.size),
        "index_entries": int(index.cell.size),
        "phase_seconds": {"standard": t_standard, "index": t_index, "em": t_em},
    }
    return OccupancyMap(
        grid=grid,
        probability=probability,
        observed=observed,
        mode="em",
        params=_params_json(params, "em"),
        runtime_s=t_standard + t_index + t_em,
        source_log=str(path),
        occupied=occupied.reshape(grid.shape) & observed,
        stats=stats,
    )


def cluster_forward_index(run: _EMInputs, clusters: np.ndarray, occupied: np.ndarray, forward) -> ForwardIndex:
    """The forward index EM inside ``clusters`` (ids, 0 outside) uses: the readings whose cones
    hold a cluster cell, each cone without the cells outside every cluster that the flat map
    ``occupied`` holds free (they stay free, and a free cell changes no likelihood)."""
    from aogm_cli.mapping.cluster import readings_near_clusters

    near = readings_near_clusters(clusters, run.rows, run.cols, run.z, run.grid, run.sensor.max_range, forward)
    in_cluster = clusters.reshape(-1) > 0
    return build_forward_index(run.rows[near], run.cols[near], run.bins[near], run.z[near], run.grid, run.templates,
                               run.sensor.max_range, forward, mask=in_cluster, held_free=~(in_cluster | occupied))


def map_adaptive(path: str | Path, params: MapParams, detector_path: str | None = None,
                 progress: Progress | None = None) -> OccupancyMap:
    """The paper's adaptive map: standard log-odds everywhere, then EM inside each cluster
    (cells outside the cluster held at the thresholded standard map); a cluster's cells get
    EM's residual probability."""
    from aogm_cli.detector.network import default_detector_path, load_detector
    from aogm_cli.mapping.cluster import (
        cluster_contacts,
        cone_bands,
        coupled_groups,
        label_clusters,
        near_occupied,
    )

    detector = load_detector(detector_path or default_detector_path())
    config = params.em
    run = _em_inputs(path, params)
    grid, sensor, log_odds, observed, t_standard = run.grid, run.sensor, run.log_odds, run.observed, run.t_standard
    templates, rows, cols, bins, z, ranges = run.templates, run.rows, run.cols, run.bins, run.z, run.ranges

    t0 = time.perf_counter()
    flags = detector.flag(ranges, sensor.max_range).reshape(-1)
    t_detect = time.perf_counter() - t0

    t0 = time.perf_counter()
    # a flagged cone's cluster is its band near the range, z - band_below .. z + alpha (where the
    # standard map thickens walls towards the robot), next to cells the standard map holds
    # occupied, minus cells it holds at its free clamp (mapping.cluster)
    region, _ = cone_bands(grid, templates, rows[flags], cols[flags], bins[flags], z[flags],
                           params.adaptive.band_below, params.inverse_model.alpha)
    region &= observed & (log_odds > params.inverse_model.clamp_min)
    region &= near_occupied(log_odds, params.adaptive.near_occupied)
    clusters, n_clusters = label_clusters(region)
    t_cluster = time.perf_counter() - t0

    t0 = time.perf_counter()
    occupied = np.ascontiguousarray((log_odds > 0).reshape(-1))  # the thresholded standard map
    probability = probability_from_log_odds(log_odds, observed).reshape(-1)
    sweeps, flips = [], []
    t_index = 0.0
    if n_clusters:
        # one index over the readings whose cones hold a cluster cell ...
        flat_clusters = clusters.reshape(-1)
        index = cluster_forward_index(run, clusters, occupied, config.forward)
        pairs = cluster_contacts(index.ptr, flat_clusters[index.cell])
        # ... clusters that share a reading are coupled through it: EM runs once per group of
        # coupled clusters (clusters that share none are independent, as the paper has them)
        group = coupled_groups(pairs, n_clusters)
        group_of_reading = np.zeros(index.n_readings, dtype=np.int64)
        group_of_reading[pairs[1]] = group[pairs[0] - 1]
        cell_group = np.where(flat_clusters > 0, group[np.maximum(flat_clusters, 1) - 1], -1)
        n_groups = int(group.max()) + 1
        t_index = time.perf_counter() - t0
        for k in range(n_groups):
            cells = np.flatnonzero(cell_group == k)
            readings = np.flatnonzero((group_of_reading == k) & (np.diff(index.ptr) > 0))
            # one group holding every reading of the index: use it as it is
            sub = index if n_groups == 1 else select_readings(index, readings)
            if config.start == "empty":
                occupied[cells] = False
            result = run_em(sub, occupied, cells, config)
            probability[result.candidates] = result.residual
            sweeps.append(result.sweeps)
            flips.append(int(sum(result.flips)))
            if progress:
                progress("cluster group", k + 1, n_groups)
    t_em = time.perf_counter() - t0 - t_index
    probability = probability.reshape(grid.shape)
    probability[~observed] = 0.5
    stats = {
        "clusters": n_clusters,
        "cells_in_clusters": int(region.sum()),
        "observed_cells": int(observed.sum()),
        "flagged_readings": int(flags.sum()),
        "readings": int(flags.size),
        "cluster_groups": len(sweeps),
        "em_sweeps_per_group": sweeps,
        "em_flips_per_group": flips,
        "index_entries": int(index.cell.size) if n_clusters else 0,
        "phase_seconds": {"standard": t_standard, "detector": t_detect, "clusters": t_cluster, "index": t_index,
                          "em": t_em},
        "detector": str(detector_path or "packaged"),
    }
    return OccupancyMap(
        grid=grid,
        probability=probability,
        observed=observed,
        mode="adaptive",
        params=_params_json(params, "adaptive") | {"detector": stats["detector"]},
        runtime_s=t_standard + t_detect + t_cluster + t_index + t_em,
        source_log=str(path),
        log_odds=log_odds,
        occupied=occupied.reshape(grid.shape) & observed,
        clusters=clusters,
        stats=stats,
    )


def _params_json(params: MapParams, mode: str) -> dict:
    d = params.as_dict()
    d["mode"] = mode
    return d
