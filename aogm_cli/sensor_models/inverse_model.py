"""The sonar inverse model of standard mapping (Elfes 1989; Moravec 1988): ``InverseModelConfig`` (every
parameter, validated once, recorded in map files), ``inverse_model`` (the model as a vectorised function,
the reference the compiled kernels are tested against) and ``inverse_update`` (the kernels' constants)."""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import NamedTuple

import numba
import numpy as np

from aogm_cli.core.errors import InputError

MODELS = ("elfes", "constant", "exact")  # exact: derived from the forward model (mapping.exact)


@dataclass(frozen=True)
class InverseModelConfig:
    """Parameters of the sonar inverse model and of the log-odds update (log-odds, metres).
    Defaults: OctoMap's hit/miss probabilities 0.7/0.4 and clamps 0.12/0.97; prior p = 0.5."""

    model: str = "elfes"
    l_occ: float = 0.85
    l_free: float = -0.41
    l0: float = 0.0
    clamp_min: float = -2.0
    clamp_max: float = 3.5
    # alpha, the obstacle thickness (Elfes' 2 epsilon): about the Polaroid's accuracy (1% of the
    # reading) and one default cell; thicker arcs thicken walls towards the robot (docs/algorithms.md).
    # On coarser grids choose alpha of about the resolution.
    alpha: float = 0.05

    def validate(self) -> InverseModelConfig:
        """Return self, or raise ``InputError(key=<field>)`` for an impossible value (types: ``params._checked``)."""
        if self.model not in MODELS:
            raise InputError(f"expected one of {', '.join(MODELS)}, got {self.model!r}", key="model")
        if self.alpha <= 0:
            raise InputError(f"expected a positive obstacle thickness (m), got {self.alpha}", key="alpha")
        if self.l_occ < self.l0:
            raise InputError(f"expected l_occ >= l0 = {self.l0}, got {self.l_occ}", key="l_occ")
        if self.l_free > self.l0:
            raise InputError(f"expected l_free <= l0 = {self.l0}, got {self.l_free}", key="l_free")
        if self.l_free >= self.l_occ:
            raise InputError(f"expected l_free < l_occ = {self.l_occ}, got {self.l_free}", key="l_free")
        if self.clamp_min >= self.clamp_max:
            raise InputError(f"expected clamp_min < clamp_max = {self.clamp_max}, got {self.clamp_min}", key="clamp_min")
        if not self.clamp_min <= self.l0 <= self.clamp_max:
            raise InputError(
                f"expected the prior l0 within [clamp_min, clamp_max] = [{self.clamp_min}, {self.clamp_max}], got {self.l0}",
                key="l0",
            )
        return self

    def as_dict(self) -> dict:
        """Every parameter, JSON-able, for the ``params`` attribute of map files."""
        d = asdict(self)
        for k, v in d.items():
            if k != "model":
                d[k] = float(v)
        return d


def angular_profile(theta, beam_width: float):
    """Elfes' E_a(theta) = 1 - (2 theta / beta)^2 inside the cone, 0 outside."""
    theta = np.asarray(theta, dtype=np.float64)
    return np.where(np.abs(theta) <= 0.5 * beam_width, 1.0 - (2.0 * theta / beam_width) ** 2, 0.0)


def range_profile(d, z_free, min_range: float):
    """Elfes' E_r(d) = 1 - ((d - Rmin) / (z_free - Rmin))^2 on [Rmin, z_free), 0 elsewhere
    (``z_free``: z - alpha/2, or max_range for a max-range reading)."""
    d = np.asarray(d, dtype=np.float64)
    z_free = np.asarray(z_free, dtype=np.float64)
    span = z_free - min_range
    with np.errstate(divide="ignore", invalid="ignore"):
        u = (d - min_range) / span
        e = 1.0 - u * u
    return np.where((d >= min_range) & (d < z_free) & (span > 0), e, 0.0)


# The model (Elfes 1989; Probabilistic Robotics table 9.2): a cell at range d inside the cone has log-odds
# * occupied arc, z - alpha/2 <= d <= min(z + alpha/2, max_range): l0 + w_occ * (l_occ - l0)
# * free region, min_range <= d < z - alpha/2:                     l0 + w_free * (l_free - l0)
# * anything else (beyond the arc, outside the cone, nearer than min_range): l0 (no evidence)
# with weights "elfes": w_free = E_r(d) E_a(theta), w_occ = E_a(theta); "constant": both 1.
# A max-range reading (z >= max_range) is free evidence only, up to max_range inclusive; a NaN or
# negative reading carries none.
def inverse_model(d, theta, z, config: InverseModelConfig, *, beam_width: float, min_range: float, max_range: float):
    """Log-odds l(x | z) of a cell at range ``d`` (m) and bearing ``theta`` (rad, from the beam
    axis) given reading ``z`` (m; +inf = max-range reading, NaN = invalid). Broadcasts."""
    d = np.asarray(d, dtype=np.float64)
    theta = np.asarray(theta, dtype=np.float64)
    z = np.asarray(z, dtype=np.float64)
    half = 0.5 * config.alpha
    in_cone = np.abs(theta) <= 0.5 * beam_width
    valid = z >= 0  # False for NaN and negative readings
    max_reading = valid & (z >= max_range)
    echo = valid & ~max_reading
    if config.model == "elfes":
        w_angle = angular_profile(theta, beam_width)
    else:
        w_angle = np.ones_like(theta)
    z_echo = np.where(echo, z, 0.0)
    z_free = np.where(echo, z_echo - half, max_range)
    # written as the compiled kernel compares, so that both agree on cells at the boundaries
    arc = echo & (d >= z_free) & (d <= np.minimum(z_echo + half, max_range))
    free_region = valid & ~arc & (d >= min_range) & np.where(echo, d < z_free, d <= max_range)
    if config.model == "elfes":
        w_free = range_profile(d, z_free, min_range) * w_angle
    else:
        w_free = np.ones_like(w_angle)
    out = np.full(np.broadcast(d, theta, z).shape, config.l0, dtype=np.float64)
    out = np.where(in_cone & free_region, config.l0 + w_free * (config.l_free - config.l0), out)
    out = np.where(in_cone & arc, config.l0 + w_angle * (config.l_occ - config.l0), out)
    return out


class InverseUpdate(NamedTuple):
    """The per-map constants of the log-odds update, as the compiled mappers take them."""

    half_alpha: float  # alpha / 2 (m): half the occupied arc's thickness
    min_range: float  # the sensor's (m): no evidence nearer
    max_range: float  # the sensor's (m): a reading >= max_range is a max-range reading
    l_free_minus_l0: float  # free increment at full weight (<= 0)
    l_occ_minus_l0: float  # occupied increment at full weight (>= 0)
    clamp_min: float  # bounds of every cell's log-odds after each update
    clamp_max: float
    l0: float  # the prior a cell starts from when first observed
    elfes: bool  # Elfes' weights (model "elfes"); else constant ones (rays always use these)
    resolution: float  # the grid's cell size (m)


UNOBSERVED = np.float32(-np.inf)  # a cell of the mappers' log-odds state that no reading reached yet


def observed_log_odds(state: np.ndarray, l0: float) -> tuple[np.ndarray, np.ndarray]:
    """(log_odds, observed) of a mapper's log-odds ``state``; unobserved cells hold the prior ``l0``."""
    log_odds = state.copy()
    observed = log_odds != UNOBSERVED
    log_odds[~observed] = np.float32(l0)
    return log_odds, observed


def inverse_update(config: InverseModelConfig, sensor, resolution: float) -> InverseUpdate:
    """The ``InverseUpdate`` of ``config`` for ``sensor`` on a grid of ``resolution`` metres."""
    return InverseUpdate(
        half_alpha=0.5 * float(config.alpha),
        min_range=float(sensor.min_range),
        max_range=float(sensor.max_range),
        l_free_minus_l0=float(config.l_free) - float(config.l0),
        l_occ_minus_l0=float(config.l_occ) - float(config.l0),
        clamp_min=float(config.clamp_min),
        clamp_max=float(config.clamp_max),
        l0=float(config.l0),
        elfes=config.model == "elfes",
        resolution=float(resolution),
    )


@numba.njit(cache=True, inline="always")
def float32_update(update):
    """(c_occ, lo, hi, l0) of an ``InverseUpdate`` as float32, as the compiled mappers use them."""
    return (np.float32(update.l_occ_minus_l0), np.float32(update.clamp_min), np.float32(update.clamp_max),
            np.float32(update.l0))


@numba.njit(cache=True, inline="always")
def occupied_arc(z, half_alpha, max_range):
    """(start, end) of the occupied arc of an echo at ``z``, cut at max_range (one definition for all)."""
    return z - half_alpha, min(z + half_alpha, max_range)
