"""The cluster detector in memory and its inference in numpy (no file I/O, no scikit-learn):
``Detector.flag`` turns a (T, S) range array into the paper's y (which readings make clusters)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from aogm_cli.detector.features import FeatureSpec, features

LAYOUT = "y = activation(x @ weight + bias); weight has shape (inputs, outputs); the last layer's one output is p(y = 1)"


def _identity(x):
    return x


def _relu(x):
    return np.maximum(x, 0.0)


def _logistic(x):
    # 1 / (1 + exp(-x)), computed without overflow warnings for large |x|
    out = np.empty_like(x)
    pos = x >= 0
    out[pos] = 1.0 / (1.0 + np.exp(-x[pos]))
    e = np.exp(x[~pos])
    out[~pos] = e / (1.0 + e)
    return out


ACTIVATIONS = {"identity": _identity, "relu": _relu, "tanh": np.tanh, "logistic": _logistic}


@dataclass(frozen=True)
class Layer:
    """One dense layer: ``activation(x @ weight + bias)`` with weight (inputs, outputs)."""

    weight: np.ndarray
    bias: np.ndarray
    activation: str

    def __call__(self, x: np.ndarray) -> np.ndarray:
        return ACTIVATIONS[self.activation](x @ self.weight + self.bias)


@dataclass(frozen=True)
class Detector:
    """A trained cluster detector: layers, the feature spec they expect, and the flag threshold."""

    layers: tuple[Layer, ...]
    feature_spec: FeatureSpec
    threshold: float
    labels: dict = field(default_factory=dict)  # the label definition it was trained on
    metrics: dict = field(default_factory=dict)  # training and validation precision/recall/F1
    training: dict = field(default_factory=dict)  # how it was trained (network, seed, logs)
    path: str | None = None
    # the sensor models it carries, learned on its training logs: per sensor its record and model
    # (``io.modelfile``'s ``sensor`` and ``model``) and the logs it was learned from
    sensor_models: tuple = ()

    def predict_proba(self, x: np.ndarray) -> np.ndarray:
        """(N,) float64 p(y = 1) for (N, F) features (the second column of sklearn's predict_proba)."""
        h = np.asarray(x, dtype=np.float64)
        if h.ndim != 2 or h.shape[1] != self.feature_spec.n_features:
            raise ValueError(f"expected features of shape (N, {self.feature_spec.n_features}), got {h.shape}")
        for layer in self.layers:
            h = layer(h)
        return h[:, 0]

    def flag_features(self, x: np.ndarray) -> np.ndarray:
        """(N,) bool: p(y = 1) >= threshold."""
        return self.predict_proba(x) >= self.threshold

    def flag(self, ranges: np.ndarray, max_range: float, chunk: int = 8192) -> np.ndarray:
        """(T, S) bool: the readings whose swept region is cluttered or erroneous (y = 1).

        ``chunk`` scans at a time (the features and the hidden layer are about 200 bytes per
        reading), each chunk with the ``time_neighbours`` scans on either side that its
        features read, so the flags equal those of the whole log at once."""
        ranges = np.asarray(ranges)
        out = np.zeros(ranges.shape, dtype=bool)
        pad = self.feature_spec.time_neighbours
        n = ranges.shape[0] if ranges.ndim else 0
        for start in range(0, n, chunk):
            stop = min(start + chunk, n)
            lo, hi = max(start - pad, 0), min(stop + pad, n)
            part = ranges[lo:hi]
            flags = self.flag_features(features(part, max_range, self.feature_spec)).reshape(part.shape)
            out[start:stop] = flags[start - lo : start - lo + stop - start]
        return out


@dataclass(frozen=True)
class ConstantDetector:
    """A baseline in the place of a trained detector: flags every reading or none."""

    flags: bool
    path: str | None = None

    @property
    def name(self) -> str:
        return "all" if self.flags else "none"

    def flag(self, ranges: np.ndarray, max_range: float) -> np.ndarray:
        """(T, S) bool, all ``flags``."""
        return np.full(np.shape(ranges), self.flags, dtype=bool)
