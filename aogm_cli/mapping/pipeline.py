"""What every mode shares between a log and its map: the log's grid, the parameters a map records, timing without
reading I/O. A *log source* is an open ``io.logfile.LogReader`` or an in-memory ``core.log.Log``."""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from aogm_cli.core.errors import InputError
from aogm_cli.core.grid import GridSpec
from aogm_cli.mapping.params import MapParams

Progress = Callable[[str, int, int], None]  # (phase, done, total)


def log_grid(log, resolution: float) -> GridSpec:
    """The truth grid of a simulated log; otherwise the poses' bounds plus max range."""
    grid = log.truth_grid()
    if grid is not None:
        return grid
    pose = log.poses()
    finite = np.isfinite(pose).all(axis=1)
    if not finite.any():
        raise InputError("no finite pose; cannot place a grid", file=log.path, key="/scans/pose")
    sensor = log.sensor
    reach = sensor.max_range + float(np.max(np.hypot(sensor.mount[:, 0], sensor.mount[:, 1]), initial=0.0))
    lo = pose[finite, :2].min(axis=0) - reach
    hi = pose[finite, :2].max(axis=0) + reach
    # snap the origin to the resolution so that maps of one log at one resolution align
    lo = np.floor(lo / resolution) * resolution
    return GridSpec.covering(lo[0], lo[1], hi[0], hi[1], resolution)


class TimedSource:
    """A log source that adds up the seconds spent reading it, so that mapping's time can leave them out."""

    def __init__(self, source):
        self.source = source
        self.io_seconds = 0.0

    def __getattr__(self, name):  # sensor, n_scans, path, truth_grid(), poses(), ...
        return getattr(self.source, name)

    def chunks(self, size: int):
        chunks = iter(self.source.chunks(size))
        while True:
            t0 = time.perf_counter()
            chunk = next(chunks, None)
            self.io_seconds += time.perf_counter() - t0
            if chunk is None:
                return
            yield chunk

    def read(self):
        t0 = time.perf_counter()
        whole = self.source.read()
        self.io_seconds += time.perf_counter() - t0
        return whole


def params_json(params: MapParams, mode: str, grid: GridSpec) -> dict:
    """The parameters a map of ``mode`` records: every parameter, defaults included, and its grid."""
    d = params.as_dict()
    d["mode"] = mode
    d["grid"] = {"origin": [grid.origin_x, grid.origin_y], "resolution": grid.resolution,
                 "shape": [grid.height, grid.width]}
    return d
