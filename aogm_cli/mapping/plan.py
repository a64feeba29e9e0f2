"""A map's plan, decided once before its first stage (``plan_map``): sensor kind, the sensor model's origin and keys
learned, what adaptive is outside its clusters, thinning, EM's start. Stages read it; none asks again."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from aogm_cli.core.log import SensorSpec
from aogm_cli.mapping.learned import BUILDING, CONFIGURED, FROM_LOG, Learned
from aogm_cli.mapping.params import MapParams
from aogm_cli.sensor_models.exact_inverse import MARGIN
from aogm_cli.sensor_models.ray import is_narrow_beam

CONE, NARROW_BEAM = "cone", "narrow beam"  # ``Plan.sensor``: a sonar's cone, or a ray (``ray.is_narrow_beam``)
# adaptive's thinning margin with the thinned map outside: any (the ``decided`` stage checks each free cell;
# docs/algorithms.md, "Adaptive with the thinned map outside its clusters"); elsewhere ``MARGIN``
OUTSIDE_MARGIN = 0.0


@dataclass(frozen=True)
class Plan:
    """What a map of ``mode`` does, decided from what it is given (``plan_map``); every field is described where
    users read it (docs/commands.md, the map's root attribute ``plan``). ``thinning`` is the margin (None: not
    thinned); ``start`` EM's ("elfes in clusters": thinned outside, Elfes' inside); ``stages``: ``modes``'."""

    mode: str
    sensor: str
    model: str
    learns: tuple[str, ...]
    calibrates: bool
    fits_rates: bool
    incidence: bool
    outside: str | None
    thinning: float | None
    start: str | None
    stages: tuple[str, ...] = ()

    @property
    def learns_lobe(self) -> bool:
        return "lobe_deg" in self.learns

    @property
    def decides(self) -> bool:
        """Adaptive keeps the thinned map outside, whose free cells the readings must hold free."""
        return self.outside == "thinned" and self.thinning is not None

    def as_dict(self) -> dict:
        """What the map file records (root attribute ``plan``)."""
        return dataclasses.asdict(self) | {"learns": list(self.learns), "stages": list(self.stages)}


def learned_keys(params: MapParams, given: Learned | None) -> tuple[str, ...]:
    """The forward model's keys a map learns from its log (of a robot's model given, the building's part only, the
    lobe not when the model carries one)."""
    config = params.calibration
    if not config.enabled:
        return ()
    return tuple(k for k in config.learned if given is None or (given.made_by is None and k in BUILDING
                                                                 and not (k == "lobe_deg" and given.carries_lobe)))


def auto_outside(known: bool, sensor: str) -> str:
    """``adaptive.outside`` "auto": "thinned" for a cone whose forward model is ``known`` before the map (the
    thinning and clusters need it), else "elfes" (learned in the clusters, after them)."""
    return "thinned" if known and sensor == CONE else "elfes"


def plan_map(mode: str, params: MapParams, sensor: SensorSpec, resolution: float, given: Learned | None) -> Plan:
    """The plan of a ``mode`` map of a log of ``sensor`` at ``resolution``, with the forward model ``given``."""
    kind = NARROW_BEAM if is_narrow_beam(sensor, resolution) else CONE
    thinnable = params.inverse_model.model != "exact" and kind == CONE  # a ray draws walls one cell thick
    if mode == "standard":
        return Plan(mode, kind, CONFIGURED, (), False, False, False, None,
                    MARGIN if thinnable and params.exact.thin else None, None)
    incidence = params.em.forward.specular_deg < 90.0 and kind == CONE  # at 90 no beam is deflected
    learns = tuple(k for k in learned_keys(params, given) if k != "lobe_deg" or kind == CONE)  # no lobe of a ray
    calibrates = params.calibration.enabled and given is None
    robots = given is not None and given.made_by is None and given.sensor is not None
    model = given.origin if given is not None else FROM_LOG if calibrates else CONFIGURED
    if mode == "em":
        thinning = MARGIN if thinnable and params.exact.thin else None
        return Plan(mode, kind, model, learns, calibrates, robots and "p_max" in learns, incidence, None, thinning,
                    "standard")
    outside = params.adaptive.outside
    if outside == "auto":
        outside = auto_outside(given is not None and given.sensor is not None, kind)
    thinning = (OUTSIDE_MARGIN if outside == "thinned" else MARGIN) if thinnable and (
        outside == "thinned" or params.exact.thin) else None
    start = "elfes in clusters" if outside == "thinned" and thinning is not None else "standard"
    return Plan(mode, kind, model, learns, calibrates, robots and "p_max" in learns, incidence, outside, thinning,
                start)
