"""What a map learns from its log, apart from what was configured: the sensor's forward model (once per robot) and
the building's part (per log: p_max, the lobe that hears), each with where it came from, and the
model EM uses made of both."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from aogm_cli.sensor_models.forward_model import ForwardModelConfig

SENSOR_KEYS = ("sigma", "p_rand", "p_hit", "p_max")  # the forward model's parameters calibration sets
# what a robot's model leaves to each log: the building's max-range share (``stages.rates``), and the lobe that hears
# (``stages.lobe``) when the model carries none (the packaged detector's, whose training logs disagree on it, or a
# model file of an older aogm)
BUILDING = ("p_max", "lobe_deg")

# where a sensor model came from (``Learned.origin``)
CONFIGURED = "configured"  # the values of --params / the defaults: nothing learned
FROM_LOG = "learned from this log"


@dataclass(frozen=True)
class SensorModel:
    """The forward model's parameters that belong to the sensor: learned once per robot, carried to its logs."""

    sigma: float
    p_rand: float
    p_hit: float
    p_max: float

    @classmethod
    def of(cls, forward: ForwardModelConfig) -> SensorModel:
        return cls(*(float(getattr(forward, k)) for k in SENSOR_KEYS))

    @classmethod
    def read(cls, values: dict) -> SensorModel:
        """The model of a map's, model file's or detector's record (an ``opening_deg`` older ones carry: ignored)."""
        return cls(*(float(values[k]) for k in SENSOR_KEYS))

    def as_dict(self) -> dict:
        return dataclasses.asdict(self)


@dataclass(frozen=True)
class Learned:
    """What a map learned from its log or was given (None: as configured), with its records and the seconds
    learning took (a model carried from another map of the log counts them in its cost; a file's does not)."""

    sensor: SensorModel | None = None
    origin: str = CONFIGURED
    calibration: dict | None = None  # ``calibration.calibration_rounds``' record
    seconds: float = 0.0
    made_by: str | None = None  # the mode of the map of the same log that learned it (``carried``)
    rates: dict | None = None  # the building's p_max fitted for a robot's model (``stages.rates``)
    lobe_deg: float | None = None  # the lobe that hears (``ForwardModelConfig.lobe_deg``), learned or carried
    lobe_range: float | None = None
    lobe: dict | None = None  # ``beam_model.lobe_record``'s record

    @property
    def carries_lobe(self) -> bool:
        """A robot's model (given, not learned by another map of the log) that carries the lobe: no log learns it."""
        return self.made_by is None and self.lobe_deg is not None

    def model(self, configured: ForwardModelConfig) -> ForwardModelConfig:
        """The forward model EM uses: ``configured`` with what was learned in its place."""
        values = {} if self.sensor is None else {k: getattr(self.sensor, k) for k in SENSOR_KEYS}
        if self.lobe_deg is not None:  # learned from this log or carried: it wins over a configured lobe
            values["lobe_deg"], values["lobe_range"] = self.lobe_deg, self.lobe_range
        return dataclasses.replace(configured, **values)

    def kept_for(self, learn: tuple[str, ...]) -> Learned:
        """This model as a map whose ``calibration.learn`` is ``learn`` takes it: a carried lobe only in place of
        learning one (without lobe_deg in ``learn`` the configured lobe stays)."""
        if not self.carries_lobe or "lobe_deg" in learn:
            return self
        return dataclasses.replace(self, lobe_deg=None, lobe_range=None)

    def carried(self, mode: str, seconds: float) -> Learned:
        """What the ``mode`` map of a log learned, as another map of the same log takes it."""
        return dataclasses.replace(self, origin=f"the {mode} map of this log", made_by=mode, seconds=seconds)

    @classmethod
    def of_map(cls, learned: dict, calibration: dict | None) -> Learned:
        """What a finished map learned (its ``learned`` record and ``stats["calibration"]``)."""
        sensor = learned.get("sensor")
        rounds = None if calibration is None else {k: v for k, v in calibration.items()
                                                    if k not in ("final_em", "made_by")}
        return cls(None if sensor is None else SensorModel.read(sensor), learned.get("origin", CONFIGURED),
                   calibration=rounds, lobe_deg=learned.get("lobe_deg"), lobe_range=learned.get("lobe_range"),
                   lobe=learned.get("lobe"))

    def as_dict(self) -> dict:
        """What the map file records beside its params (root attribute ``learned``)."""
        return {"sensor": None if self.sensor is None else self.sensor.as_dict(), "origin": self.origin, "rates": self.rates,
                "lobe_deg": self.lobe_deg, "lobe_range": self.lobe_range, "lobe": self.lobe}
