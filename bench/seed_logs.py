"""The benchmarks' inputs: the paper's two seed worlds simulated with seed 1 into a temporary
folder, and a log's readings laid out as EM and adaptive mapping take them (``em_inputs``)."""

from __future__ import annotations

import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from aogm_cli.io.logfile import LogReader, write_log
from aogm_cli.mapping.modes import resolved_params, warm_up
from aogm_cli.mapping.params import MapParams
from aogm_cli.mapping.pipeline import TimedSource, log_grid
from aogm_cli.mapping.standard import set_up, standard_log_odds
from aogm_cli.sensor_models.readings import LaidOutReadings, forward_templates, lay_out_readings
from aogm_cli.simulation.sonar import simulate
from aogm_cli.world.loader import load_world

ROOT = Path(__file__).resolve().parents[1]
SEED_WORLDS = ("corridor_door", "corridor_specular")


def standard_pass(log, grid, params: MapParams, cuts=None):
    """(log_odds, observed, seconds of mapping work) of ``standard.standard_log_odds``, its set-up
    and reading the log left out of the seconds: what the benchmarks time the standard map by."""
    set_up(log.sensor, grid, params)
    timed = TimedSource(log)
    t0 = time.perf_counter()
    log_odds, observed = standard_log_odds(timed, grid, params, cuts)
    return log_odds, observed, time.perf_counter() - t0 - timed.io_seconds


def for_each_seed_log(bench: Callable[[str, Path], None]) -> None:
    """Call ``bench(world_name, log_path)`` for each seed world's simulated log."""
    with tempfile.TemporaryDirectory() as folder:
        for world in SEED_WORLDS:
            log_path = Path(folder) / f"{world}.h5"
            write_log(log_path, simulate(load_world(ROOT / "worlds" / f"{world}.yaml"), seed=1))
            bench(world, log_path)


@dataclass
class EMInputs:
    """What EM and adaptive mapping hold before their own work starts (as the em mode's first stages, ``mapping.modes``)."""

    params: MapParams  # as ``modes.resolved_params`` resolves them for the log
    readings: LaidOutReadings
    log_odds: np.ndarray
    observed: np.ndarray
    t_standard: float  # the standard pass's own clock


def em_inputs(log_path: Path, params: MapParams) -> EMInputs:
    """Compile every kernel of the em mode, run its (timed) standard pass over the whole log held
    in memory and lay out every reading (``readings.lay_out_readings``), as the em mode does."""
    with LogReader(log_path) as reader:
        params = resolved_params(reader, params)
        sensor = reader.sensor
        warm_up(sensor, params, "em")
        grid = log_grid(reader, params.resolution)
        whole = reader.read()
        log_odds, observed, t_standard = standard_pass(whole, grid, params)
    forward_templates(grid, sensor)  # one-time set-up, cached
    readings = lay_out_readings(whole.pose, whole.ranges, sensor, grid)
    return EMInputs(params, readings, log_odds, observed, t_standard)
