"""Every mapping parameter: one frozen dataclass per concern (EM, clusters, calibration; the sensor models'
own beside them), gathered in ``MapParams``, read from a ``--params`` YAML and CLI options and validated
here, once; the resolved parameters are written into every map file."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import asdict, dataclass, field
from typing import Any

from aogm_cli.core.errors import InputError
from aogm_cli.io.yamlfile import read_yaml
from aogm_cli.sensor_models.exact_inverse import ExactModelConfig
from aogm_cli.sensor_models.forward_model import ForwardModelConfig
from aogm_cli.sensor_models.inverse_model import InverseModelConfig
from aogm_cli.sensor_models.surface import SurfaceConfig


def check_field_types(config) -> None:
    """Raise ``InputError(key=<field>)`` unless each field of the dataclass ``config`` has its
    declared type: float fields a finite number (not a bool), int fields a whole number (not a
    bool, not 2.5 or 2.0), str fields a string, bool fields true or false. Nested dataclasses are
    left to their own check."""
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
    """EM parameters: the forward model, the occupancy prior, the sweep limit and the start."""

    forward: ForwardModelConfig = field(default_factory=ForwardModelConfig)
    prior_occupied: float = 0.3  # prior p(m_x = 1) of every cell
    max_sweeps: int = 20
    start: str = "standard"  # "standard": the thresholded standard map; "empty": all free
    # What EM reports at the cells it leaves free although no reading objects to an obstacle
    # there (occupancy would lower the data log-likelihood by at most hidden_gain: a wall's far
    # layers, the space behind a wall, a gap in a wall that the prior alone keeps open): "prior"
    # (Thrun's residual, the prior 0.3, which a planner reads as free), "standard" (the standard
    # map's estimate) or "unobserved" (the standard map's estimate where it is above 0.5, else
    # unobserved: p 0.5, /map/observed false). Measured on the 13 bundled worlds (README, "What
    # EM reports where the data say nothing"): "unobserved" cuts EM's planner leak from
    # 0.04-0.34 to 0.00-0.07 and lifts its wall-surface recall to the standard map's or above
    hidden: str = "unobserved"
    hidden_gain: float = 0.05

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
        if self.hidden not in ("unobserved", "standard", "prior"):
            raise InputError(f"expected 'unobserved', 'standard' or 'prior', got {self.hidden!r}", key="hidden")
        if not self.hidden_gain >= 0:
            raise InputError(f"expected a number >= 0, got {self.hidden_gain!r}", key="hidden_gain")
        if self.start not in ("standard", "empty"):
            raise InputError(f"expected 'standard' or 'empty', got {self.start!r}", key="start")
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
    """Where a flagged reading's cluster cells lie: its cone from ``band_below`` metres before
    its range to alpha beyond it (a max-range reading has no band), within ``near_occupied``
    cells (8-connected) of a cell the standard map holds occupied."""

    band_below: float = 0.2
    # 0: only cells the standard map holds occupied (where it draws walls too thick, closes
    # openings); measured against 1 on the nine bundled worlds (bench/params_sweep.py
    # adaptive): as accurate or more on each, clusters 35-45% smaller, 10-20% faster
    near_occupied: int = 0
    # also cluster the cells whose occupied evidence alone (the inverse model's arcs) reaches
    # this many log-odds but which the standard map holds free: walls that too-long specular or
    # multipath readings cleared, which no flagged band reaches (0: none). README, "What EM
    # reports where the data say nothing"
    contested: float = 0.5
    # also cluster the cells whose standard log-odds lie within this of the prior (0: none):
    # about one free reading's worth (l_free -0.41) or less, where EM decides free or unknown
    weak: float = 0.45
    # every cluster grown by this many cells (8-connected): the wall's back layers, which the
    # standard map holds free where too-long readings crossed them (corridor_specular adaptive
    # accuracy 0.9598 -> 0.9716 at 2; 1 gave 0.9725 but lower surface recall elsewhere); sonar
    # cones only (narrow beams: 0), as it cost the intel laser log's held-out AUC 0.9863 -> 0.9737
    grow: int = 2
    # the scale of the probabilities outside the clusters (issue 28): "em", the EM probability of
    # the cluster cells that the log's readings end in as often (``adaptive.one_scale``); "mixed",
    # the standard map's own (before: two scales that rank cells unlike each other)
    scale: str = "em"

    def validate(self) -> AdaptiveConfig:
        check_field_types(self)
        if self.scale not in ("em", "mixed"):
            raise InputError(f"expected 'em' or 'mixed', got {self.scale!r}", key="scale")
        if isinstance(self.grow, bool) or not isinstance(self.grow, int) or self.grow < 0:
            raise InputError(f"expected a whole number >= 0, got {self.grow!r}", key="grow")
        for key in ("contested", "weak"):
            if not getattr(self, key) >= 0:
                raise InputError(f"expected a number >= 0 (log-odds), got {getattr(self, key)!r}", key=key)
        if not self.band_below >= 0:
            raise InputError(f"expected a number >= 0 (m), got {self.band_below!r}", key="band_below")
        if isinstance(self.near_occupied, bool) or not isinstance(self.near_occupied, int) or self.near_occupied < 0:
            raise InputError(f"expected a whole number >= 0, got {self.near_occupied!r}", key="near_occupied")
        return self

    def as_dict(self) -> dict:
        return asdict(self)


@dataclass(frozen=True)
class CalibrationConfig:
    """How EM learns its forward model from the log it maps (``mapping.calibration``): on or off,
    at most ``rounds`` EM runs alternated with closed-form fits of sigma, p_rand, p_hit and
    p_max (each at most ``fit_iterations`` updates at one map, on at most ``max_readings``
    readings), ended when no parameter moves by more than ``tolerance`` (sigma relative, the
    probabilities absolute); each learned value is clipped to its bounds."""

    enabled: bool = True
    # which of the forward model's parameters are learned (specular_deg once, from the echo rate by
    # angle of incidence at the standard map's surfaces; the others in rounds with EM). opening_deg
    # (once, from how wide a beam explains the echoes at the thinned standard map) only when listed:
    # on the real 8-sonar log the learned 14 degrees lowered EM's walls_kept (docs/algorithms.md)
    learn: str = "sigma,p_rand,p_hit,p_max,specular_deg"
    rounds: int = 4
    fit_iterations: int = 30
    max_readings: int = 200_000
    tolerance: float = 0.02
    # the first EM map is made with sigma at least this broad: a broad model puts each wall at
    # the readings' mean, and the sigma fitted there comes down to the data's; a narrow start
    # lets EM's map follow the noise and the fitted sigma stays narrow (corridor_door at noise
    # 0.12 m: start 0.03 -> sigma 0.064, 0.1 -> 0.101; python bench/calibration_recovery.py
    # [--params with calibration: {start_sigma: 0.03}])
    start_sigma: float = 0.1
    start_sweeps: int = 3  # the first (broad) EM run's sweep limit: its map only serves the first fit
    # specular_deg's passes: a reading passed a surface cell when its echo lies at least this far
    # beyond it (nearer, the cell may be the same wall, which the standard map draws thick;
    # `aogm calibrate corridor_door.h5` with pass_margin 0.15: its rough walls echo 0.18 -> 0.14 of
    # the time from 0 to 90 deg, with 0.3: 0.28 -> 0.50; both learn 90: rough walls echo at any
    # angle, as simulated)
    pass_margin: float = 0.3
    # the specular angle is where the echo rate falls below this share of its head-on value
    # (measured, EM at seed 1 with surface.core 0.25: 0.25 and 0.1 learn wider angles that deflect fewer beams, and give up
    # the gains of 0.5 on the *_real worlds and corridor_specular; corridor_specular_pioneer without
    # drift loses its corridor check at all three)
    specular_rate: float = 0.5
    fit_sweeps: int = 4  # the sweep limit of the later maps made for a fit (the final map: em.max_sweeps)
    # the maps the parameters are fitted at are made from every n-th scan (the broad first map
    # from every start_subsample-th), the final map from every scan: the fits need the walls'
    # places, not every reading's detail (every 3rd scan: sigma +51% at noise 0.05, every 2nd
    # +17%; bench/calibration_recovery.py)
    subsample: int = 2
    start_subsample: int = 4
    # a log of more scans calibrates on this many, in 4 runs of consecutive scans spread over it
    # (the rounds' maps and fits; the final map takes every scan), so that calibration's cost stops
    # growing with the log. Measured on the generated office at 5,000 scans (seed 1, em): 2,000
    # scans: calibration 19.3 -> 7.4 s, learned sigma 0.028 -> 0.029, the map 38.1 -> 27.0 s,
    # accuracy 0.9414 -> 0.9408 (adaptive 47.9 -> 38.1 s, 0.9404 -> 0.9392); 1,000: 5.0 s but sigma
    # 0.031 and the final EM slower (30.2 s). Every 10th scan instead of runs: sigma 0.048, 37.2 s
    max_scans: int = 2000
    # bounds: sigma from a tenth of a typical 5 cm cell to half a metre; p_rand, p_max below one
    # half each (a model that calls most readings random or dropped explains nothing); p_hit
    # away from 0 and 1 (EM needs q = 1 - p_hit > 0, and a wall missed by every reading is no wall)
    sigma_min: float = 0.005
    sigma_max: float = 0.5
    p_rand_min: float = 0.001
    p_rand_max: float = 0.5
    p_max_max: float = 0.4
    p_hit_min: float = 0.05
    p_hit_max: float = 0.95

    def validate(self) -> CalibrationConfig:
        check_field_types(self)
        unknown = set(self.learned) - {"sigma", "p_rand", "p_hit", "p_max", "specular_deg", "opening_deg"}
        if unknown or not self.learned:
            raise InputError("expected a comma-separated list of sigma, p_rand, p_hit, p_max, specular_deg, opening_deg, "
                             f"got {self.learn!r}", key="learn")
        for key in ("rounds", "fit_iterations", "max_readings", "start_sweeps", "fit_sweeps", "subsample", "start_subsample",
                    "max_scans"):
            if getattr(self, key) < 1:
                raise InputError(f"expected a whole number >= 1, got {getattr(self, key)}", key=key)
        if not 0 < self.tolerance < 1:
            raise InputError(f"expected a number in (0, 1), got {self.tolerance:g}", key="tolerance")
        if not 0 < self.specular_rate < 1:
            raise InputError(f"expected a number in (0, 1), got {self.specular_rate:g}", key="specular_rate")
        if not self.pass_margin >= 0:
            raise InputError(f"expected a number >= 0 (m), got {self.pass_margin:g}", key="pass_margin")
        if not self.start_sigma > 0:
            raise InputError(f"expected a positive number (m), got {self.start_sigma:g}", key="start_sigma")
        if not 0 < self.sigma_min <= self.sigma_max:
            raise InputError(f"expected 0 < sigma_min <= sigma_max, got {self.sigma_min:g}, {self.sigma_max:g}",
                             key="sigma_min")
        if not 0 < self.p_rand_min <= self.p_rand_max < 1:
            raise InputError(f"expected 0 < p_rand_min <= p_rand_max < 1, got {self.p_rand_min:g}, {self.p_rand_max:g}",
                             key="p_rand_min")
        if not 0 <= self.p_max_max < 1 or self.p_rand_max + self.p_max_max >= 1:
            raise InputError(f"expected p_max_max in [0, 1) with p_rand_max + p_max_max < 1, got {self.p_max_max:g}",
                             key="p_max_max")
        if not 0 < self.p_hit_min <= self.p_hit_max < 1:
            raise InputError(f"expected 0 < p_hit_min <= p_hit_max < 1, got {self.p_hit_min:g}, {self.p_hit_max:g}",
                             key="p_hit_min")
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


def resolve_params(params_file: str | None = None, overrides: dict[str, dict[str, Any]] | None = None) -> MapParams:
    """Defaults, then the YAML file's values, then ``overrides`` ({section: {key: value}}; None
    values ignored). Raises InputError naming the file and ``section.key``."""
    raw: dict[str, Any] = {}
    file = params_file
    if params_file:
        raw = read_yaml(params_file)[1] or {}
        if not isinstance(raw, dict):
            raise InputError("expected a mapping with sections inverse_model, em, adaptive, calibration, surface, exact and key resolution",
                             file=file)
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

    def checked(kind):
        """A section's config of dataclass ``kind``: its fields' types, then its own checks."""
        def make(values):
            config = kind(**values)
            check_field_types(config)
            return config.validate()
        return make

    inverse = build("inverse_model", checked(InverseModelConfig))
    em = build(
        "em",
        lambda v: EMConfig(
            forward=ForwardModelConfig(**{k: x for k, x in v.items() if k in forward_keys}),
            **{k: x for k, x in v.items() if k not in forward_keys},
        ).validate(),
    )
    adaptive = build("adaptive", lambda v: AdaptiveConfig(**v).validate())
    calibration = build("calibration", lambda v: CalibrationConfig(**v).validate())
    surface = build("surface", checked(SurfaceConfig))
    exact = build("exact", checked(ExactModelConfig))
    if (isinstance(resolution, bool) or not isinstance(resolution, (int, float)) or not math.isfinite(resolution)
            or not resolution > 0):
        raise InputError(f"expected a positive number (m per cell), got {resolution!r}", file=file, key="resolution")
    return MapParams(float(resolution), inverse, em, adaptive, calibration, surface, exact)
