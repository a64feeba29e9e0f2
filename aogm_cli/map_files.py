"""The library's entry for mapping log files (``map_file``), which the commands, ``aogm_cli.api`` and
``aogm compare`` call: the ``--params`` YAML, the detector file, the sensor model file and the log are
read here, where the forward model a map uses is chosen (``sensor_model``), and handed to the mappers
as values (``mapping.modes.map_source``), which open no file."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Any

import numpy as np

from aogm_cli.core.budget import Limits, check
from aogm_cli.core.occupancy_map import OccupancyMap
from aogm_cli.detector.network import ConstantDetector, Detector
from aogm_cli.io import template_store
from aogm_cli.io.detectorfile import BASELINE_DETECTORS, file_sha256, load_detector
from aogm_cli.io.logfile import LogReader
from aogm_cli.io.modelfile import LOBE_KEYS, MODEL_KEYS, check_sensor, model_for, read_model, sensor_record
from aogm_cli.io.yamlfile import read_yaml
from aogm_cli.mapping.learned import FROM_LOG, SENSOR_KEYS, Learned, SensorModel
from aogm_cli.mapping.map_cost import map_estimate
from aogm_cli.mapping.params import LEARNABLE, MapParams, params_from
from aogm_cli.mapping.pipeline import Progress, log_grid
from aogm_cli.mapping.plan import auto_outside, plan_map
from aogm_cli.sensor_models import cone_build

__all__ = ["BASELINE_DETECTORS", "NamedSource", "calibration_notice", "carried_model", "check_logs", "given_model",
           "learn_sensor_models", "learned_over", "map_file", "resolve_detector", "resolve_params", "sensor_model",
           "set_em_keys"]


def resolve_params(params_file: str | Path | None = None, overrides: dict[str, dict[str, Any]] | None = None) -> MapParams:
    """Defaults, then the ``--params`` YAML file's values, then ``overrides`` (``mapping.params.params_from``)."""
    raw = (read_yaml(params_file)[1] or {}) if params_file else {}
    return params_from(raw, None if params_file is None else str(params_file), overrides)


def set_em_keys(params_file: str | Path | None = None, overrides: dict[str, dict[str, Any]] | None = None) -> set[str]:
    """The keys of section ``em`` that the ``--params`` file or ``overrides`` (an option given) set."""
    raw = (read_yaml(params_file)[1] or {}) if params_file else {}
    em = raw.get("em") if isinstance(raw, dict) else None
    return set(em or {}) | {k for k, v in ((overrides or {}).get("em") or {}).items() if v is not None}


def learned_over(mode: str, params: MapParams, keys: set[str], log, model: str | Path | None = None,
                 detector: str | None = None) -> list[str]:
    """One warning per forward-model key of ``keys`` (set by the user: ``set_em_keys``) whose value a ``mode`` map of
    ``log`` does not map with: one ``calibration.learn`` lists learns it from the log (``Plan.learns``; the value set
    only starts the fit, a lobe's is replaced), a sensor model given or carried (``sensor_model``) replaces it, or
    (``lobe_range``) no lobe is configured for it to shape."""
    if mode == "standard" or not keys & {*LEARNABLE, "lobe_range"}:
        return []
    given = sensor_model(mode, params, log, str(getattr(log, "path", "")), model, detector)
    learns = plan_map(mode, params, log.sensor, log_grid(log, params.resolution).resolution, given).learns
    forward, out = params.em.forward, []
    for key in (k for k in (*LEARNABLE, "lobe_range") if k in keys):
        learned = "lobe_deg" if key == "lobe_range" else key
        with_value = f"to map with {getattr(forward, key):g}"
        if learned in learns:
            out.append(f"warning: em.{key} is learned from the log (calibration.learn lists {learned}); take "
                       f"{learned} out of calibration.learn {with_value}")
        elif learned == "lobe_deg" and given is not None and given.carries_lobe:
            out.append(f"warning: em.{key} is the lobe the sensor's model carries ({given.origin}); take lobe_deg out "
                       f"of calibration.learn {with_value}")
        elif given is not None and key in SENSOR_KEYS:
            fix = ("map without --forward-model" if given.origin.startswith("file ") else "set calibration.carried: false")
            out.append(f"warning: em.{key} is the sensor model's, {given.origin}; {fix} and take {key} out of "
                       f"calibration.learn {with_value}")
        elif key == "lobe_range" and forward.lobe_deg == 0:
            out.append("warning: em.lobe_range has no effect while em.lobe_deg is 0 (every cell of the cone hears); "
                       "set em.lobe_deg too")
    return out


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
             progress: Progress | None = None, limits: Limits | None = None, model: Learned | str | Path | None = None,
             source=None) -> OccupancyMap:
    """Map the log at ``path`` in ``mode``, or the log source ``source`` named by ``path`` (the log
    open already, or the scans a held-out split keeps), with the forward model ``sensor_model``
    chooses (``model``: one another map of the same log learned, or a model file's path;
    ``detector``: see ``resolve_detector``); refused (``InputError``) before any work when its
    estimate exceeds ``limits`` (``mapping.modes.map_source``)."""
    from aogm_cli.mapping.modes import ALL, Flagger, map_source

    cone_build.use_store(template_store.STORE)  # cone templates kept on disk, in a Dask worker too
    flagger = Flagger(*resolve_detector(detector)) if mode == "adaptive" else ALL

    def run(log):
        given = sensor_model(mode, params, log, str(path), model, detector, flagger.detector)
        return map_source(log, mode, params, flagger, progress, limits, str(path), given)

    if source is not None:
        return run(source)
    with LogReader(path) as reader:
        return run(reader)


def sensor_model(mode: str, params: MapParams, log, name: str, model: Learned | str | Path | None = None,
                 detector: str | None = None, loaded=None) -> Learned | None:
    """Where the forward model of a ``mode`` map of ``log`` (a log source named ``name``) comes
    from, decided here only: none for the standard mode; ``model``, learned by another map of the
    same log, or the model file at that path (``given_model``); else, with ``calibration.carried``,
    the one ``detector`` carries for the log's sensor (``carried_model``; ``loaded``: that detector
    as the adaptive mode read it); else none (the map learns it from the log, or takes the
    configured values: ``mapping.plan``). A robot's model keeps its lobe only where the map would
    learn one (``Learned.kept_for``)."""
    if mode == "standard":
        return None
    if isinstance(model, Learned):
        return model
    if model:
        return given_model(model, log.sensor, name).kept_for(params.calibration.learned)
    if params.calibration.enabled and params.calibration.carried:
        carried = carried_model(detector, log.sensor, log.truth_grid() is not None, loaded)
        return None if carried is None else carried.kept_for(params.calibration.learned)
    return None


def carried_model(detector: str | None, sensor, simulated: bool, loaded=None) -> Learned | None:
    """The sensor model that the detector ``detector`` (a file; the packaged one for None or a
    baseline) carries for ``sensor`` of a ``simulated`` log or not (``io.modelfile.model_for``),
    as a map takes it: learned once for the robot, so only the building's part (``learned.BUILDING``)
    is learned from the log; None when it carries none for that sensor (the map calibrates on its
    log). ``loaded``: that detector as the adaptive mode already read it (a baseline's is not)."""
    spec = None if detector in BASELINE_DETECTORS else detector
    carrier = loaded if isinstance(loaded, Detector) else load_detector(spec)
    model = model_for(carrier.sensor_models, sensor, simulated)
    if model is None:
        return None
    return robots_model(model["model"], f"carried by the {'packaged' if spec is None else spec} detector")


def robots_model(values: dict, origin: str) -> Learned:
    """A robot's model (``io.modelfile.model_values``) as its maps take it: the sensor's part, and the lobe when it
    carries one (``io.modelfile.LOBE_KEYS``; then no log learns it)."""
    return Learned(sensor=SensorModel.read(values), origin=origin, lobe_deg=values.get("lobe_deg"),
                   lobe_range=values.get("lobe_range"))


def calibration_notice(path, m: OccupancyMap) -> str | None:
    """The line that says a map calibrated its sensor's model on its own log (no model given, and
    none carried by the detector for that sensor or ``calibration.carried`` false), or None."""
    if m.mode == "standard" or (m.learned or {}).get("origin") != FROM_LOG:
        return None
    if not m.params.get("calibration", {}).get("carried", True):
        why = "calibration.carried is false"
    else:
        why = ("the detector carries none for its sensor; aogm calibrate LOG -o MODEL learns one, --forward-model "
               "MODEL carries it")
    if (m.mode == "adaptive" and m.stats.get("outside") == "elfes" and m.params.get("adaptive", {}).get("outside") == "auto"
            and auto_outside(True, (m.plan or {}).get("sensor")) == "thinned"):
        why += "; with a model given, adaptive keeps the thinned map outside its clusters, at less cost"
    return f"{path}: calibrated the sensor's model on this log ({why})"


def learn_sensor_models(paths, params: MapParams, advance=None) -> tuple[dict, ...]:
    """The sensor models a detector trained on the logs at ``paths`` carries: one per sensor among
    them, each value the median over its logs' calibrations (an em map each, as ``aogm
    calibrate``), with the logs' names; the lobe (``model_record``) only when every log learned the same shape (all the
    whole cone, or all a narrower lobe: their median), as a lobe some logs learn and others not is the logs', not the
    transducer's."""
    groups: dict[str, tuple[dict, list, list]] = {}
    for path in paths:
        m = map_file(path, "em", dataclasses.replace(params, calibration=dataclasses.replace(params.calibration,
                                                                                            carried=False)))
        with LogReader(path) as reader:
            record = sensor_record(reader.sensor) | {"simulated": reader.has_truth}
        key = json.dumps(record, sort_keys=True)
        groups.setdefault(key, (record, [], []))
        groups[key][1].append(model_record(m.learned))
        groups[key][2].append(Path(path).name)
        if advance is not None:
            advance(1)
    return tuple({"sensor": record, "model": {k: float(np.median([v[k] for v in values]))
                                              for k in (*MODEL_KEYS, *(LOBE_KEYS if one_lobe(values) else ()))},
                  "learned_from": names} for record, values, names in groups.values())


def one_lobe(values: list[dict]) -> bool:
    """Every model of ``values`` (``model_record``) has a lobe, and all the same shape: the whole cone, or narrower."""
    return all("lobe_deg" in v for v in values) and len({v["lobe_deg"] == 0.0 for v in values}) == 1


def model_record(learned: dict) -> dict:
    """The robot's model a map learned (its ``learned`` record): the sensor's part, and the lobe if it learned one
    (``io.modelfile.LOBE_KEYS``), as a model file or detector carries it."""
    lobe = {} if learned.get("lobe_deg") is None else {k: float(learned[k]) for k in LOBE_KEYS}
    return dict(learned["sensor"]) | lobe


def given_model(path: str | Path, sensor, log: str | Path) -> Learned:
    """The sensor model file at ``path`` (``aogm calibrate -o``) as a map of the log ``log``, of
    ``sensor``, takes it: refused (``InputError`` naming the model file and what differs) when it
    was learned for another sensor."""
    values, record = read_model(path)
    check_sensor(record, sensor, str(path), str(log))
    return robots_model(values, f"file {path}")


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
