"""Training the cluster detector: simulated logs -> features and labels -> a small MLP -> a Detector.
The only module that imports scikit-learn (``MLPClassifier``; inference lives in ``detector.network``);
validation is by world: whole logs are held out, never random readings."""

from __future__ import annotations

import warnings
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass

import numpy as np

from aogm_cli.core.errors import InputError
from aogm_cli.core.log import Log
from aogm_cli.detector.features import FeatureSpec, features
from aogm_cli.detector.network import Detector, Layer
from aogm_cli.io.detectorfile import TRAINING_LOGS
from aogm_cli.training.config import TrainingConfig
from aogm_cli.training.labels import LabelDefinition, StandardMapOf, labels
from aogm_cli.training.provenance import training_logs

THRESHOLDS = np.round(np.arange(0.05, 0.951, 0.01), 2)  # candidate flag thresholds


@dataclass(frozen=True)
class Dataset:
    """Features (N, F) and labels (N,) of some logs, with their names."""

    x: np.ndarray
    y: np.ndarray
    logs: tuple[str, ...]


def log_dataset(log: Log, spec: FeatureSpec, definition: LabelDefinition, name: str = "",
                standard_map_of: StandardMapOf | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(T*S, F) features and (T*S,) bool labels of one simulated log, rows in reading order
    (``labels.labels``: rule (c) needs ``standard_map_of``)."""
    y = labels(log, definition, file=name or None, standard_map_of=standard_map_of).ravel()
    return features(log.ranges, log.sensor.max_range, spec), y


def build_dataset(named_logs: Sequence[tuple[str, Log]], spec: FeatureSpec, definition: LabelDefinition,
                  progress: Callable[[int], None] | None = None,
                  standard_map_of: StandardMapOf | None = None) -> Dataset:
    """The logs' samples stacked in the order given."""
    xs, ys = [], []
    for name, log in named_logs:
        x, y = log_dataset(log, spec, definition, name, standard_map_of)
        xs.append(x)
        ys.append(y)
        if progress:
            progress(1)
    if not xs:
        return Dataset(np.zeros((0, spec.n_features), np.float32), np.zeros(0, bool), ())
    return Dataset(np.concatenate(xs), np.concatenate(ys), tuple(n for n, _ in named_logs))


def scores(y: np.ndarray, flagged: np.ndarray) -> dict:
    """Precision, recall and F1 of ``flagged`` against ``y``, with the sample counts (JSON-able)."""
    y = np.asarray(y, dtype=bool)
    flagged = np.asarray(flagged, dtype=bool)
    tp = int(np.count_nonzero(y & flagged))
    n_flag = int(np.count_nonzero(flagged))
    n_pos = int(np.count_nonzero(y))
    precision = tp / n_flag if n_flag else 0.0
    recall = tp / n_pos if n_pos else 0.0
    f1 = 2 * precision * recall / (precision + recall) if precision + recall > 0 else 0.0
    return {
        "precision": round(precision, 6),
        "recall": round(recall, 6),
        "f1": round(f1, 6),
        "n_samples": int(y.size),
        "n_positive": n_pos,
        "n_flagged": n_flag,
    }


def choose_threshold(y: np.ndarray, p: np.ndarray, beta: float = 1.0) -> float:
    """The threshold in 0.05..0.95 (steps of 0.01) maximising F_beta of ``p >= threshold``; ties -> the lowest."""
    y = np.asarray(y, dtype=bool)
    p = np.asarray(p, dtype=np.float64)
    flagged = p[None, :] >= THRESHOLDS[:, None]
    tp = np.count_nonzero(flagged & y, axis=1).astype(np.float64)
    n_flag = np.count_nonzero(flagged, axis=1)
    n_pos = max(int(np.count_nonzero(y)), 1)
    b2 = beta * beta
    # F_beta = (1 + b2) tp / ((1 + b2) tp + b2 fn + fp) = (1 + b2) tp / (b2 n_pos + n_flag)
    f_beta = (1 + b2) * tp / np.maximum(b2 * n_pos + n_flag, 1)
    return float(THRESHOLDS[int(np.argmax(f_beta))])


def fit_mlp(data: Dataset, config: TrainingConfig):
    """An sklearn MLPClassifier with one hidden layer fitted to ``data`` (deterministic per seed)."""
    try:
        from sklearn.exceptions import ConvergenceWarning
        from sklearn.neural_network import MLPClassifier
    except ImportError:
        raise RuntimeError("aogm train needs scikit-learn, a dependency of aogm: reinstall aogm "
                           "(pip install .) or pip install scikit-learn") from None
    if data.y.size == 0:
        raise InputError("no readings to train on", key="logs")
    if data.y.all() or not data.y.any():
        raise InputError(f"the training logs hold only {'positive' if data.y.any() else 'negative'} labels; "
                         "training needs both (use longer or more varied logs)", key="labels")
    model = MLPClassifier(
        hidden_layer_sizes=(config.hidden,),
        activation=config.activation,
        solver="adam",
        alpha=config.alpha,
        max_iter=config.max_iter,
        random_state=config.seed,
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        model.fit(data.x, data.y)
    return model


def layers_of(model) -> tuple[Layer, ...]:
    """The fitted MLP's weights as numpy layers (hidden activation, then the logistic output)."""
    out = []
    for i, (w, b) in enumerate(zip(model.coefs_, model.intercepts_, strict=True)):
        last = i == len(model.coefs_) - 1
        out.append(Layer(np.asarray(w, np.float64), np.asarray(b, np.float64), model.out_activation_ if last else model.activation))
    return tuple(out)


def train_detector(
    train_logs: Sequence[tuple[str, Log]],
    validation_logs: Sequence[tuple[str, Log]] = (),
    spec: FeatureSpec | None = None,
    definition: LabelDefinition | None = None,
    config: TrainingConfig | None = None,
    progress: Callable[[int], None] | None = None,
    standard_map_of: StandardMapOf | None = None,
) -> Detector:
    """Fit the detector on ``train_logs`` (name, log) and score it there and on ``validation_logs``;
    label rule (c) compares each log's standard map, ``standard_map_of(log)``, with its truth.

    The flag threshold maximises F_beta on the training data; ``metrics`` holds precision,
    recall, F1 and sample counts on training and validation (None without validation logs);
    ``training[TRAINING_LOGS]`` which logs it learnt from and was validated on (``provenance``).
    ``progress(1)`` is called per log labelled and once after fitting.
    """
    spec = spec or FeatureSpec()
    definition = definition or LabelDefinition()
    config = config or TrainingConfig()
    train = build_dataset(train_logs, spec, definition, progress, standard_map_of)
    validation = build_dataset(validation_logs, spec, definition, progress, standard_map_of)
    model = fit_mlp(train, config)
    if progress:
        progress(1)
    detector = Detector(layers_of(model), spec, 0.5)
    p_train = detector.predict_proba(train.x)
    threshold = choose_threshold(train.y, p_train, config.beta)
    metrics = {
        "threshold": threshold,
        "threshold_rule": f"maximises F_beta (beta = {config.beta:g}) on the training data",
        "train": scores(train.y, p_train >= threshold) | {"logs": list(train.logs)},
        "validation": None,
    }
    if validation.y.size:
        metrics["validation"] = scores(validation.y, detector.predict_proba(validation.x) >= threshold) | {"logs": list(validation.logs)}
    import sklearn

    training = asdict(config) | {
        "network": f"MLP {spec.n_features}-{config.hidden}-1, {config.activation} hidden layer, logistic output",
        "solver": "adam",
        "n_iter": int(model.n_iter_),
        "final_loss": float(model.loss_),
        "sklearn_version": sklearn.__version__,
        "train_logs": list(train.logs),
        "validation_logs": list(validation.logs),
        TRAINING_LOGS: training_logs(train_logs, validation_logs),
    }
    return Detector(detector.layers, spec, threshold, definition.as_dict(), metrics, training)


def split_by_world(logs: Sequence[str], validation: Sequence[str] = ()) -> tuple[list[str], list[str]]:
    """(training, validation) log paths: whole logs, never readings, are held out.

    With ``validation`` given, those logs are held out (and dropped from ``logs`` if listed
    there too). Without it, the last max(1, n // 4) of n >= 2 logs are held out; a single log
    trains without validation.
    """
    logs = list(dict.fromkeys(logs))
    if validation:
        held = list(dict.fromkeys(validation))
        held_set = {_same_file_key(p) for p in held}
        train = [p for p in logs if _same_file_key(p) not in held_set]
    elif len(logs) >= 2:
        n_held = max(1, len(logs) // 4)
        train, held = logs[:-n_held], logs[-n_held:]
    else:
        train, held = logs, []
    if not train:
        raise InputError("every log is held out for validation; give at least one more log to train on", key="LOG.h5")
    return train, held


def _same_file_key(path: str) -> str:
    import os

    return os.path.realpath(path)
