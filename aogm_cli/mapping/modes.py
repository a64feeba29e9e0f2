"""The three modes, each a list of stages (``mode_stages``), behind one call: ``map_source`` resolves the
parameters the log derives, compiles the mode's kernels on a tiny synthetic log, and maps the log."""

from __future__ import annotations

import dataclasses
import time
from typing import NamedTuple

import numpy as np

from aogm_cli.core import jit_cache
from aogm_cli.core.budget import Limits, active_limits, check, using
from aogm_cli.core.log import Log, SensorSpec
from aogm_cli.core.occupancy_map import MODES, OccupancyMap
from aogm_cli.detector.network import ConstantDetector
from aogm_cli.mapping import stages as S
from aogm_cli.mapping.learned import Learned
from aogm_cli.mapping.map_cost import map_estimate
from aogm_cli.mapping.params import MapParams
from aogm_cli.mapping.pipeline import Progress, TimedSource, log_grid
from aogm_cli.mapping.plan import Plan, plan_map
from aogm_cli.mapping.runner import Stage, has, lacks, run_stages
from aogm_cli.mapping.state import State

__all__ = ["ALL", "Flagger", "map_in_mode", "map_source", "mode_stages", "planned", "warm_up"]


# Every stage once: its name (the map's phase), its function, the state's fields it reads and writes.
SET_UP_CONES = Stage("set_up", S.set_up_cones, timed=False)
STANDARD_STREAMED = Stage("standard", S.standard_streamed, writes=("standard",))
THINNING_STREAMED = Stage("thinning", S.thinning_streamed, ("standard",), ("standard",))
STANDARD_VIEW = Stage("view", S.standard_view, ("standard",), ("view",), timed=False)
READ = Stage("read", S.read, writes=("whole",), timed=False)
SET_UP = Stage("set_up", S.set_up_em, ("whole",), timed=False)
READINGS = Stage("readings", S.readings, ("whole",), ("readings",), when=lacks("readings"))
STANDARD = Stage("standard", S.standard, ("whole", "readings"), ("standard",), when=lacks("standard"))
WALLS = Stage("walls", S.walls, ("whole", "readings", "standard"), ("echo_walls",))
LOBE = Stage("lobe", S.lobe, ("whole", "readings", "standard", "echo_walls", "exact?"), ("learned", "readings", "exact"))
DEFLECTIONS = Stage("deflections", S.deflections, ("readings", "standard"), ("learned", "readings", "standard"))
RATES = Stage("rates", S.rates, ("whole", "readings", "standard", "echo_walls"), ("learned",))
THINNING = Stage("thinning", S.thinning, ("whole", "readings", "standard", "exact?"), ("standard",))
WHOLE_LOG = Stage("region", S.whole_log, ("readings",), ("region",), timed=False)
DETECTOR = Stage("detector", S.detect, ("whole",), ("flags",))
CLUSTERS = Stage("clusters", S.clusters, ("whole", "readings", "standard", "flags"), ("clusters", "region"))
START = Stage("start", S.start, ("standard", "clusters?"), ("occupied",), timed=False)
CALIBRATION = Stage("calibration", S.calibration, ("readings", "occupied", "region"), ("learned",), when=has("region"))
INDEX = Stage("index", S.index, ("region", "occupied"), ("problem", "candidates"), when=has("region"))
SWEEPS = Stage("sweeps", S.sweeps, ("problem", "candidates", "occupied"), ("em",), when=has("region"))
DECIDED = Stage("decided", S.final_evidence, ("readings", "occupied"), ("final_evidence",))
EM_VIEW = Stage("view", S.em_mode_view, ("whole", "standard", "em"), ("view",))
ADAPTIVE_VIEW = Stage("view", S.adaptive_view, ("whole", "standard", "clusters", "em?", "final_evidence?"), ("view",))


def mode_stages(plan: Plan) -> tuple[Stage, ...]:
    """The stages of ``plan.mode`` as its plan has them; READINGS and STANDARD run again after a stage drops them."""
    incidence = plan.incidence
    thinned = plan.thinning is not None
    if plan.mode == "standard":
        return _present(SET_UP_CONES,
                        STANDARD_STREAMED,
                        thinned and THINNING_STREAMED,
                        STANDARD_VIEW)
    prepared = (READ, SET_UP, READINGS, STANDARD,  # the em and adaptive modes alike
                incidence and DEFLECTIONS, incidence and STANDARD,
                (plan.learns_lobe or plan.fits_rates) and WALLS,
                plan.fits_rates and RATES,  # at the whole cones; again in LOBE when its lobe narrows them
                plan.learns_lobe and LOBE,
                thinned and THINNING)
    if plan.mode == "em":
        return _present(*prepared,
                        WHOLE_LOG,
                        START,
                        plan.calibrates and CALIBRATION,
                        INDEX,
                        SWEEPS,
                        EM_VIEW)
    return _present(*prepared,
                    DETECTOR,
                    CLUSTERS,
                    START,
                    plan.calibrates and CALIBRATION,
                    INDEX,
                    SWEEPS,
                    plan.decides and DECIDED,
                    ADAPTIVE_VIEW)


def _present(*stages) -> tuple[Stage, ...]:
    """The stages the plan keeps (one it leaves out is False)."""
    return tuple(stage for stage in stages if stage)


class Flagger(NamedTuple):
    """The adaptive mode's detector (with ``flag(ranges, max_range)``) and what the map records of it."""

    detector: object
    record: dict


ALL = Flagger(ConstantDetector(True), {"detector": "all"})  # the baseline that flags every reading


def map_in_mode(log, mode: str, params: MapParams, flagger: Flagger = ALL, progress: Progress | None = None,
                given: Learned | None = None) -> OccupancyMap:
    """Map a log source in ``mode``: its plan, then its stages; ``given``: a forward model instead of learning one."""
    stages, state = planned(log, mode, params, flagger, progress, given)
    state, phases = run_stages(stages, state)
    if given is not None and given.seconds:  # learned by another map of this log: its cost counts here too
        phases["calibration"] = phases.get("calibration", 0.0) + given.seconds
    return S.finished(state, phases)


def planned(log, mode: str, params: MapParams, flagger: Flagger = ALL, progress: Progress | None = None,
            given: Learned | None = None) -> tuple[tuple[Stage, ...], State]:
    """The stages of a ``mode`` map of ``log`` (``map_in_mode``) and its state before the first."""
    if mode not in MODES:
        raise ValueError(f"unknown mode {mode!r}; expected one of {', '.join(MODES)}")
    grid = log_grid(log, params.resolution)
    plan = plan_map(mode, params, log.sensor, grid.resolution, given)
    stages = mode_stages(plan)
    plan = dataclasses.replace(plan, stages=tuple(stage.name for stage in stages))
    return stages, State(params, TimedSource(log), grid, plan, *flagger, progress, learned=given or Learned())


def resolved_params(log, params: MapParams) -> MapParams:
    """``params`` with the values the log decides: a simulated log's truth grid's resolution."""
    return dataclasses.replace(params, resolution=log_grid(log, params.resolution).resolution)


def map_source(log, mode: str, params: MapParams, flagger: Flagger = ALL, progress: Progress | None = None,
               limits: Limits | None = None, file: str | None = None, given: Learned | None = None) -> OccupancyMap:
    """Map a log source in ``mode`` unless its estimate exceeds ``limits``; ``stats["untimed_seconds"]`` has
    what ``runtime_s`` leaves out (``compile``, ``read_and_set_up``)."""
    params = resolved_params(log, params)
    check(map_estimate(log, mode, params), limits, file=file)
    t0 = time.perf_counter()
    warm_up(log.sensor, params, mode)
    t_compile = time.perf_counter() - t0
    t0 = time.perf_counter()
    with using(limits or active_limits()):  # EM's sweeps take their threads from the limits in force
        m = map_in_mode(log, mode, params, flagger, progress, given)
    t_total = time.perf_counter() - t0
    m.stats["untimed_seconds"] = {"compile": t_compile, "read_and_set_up": max(0.0, t_total - m.runtime_s)}
    return m


def tiny_log(sensor: SensorSpec) -> Log:
    """Three scans of ``sensor`` in a round room, one reading without echo: every mode's kernels run."""
    pose = np.array([[0.0, 0.0, 0.0], [0.2, 0.1, 0.7], [0.1, 0.3, 1.9]])
    z = 0.5 * (max(sensor.min_range, 0.0) + sensor.max_range)
    ranges = np.full((3, sensor.count), z, dtype=np.float32)
    ranges[1, 0] = np.inf
    return Log(np.arange(3.0), pose, ranges, sensor, source="warm-up")


def warm_up(sensor: SensorSpec, params: MapParams, mode: str) -> None:
    """Compile (or load) the kernels ``mode`` runs by mapping ``tiny_log(sensor)``, so that ``runtime_s`` leaves
    compilation out; EM modes run twice (converged and stopped by the sweep limit: each ends in its own kernel)."""
    jit_cache.load_lean()
    log = tiny_log(sensor)
    map_in_mode(log, mode, params)
    if mode != "standard":
        # stopped by the sweep limit, with a specular angle of 30 degrees: deflected beams
        forward = dataclasses.replace(params.em.forward, specular_deg=30.0)
        # and, for adaptive, the thinned map outside the clusters ("auto" chose Elfes' map above)
        one_sweep = dataclasses.replace(params, em=dataclasses.replace(params.em, forward=forward, max_sweeps=1),
                                        adaptive=dataclasses.replace(params.adaptive, outside="thinned"))
        map_in_mode(log, mode, one_sweep)
