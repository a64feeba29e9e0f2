"""Mapping a log file, at the edge where files are opened: the ``--params`` YAML, the detector file,
the sensor model file and the log itself are read here and handed to the mappers as values
(``mapping.modes.map_source``), which open no file."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from aogm_cli.core.budget import Limits, check
from aogm_cli.core.occupancy_map import OccupancyMap
from aogm_cli.detector.network import ConstantDetector
from aogm_cli.io import template_store
from aogm_cli.io.detectorfile import BASELINE_DETECTORS, file_sha256, load_detector
from aogm_cli.io.logfile import LogReader
from aogm_cli.io.modelfile import check_sensor, read_model
from aogm_cli.io.yamlfile import read_yaml
from aogm_cli.mapping.learned import Learned, SensorModel
from aogm_cli.mapping.map_cost import map_estimate
from aogm_cli.mapping.params import MapParams, params_from
from aogm_cli.mapping.pipeline import Progress
from aogm_cli.sensor_models import cone

__all__ = ["BASELINE_DETECTORS", "NamedSource", "check_logs", "given_model", "map_file", "resolve_detector",
           "resolve_params"]


def resolve_params(params_file: str | Path | None = None, overrides: dict[str, dict[str, Any]] | None = None) -> MapParams:
    """Defaults, then the ``--params`` YAML file's values, then ``overrides`` (``mapping.params.params_from``)."""
    raw = (read_yaml(params_file)[1] or {}) if params_file else {}
    return params_from(raw, None if params_file is None else str(params_file), overrides)


def resolve_detector(spec: str | None):
    """(detector, what the map records of it): the packaged detector for None, a baseline for
    "all" / "none", else the detector file at ``spec`` (checked by ``io.detectorfile.load_detector``);
    a file's record holds its sha256 as it was used."""
    if spec in BASELINE_DETECTORS:
        return ConstantDetector(spec == "all"), {"detector": spec}
    detector = load_detector(spec)
    record = {"detector": "packaged" if spec is None else str(spec)}
    if getattr(detector, "path", None):
        record["detector_sha256"] = file_sha256(detector.path)
    return detector, record


def map_file(path: str | Path, mode: str, params: MapParams, detector: str | None = None,
             progress: Progress | None = None, limits: Limits | None = None, given: Learned | None = None,
             source=None) -> OccupancyMap:
    """Map the log at ``path`` in ``mode`` (``detector``: see ``resolve_detector``; ``given``: a
    forward model to use instead of learning one), or the log source ``source`` (the scans a
    held-out split keeps) named by ``path``; refused (``InputError``) before any work when its
    estimate exceeds ``limits`` (``mapping.modes.map_source``)."""
    from aogm_cli.mapping.modes import ALL, Flagger, map_source

    cone.use_store(template_store.STORE)  # cone templates kept on disk, in a Dask worker too
    flagger = Flagger(*resolve_detector(detector)) if mode == "adaptive" else ALL
    if source is not None:
        return map_source(source, mode, params, flagger, progress, limits, str(path), given)
    with LogReader(path) as reader:
        return map_source(reader, mode, params, flagger, progress, limits, str(path), given)


def given_model(path: str | Path, log: str | Path) -> Learned:
    """The sensor model file at ``path`` (``aogm calibrate -o``) as a map of the log file ``log``
    takes it: refused (``InputError`` naming the model file and what differs) when it was learned
    for another sensor."""
    values, record = read_model(path)
    with LogReader(log) as reader:
        check_sensor(record, reader.sensor, str(path), str(log))
    return Learned(sensor=SensorModel(**values), origin=f"file {path}", opening_deg=values["opening_deg"])


class NamedSource:
    """A log source in memory (the scans a held-out split keeps) named as the file it came from,
    with what its map's params record of it (``recorded``, e.g. the split)."""

    def __init__(self, log, path: str, recorded: dict):
        self.log, self.path, self.recorded = log, path, recorded

    def __getattr__(self, name):  # sensor, n_scans, truth_grid(), poses(), chunks(), read()
        return getattr(self.log, name)


def check_logs(tasks, params: MapParams, limits=None) -> None:
    """Refuse (``InputError``) the first (log path, mode) of ``tasks`` whose map would exceed ``limits``."""
    for path, mode in tasks:
        with LogReader(path) as reader:
            check(map_estimate(reader, mode, params), limits, file=str(path))
