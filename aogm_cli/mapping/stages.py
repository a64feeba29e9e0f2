"""The stages the modes are made of (``modes.mode_stages``): each takes the ``State`` and returns the next with what
it adds, as its plan says; and the finished map (``finished``)."""

from __future__ import annotations

import dataclasses
import functools

import numpy as np

from aogm_cli.core.occupancy_map import OccupancyMap
from aogm_cli.mapping import adaptive as A
from aogm_cli.mapping import beam_model as B
from aogm_cli.mapping import em as E
from aogm_cli.mapping.calibration import calibration_rounds, fit_at_map, sample_readings
from aogm_cli.mapping.exact import map_evidence
from aogm_cli.mapping.learned import FROM_LOG, Learned, SensorModel
from aogm_cli.mapping.pipeline import params_json
from aogm_cli.mapping.standard import (
    echo_walls,
    probability_from_log_odds,
    set_up,
    standard_log_odds,
    thin_pass,
)
from aogm_cli.mapping.state import Clusters, EMRegion, StandardMap, State, View
from aogm_cli.mapping.view import decided_free, em_view, joined_view
from aogm_cli.sensor_models.readings import lay_out_readings

RATES_START = 0.05  # the fit of p_max starts from at least this share (from 0 it would get no weight)
RATES_READINGS = 1000  # readings the fit of p_max is made on (every n-th beyond)


# --- the standard map ----------------------------------------------------------------------------


def set_up_cones(s: State) -> State:
    """Set-up: the cone templates of the grid, built or found in their caches."""
    set_up(s.source.sensor, s.grid, s.in_use)
    return s


def standard_streamed(s: State) -> State:
    """The standard map (Elfes, Moravec) of the scans streamed from the source."""
    return s.but(standard=StandardMap(*standard_log_odds(s.source, s.grid, s.in_use)))


def thinning_streamed(s: State) -> State:
    """The standard map thinned by the exact inverse model (``standard.thin_pass``), the scans streamed."""
    log_odds, evidence = thin_pass(s.source, s.grid, s.in_use, s.standard.log_odds, s.standard.observed, None,
                                   s.plan.thinning)
    return s.but(standard=StandardMap(log_odds, s.standard.observed, evidence, s.standard.log_odds))


def standard_view(s: State) -> State:
    """The standard map's probabilities."""
    log_odds, observed = s.standard.log_odds, s.standard.observed
    return s.but(view=View(probability_from_log_odds(log_odds, observed), observed))


# --- what EM's modes prepare ---------------------------------------------------------------------


def read(s: State) -> State:
    """The scans in memory."""
    return s.but(whole=s.source.read())


def set_up_em(s: State) -> State:
    """Set-up: the cone and forward templates of the grid, built or found in their caches."""
    set_up(s.whole.sensor, s.grid, s.in_use)
    E.prepared_templates(s.grid, s.whole.sensor)
    return s


def readings(s: State) -> State:
    """Every reading laid out on its cone (``readings.lay_out_readings``), the cells the lobe hears marked."""
    run = lay_out_readings(s.whole.pose, s.whole.ranges, s.whole.sensor, s.grid)
    return s.but(readings=B.heard_run(run, s.in_use.em.forward))


def standard(s: State) -> State:
    """The standard map of the scans in memory, the deflected beams (if any) cut."""
    return s.but(standard=StandardMap(*standard_log_odds(s.whole, s.grid, s.in_use, cuts=s.readings.cuts)))


def lobe(s: State) -> State:
    """The lobe that hears (``beam_model.lobe_record``), learned at the standard map's walls thinned (their exact
    pass kept for ``thinning``); the readings' cones keep the cells it hears (the whole cone when it explains the
    echoes as well: ``lobe_deg`` 0), and ``rates`` fits p_max again when that changed them."""
    walls, exact = B.lobe_walls(s.whole, s.readings, s.in_use, s.standard.log_odds, s.standard.observed,
                                s.echo_walls, s.exact)
    found = B.lobe_record(s.readings, s.in_use, walls)
    lobe_deg, lobe_range = (0.0, s.in_use.em.forward.lobe_range) if found.full_cone else (found.theta0_deg, found.r0_m)
    s = s.but(learned=dataclasses.replace(s.learned, lobe_deg=lobe_deg, lobe_range=lobe_range, lobe=found.as_dict()),
              exact=exact)
    heard = B.heard_run(s.readings, s.in_use.em.forward)
    if heard is s.readings:
        return s
    return rates(s.but(readings=heard)) if s.plan.fits_rates else s.but(readings=heard)


def deflections(s: State) -> State:
    """The echoes' surfaces, beams met beyond ``em.specular_deg`` stopped (standard map taken away)."""
    normals = B.surfaces(s.readings, s.standard.log_odds)
    run = B.deflected_run(s.readings, normals, s.in_use)
    return s if run is None else s.but(readings=run, standard=None)


def walls(s: State) -> State:
    """The standard map with the cells occupied evidence alone makes walls (``standard.echo_walls``), for ``lobe``
    and ``rates``: the standard map loses walls that passing beams clear, grazing or unheard."""
    return s.but(echo_walls=echo_walls(s.whole, s.grid, s.in_use, s.standard.log_odds, s.readings.cuts))


def rates(s: State) -> State:
    """With a robot's model: the building's share of max-range readings (p_max) fitted at the standard map
    plus the cells occupied evidence alone holds (``walls``): readings crossing cleared walls count as lost."""
    walls = s.echo_walls > 0
    config = dataclasses.replace(s.params.calibration, learn="p_max")
    forward = s.in_use.em.forward
    start = dataclasses.replace(forward, p_max=max(forward.p_max, RATES_START))
    readings = sample_readings(s.readings, RATES_READINGS)
    fit = fit_at_map(s.readings, readings, np.ascontiguousarray(walls.reshape(-1)), start, config, loglik=False).forward
    values = {"p_max": float(fit.p_max)}
    return s.but(learned=dataclasses.replace(s.learned, sensor=dataclasses.replace(s.learned.sensor, **values),
                                             rates=values))


def thinning(s: State) -> State:
    """The standard map thinned by the exact inverse model at the plan's margin (``standard.thin_pass``; the exact
    pass the lobe's walls were thinned with, when made with the same models)."""
    log_odds, evidence = thin_pass(s.whole, s.grid, s.in_use, s.standard.log_odds, s.standard.observed,
                                   s.readings.cuts, s.plan.thinning, s.exact)
    return s.but(standard=StandardMap(log_odds, s.standard.observed, evidence, s.standard.log_odds))


# --- where EM works ------------------------------------------------------------------------------


def whole_log(s: State) -> State:
    """The em mode's region: every cell some cone holds, every reading."""
    return s.but(region=EMRegion(E.whole_log_problems(s.readings), lambda: None))


def detect(s: State) -> State:
    """The readings the detector flags (the cluttered and erroneous ones)."""
    return s.but(flags=s.detector.flag(s.whole.ranges, s.whole.sensor.max_range).reshape(-1))


def clusters(s: State) -> State:
    """The clusters of the flagged readings (``adaptive.find_clusters``) and EM's region there (None: none)."""
    ids, count = A.find_clusters(s.readings, s.flags, s.standard, s.in_use, s.plan, s.whole)
    region = None
    if count > 0:
        near = functools.partial(A.near_clusters, s.readings, ids, s.in_use.em.forward)
        region = EMRegion(A.cluster_problems(s.readings, ids), near)
    return s.but(clusters=Clusters(ids, count), region=region)


def start(s: State) -> State:
    """EM's start (``Plan.start``); with the thinned map outside the clusters, Elfes' inside, so that EM thins
    a wall's inner layers as from Elfes' map (from the thinned map it keeps single cells of them)."""
    flat = (s.standard.log_odds > 0).reshape(-1)
    if s.plan.start == "elfes in clusters":
        inside = s.clusters.ids.reshape(-1) > 0
        flat[inside] = s.standard.elfes.reshape(-1)[inside] > 0
    return s.but(occupied=np.ascontiguousarray(flat))


def _on_sweep(s: State):
    max_sweeps = s.params.em.max_sweeps
    def on_sweep(sweep, flips, objective):
        if s.progress:
            s.progress("em sweep", sweep, max_sweeps)
    return on_sweep


def calibration(s: State) -> State:
    """The forward model learned in rounds of EM and fits (``calibration.calibration_rounds``)."""
    used, record = calibration_rounds(s.readings, s.occupied, s.in_use.em, s.params.calibration,
                                      E.em_step(s.region.problems, _on_sweep(s)), s.region.fitted_readings())
    return s.but(learned=dataclasses.replace(s.learned, sensor=SensorModel.of(used.forward), origin=FROM_LOG,
                                             calibration=record))


def index(s: State) -> State:
    """EM's problem under the start map, with the forward model learned or given."""
    problem, candidates = s.region.problems(s.in_use.em, s.occupied, None)
    return s.but(problem=problem, candidates=candidates)


def sweeps(s: State) -> State:
    """EM's sweeps: hill climbing by single-cell flips (``em.run_em``)."""
    config = s.in_use.em
    result = E.run_em(s.problem, s.occupied, s.candidates, config, _on_sweep(s))
    return s.but(em=E.EMOutcome(config, result, s.problem))


def final_evidence(s: State) -> State:
    """Each cell's evidence at the map adaptive leaves, as EM scores a candidate (``exact.map_evidence``)."""
    return s.but(final_evidence=map_evidence(s.readings, s.in_use.em.forward, s.occupied))


def em_mode_view(s: State) -> State:
    """EM's residuals on its candidates, the standard map's elsewhere, as a planner sees them."""
    whole = s.whole
    return s.but(view=View(*em_view(s.standard.log_odds, s.standard.observed, s.em, s.grid, whole.pose,
                                    whole.sensor, s.in_use)))


def adaptive_view(s: State) -> State:
    """EM's residuals in the clusters, the standard map's outside (``view.joined_view``); with the thinned map
    outside (``Plan.decides``) a free cell there not ``decided_free`` is unknown, as EM treats its own."""
    observed = s.standard.observed
    if s.plan.decides:
        observed = observed & ~((s.clusters.ids == 0) & (s.standard.log_odds <= 0) & ~decided_free(s.final_evidence))
    return s.but(view=View(*joined_view(s.standard.log_odds, observed, s.em, s.clusters.ids, s.whole, s.grid,
                                        s.in_use, s.final_evidence)))


# --- the map -------------------------------------------------------------------------------------


def finished(s: State, phases: dict) -> OccupancyMap:
    """The map of the last state: layers, parameters, what was learned, plan, one stats format."""
    grid, view, mode = s.grid, s.view, s.plan.mode
    em = mode != "standard"
    occupied = None if s.occupied is None else s.occupied.reshape(grid.shape) & view.observed
    params = (params_json(s.params, mode, grid) | (s.detector_record if mode == "adaptive" else {})
              | getattr(s.source, "recorded", {}))  # what the log source says of itself: a held-out split
    return OccupancyMap(grid=grid, probability=view.probability, observed=view.observed, mode=mode, params=params,
                        runtime_s=sum(phases.values()), source_log=s.source.path,
                        log_odds=None if mode == "em" else s.standard.log_odds, occupied=occupied if em else None,
                        clusters=s.clusters.ids if mode == "adaptive" else None,
                        stats=map_stats(s, phases, em), learned=s.learned.as_dict(), plan=s.plan.as_dict())


def map_stats(s: State, phases: dict, em: bool) -> dict:
    """The map's statistics: scans, phases, the deflected readings, EM's and the calibration's, an adaptive map's clusters'."""
    stats: dict = {"scans": s.source.n_scans, "phase_seconds": phases}
    if s.plan.incidence:  # the readings a surface met beyond the specular angle deflected (``deflections``)
        shadow = s.readings.shadow
        stats["deflected_readings"] = 0 if shadow is None else int(np.isfinite(shadow).sum())
    if em:
        stats |= E.em_stats(s.em)
        record = calibration_record(s.learned, s.em)
        if record is not None:
            stats["calibration"] = record
    if s.plan.mode == "adaptive":
        c = s.clusters
        stats |= {"clusters": c.count, "cells_in_clusters": int((c.ids > 0).sum()),
                  "cluster_groups": A.coupled_groups(s.em.problem, c.count) if s.em is not None else 0,
                  "observed_cells": int(s.view.observed.sum()), "flagged_readings": int(s.flags.sum()),
                  "readings": int(s.flags.size), "detector": s.detector_record["detector"],
                  "outside": s.plan.outside}
    return stats


def calibration_record(learned: Learned, outcome: E.EMOutcome | None) -> dict | None:
    """What the map records of its calibration (None: nothing): rounds, final EM run, maker."""
    if learned.calibration is None:
        return None
    record = dict(learned.calibration)
    if outcome is not None:
        record["final_em"] = {"em_objective": float(outcome.result.objective[-1]), "em_sweeps": int(outcome.result.sweeps)}
    if learned.made_by is not None:
        record["made_by"] = learned.made_by
    return record
