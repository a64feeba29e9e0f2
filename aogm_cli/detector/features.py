"""The detector's input: the paper's P = [p_1 .. p_R], R neighbouring sonar measurements per reading.
``FeatureSpec`` says which and how they are normalised (stored as JSON in the detector file, root
attribute ``features``); ``features`` rebuilds the inputs from it."""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass

import numpy as np

from aogm_cli.core.errors import InputError

MAX_NEIGHBOURS = 1000  # beyond any ring or scan window; bounds the feature count a file can ask for
NORMALISATION = "range / max_range clipped to [0, 1]; +inf (no echo) and NaN (invalid) -> 1.0"


# For reading (scan t, sonar j) the R measurements are the ranges of sonars j-k .. j+k of the same
# ring reading (indices wrap around the ring; sonars are assumed ordered around the ring, as ``aogm
# simulate`` writes them) and of sonar j at scans t-m .. t-1, t+1 .. t+m (clipped at the ends of the
# log). Each range is divided by max_range and clipped to [0, 1]; +inf (no echo) and NaN (invalid)
# become 1.0. Optional extras: each neighbour minus the centre reading (``differences``), and a 0/1
# flag per measurement for a missing echo (``missing_flags``).
@dataclass(frozen=True)
class FeatureSpec:
    """Which neighbouring measurements make up a sample, and which extra features follow them."""

    ring_neighbours: int = 2  # k: sonars j-k .. j+k of the same ring reading
    time_neighbours: int = 1  # m: sonar j at scans t-m .. t+m (t itself counted once)
    differences: bool = True  # neighbour minus centre, for every neighbour
    missing_flags: bool = True  # 1.0 where a measurement is +inf or NaN

    def __post_init__(self):
        for name in ("ring_neighbours", "time_neighbours"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or not 0 <= v <= MAX_NEIGHBOURS:
                raise InputError(f"expected a whole number in 0..{MAX_NEIGHBOURS}, got {v!r}", key=f"features.{name}")
        for name in ("differences", "missing_flags"):
            if not isinstance(getattr(self, name), bool):
                raise InputError(f"expected true or false, got {getattr(self, name)!r}", key=f"features.{name}")

    def measurements(self) -> list[tuple[str, int]]:
        """The R measurements in feature order: ("ring", offset) then ("time", offset); ("ring", 0) is the reading."""
        k, m = self.ring_neighbours, self.time_neighbours
        ring = [("ring", o) for o in range(-k, k + 1)]
        time = [("time", o) for o in range(-m, m + 1) if o != 0]
        return ring + time

    @property
    def r(self) -> int:
        """R, the number of measurements per sample."""
        return 2 * self.ring_neighbours + 1 + 2 * self.time_neighbours

    def names(self) -> list[str]:
        """One name per feature column, e.g. ``ring-1``, ``time+1``, ``diff ring-1``, ``missing ring+0``."""
        base = [f"{kind}{offset:+d}" for kind, offset in self.measurements()]
        out = list(base)
        if self.differences:
            out += [f"diff {n}" for n in base if n != "ring+0"]
        if self.missing_flags:
            out += [f"missing {n}" for n in base]
        return out

    @property
    def n_features(self) -> int:
        return len(self.names())

    def to_json(self) -> str:
        """The JSON written to the detector file: the choices, R, the normalisation and the column names."""
        return json.dumps(
            asdict(self) | {"R": self.r, "measurements": self.measurements(), "normalisation": NORMALISATION, "names": self.names()}
        )

    @classmethod
    def from_json(cls, text: str | bytes, file: str | None = None) -> FeatureSpec:
        """Parse the ``features`` attribute of a detector file (the derived keys are checked, not trusted)."""
        key = "features"
        try:
            raw = json.loads(text)
        except (TypeError, ValueError):
            raise InputError("expected a JSON object", file=file, key=key) from None
        if not isinstance(raw, dict):
            raise InputError(f"expected a JSON object, got {type(raw).__name__}", file=file, key=key)
        fields = ("ring_neighbours", "time_neighbours", "differences", "missing_flags")
        missing = [f for f in fields if f not in raw]
        if missing:
            raise InputError("missing entry", file=file, key=f"{key}.{missing[0]}")
        try:
            spec = cls(**{f: raw[f] for f in fields})
        except InputError as exc:
            raise (exc.in_file(file) if file else exc) from None
        if "R" in raw and raw["R"] != spec.r:
            raise InputError(f"expected {spec.r} (from the neighbours), got {raw['R']!r}", file=file, key=f"{key}.R")
        if "normalisation" in raw and raw["normalisation"] != NORMALISATION:
            raise InputError(f"unknown normalisation {raw['normalisation']!r}; expected {NORMALISATION!r}", file=file, key=f"{key}.normalisation")
        return spec


def normalise(ranges: np.ndarray, max_range: float) -> np.ndarray:
    """Ranges / max_range clipped to [0, 1], with +inf and NaN -> 1.0 (float32)."""
    r = np.asarray(ranges, dtype=np.float64)
    out = np.ones(r.shape, dtype=np.float64)
    finite = np.isfinite(r)
    out[finite] = np.clip(r[finite] / float(max_range), 0.0, 1.0)
    return out.astype(np.float32)


def neighbour_ranges(ranges: np.ndarray, spec: FeatureSpec) -> np.ndarray:
    """(T, S, R) raw ranges of every reading's R measurements, in ``spec.measurements()`` order."""
    r = np.asarray(ranges)
    if r.ndim != 2:
        raise ValueError(f"ranges must be (T, S), got shape {r.shape}")
    n_scans, n_sonars = r.shape
    columns = []
    for kind, offset in spec.measurements():
        if kind == "ring":
            columns.append(r[:, (np.arange(n_sonars) + offset) % n_sonars])
        else:
            columns.append(r[np.clip(np.arange(n_scans) + offset, 0, n_scans - 1), :])
    return np.stack(columns, axis=-1)


def features(ranges: np.ndarray, max_range: float, spec: FeatureSpec) -> np.ndarray:
    """(T*S, F) float32 features of every reading; row t*S + j is reading (scan t, sonar j).

    Columns follow ``spec.names()``: the R normalised measurements, then (if chosen) each
    neighbour minus the centre, then (if chosen) the missing-echo flags.
    """
    if not max_range > 0:
        raise ValueError(f"max_range must be positive, got {max_range}")
    raw = neighbour_ranges(ranges, spec)
    n_scans, n_sonars, r = raw.shape
    values = normalise(raw, max_range)
    parts = [values]
    if spec.differences:
        centre = spec.ring_neighbours  # ("ring", 0) sits after the k left ring neighbours
        others = [i for i in range(r) if i != centre]
        parts.append(values[..., others] - values[..., centre : centre + 1])
    if spec.missing_flags:
        parts.append((~np.isfinite(raw)).astype(np.float32))
    return np.concatenate(parts, axis=-1).reshape(n_scans * n_sonars, -1).astype(np.float32, copy=False)
