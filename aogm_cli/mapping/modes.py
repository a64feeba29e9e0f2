"""The three modes behind one call: ``map_file(path, mode, params, detector)`` opens a log, resolves
the parameters it derives (the grid's resolution), compiles every kernel the mode runs by mapping a
tiny synthetic log with the same sensor, and maps the log (``map_in_mode``)."""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import numpy as np

from aogm_cli.core import jit_cache
from aogm_cli.core.budget import Limits, check
from aogm_cli.core.log import Log, SensorSpec
from aogm_cli.core.occupancy_map import MODES, OccupancyMap
from aogm_cli.detector.network import ConstantDetector
from aogm_cli.io.detectorfile import BASELINE_DETECTORS, file_sha256, load_detector
from aogm_cli.io.logfile import LogReader
from aogm_cli.mapping.map_cost import map_estimate
from aogm_cli.mapping.params import MapParams
from aogm_cli.mapping.pipeline import Progress, log_grid
from aogm_cli.mapping.standard import map_standard

__all__ = ["BASELINE_DETECTORS", "map_file", "map_in_mode", "map_source", "resolve_detector", "warm_up"]


def resolve_detector(spec: str | None):
    """(detector, name): the packaged detector for None, a baseline for "all" / "none", else
    the detector file at ``spec`` (checked by ``io.detectorfile.load_detector``)."""
    if spec in BASELINE_DETECTORS:
        return ConstantDetector(spec == "all"), spec
    detector = load_detector(spec)
    return detector, "packaged" if spec is None else str(spec)


def map_in_mode(log, mode: str, params: MapParams, detector=None, detector_name: str = "packaged",
            progress: Progress | None = None) -> OccupancyMap:
    """Map a log source (an open ``LogReader`` or a ``Log``) in ``mode``; adaptive needs ``detector``.
    EM's and adaptive's modules are imported here, when used (a standard map's start-up is most of its time)."""
    if mode == "standard":
        m = map_standard(log, params, progress)
    elif mode == "em":
        from aogm_cli.mapping.em import map_em

        m = map_em(log, params, progress)
    elif mode == "adaptive":
        from aogm_cli.mapping.adaptive import map_adaptive

        m = map_adaptive(log, params, detector, detector_name, progress)
    else:
        raise ValueError(f"unknown mode {mode!r}; expected one of {', '.join(MODES)}")
    if mode == "adaptive" and getattr(detector, "path", None):  # the detector file's identity, as it was used
        m.params["detector_sha256"] = file_sha256(detector.path)
    return m


def resolved_params(log, params: MapParams) -> MapParams:
    """``params`` with the values the log decides: a simulated log's maps take its truth grid,
    and so its resolution."""
    return dataclasses.replace(params, resolution=log_grid(log, params.resolution).resolution)


def map_file(path: str | Path, mode: str, params: MapParams, detector: str | None = None,
             progress: Progress | None = None, limits: Limits | None = None) -> OccupancyMap:
    """Map the log at ``path`` in ``mode`` (``detector``: see ``resolve_detector``); refused
    (``InputError``) before any work when its estimate exceeds ``limits`` (default: the
    limits in force, ``core.budget.active_limits``).

    The map's ``runtime_s`` is its mapping work; ``stats["untimed_seconds"]`` says what was
    left out: ``compile`` (the warm-up) and ``read_and_set_up`` (reading the log, cached
    one-time templates)."""
    with LogReader(path) as reader:
        return map_source(reader, mode, params, detector, progress, limits, file=str(path))


def map_source(log, mode: str, params: MapParams, detector: str | None = None, progress: Progress | None = None,
               limits: Limits | None = None, file: str | None = None) -> OccupancyMap:
    """``map_file`` on a log source (an open ``LogReader`` or an in-memory ``Log``, such as the
    scans a held-out split keeps); ``file`` names it in a refusal."""
    flagger, name = resolve_detector(detector) if mode == "adaptive" else (None, "")
    params = resolved_params(log, params)
    check(map_estimate(log, mode, params), limits, file=file)
    t0 = time.perf_counter()
    warm_up(log.sensor, params, mode)
    t_compile = time.perf_counter() - t0
    t0 = time.perf_counter()
    m = map_in_mode(log, mode, params, flagger, name, progress)
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
    modes run twice: to convergence and stopped by the sweep limit (each ends in its own kernel).
    Cached kernels are loaded without numba's full start-up (``core.jit_cache``)."""
    jit_cache.load_lean()
    log = tiny_log(sensor)
    map_in_mode(log, mode, params, ConstantDetector(True), "all")
    if mode != "standard":
        # stopped by the sweep limit, and with a specular angle given (the tiny log learns none: too
        # few readings), so that the deflected beams' kernel runs too
        forward = dataclasses.replace(params.em.forward, specular_deg=30.0)
        learn = ",".join(k for k in params.calibration.learned if k != "specular_deg") or "sigma"
        one_sweep = dataclasses.replace(params, em=dataclasses.replace(params.em, forward=forward, max_sweeps=1),
                                        calibration=dataclasses.replace(params.calibration, learn=learn))
        map_in_mode(log, mode, one_sweep, ConstantDetector(True), "all")
