"""The sensor model file (YAML) that ``aogm calibrate -o MODEL`` writes and ``--forward-model MODEL``
reads: the forward model's sensor part (sigma, p_rand, p_hit, p_max, and the transducer's lobe that hears:
lobe_deg, lobe_range) and the sensor it was learned for, checked against every log it is used with."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import yaml

from aogm_cli.core.errors import InputError
from aogm_cli.core.log import SensorSpec
from aogm_cli.io.yamlfile import read_yaml

FORMAT = "aogm-sensor-model"
FORMAT_VERSION = 1
# ``mapping.learned.SensorModel``'s fields; the ``opening_deg`` that older files and detectors carry is not read
MODEL_KEYS = ("sigma", "p_rand", "p_hit", "p_max")
# the lobe that hears (``ForwardModelConfig.lobe_deg``, 0: the whole cone), carried with the model; a file without
# it (an older one) leaves the lobe to each log
LOBE_KEYS = ("lobe_deg", "lobe_range")
MOUNT_TOLERANCE = 1e-6  # m and rad: mounts that differ by less are the same sensor
ANGLE_TOLERANCE = 1e-6  # degrees


def sensor_record(sensor: SensorSpec) -> dict:
    """What a model file says of the sensor it was learned for."""
    return {"kind": sensor.kind, "count": sensor.count, "beam_width_deg": round(math.degrees(sensor.beam_width), 9),
            "min_range": float(sensor.min_range), "max_range": float(sensor.max_range),
            "mounts": [[float(x), float(y), round(math.degrees(yaw), 9)] for x, y, yaw in np.asarray(sensor.mount)]}


def model_bytes(model: dict, sensor: SensorSpec, source: str, provenance: dict | None = None) -> bytes:
    """The model file of ``model`` (``MODEL_KEYS``' values and the lobe's, if any), learned from the log ``source``
    of ``sensor``."""
    body = {"format": FORMAT, "format_version": FORMAT_VERSION, "sensor": sensor_record(sensor),
            "model": {k: float(model[k]) for k in (*MODEL_KEYS, *LOBE_KEYS) if model.get(k) is not None},
            "learned_from": source}
    if provenance is not None:
        body["provenance"] = json.loads(json.dumps(provenance))
    head = (f"# the forward model of a {sensor.kind} ring of {sensor.count}, learned by aogm calibrate from {source}:\n"
            "# aogm map LOG --forward-model THIS_FILE maps other logs of the same sensor without calibrating\n")
    return (head + yaml.safe_dump(body, sort_keys=False)).encode()


def _number(value, file: str, key: str, low: float, high: float, *, closed_high: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise InputError(f"expected a number, got {value!r}", file=file, key=key)
    if not (low <= value <= high if closed_high else low <= value < high):
        raise InputError(f"expected a number in [{low:g}, {high:g}{']' if closed_high else ')'}, got {value!r}",
                         file=file, key=key)
    return float(value)


def _mapping(body, file: str, key: str | None) -> dict:
    if not isinstance(body, dict):
        raise InputError("expected a mapping", file=file, key=key)
    return body


def read_model(path: str | Path) -> tuple[dict, dict]:
    """(the model, the sensor record) of the model file at ``path``; InputError naming the file and
    key when it is damaged, not a model file, or of a newer format version."""
    file = str(path)
    body = _mapping(read_yaml(path)[1], file, None)
    if body.get("format") != FORMAT:
        raise InputError(f"expected format {FORMAT!r} (a file of aogm calibrate -o), got {body.get('format')!r}",
                         file=file, key="format")
    version = body.get("format_version")
    if isinstance(version, bool) or not isinstance(version, int) or version < 1:
        raise InputError(f"expected a whole number >= 1, got {version!r}", file=file, key="format_version")
    if version > FORMAT_VERSION:
        raise InputError(f"format version {version} is newer than this aogm reads ({FORMAT_VERSION}): "
                         "update aogm, or calibrate again", file=file, key="format_version")
    model = model_values(_mapping(body.get("model"), file, "model"), file, "model")
    return model, _sensor(_mapping(body.get("sensor"), file, "sensor"), file)


def model_values(values: dict, file: str, key: str) -> dict:
    """``MODEL_KEYS``' values of a model (the mapping at ``key`` of ``file``) and ``LOBE_KEYS``' (both or
    neither), checked."""
    bounds = {"sigma": (1e-6, 10.0), "p_rand": (1e-9, 1.0), "p_hit": (1e-9, 1.0), "p_max": (0.0, 1.0)}
    model = {k: _number(values.get(k), file, f"{key}.{k}", *bounds[k]) for k in MODEL_KEYS}
    if model["p_rand"] + model["p_max"] >= 1:
        raise InputError(f"expected p_rand + p_max < 1, got {model['p_rand'] + model['p_max']:g}", file=file,
                         key=f"{key}.p_max")
    lobe = [k for k in LOBE_KEYS if k in values]
    if lobe:
        missing = next((k for k in LOBE_KEYS if k not in values), None)
        if missing is not None:
            raise InputError(f"expected both {' and '.join(LOBE_KEYS)}, got only {lobe[0]}", file=file,
                             key=f"{key}.{missing}")
        model["lobe_deg"] = _number(values["lobe_deg"], file, f"{key}.lobe_deg", 0.0, 90.0, closed_high=True)
        model["lobe_range"] = _number(values["lobe_range"], file, f"{key}.lobe_range", 1e-9, math.inf)
    return model


def carried_models(body, file: str, key: str) -> tuple[dict, ...]:
    """The sensor models a detector file carries (a list of ``{"sensor", "model", "learned_from"}``
    at ``key``), checked; InputError naming ``file`` and the key."""
    if not isinstance(body, list):
        raise InputError("expected a list of sensor models", file=file, key=key)
    out = []
    for i, entry in enumerate(body):
        entry = _mapping(entry, file, f"{key}[{i}]")
        out.append({"sensor": _sensor(_mapping(entry.get("sensor"), file, f"{key}[{i}].sensor"), file),
                    "model": model_values(_mapping(entry.get("model"), file, f"{key}[{i}].model"), file,
                                          f"{key}[{i}].model"),
                    "learned_from": entry.get("learned_from", [])})
    return tuple(out)


def _sensor(record: dict, file: str) -> dict:
    count = record.get("count")
    if isinstance(count, bool) or not isinstance(count, int) or count < 1:
        raise InputError(f"expected a whole number >= 1, got {count!r}", file=file, key="sensor.count")
    mounts = record.get("mounts")
    try:
        array = np.asarray(mounts, dtype=np.float64)
    except (TypeError, ValueError):
        array = np.zeros((0,))
    if array.shape != (count, 3) or not np.isfinite(array).all():
        raise InputError(f"expected {count} rows of x, y, yaw (degrees), got {mounts!r}", file=file, key="sensor.mounts")
    for key in ("beam_width_deg", "max_range"):
        _number(record.get(key), file, f"sensor.{key}", 0.0, math.inf)
    return record


def sensor_differences(record: dict, sensor: SensorSpec) -> list[tuple[str, str]]:
    """(key, what differs) between the sensor a model was learned for (``record``) and ``sensor``:
    count, mounts, beam width and range; empty when it is the same sensor."""
    ours = sensor_record(sensor)
    differs = []
    if record["count"] != ours["count"]:
        differs.append(("sensor.count", f"{record['count']} sensors, the log's {ours['count']}"))
    elif not np.allclose(np.asarray(record["mounts"], float), np.asarray(ours["mounts"], float), rtol=0,
                         atol=MOUNT_TOLERANCE):
        differs.append(("sensor.mounts", f"mounts {record['mounts']}, the log's {ours['mounts']}"))
    if abs(record["beam_width_deg"] - ours["beam_width_deg"]) > ANGLE_TOLERANCE:
        differs.append(("sensor.beam_width_deg", f"a beam of {record['beam_width_deg']:g} deg, the log's "
                                                 f"{ours['beam_width_deg']:g}"))
    if abs(record["max_range"] - ours["max_range"]) > MOUNT_TOLERANCE:
        differs.append(("sensor.max_range", f"max range {record['max_range']:g} m, the log's {ours['max_range']:g}"))
    return differs


def check_sensor(record: dict, sensor: SensorSpec, file: str, log: str) -> None:
    """InputError naming the model ``file`` unless the sensor it was learned for is the log's
    (``sensor_differences``)."""
    differs = sensor_differences(record, sensor)
    if differs:
        key, what = differs[0]
        raise InputError(f"learned for another sensor than that of {log}: {'; '.join(w for _, w in differs)}",
                         file=file, key=key)


def model_for(models, sensor: SensorSpec, simulated: bool) -> dict | None:
    """The first of ``models`` (``carried_models``) learned for ``sensor``, or None. A model
    learned on simulated logs (its sensor record's ``simulated``) is for simulated logs only: a
    real ring with the same mounts is not the simulator's sensor."""
    return next((m for m in models if bool(m["sensor"].get("simulated")) == simulated
                 and not sensor_differences(m["sensor"], sensor)), None)
