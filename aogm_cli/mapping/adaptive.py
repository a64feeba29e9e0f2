"""The paper's adaptive mode: standard log-odds everywhere, then EM inside each cluster.

The detector flags readings (``detector.network``), the bands their cones sweep near their
ranges become clusters (``mapping.cluster``), and EM (``mapping.em.run_em``) runs over the
cluster cells with every other cell held at the thresholded standard map; a cluster's cells
get EM's residual probability.
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from aogm_cli.core.log import Log
from aogm_cli.core.occupancy_map import OccupancyMap
from aogm_cli.mapping.cluster import grown, label_clusters, near_occupied, readings_near_clusters
from aogm_cli.mapping.em import (
    EMOutcome,
    EMProblem,
    deflected,
    em_problem,
    em_readings,
    em_stats,
    em_view,
    em_with_phases,
    find_root,
    prepared_templates,
)
from aogm_cli.mapping.params import EMConfig, MapParams
from aogm_cli.mapping.pipeline import Progress, log_grid, params_json
from aogm_cli.mapping.standard import standard_pass
from aogm_cli.sensor_models.ray import is_narrow_beam
from aogm_cli.sensor_models.readings import LaidOutReadings, cone_bands, lay_out_readings


def cluster_problem(run: LaidOutReadings, clusters: np.ndarray, occupied: np.ndarray, config: EMConfig,
                    subset: np.ndarray | None = None) -> EMProblem:
    """EM's problem inside ``clusters`` (ids, 0 outside): the readings whose cones could reach a
    cluster cell (``cluster.readings_near_clusters``; of those ``subset`` marks, if given), under
    the flat map ``occupied``, with which clusters share a reading."""
    near = readings_near_clusters(clusters, run.rows, run.cols, run.z, run.grid, run.sensor.max_range, config.forward)
    if subset is not None:
        near = near[subset[near]]
    rd = em_readings(run.cones, run.templates, run.grid, run.sensor.max_range,
                     config.forward, select=near, shadow=run.shadow)
    return em_problem(rd, run.templates, run.grid.shape, occupied, config, labels=clusters.reshape(-1))


def coupled_groups(problem: EMProblem, n_clusters: int) -> int:
    """How many groups of coupled clusters (clusters joined through a reading whose cone holds
    cells of both): independent problems, which one EM run over every cluster solves at once."""
    parent = problem.parent
    roots = {int(find_root(parent, k)) for k in range(1, n_clusters + 1)}
    return len(roots)


def contested_cells(log: Log, grid, params: MapParams, log_odds: np.ndarray,
                    shadow: np.ndarray | None = None) -> tuple[np.ndarray, float]:
    """(cells (H, W) whose occupied evidence alone reaches ``adaptive.contested`` log-odds but
    which the standard map holds free, seconds): where the readings disagree and the standard
    map cannot explain them (walls that specular or multipath readings, too long, cleared).
    One more standard pass, with the inverse model's free evidence set to nothing (and the
    deflected beams, ``shadow``, stopped: they hit nothing)."""
    inverse = dataclasses.replace(params.inverse_model, l_free=params.inverse_model.l0)
    cuts = None if shadow is None else shadow.reshape(np.shape(log.ranges))
    hits, _, seconds = standard_pass(log, grid, dataclasses.replace(params, inverse_model=inverse), cuts=cuts)
    return (hits - params.inverse_model.l0 >= params.adaptive.contested) & (log_odds <= 0), seconds


def find_clusters(run: LaidOutReadings, flags: np.ndarray, log_odds: np.ndarray, observed: np.ndarray,
                  params: MapParams, contested: np.ndarray | None = None) -> tuple[np.ndarray, int]:
    """(cluster ids (H, W), count): a flagged cone's band near its range, z - band_below ..
    z + alpha (where the standard map thickens walls towards the robot), next to cells the
    standard map holds occupied, minus cells it holds at its free clamp; the ``contested``
    cells (``contested_cells``) when given; and the cells whose log-odds lie within
    ``adaptive.weak`` of the prior (the standard map barely knows them: space behind a wall
    that one random reading crossed, which a wall EM opens would let a planner into); all
    grown by ``adaptive.grow`` cells (8-connected), so that a wall's back layers, which the
    standard map holds free where too-long readings crossed them, are EM's to decide too (for
    cones only: on the intel laser log growing cost adaptive's held-out AUC 0.9863 -> 0.9737)."""
    region, _ = cone_bands(run.grid, run.templates, tuple(a[flags] for a in run.cones),
                           params.adaptive.band_below, params.inverse_model.alpha)
    region &= observed & (log_odds > params.inverse_model.clamp_min)
    region &= near_occupied(log_odds, params.adaptive.near_occupied)
    if contested is not None:
        region |= contested & observed
    if params.adaptive.weak > 0:
        region |= observed & (np.abs(log_odds - params.inverse_model.l0) < params.adaptive.weak)
    grow = 0 if is_narrow_beam(run.sensor, run.grid.resolution) else params.adaptive.grow
    return label_clusters(observed & grown(region, grow))


def em_in_clusters(run: LaidOutReadings, clusters: np.ndarray, n_clusters: int, occupied: np.ndarray,
                   params: MapParams, progress: Progress | None = None,
                   incidence: dict | None = None) -> tuple[EMOutcome, int]:
    """EM over every cluster cell at once, every other cell held at ``occupied`` (flat, updated
    in place): (its outcome, how many groups of coupled clusters it solved). Clusters that share
    no reading are independent (as the paper has them): one run gives each its own result."""
    cells = np.flatnonzero(clusters.reshape(-1) > 0)

    def problem_for(config: EMConfig, occ: np.ndarray, subset: np.ndarray | None):
        if config.start == "empty":
            occ[cells] = False
        return cluster_problem(run, clusters, occ, config, subset), cells

    # the model is fitted on the readings EM explains: those whose cones reach a cluster
    # (outside the clusters the thresholded standard map stands, and readings crossing its
    # thick walls looked random: p_rand 0.29 on the intel log when fitted on every reading)
    near = np.zeros(run.z.size, dtype=bool)
    near[readings_near_clusters(clusters, run.rows, run.cols, run.z, run.grid, run.sensor.max_range,
                                params.em.forward)] = True
    outcome = em_with_phases(run, occupied, params, problem_for, select=near, progress=progress, incidence=incidence)
    return outcome, coupled_groups(outcome.problem, n_clusters)


def map_adaptive(log, params: MapParams, detector, detector_name: str = "packaged",
                 progress: Progress | None = None) -> OccupancyMap:
    """The adaptive mode on a log source (``pipeline``) with ``detector`` (anything with
    ``flag(ranges, max_range)``: a trained ``Detector`` or a ``ConstantDetector``)."""
    grid = log_grid(log, params.resolution)
    sensor = log.sensor
    whole = log.read()  # EM needs every reading in memory: read the scans once
    log_odds, observed, t_standard = standard_pass(whole, grid, params)
    prepared_templates(grid, sensor)  # outside the clock
    t0 = time.perf_counter()
    run = lay_out_readings(whole.pose, whole.ranges, sensor, grid)
    t_readings = time.perf_counter() - t0
    angle = deflected(whole, run, params, log_odds, observed)
    run, params, log_odds, observed = angle.run, angle.params, angle.log_odds, angle.observed

    t0 = time.perf_counter()
    flags = detector.flag(whole.ranges, sensor.max_range).reshape(-1)
    t_detect = time.perf_counter() - t0

    t0 = time.perf_counter()
    contested, t_hits = (contested_cells(whole, grid, params, log_odds, run.shadow) if params.adaptive.contested > 0
                         else (None, 0.0))
    clusters, n_clusters = find_clusters(run, flags, log_odds, observed, params, contested)
    t_cluster = time.perf_counter() - t0

    occupied = np.ascontiguousarray((log_odds > 0).reshape(-1))  # the thresholded standard map
    outcome, groups = (em_in_clusters(run, clusters, n_clusters, occupied, params, progress, angle.incidence)
                       if n_clusters else (None, 0))
    t0 = time.perf_counter()
    probability, observed = em_view(log_odds, observed, outcome, grid, whole.pose, sensor, params)
    seconds = outcome.seconds if outcome else {"index": 0.0, "calibration": 0.0, "sweeps": 0.0}
    phases = {"standard": t_standard, "readings": t_readings, "deflections": angle.seconds, "detector": t_detect,
              "clusters": t_cluster,
              **seconds, "view": time.perf_counter() - t0}
    stats = {
        "clusters": n_clusters,
        "cells_in_clusters": int((clusters > 0).sum()),
        "cluster_groups": groups,
        "observed_cells": int(observed.sum()),
        "flagged_readings": int(flags.sum()),
        "readings": int(flags.size),
        **em_stats(outcome),
        "phase_seconds": phases,
        "detector": detector_name,
    }
    return OccupancyMap(
        grid=grid,
        probability=probability,
        observed=observed,
        mode="adaptive",
        params=params_json(dataclasses.replace(params, em=outcome.config if outcome else params.em), "adaptive", grid)
        | {"detector": detector_name},
        runtime_s=sum(phases.values()),
        source_log=log.path,
        log_odds=log_odds,
        occupied=occupied.reshape(grid.shape) & observed,
        clusters=clusters,
        stats=stats,
    )
