"""What an aogm log, map or detector file holds, as a JSON-able summary (``describe``: kind,
shape, grid, parameters, stats, provenance), read through each kind's checking reader; ``aogm
info`` prints it and ``aogm_cli.info`` returns it.
"""

from __future__ import annotations

from aogm_cli.core.errors import InputError
from aogm_cli.io import detectorfile, logfile, mapfile
from aogm_cli.io.detectorfile import TRAINING_LOGS, load_detector
from aogm_cli.io.h5file import file_format
from aogm_cli.io.logfile import LogReader
from aogm_cli.io.mapfile import read_map_file
from aogm_cli.io.provenance import read_provenance


def describe(file: str) -> dict:
    """The summary of ``file`` as a JSON-able dict: ``kind``, the kind's fields, ``provenance``
    (None when none is recorded). InputError for a missing, damaged or non-aogm file."""
    expected = "an aogm log, map or detector"
    kinds = {logfile.FORMAT: _log, mapfile.FORMAT: _map, detectorfile.FORMAT: _detector}
    fmt, provenance = file_format(file, expected, lambda f: read_provenance(f, file))
    if fmt not in kinds:
        raise InputError(f"expected {expected} ({', '.join(map(repr, kinds))}), got {fmt!r}", file=file, key="format")
    # the kind's reader checks the file's version and contents
    return {"file": file, "kind": fmt.removeprefix("aogm-"), **kinds[fmt](file), "provenance": provenance}


def _grid(grid) -> dict:
    return {"origin": [grid.origin_x, grid.origin_y], "resolution": grid.resolution, "shape": [grid.height, grid.width]}


def _log(file: str) -> dict:
    with LogReader(file) as log:
        truth = log.truth()
        return {
            "shape": {"scans": log.n_scans, "sensors": log.sensor.count},
            "source": log.source,
            "seed": log.seed,
            "sensor": log.sensor.as_dict(),
            "grid": None if truth is None else _grid(truth.grid),
            "checks": None if truth is None else [c["name"] for c in truth.checks],
        }


def _map(file: str) -> dict:
    m = read_map_file(file)
    layers = {"log_odds": m.log_odds, "occupied": m.occupied, "clusters": m.clusters}
    return {
        "shape": {"height": m.grid.height, "width": m.grid.width},
        "mode": m.mode,
        "source_log": m.source_log,
        "grid": _grid(m.grid),
        "layers": ["probability", "observed", *(name for name, layer in layers.items() if layer is not None)],
        "observed_cells": int(m.observed.sum()),
        "occupied_cells": int((m.probability[m.observed] > 0.5).sum()),
        "runtime_s": m.runtime_s,
        "params": m.params,
        "learned": m.learned,
        "plan": m.plan,
        "stats": m.stats,
    }


def _detector(file: str) -> dict:
    d = load_detector(file)
    spec = d.feature_spec
    return {
        "shape": [spec.n_features, *(layer.weight.shape[1] for layer in d.layers)],
        "features": {"ring_neighbours": spec.ring_neighbours, "time_neighbours": spec.time_neighbours,
                     "differences": spec.differences, "missing_flags": spec.missing_flags, "count": spec.n_features},
        "network": d.training.get("network"),
        "threshold": d.threshold,
        "metrics": d.metrics,
        "training_logs": d.training.get(TRAINING_LOGS),
    }
