"""The detector file (HDF5) of CONTRACT.md: ``save_detector`` writes one atomically,
``load_detector`` reads and checks one (the packaged detector when no path is given).
"""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import numpy as np

from aogm_cli.core.errors import InputError
from aogm_cli.detector.features import FeatureSpec
from aogm_cli.detector.network import ACTIVATIONS, LAYOUT, Detector, Layer
from aogm_cli.io.atomic import write_files_atomically
from aogm_cli.io.h5file import (
    dataset,
    hdf5_bytes,
    json_attr,
    number_attr,
    open_input,
    read_dataset,
    reading,
    text_attr,
)
from aogm_cli.io.modelfile import carried_models
from aogm_cli.io.provenance import file_sha256, write_header, write_provenance

FORMAT = "aogm-detector"
FORMAT_VERSION = 1
BASELINE_DETECTORS = ("all", "none")  # --detector all|none: flag every reading, or none
# Root attribute (JSON) naming the logs the detector was trained and validated on, per log its
# file, world, realistic flag, seed and scans (training.provenance); in memory it is the
# ``training`` dict's entry of the same name. Files written before it existed have none.
TRAINING_LOGS = "training_logs"
# Root attribute (JSON): the sensor models the detector carries (``io.modelfile.carried_models``),
# learned by ``aogm train`` on its training logs, one per sensor; a map of a log of that sensor
# takes its model instead of calibrating. Files written before it existed carry none.
SENSOR_MODELS = "sensor_models"


def default_detector_path() -> Path:
    """The detector that ships inside the package (rebuilt by ``make detector``)."""
    return Path(__file__).resolve().parent.parent / "data" / "detector.h5"


def detector_bytes(detector: Detector, provenance: dict | None = None) -> bytes:
    """The detector file of ``detector`` (CONTRACT.md) as sealed HDF5 bytes, with ``provenance``
    (``io.provenance.provenance``) in the root attribute of that name when given."""

    def fill(f: h5py.File) -> None:
        write_header(f, FORMAT, FORMAT_VERSION)
        f.attrs["features"] = detector.feature_spec.to_json()
        f.attrs["metrics"] = json.dumps(detector.metrics)
        f.attrs["threshold"] = float(detector.threshold)
        f.attrs["labels"] = json.dumps(detector.labels)
        training = dict(detector.training)
        logs = training.pop(TRAINING_LOGS, None)
        f.attrs["training"] = json.dumps(training)
        if logs is not None:
            f.attrs[TRAINING_LOGS] = json.dumps(logs)
        if detector.sensor_models:
            f.attrs[SENSOR_MODELS] = json.dumps(list(detector.sensor_models))
        write_provenance(f, provenance)
        group = f.create_group("layers")
        group.attrs["layout"] = LAYOUT
        for i, layer in enumerate(detector.layers):
            g = group.create_group(str(i))
            g.create_dataset("weight", data=np.asarray(layer.weight, dtype=np.float64))
            g.create_dataset("bias", data=np.asarray(layer.bias, dtype=np.float64))
            g.attrs["activation"] = layer.activation

    return hdf5_bytes(fill)


def save_detector(path: str | Path, detector: Detector, provenance: dict | None = None) -> None:
    """Write ``detector`` to ``path`` in the format of CONTRACT.md (atomically), with ``provenance``."""
    write_files_atomically([(Path(path), detector_bytes(detector, provenance))])


def load_detector(path: str | Path | None = None) -> Detector:
    """Read and check a detector file; ``None`` reads the packaged default detector."""
    path = str(default_detector_path() if path is None else path)
    with open_input(path, FORMAT, FORMAT_VERSION) as f:
        return _read(f, path)


def _read(f: h5py.File, path: str) -> Detector:
    spec = FeatureSpec.from_json(text_attr(f, "features", path, "features"), file=path)
    metrics = json_attr(f, "metrics", path, "metrics", dict)
    labels = json_attr(f, "labels", path, "labels", dict, required=False) or {}
    training = json_attr(f, "training", path, "training", dict, required=False) or {}
    logs = json_attr(f, TRAINING_LOGS, path, TRAINING_LOGS, dict, required=False)
    if logs is not None:
        training[TRAINING_LOGS] = logs
    carried = json_attr(f, SENSOR_MODELS, path, SENSOR_MODELS, list, required=False)
    models = () if carried is None else carried_models(carried, path, SENSOR_MODELS)
    threshold = number_attr(f, "threshold", path, "threshold")
    if not 0.0 <= threshold <= 1.0:
        raise InputError(f"expected a probability in [0, 1], got {threshold}", file=path, key="threshold")
    with reading(path, "/layers"):
        group = f.get("layers")
        if not isinstance(group, h5py.Group) or len(group) == 0:
            raise InputError("missing group (the network's weights)", file=path, key="/layers")
        found = sorted(group.keys())
    names = sorted(found, key=lambda k: int(k) if k.isdigit() else -1)
    if names != [str(i) for i in range(len(names))]:
        raise InputError(f"expected layers named 0..{len(names) - 1}, got {found}", file=path, key="/layers")
    layers = []
    inputs = spec.n_features
    for name in names:
        layers.append(_layer(f, name, inputs, path))
        inputs = layers[-1].weight.shape[1]
    if inputs != 1 or layers[-1].activation != "logistic":
        raise InputError(
            f"expected the last layer to have 1 logistic output, got {inputs} {layers[-1].activation}",
            file=path,
            key=f"/layers/{names[-1]}",
        )
    return Detector(tuple(layers), spec, threshold, labels, metrics, training, path, models)


def _layer(f: h5py.File, name: str, inputs: int, path: str) -> Layer:
    """Layer ``name``: weight (inputs, outputs) and bias (outputs,) finite numbers, a known activation."""
    key = f"layers/{name}"
    with reading(path, "/" + key):
        if not isinstance(f[key], h5py.Group):
            raise InputError("expected a group (weight, bias)", file=path, key="/" + key)
    dims = {"inputs": inputs}
    dataset(f, f"{key}/weight", path, ("inputs", "outputs"), "iuf", "numbers", dims)
    dataset(f, f"{key}/bias", path, ("outputs",), "iuf", "numbers", dims)
    weight = read_dataset(f, f"{key}/weight", path).astype(np.float64)
    bias = read_dataset(f, f"{key}/bias", path).astype(np.float64)
    if not (np.all(np.isfinite(weight)) and np.all(np.isfinite(bias))):
        raise InputError("expected finite numbers", file=path, key="/" + key)
    activation = text_attr(f[key], "activation", path, f"/{key}.activation", required=False)
    if activation not in ACTIVATIONS:
        raise InputError(f"expected one of {sorted(ACTIVATIONS)}, got {activation!r}", file=path, key=f"/{key}.activation")
    return Layer(weight, bias, activation)


def detector_identity(spec: str | None) -> dict:
    """``{"path", "sha256"}`` of the detector that ``spec`` names (``--detector``, or a map's
    recorded ``params["detector"]``): None / "packaged" is the file inside the package (its path
    there), "all" / "none" a baseline (its name, sha256 null), anything else a detector file."""
    if spec in BASELINE_DETECTORS:
        return {"path": spec, "sha256": None}
    if spec is None or spec == "packaged":
        path = default_detector_path()
        return {"path": path.relative_to(path.parents[2]).as_posix(), "sha256": file_sha256(path)}
    return {"path": str(spec), "sha256": file_sha256(spec)}
