"""The stages a mode is made of, and the runner that runs a mode as a list of them: each stage takes
the mapping's typed state and returns the next (what it adds: the scans, the standard map, the laid-out
readings, what was learned, the clusters, EM's problem and outcome, the view); the runner times each."""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from aogm_cli.core.grid import GridSpec
from aogm_cli.core.log import Log
from aogm_cli.core.occupancy_map import OccupancyMap
from aogm_cli.mapping import adaptive as A
from aogm_cli.mapping import em as E
from aogm_cli.mapping.calibration import calibration_rounds, fit_at_map, sample_readings
from aogm_cli.mapping.exact import map_evidence
from aogm_cli.mapping.learned import BUILDING, FROM_LOG, Learned, SensorModel
from aogm_cli.mapping.params import EMConfig, MapParams
from aogm_cli.mapping.pipeline import Progress, TimedSource, params_json
from aogm_cli.mapping.standard import (
    decided_free,
    occupied_evidence,
    probability_from_log_odds,
    set_up,
    standard_log_odds,
    thin_pass,
    thins,
)
from aogm_cli.sensor_models.exact_inverse import MARGIN
from aogm_cli.sensor_models.ray import is_narrow_beam
from aogm_cli.sensor_models.readings import LaidOutReadings, lay_out_readings

# log-odds of occupied evidence alone that put a cell the map holds free among the walls the
# building's rates are fitted at (``rates``; measured on the 13 worlds without a Pioneer with the
# carried model: 2 keeps corridor_specular's wall (leak 0.003, 0.087 at the map alone), 1 and 3 no
# better; docs/algorithms.md, "The sensor model a detector carries")
RATES_EVIDENCE = 2.0
RATES_START = 0.05  # the fit of p_max starts from at least this share (from 0 it would get no weight)
# readings the fit of p_max is made on (every n-th beyond): one share, known within about 0.01 from
# 1000; on the 13 worlds accuracy as with every reading within 0.001
RATES_READINGS = 1000


@dataclass(frozen=True)
class StandardMap:
    """A log-odds map and its observed cells, (H, W) each (``standard.standard_map``); once
    thinned (``standard.thin_pass``), the exact model's ``evidence`` and Elfes' log-odds before."""

    log_odds: np.ndarray
    observed: np.ndarray
    evidence: np.ndarray | None = None
    elfes: np.ndarray | None = None


@dataclass(frozen=True)
class Clusters:
    """Where the adaptive mode runs EM: cluster ids (H, W), 0 outside, their count, the readings
    the detector flagged."""

    ids: np.ndarray
    count: int
    flags: np.ndarray


@dataclass(frozen=True)
class Problem:
    """EM's final problem (``em.em_problem``), its candidate cells and the model it is made with."""

    problem: E.EMProblem
    candidates: np.ndarray
    config: EMConfig


class View(NamedTuple):
    probability: np.ndarray
    observed: np.ndarray  # the map file's layers, (H, W)


@dataclass(frozen=True)
class State:
    """A map in the making: what it was given (the configured ``params``, the log source, its
    grid, a model ``given`` to use instead of learning one, the detector) and what the stages
    have added so far."""

    params: MapParams
    source: TimedSource
    grid: GridSpec
    given: Learned | None = None
    detector: object = None  # anything with ``flag(ranges, max_range)``
    detector_record: dict | None = None  # what the map's params record of it
    progress: Progress | None = None
    whole: Log | None = None  # the scans in memory, the sensor with the beam's opening
    readings: LaidOutReadings | None = None
    standard: StandardMap | None = None
    learned: Learned = Learned()
    clusters: Clusters | None = None
    occupied: np.ndarray | None = None  # flat bool: EM's binary map, updated in place
    problem: Problem | None = None
    em: E.EMOutcome | None = None
    final_evidence: np.ndarray | None = None  # (H, W): each cell's evidence at the final map (``decided``)
    view: View | None = None

    def but(self, **changes) -> State:
        return dataclasses.replace(self, **changes)

    @property
    def in_use(self) -> MapParams:
        """The configured parameters with the forward model learned so far in EM's place: what
        the mappers are handed (the map records ``params`` and ``learned`` apart)."""
        forward = self.learned.model(self.params.em.forward)
        return dataclasses.replace(self.params, em=dataclasses.replace(self.params.em, forward=forward))

    @property
    def log(self):
        """The scans in memory once read (the sensor with the beam's opening), else the source."""
        return self.whole if self.whole is not None else self.source


class Stage(NamedTuple):
    """One step of a mode: its name (the map's ``phase_seconds`` key), what it does, whether its
    seconds are mapping work (set-up is not) and when it runs (None: always)."""

    name: str
    run: Callable[[State], State]
    timed: bool = True
    when: Callable[[State], bool] | None = None


def run_stages(stages: tuple[Stage, ...], state: State, clock=time.perf_counter) -> tuple[State, dict]:
    """Run ``stages`` in order: (the last state, the seconds of each timed stage that ran, reading
    the log left out)."""
    phases: dict[str, float] = {}
    for stage in stages:
        if stage.when is not None and not stage.when(state):
            continue
        t0, io0 = clock(), state.source.io_seconds
        state = stage.run(state)
        if stage.timed:
            phases[stage.name] = phases.get(stage.name, 0.0) + clock() - t0 - (state.source.io_seconds - io0)
    return state, phases


def learns(s: State, key: str) -> bool:
    """Whether this map learns ``key`` (a forward model parameter) from its log: calibration on
    and ``key`` listed, and not given. A model carried from another map of the same log gives
    everything; one from a file or carried by the detector (a robot's) the sensor's part, so only
    the building's (``learned.BUILDING``: the specular angle and p_max) is learned."""
    config = s.params.calibration
    if not config.enabled or key not in config.learned:
        return False
    return s.given is None or (s.given.made_by is None and key in BUILDING)


# --- the stages ----------------------------------------------------------------------------------


def read(s: State) -> State:
    """The scans in memory (EM needs every reading), the sensor narrowed to the beam's opening as
    configured or given, unless it is learned (``opening``)."""
    whole = s.source.read()
    if not learns(s, "opening_deg"):
        whole = E.with_opening(whole, s.grid, s.in_use.em.forward.opening_deg)
    return s.but(whole=whole)


def templates(s: State) -> State:
    """Set-up: the cone and forward templates of the grid, built or found in their caches."""
    log = s.log
    set_up(log.sensor, s.grid, s.in_use)
    if s.whole is not None:
        E.prepared_templates(s.grid, s.whole.sensor)
    return s


def standard(s: State) -> State:
    """The standard map (Elfes, Moravec) of the scans, streamed from the source when not in memory."""
    log = s.log
    return s.but(standard=StandardMap(*standard_log_odds(log, s.grid, s.in_use)))


def readings(s: State) -> State:
    """Every reading laid out on its cone (``readings.lay_out_readings``)."""
    return s.but(readings=lay_out_readings(s.whole.pose, s.whole.ranges, s.whole.sensor, s.grid))


def opening(s: State) -> State:
    """The beam's opening learned at the thinned standard map (``em.opening_record``); when it is
    narrower than the log's beam, the sensor narrowed, the readings laid out and the standard map
    made again."""
    record = E.opening_record(s.whole, s.readings, s.in_use, s.standard.log_odds, s.standard.observed)
    s = s.but(learned=dataclasses.replace(s.learned, opening_deg=record["opening_deg"], opening=record))
    narrowed = E.with_opening(s.whole, s.grid, record["opening_deg"])
    if narrowed is s.whole:
        return s
    return standard(readings(s.but(whole=narrowed)))


def deflections(s: State) -> State:
    """The angle of incidence: the surfaces the echoes came from, the specular angle learned there
    when calibration learns it, and the standard map made again with the beams that met a surface
    beyond it stopped there."""
    normals = E.surfaces(s.readings, s.in_use, s.standard.log_odds)
    if normals is None:
        return s
    if learns(s, "specular_deg"):
        record = E.specular_record(s.readings, s.in_use, s.standard.log_odds, normals)
        s = s.but(learned=dataclasses.replace(s.learned, specular_deg=record["specular_deg"], incidence=record))
    run = E.deflected_run(s.readings, normals, s.in_use)
    if run is None:
        return s
    return s.but(readings=run, standard=StandardMap(*standard_log_odds(s.whole, s.grid, s.in_use, cuts=_cuts(run))))


def _cuts(run: LaidOutReadings) -> np.ndarray | None:
    return None if run.shadow is None else run.shadow.reshape(run.ranges.shape)


def thinning(s: State, margin: float = MARGIN) -> State:
    """The standard map thinned by the exact inverse model (``standard.thin_pass``)."""
    log = s.log
    cuts = None if s.readings is None else _cuts(s.readings)
    log_odds, evidence = thin_pass(log, s.grid, s.in_use, s.standard.log_odds, s.standard.observed, cuts, margin)
    return s.but(standard=StandardMap(log_odds, s.standard.observed, evidence, s.standard.log_odds))


# log-odds below the exact model's prior at which adaptive's thinning frees a cell when the thinned map
# stands outside the clusters: any (the ``decided`` stage then checks each free cell against the
# readings). On the 13 worlds (seed 1) the clusters' mean share 0.151 at ``MARGIN`` (0.5), 0.138 at 0,
# accuracy within 0.002 of it; the standard mode's ``exact.thin`` keeps 0.5 (at 0 it fails
# furnished_room's and corridor_specular_real's checks: leak 0.081)
OUTSIDE_MARGIN = 0.0


def thinning_outside(s: State) -> State:
    """Adaptive's thinning: at ``OUTSIDE_MARGIN`` when the thinned map stands outside the clusters,
    else (``exact.thin`` with Elfes' map outside) as the em mode's."""
    return thinning(s, OUTSIDE_MARGIN if outside(s) == "thinned" else MARGIN)


def detect(s: State) -> State:
    """The readings the detector flags (the cluttered and erroneous ones)."""
    flags = s.detector.flag(s.whole.ranges, s.whole.sensor.max_range).reshape(-1)
    return s.but(clusters=Clusters(np.zeros(s.grid.shape, dtype=np.int32), 0, flags))


def clusters(s: State) -> State:
    """The clusters of the flagged readings, with the contested and weak cells (``adaptive.find_clusters``)."""
    ids, count = A.find_clusters(s.readings, s.clusters.flags, s.standard, s.in_use, outside(s), s.whole)
    return s.but(clusters=Clusters(ids, count, s.clusters.flags))


def _problems(s: State) -> E.ProblemFor:
    """The mode's EM problems: every cell some cone holds, or the clusters' cells."""
    if s.clusters is None:
        return E.whole_log_problems(s.readings)
    return A.cluster_problems(s.readings, s.clusters.ids)


def _on_sweep(s: State):
    max_sweeps = s.params.em.max_sweeps

    def on_sweep(sweep, flips, objective):
        if s.progress:
            s.progress("em sweep", sweep, max_sweeps)

    return on_sweep


def start(s: State) -> State:
    """EM's start: the thresholded standard map (the em mode's empty with ``em.start`` "empty");
    with the thinned map outside the clusters, Elfes' map inside them, so that EM thins a wall's
    inner layers there as it does from Elfes' map (started from the thinned map it keeps single
    cells of them: corridor_door's block 0.061, against 0.057 and EM's 0.056)."""
    empty = s.clusters is None and s.params.em.start != "standard"
    flat = np.zeros(s.grid.height * s.grid.width, bool) if empty else (s.standard.log_odds > 0).reshape(-1)
    if s.clusters is not None and s.standard.elfes is not None and outside(s) == "thinned":
        inside = s.clusters.ids.reshape(-1) > 0
        flat[inside] = s.standard.elfes.reshape(-1)[inside] > 0
    return s.but(occupied=np.ascontiguousarray(flat))


def calibration(s: State) -> State:
    """The sensor's forward model learned in rounds of EM and closed-form fits
    (``calibration.calibration_rounds``), on the readings whose cones reach EM's cells."""
    config = s.in_use.em
    select = None if s.clusters is None else A.near_clusters(s.readings, s.clusters.ids, config.forward)
    used, record = calibration_rounds(s.readings, s.occupied, config, s.params.calibration,
                                      E.em_step(_problems(s), _on_sweep(s)), select)
    sensor = SensorModel.of(used.forward)
    return s.but(learned=dataclasses.replace(s.learned, sensor=sensor, origin=FROM_LOG, calibration=record))


def rates(s: State) -> State:
    """With a robot's model (carried by the detector, or a file's): the building's share of
    max-range readings (p_max: beams that specular walls send away, open space) fitted on
    ``RATES_READINGS`` of the readings (``calibration.fit_at_map``) at the standard map thresholded, with the
    cells the occupied evidence alone holds occupied by ``RATES_EVIDENCE``
    (``standard.occupied_evidence``): the walls passing beams cleared are there, so that the
    readings crossing them count as lost ones, as a calibration of the log finds them; the
    sensor's sigma, p_hit and p_rand are kept."""
    cuts = None if s.readings.shadow is None else _cuts(s.readings)
    walls = (s.standard.log_odds > 0) | (occupied_evidence(s.whole, s.grid, s.in_use, cuts) >= RATES_EVIDENCE)
    config = dataclasses.replace(s.params.calibration, learn="p_max")
    forward = s.in_use.em.forward
    start = dataclasses.replace(forward, p_max=max(forward.p_max, RATES_START))
    fit = fit_at_map(s.readings, sample_readings(s.readings, RATES_READINGS), np.ascontiguousarray(walls.reshape(-1)),
                     start, config, loglik=False).forward
    values = {"p_max": float(fit.p_max)}
    return s.but(learned=dataclasses.replace(s.learned, sensor=dataclasses.replace(s.learned.sensor, **values),
                                             rates=values))


def index(s: State) -> State:
    """EM's problem under the start map, with the forward model learned or given."""
    config = s.in_use.em
    problem, candidates = _problems(s)(config, s.occupied, None)
    return s.but(problem=Problem(problem, candidates, config))


def sweeps(s: State) -> State:
    """EM's sweeps: hill climbing by single-cell flips (``em.run_em``)."""
    p = s.problem
    result = E.run_em(p.problem, s.occupied, p.candidates, p.config, _on_sweep(s))
    return s.but(em=E.EMOutcome(p.config, result, p.problem))


def decided(s: State) -> State:
    """Each cell's evidence at the map adaptive leaves (the thinned map outside the clusters, EM's
    inside), as EM scores a candidate (``exact.map_evidence``). Outside the clusters a free cell
    is free to a planner only where its occupancy would lower the readings' likelihood by more
    than ``HIDDEN_GAIN``, as EM decides the cells it leaves free (``em.decided``); the others are
    behind a wall, crossed only by readings the map cannot explain, or wanted occupied by the
    readings: unknown (``em_view``). Their probabilities are EM's residuals at that map
    (``adaptive.joined_view``)."""
    return s.but(final_evidence=map_evidence(s.readings, s.in_use.em.forward, s.occupied))


def standard_view(s: State) -> State:
    """The standard map's probabilities."""
    log_odds, observed = s.standard.log_odds, s.standard.observed
    return s.but(view=View(probability_from_log_odds(log_odds, observed), observed))


def em_view(s: State) -> State:
    """EM's residuals on its candidates, the standard map's elsewhere, as a planner sees them."""
    params, whole = s.in_use, s.whole
    if s.clusters is None:
        return s.but(view=View(*E.em_view(s.standard.log_odds, s.standard.observed, s.em, s.grid, whole.pose,
                                         whole.sensor, params)))
    observed = s.standard.observed
    if s.final_evidence is not None:  # outside the clusters the thinned map, its free cells no reading holds free unknown
        observed = observed & ~((s.clusters.ids == 0) & (s.standard.log_odds <= 0) & ~decided_free(s.final_evidence))
    return s.but(view=View(*A.joined_view(s.standard.log_odds, observed, s.em, s.clusters.ids, whole, s.grid,
                                          params, s.final_evidence)))


# when a stage runs
def learns_opening(s: State) -> bool:
    return learns(s, "opening_deg") and not is_narrow_beam(s.whole.sensor, s.grid.resolution)


def thinned(s: State) -> bool:
    log = s.log
    return thins(log.sensor, s.grid, s.params)


def outside(s: State) -> str:
    """What the adaptive map is outside its clusters (``adaptive.outside``): "auto" is "thinned"
    for a cone whose forward model is known before the map is made (carried by the detector, from
    a file or from another map of the log: the thinning and the clusters need it), else "elfes"
    (the model is learned from the log by EM in the clusters, after them; a narrow beam's map is
    never thinned)."""
    chosen = s.params.adaptive.outside
    if chosen != "auto":
        return chosen
    return auto_outside(s.given is not None and s.given.sensor is not None, s.log.sensor, s.grid.resolution)


def auto_outside(known: bool, sensor, resolution: float) -> str:
    """What ``adaptive.outside`` "auto" is for ``sensor`` at ``resolution``, its forward model
    ``known`` before the map is made or not (``outside``)."""
    return "thinned" if known and not is_narrow_beam(sensor, resolution) else "elfes"


def thins_outside(s: State) -> bool:
    """Adaptive with the thinned map outside its clusters thins a cone's map (and ``exact.thin``
    thins it in any mode)."""
    return thins(s.log.sensor, s.grid, s.params, always=outside(s) == "thinned")


def keeps_thinned(s: State) -> bool:
    """Adaptive with the thinned map outside its clusters, on a map that was thinned (not a narrow
    beam's)."""
    return outside(s) == "thinned" and s.standard.evidence is not None


def runs_em(s: State) -> bool:
    return s.clusters is None or s.clusters.count > 0


def fits_rates(s: State) -> bool:
    """A robot's model (``learns`` the building's part only) whose p_max the log sets."""
    robots = s.given is not None and s.given.made_by is None and s.given.sensor is not None
    return runs_em(s) and robots and learns(s, "p_max")


def calibrates(s: State) -> bool:
    return runs_em(s) and s.params.calibration.enabled and s.given is None


# --- the map -------------------------------------------------------------------------------------


def finished(mode: str, s: State, phases: dict) -> OccupancyMap:
    """The map of the last state: its layers, the configured parameters, what was learned, and
    one stats format for every mode."""
    grid, view = s.grid, s.view
    em = mode != "standard"
    occupied = None if s.occupied is None else s.occupied.reshape(grid.shape) & view.observed
    params = (params_json(s.params, mode, grid) | (s.detector_record if s.clusters is not None else {})
              | getattr(s.source, "recorded", {}))  # what the log source says of itself: a held-out split
    return OccupancyMap(grid=grid, probability=view.probability, observed=view.observed, mode=mode, params=params,
                        runtime_s=sum(phases.values()), source_log=s.source.path,
                        log_odds=None if mode == "em" else s.standard.log_odds, occupied=occupied if em else None,
                        clusters=None if s.clusters is None else s.clusters.ids,
                        stats=map_stats(s, phases, em), learned=s.learned.as_dict())


def map_stats(s: State, phases: dict, em: bool) -> dict:
    """The map's statistics: its scans and phases; EM's (``em.em_stats``) and the calibration's
    record when EM ran; the clusters' when there are clusters."""
    stats: dict = {"scans": s.source.n_scans, "phase_seconds": phases}
    if em:
        stats |= E.em_stats(s.em)
        record = calibration_record(s.learned, s.em)
        if record is not None:
            stats["calibration"] = record
    if s.clusters is not None:
        c = s.clusters
        stats |= {"clusters": c.count, "cells_in_clusters": int((c.ids > 0).sum()),
                  "cluster_groups": A.coupled_groups(s.em.problem, c.count) if s.em is not None else 0,
                  "observed_cells": int(s.view.observed.sum()), "flagged_readings": int(c.flags.sum()),
                  "readings": int(c.flags.size), "detector": s.detector_record["detector"],
                  "outside": outside(s)}  # what the map is outside the clusters (``adaptive.outside`` "auto" decided)
    return stats


def calibration_record(learned: Learned, outcome: E.EMOutcome | None) -> dict | None:
    """What the map records of its calibration (None: nothing calibrated): the rounds' record,
    the final map's EM objective and sweeps, how the opening and the specular angle were learned,
    and, for a model carried from another map of the log, which mode made it."""
    if learned.calibration is None:
        return None
    record = dict(learned.calibration)
    if outcome is not None:
        record["final_em"] = {"em_objective": float(outcome.result.objective[-1]), "em_sweeps": int(outcome.result.sweeps)}
    for key in ("opening", "incidence"):
        if getattr(learned, key) is not None:
            record[key] = getattr(learned, key)
    if learned.made_by is not None:
        record["made_by"] = learned.made_by
    return record
