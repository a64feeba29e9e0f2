"""The paper's adaptive mode: standard log-odds everywhere, then EM inside each cluster.

The detector flags readings (``detector.network``), the bands their cones sweep near their
ranges become clusters (``mapping.cluster``), and EM (``mapping.em.run_em``) runs once per
group of coupled clusters with every other cell held at the thresholded standard map; a
cluster's cells get EM's residual probability.
"""

from __future__ import annotations

import time

import numpy as np

from aogm_cli.core.occupancy_map import OccupancyMap
from aogm_cli.mapping.cluster import (
    cluster_contacts,
    cone_bands,
    coupled_groups,
    label_clusters,
    near_occupied,
    readings_near_clusters,
)
from aogm_cli.mapping.em import run_em
from aogm_cli.mapping.params import MapParams
from aogm_cli.mapping.pipeline import Progress, Readings, forward_templates, lay_out_readings, log_grid, params_json
from aogm_cli.mapping.sensor_models.forward_model import ForwardIndex, build_forward_index, select_readings
from aogm_cli.mapping.standard import probability_from_log_odds, standard_pass


def cluster_forward_index(run: Readings, clusters: np.ndarray, occupied: np.ndarray, forward) -> ForwardIndex:
    """The forward index EM inside ``clusters`` (ids, 0 outside) uses: the readings whose cones
    hold a cluster cell, each cone without the cells outside every cluster that the flat map
    ``occupied`` holds free (they stay free, and a free cell changes no likelihood)."""
    near = readings_near_clusters(clusters, run.rows, run.cols, run.z, run.grid, run.sensor.max_range, forward)
    in_cluster = clusters.reshape(-1) > 0
    return build_forward_index(run.rows[near], run.cols[near], run.bins[near], run.z[near], run.grid, run.templates,
                               run.sensor.max_range, forward, mask=in_cluster, held_free=~(in_cluster | occupied))


def find_clusters(run: Readings, flags: np.ndarray, log_odds: np.ndarray, observed: np.ndarray,
                  params: MapParams) -> tuple[np.ndarray, int]:
    """(cluster ids (H, W), count): a flagged cone's band near its range, z - band_below ..
    z + alpha (where the standard map thickens walls towards the robot), next to cells the
    standard map holds occupied, minus cells it holds at its free clamp."""
    region, _ = cone_bands(run.grid, run.templates, run.rows[flags], run.cols[flags], run.bins[flags], run.z[flags],
                           params.adaptive.band_below, params.inverse_model.alpha)
    region &= observed & (log_odds > params.inverse_model.clamp_min)
    region &= near_occupied(log_odds, params.adaptive.near_occupied)
    return label_clusters(region)


def em_in_clusters(run: Readings, clusters: np.ndarray, n_clusters: int, occupied: np.ndarray,
                   probability: np.ndarray, params: MapParams, progress: Progress | None = None) -> dict:
    """EM once per group of coupled clusters; ``occupied`` and ``probability`` (flat) are updated
    in place. Returns the stats of the run and the seconds spent indexing (``t_index``)."""
    config = params.em
    sweeps, flips = [], []
    t0 = time.perf_counter()
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
    return {"cluster_groups": len(sweeps), "em_sweeps_per_group": sweeps, "em_flips_per_group": flips,
            "index_entries": int(index.cell.size), "t_index": t_index}


def map_adaptive(log, params: MapParams, detector, detector_name: str = "packaged",
                 progress: Progress | None = None) -> OccupancyMap:
    """The adaptive mode on a log source (``pipeline``) with ``detector`` (anything with
    ``flag(ranges, max_range)``: a trained ``Detector`` or a ``ConstantDetector``)."""
    grid = log_grid(log, params.resolution)
    sensor = log.sensor
    whole = log.read()  # EM needs every reading in memory: read the scans once
    log_odds, observed, t_standard = standard_pass(log, grid, params, chunks=[(0, whole.time, whole.pose, whole.ranges)])
    forward_templates(grid, sensor)  # one-time set-up, cached, outside the clock
    t0 = time.perf_counter()
    run = lay_out_readings(whole.pose, whole.ranges, sensor, grid)
    t_readings = time.perf_counter() - t0

    t0 = time.perf_counter()
    flags = detector.flag(whole.ranges, sensor.max_range).reshape(-1)
    t_detect = time.perf_counter() - t0

    t0 = time.perf_counter()
    clusters, n_clusters = find_clusters(run, flags, log_odds, observed, params)
    t_cluster = time.perf_counter() - t0

    t0 = time.perf_counter()
    occupied = np.ascontiguousarray((log_odds > 0).reshape(-1))  # the thresholded standard map
    probability = probability_from_log_odds(log_odds, observed).reshape(-1)
    em_stats = {"cluster_groups": 0, "em_sweeps_per_group": [], "em_flips_per_group": [], "index_entries": 0,
                "t_index": 0.0}
    if n_clusters:
        em_stats = em_in_clusters(run, clusters, n_clusters, occupied, probability, params, progress)
    probability = probability.reshape(grid.shape)
    probability[~observed] = 0.5
    t_index = em_stats.pop("t_index")
    t_em = time.perf_counter() - t0 - t_index
    phases = {"standard": t_standard, "readings": t_readings, "detector": t_detect, "clusters": t_cluster,
              "index": t_index, "em": t_em}
    stats = {
        "clusters": n_clusters,
        "cells_in_clusters": int((clusters > 0).sum()),
        "observed_cells": int(observed.sum()),
        "flagged_readings": int(flags.sum()),
        "readings": int(flags.size),
        **em_stats,
        "phase_seconds": phases,
        "detector": detector_name,
    }
    return OccupancyMap(
        grid=grid,
        probability=probability,
        observed=observed,
        mode="adaptive",
        params=params_json(params, "adaptive", grid) | {"detector": detector_name},
        runtime_s=sum(phases.values()),
        source_log=log.path,
        log_odds=log_odds,
        occupied=occupied.reshape(grid.shape) & observed,
        clusters=clusters,
        stats=stats,
    )
