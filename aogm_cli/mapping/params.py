"""Every mapping parameter in one frozen object, read from a ``--params`` YAML and CLI options.

Validation happens here, once; the resolved parameters are written into every map file.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

from aogm_cli.errors import InputError
from aogm_cli.mapping.cluster import AdaptiveConfig
from aogm_cli.mapping.em import EMConfig
from aogm_cli.mapping.forward_model import ForwardModelConfig
from aogm_cli.mapping.inverse_model import InverseModelConfig
from aogm_cli.yamlfile import read_yaml


@dataclass(frozen=True)
class MapParams:
    """Parameters of all mappers: grid resolution (logs without truth), inverse model, EM, clusters."""

    resolution: float = 0.05
    inverse_model: InverseModelConfig = field(default_factory=InverseModelConfig)
    em: EMConfig = field(default_factory=EMConfig)
    adaptive: AdaptiveConfig = field(default_factory=AdaptiveConfig)

    def as_dict(self) -> dict:
        return {"resolution": self.resolution, "inverse_model": self.inverse_model.as_dict(), "em": self.em.as_dict(),
                "adaptive": self.adaptive.as_dict()}


SECTIONS = {
    "inverse_model": {f.name for f in dataclasses.fields(InverseModelConfig)},
    "em": {f.name for f in dataclasses.fields(EMConfig) if f.name != "forward"}
    | {f.name for f in dataclasses.fields(ForwardModelConfig)},
    "adaptive": {f.name for f in dataclasses.fields(AdaptiveConfig)},
}


def resolve_params(params_file: str | None = None, overrides: dict[str, dict[str, Any]] | None = None) -> MapParams:
    """Defaults, then the YAML file's values, then ``overrides`` ({section: {key: value}}; None
    values ignored). Raises InputError naming the file and ``section.key``."""
    raw: dict[str, Any] = {}
    file = params_file
    if params_file:
        raw = read_yaml(params_file)[1] or {}
        if not isinstance(raw, dict):
            raise InputError("expected a mapping with sections inverse_model, em, adaptive and key resolution", file=file)
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
    for section, values in (overrides or {}).items():
        if section == "resolution":
            if values is not None:
                resolution, file = values, None
            continue
        for key, value in values.items():
            if value is not None:
                merged[section][key] = value
    forward_keys = {f.name for f in dataclasses.fields(ForwardModelConfig)}

    def build(section: str, make):
        try:
            return make(merged[section])
        except InputError as exc:
            raise InputError(exc.message, file=file, key=f"{section}.{exc.key}") from None
        except (TypeError, ValueError) as exc:
            raise InputError(f"invalid value: {exc}", file=file, key=section) from None

    inverse = build("inverse_model", lambda v: InverseModelConfig(**v).validate())
    em = build(
        "em",
        lambda v: EMConfig(
            forward=ForwardModelConfig(**{k: x for k, x in v.items() if k in forward_keys}),
            **{k: x for k, x in v.items() if k not in forward_keys},
        ).validate(),
    )
    adaptive = build("adaptive", lambda v: AdaptiveConfig(**v).validate())
    if isinstance(resolution, bool) or not isinstance(resolution, (int, float)) or not resolution > 0:
        raise InputError(f"expected a positive number (m per cell), got {resolution!r}", file=file, key="resolution")
    return MapParams(float(resolution), inverse, em, adaptive)
