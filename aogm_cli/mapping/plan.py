"""A map's plan, decided once before its first stage (``plan_map``): the log's sensor kind, where the
sensor model comes from and which of its keys this log teaches, what an adaptive map is outside its
clusters, how the standard map is thinned and where EM starts. Stages read it; none asks again."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from aogm_cli.core.log import SensorSpec
from aogm_cli.mapping.learned import BUILDING, CONFIGURED, FROM_LOG, Learned
from aogm_cli.mapping.params import MapParams
from aogm_cli.sensor_models.exact_inverse import MARGIN
from aogm_cli.sensor_models.ray import is_narrow_beam

CONE, NARROW_BEAM = "cone", "narrow beam"  # ``Plan.sensor``: a sonar's cone, or a ray (``ray.is_narrow_beam``)
# log-odds below the exact model's prior at which adaptive's thinning frees a cell when the thinned map
# stands outside the clusters: any (the ``decided`` stage then checks each free cell against the
# readings; docs/algorithms.md, "Adaptive with the thinned map outside its clusters"); elsewhere ``MARGIN``
OUTSIDE_MARGIN = 0.0


@dataclass(frozen=True)
class Plan:
    """What a map of ``mode`` does, decided from what it is given (``plan_map``).

    ``sensor``: ``CONE`` or ``NARROW_BEAM``. ``model``: where the forward model comes from (a
    ``Learned.origin``). ``learns``: the forward model's keys learned from this log; ``calibrates``:
    in calibration rounds of EM (no model given), ``fits_rates``: the building's p_max at the
    standard map (a robot's model given). ``incidence``: the angle of incidence plays its part
    (surfaces of a cone's echoes). ``outside``: what an adaptive map is outside its clusters
    ("thinned" or "elfes"; None for the other modes). ``thinning``: the margin the standard map is
    thinned at (None: not thinned). ``start``: EM's start map ("standard", "empty", or "elfes in
    clusters": the thinned map outside, Elfes' inside; None for the standard mode). ``stages``:
    the stages the mode runs (``modes.mode_stages``)."""

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
    def learns_opening(self) -> bool:
        return "opening_deg" in self.learns

    @property
    def decides(self) -> bool:
        """Adaptive keeps the thinned map outside its clusters, whose free cells the readings must
        hold free (``stages.final_evidence``)."""
        return self.outside == "thinned" and self.thinning is not None

    def as_dict(self) -> dict:
        """What the map file records (root attribute ``plan``)."""
        return dataclasses.asdict(self) | {"learns": list(self.learns), "stages": list(self.stages)}


def learned_keys(params: MapParams, given: Learned | None) -> tuple[str, ...]:
    """The forward model's keys a map learns from its log: calibration on and the key listed; of a
    model given, a robot's (a file's, or carried by the detector) leaves the building's part
    (``learned.BUILDING``) to the log, one from another map of the same log nothing."""
    config = params.calibration
    if not config.enabled:
        return ()
    return tuple(k for k in config.learned if given is None or (given.made_by is None and k in BUILDING))


def auto_outside(known: bool, sensor: str) -> str:
    """What ``adaptive.outside`` "auto" is: "thinned" for a cone whose forward model is ``known``
    before the map is made (the thinning and the clusters need it), else "elfes" (the model is
    learned by EM in the clusters, after them; a narrow beam's map is never thinned)."""
    return "thinned" if known and sensor == CONE else "elfes"


def plan_map(mode: str, params: MapParams, sensor: SensorSpec, resolution: float, given: Learned | None) -> Plan:
    """The plan of a ``mode`` map of a log of ``sensor`` at ``resolution``, with the forward model
    ``given`` (a file's, the detector's or another map's; None: none)."""
    kind = NARROW_BEAM if is_narrow_beam(sensor, resolution) else CONE
    thinnable = params.inverse_model.model != "exact" and kind == CONE  # a ray draws walls one cell thick
    if mode == "standard":
        return Plan(mode, kind, CONFIGURED, (), False, False, False, None,
                    MARGIN if thinnable and params.exact.thin else None, None)
    incidence = params.surface.enabled and kind == CONE
    # what this log can teach: no specular angle without surfaces, no opening of a ray
    learns = tuple(k for k in learned_keys(params, given)
                   if (k != "specular_deg" or incidence) and (k != "opening_deg" or kind == CONE))
    calibrates = params.calibration.enabled and given is None
    robots = given is not None and given.made_by is None and given.sensor is not None
    model = given.origin if given is not None else FROM_LOG if calibrates else CONFIGURED
    if mode == "em":
        thinning = MARGIN if thinnable and params.exact.thin else None
        start = "standard" if params.em.start == "standard" else "empty"
        return Plan(mode, kind, model, learns, calibrates, robots and "p_max" in learns, incidence, None, thinning,
                    start)
    outside = params.adaptive.outside
    if outside == "auto":
        outside = auto_outside(given is not None and given.sensor is not None, kind)
    thinning = (OUTSIDE_MARGIN if outside == "thinned" else MARGIN) if thinnable and (
        outside == "thinned" or params.exact.thin) else None
    start = "elfes in clusters" if outside == "thinned" and thinning is not None else "standard"
    return Plan(mode, kind, model, learns, calibrates, robots and "p_max" in learns, incidence, outside, thinning,
                start)
