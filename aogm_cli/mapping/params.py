"""Every mapping parameter: one frozen dataclass per concern, gathered in ``MapParams``, read from a ``--params``
YAML and CLI options and validated here, once; the resolved parameters are written into every map file."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import asdict, dataclass, field
from typing import Any

from aogm_cli.core.errors import InputError
from aogm_cli.sensor_models.exact_inverse import ExactModelConfig
from aogm_cli.sensor_models.forward_model import ForwardModelConfig
from aogm_cli.sensor_models.inverse_model import InverseModelConfig
from aogm_cli.sensor_models.surface import SurfaceConfig


def check_field_types(config) -> None:
    """Raise ``InputError(key=<field>)`` unless each field of ``config`` has its declared type (no bool as number)."""
    for f in dataclasses.fields(config):
        kind = f.type if isinstance(f.type, str) else getattr(f.type, "__name__", "")
        v = getattr(config, f.name)
        if kind == "float" and (isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v)):
            raise InputError(f"expected a finite number, got {v!r}", key=f.name)
        if kind == "int" and (isinstance(v, bool) or not isinstance(v, int)):
            raise InputError(f"expected a whole number, got {v!r}", key=f.name)
        if kind == "str" and not isinstance(v, str):
            raise InputError(f"expected a string, got {v!r}", key=f.name)
        if kind == "bool" and not isinstance(v, bool):
            raise InputError(f"expected true or false, got {v!r}", key=f.name)


@dataclass(frozen=True)
class EMConfig:
    """EM parameters: the forward model, the occupancy prior and the sweep limit. EM starts from the thresholded
    standard map and reports unobserved the cells it leaves free though no reading decides them
    (``view.residual_into``)."""

    forward: ForwardModelConfig = field(default_factory=ForwardModelConfig)
    prior_occupied: float = 0.3  # prior p(m_x = 1) of every cell
    max_sweeps: int = 20

    def validate(self) -> EMConfig:
        check_field_types(self.forward)
        self.forward.validate()
        check_field_types(self)
        if self.forward.p_hit >= 1.0:
            raise InputError(f"expected p_hit < 1 for EM, got {self.forward.p_hit:g}", key="p_hit")
        if not 0 < self.prior_occupied < 1:
            raise InputError(f"expected a probability in (0, 1), got {self.prior_occupied:g}", key="prior_occupied")
        if self.max_sweeps < 1:
            raise InputError(f"expected a whole number >= 1, got {self.max_sweeps}", key="max_sweeps")
        return self

    @property
    def l_prior(self) -> float:
        return math.log(self.prior_occupied / (1.0 - self.prior_occupied))

    def as_dict(self) -> dict:
        d = asdict(self)
        d.update(d.pop("forward"))
        return d


@dataclass(frozen=True)
class AdaptiveConfig:
    """What the adaptive map is outside its clusters and where they lie (``adaptive.find_clusters``,
    ``plan.auto_outside``; docs/algorithms.md, "The adaptive mapper")."""

    outside: str = "auto"
    contested: float = 0.5
    weak: float = 0.45
    grow: int = 2

    def validate(self) -> AdaptiveConfig:
        if self.outside not in ("auto", "elfes", "thinned"):
            raise InputError(f"expected 'auto', 'elfes' or 'thinned', got {self.outside!r}", key="outside")
        if self.grow < 0:
            raise InputError(f"expected a whole number >= 0, got {self.grow!r}", key="grow")
        for key in ("contested", "weak"):
            if not getattr(self, key) >= 0:
                raise InputError(f"expected a number >= 0 (log-odds), got {getattr(self, key)!r}", key=key)
        return self

    def as_dict(self) -> dict:
        return asdict(self)


LEARNABLE = ("sigma", "p_rand", "p_hit", "p_max", "lobe_deg")  # the keys ``calibration.learn`` accepts


@dataclass(frozen=True)
class CalibrationConfig:
    """Whether em and adaptive learn the forward model from their log; with ``carried``, a simulated log of a
    sensor the detector carries a model of learns only the building's part (p_max, the lobe)."""

    enabled: bool = True
    carried: bool = True
    learn: str = ",".join(LEARNABLE)

    def validate(self) -> CalibrationConfig:
        unknown = set(self.learned) - set(LEARNABLE)
        if unknown or not self.learned:
            raise InputError(f"expected a comma-separated list of {', '.join(LEARNABLE)}, got {self.learn!r}",
                             key="learn")
        return self

    @property
    def learned(self) -> tuple[str, ...]:
        return tuple(k.strip() for k in self.learn.split(",") if k.strip())

    def as_dict(self) -> dict:
        return asdict(self)


@dataclass(frozen=True)
class MapParams:
    """Parameters of all mappers: grid resolution (logs without truth), inverse model, EM, clusters."""

    resolution: float = 0.05
    inverse_model: InverseModelConfig = field(default_factory=InverseModelConfig)
    em: EMConfig = field(default_factory=EMConfig)
    adaptive: AdaptiveConfig = field(default_factory=AdaptiveConfig)
    calibration: CalibrationConfig = field(default_factory=CalibrationConfig)
    surface: SurfaceConfig = field(default_factory=SurfaceConfig)
    exact: ExactModelConfig = field(default_factory=ExactModelConfig)

    def as_dict(self) -> dict:
        return {"resolution": self.resolution, "inverse_model": self.inverse_model.as_dict(), "em": self.em.as_dict(),
                "adaptive": self.adaptive.as_dict(), "calibration": self.calibration.as_dict(),
                "surface": self.surface.as_dict(), "exact": self.exact.as_dict()}


SECTIONS = {
    "inverse_model": {f.name for f in dataclasses.fields(InverseModelConfig)},
    "em": {f.name for f in dataclasses.fields(EMConfig) if f.name != "forward"}
    | {f.name for f in dataclasses.fields(ForwardModelConfig)},
    "adaptive": {f.name for f in dataclasses.fields(AdaptiveConfig)},
    "calibration": {f.name for f in dataclasses.fields(CalibrationConfig)},
    "surface": {f.name for f in dataclasses.fields(SurfaceConfig)},
    "exact": {f.name for f in dataclasses.fields(ExactModelConfig)},
}


def _merged(raw: dict, file: str | None, overrides: dict) -> tuple[dict[str, dict[str, Any]], Any, str | None]:
    """(per section the values of ``raw`` and ``overrides``, the resolution, the file a bad value
    came from: None once --resolution overrides it). Unknown keys raise InputError."""
    if not isinstance(raw, dict):
        raise InputError(f"expected a mapping with sections {', '.join(SECTIONS)} and key resolution", file=file)
    for key in raw:
        if key not in SECTIONS and key != "resolution":
            raise InputError(f"unknown key; expected resolution, {', '.join(SECTIONS)}", file=file, key=str(key))
    merged: dict[str, dict[str, Any]] = {}
    for section, allowed in SECTIONS.items():
        values = raw.get(section) or {}
        if not isinstance(values, dict):
            raise InputError("expected a mapping", file=file, key=section)
        for key in values:
            if key not in allowed:
                raise InputError(f"unknown key; expected one of {', '.join(sorted(allowed))}", file=file, key=f"{section}.{key}")
        merged[section] = dict(values)
    resolution = raw.get("resolution", 0.05)
    for section, values in overrides.items():
        if section == "resolution":
            if values is not None:
                resolution, file = values, None
            continue
        merged[section].update({k: v for k, v in values.items() if v is not None})
    return merged, resolution, file


def _checked(kind):
    """A section's config of dataclass ``kind`` from its values: its fields' types, then its own checks."""
    def make(values):
        config = kind(**values)
        check_field_types(config)
        return config.validate()
    return make


def _em(values: dict) -> EMConfig:
    forward_keys = {f.name for f in dataclasses.fields(ForwardModelConfig)}
    return EMConfig(forward=ForwardModelConfig(**{k: x for k, x in values.items() if k in forward_keys}),
                    **{k: x for k, x in values.items() if k not in forward_keys}).validate()


SECTION_CONFIGS = {"inverse_model": _checked(InverseModelConfig), "em": _em, "adaptive": _checked(AdaptiveConfig),
                   "calibration": _checked(CalibrationConfig), "surface": _checked(SurfaceConfig),
                   "exact": _checked(ExactModelConfig)}


def params_from(raw: dict | None = None, file: str | None = None,
                overrides: dict[str, dict[str, Any]] | None = None) -> MapParams:
    """Defaults, then ``raw`` (``file``'s values), then ``overrides`` ({section: {key: value}}, None ignored)."""
    merged, resolution, file = _merged({} if raw is None else raw, file, overrides or {})
    sections = {}
    for section, make in SECTION_CONFIGS.items():
        try:
            sections[section] = make(merged[section])
        except InputError as exc:
            raise InputError(exc.message, file=file, key=f"{section}.{exc.key}") from None
        except (TypeError, ValueError) as exc:
            raise InputError(f"invalid value: {exc}", file=file, key=section) from None
    if (isinstance(resolution, bool) or not isinstance(resolution, (int, float)) or not math.isfinite(resolution)
            or not resolution > 0):
        raise InputError(f"expected a positive number (m per cell), got {resolution!r}", file=file, key="resolution")
    return MapParams(float(resolution), **sections)
