"""The three modes, each a list of stages (``MODE_STAGES``), behind one call: ``map_source(log, mode,
params, detector)`` resolves the parameters the log derives (the grid's resolution), compiles every
kernel the mode runs by mapping a tiny synthetic log with the same sensor, and maps the log."""

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
from aogm_cli.mapping.stages import Stage

__all__ = ["ALL", "MODE_STAGES", "Flagger", "map_in_mode", "map_source", "warm_up"]

# Each mode as the list of its stages (``mapping.stages``): the standard map; em over every cell some
# cone holds; adaptive over the clusters of the readings the detector flags.
STANDARD = (
    Stage("set_up", S.templates, timed=False),
    Stage("standard", S.standard),
    Stage("thinning", S.thinning, when=S.thinned),
    Stage("view", S.standard_view, timed=False),
)
PREPARE = (  # the em and adaptive modes' first stages
    Stage("read", S.read, timed=False),
    Stage("standard", S.standard),
    Stage("set_up", S.templates, timed=False),
    Stage("readings", S.readings),
    Stage("opening", S.opening, when=S.learns_opening),
    Stage("deflections", S.deflections),
    Stage("rates", S.rates, when=S.fits_rates),
    Stage("thinning", S.thinning, when=S.thinned),
)
EM_STAGES = (  # and their last
    Stage("start", S.start, timed=False),
    Stage("calibration", S.calibration, when=S.calibrates),
    Stage("index", S.index, when=S.runs_em),
    Stage("sweeps", S.sweeps, when=S.runs_em),
    Stage("view", S.em_view),
)
MODE_STAGES = {
    "standard": STANDARD,
    "em": PREPARE + EM_STAGES,
    "adaptive": PREPARE[:-1] + (Stage("thinning", S.thinning_outside, when=S.thins_outside), Stage("detector", S.detect),
                                Stage("clusters", S.clusters)) + EM_STAGES[:-1]
    + (Stage("decided", S.decided, when=S.keeps_thinned), EM_STAGES[-1]),
}


class Flagger(NamedTuple):
    """The adaptive mode's detector (anything with ``flag(ranges, max_range)``) and what the map's
    params record of it (``{"detector": name}``, and a file's sha256)."""

    detector: object
    record: dict


ALL = Flagger(ConstantDetector(True), {"detector": "all"})  # the baseline that flags every reading


def map_in_mode(log, mode: str, params: MapParams, flagger: Flagger = ALL, progress: Progress | None = None,
                given: Learned | None = None) -> OccupancyMap:
    """Map a log source (an open ``LogReader`` or a ``Log``) in ``mode`` (its stages,
    ``MODE_STAGES``); adaptive flags readings with ``flagger``. ``given``: the forward model to
    use instead of learning one (``mapping.learned``)."""
    if mode not in MODE_STAGES:
        raise ValueError(f"unknown mode {mode!r}; expected one of {', '.join(MODES)}")
    source = TimedSource(log)
    state = S.State(params, source, log_grid(log, params.resolution), given, *flagger, progress,
                    learned=given or Learned())
    state, phases = S.run_stages(MODE_STAGES[mode], state)
    if given is not None and given.seconds:  # learned by another map of this log: its cost counts here too
        phases["calibration"] = phases.get("calibration", 0.0) + given.seconds
    return S.finished(mode, state, phases)


def resolved_params(log, params: MapParams) -> MapParams:
    """``params`` with the values the log decides: a simulated log's maps take its truth grid,
    and so its resolution."""
    return dataclasses.replace(params, resolution=log_grid(log, params.resolution).resolution)


def map_source(log, mode: str, params: MapParams, flagger: Flagger = ALL, progress: Progress | None = None,
               limits: Limits | None = None, file: str | None = None, given: Learned | None = None) -> OccupancyMap:
    """Map a log source (an open ``LogReader`` or an in-memory ``Log``) in ``mode``, with
    ``flagger`` and ``given`` (``map_in_mode``); refused (``InputError``, naming ``file``) before any work when its estimate
    exceeds ``limits`` (default: the limits in force, ``core.budget.active_limits``).

    The map's ``runtime_s`` is its mapping work; ``stats["untimed_seconds"]`` says what was
    left out: ``compile`` (the warm-up) and ``read_and_set_up`` (reading the log, cached
    one-time templates)."""
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
    """Three scans of ``sensor`` in a round room (every reading at one range, one no echo):
    enough for every kernel of every mode to run, clusters and EM flips included."""
    pose = np.array([[0.0, 0.0, 0.0], [0.2, 0.1, 0.7], [0.1, 0.3, 1.9]])
    z = 0.5 * (max(sensor.min_range, 0.0) + sensor.max_range)
    ranges = np.full((3, sensor.count), z, dtype=np.float32)
    ranges[1, 0] = np.inf
    return Log(np.arange(3.0), pose, ranges, sensor, source="warm-up")


def warm_up(sensor: SensorSpec, params: MapParams, mode: str) -> None:
    """Compile (or load from numba's cache) the kernels ``mode`` runs, by running the mode's
    own pipeline on ``tiny_log(sensor)``, so that ``runtime_s`` leaves compilation out. EM
    modes run twice (to convergence and stopped by the sweep limit: each ends in its own kernel);
    EM's kernels take the same types whatever the number of readings (``em_kernels.ReadingTables``),
    so that these serve a cluster of one reading too.
    Cached kernels are loaded without numba's full start-up (``core.jit_cache``)."""
    jit_cache.load_lean()
    log = tiny_log(sensor)
    map_in_mode(log, mode, params)
    if mode != "standard":
        # stopped by the sweep limit, and with a specular angle given (the tiny log learns none: too
        # few readings), so that the deflected beams' kernel runs too
        forward = dataclasses.replace(params.em.forward, specular_deg=30.0)
        learn = ",".join(k for k in params.calibration.learned if k != "specular_deg") or "sigma"
        # and, for adaptive, with the thinned map outside the clusters (the tiny log has no model
        # given, so "auto" chose Elfes' map above)
        one_sweep = dataclasses.replace(params, em=dataclasses.replace(params.em, forward=forward, max_sweeps=1),
                                        calibration=dataclasses.replace(params.calibration, learn=learn),
                                        adaptive=dataclasses.replace(params.adaptive, outside="thinned"))
        map_in_mode(log, mode, one_sweep)
