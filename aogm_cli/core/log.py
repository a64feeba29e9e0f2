"""A log in memory: the range sensors, the scans and, for simulated logs, the truth. Domain types
only (no file I/O); ``aogm_cli.io.logfile`` reads and writes them as HDF5."""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
import yaml

from aogm_cli.core.errors import InputError
from aogm_cli.core.grid import GridSpec

SIMULATED_SOURCE = "aogm simulate "  # a simulated log's source: this, then the world file
CAUSE_ECHO = 0  # echo of the nearest surface in the cone
CAUSE_NO_ECHO = 1  # no echo: a max-range reading
CAUSE_RANDOM = 2  # a random reading
CAUSE_SPECULAR = 3  # specular reflection or multipath: a reading too long
SENSOR_KINDS = ("sonar", "laser")

MAX_MOUNT = 1000.0  # m, rad: a sensor's offset from the robot (and its yaw) beyond this is no robot


@dataclass(frozen=True)
class SensorSpec:
    """The range sensors of a log: mounts (S, 3) in the robot frame and the beam's properties.

    The field defaults are the sonar's, written only here: the world's ``Sonar``, the world loader,
    the importers' SONAR and text defaults and the import command's options all read them.
    """

    mount: np.ndarray
    kind: str = "sonar"
    beam_width: float = math.radians(30.0)
    min_range: float = 0.15
    max_range: float = 5.0
    noise_sigma: float = 0.02

    @property
    def count(self) -> int:
        return int(self.mount.shape[0])

    def validate(self) -> SensorSpec:
        """Return self, or raise ``InputError(key=<field>)`` for a value no mapper can use:
        kind sonar or laser, beam_width in (0, pi), 0 <= min_range < max_range finite,
        noise_sigma finite >= 0, at least one sensor with finite mounts (S, 3)."""
        def bad(key, msg):
            return InputError(msg, key=key)

        if self.kind not in SENSOR_KINDS:
            raise bad("kind", f"expected one of {', '.join(SENSOR_KINDS)}, got {self.kind!r}")
        if not 0 < self.beam_width < math.pi:
            raise bad("beam_width", f"expected a beam width in (0, pi) rad, got {self.beam_width}")
        if not (math.isfinite(self.min_range) and self.min_range >= 0):
            raise bad("min_range", f"expected a finite range >= 0 (m), got {self.min_range}")
        if not (math.isfinite(self.max_range) and self.max_range > self.min_range):
            raise bad("max_range", f"expected a finite range > min_range = {self.min_range} (m), got {self.max_range}")
        if not (math.isfinite(self.noise_sigma) and self.noise_sigma >= 0):
            raise bad("noise_sigma", f"expected a finite number >= 0 (m), got {self.noise_sigma}")
        mount = np.asarray(self.mount)
        if mount.ndim != 2 or mount.shape[0] < 1 or mount.shape[1] != 3:
            raise bad("mount", f"expected shape (S, 3) with S >= 1 sensors, got {mount.shape}")
        if not np.all(np.isfinite(mount)):
            raise bad("mount", "expected finite numbers (x, y, yaw of each sensor)")
        if np.abs(mount).max() > MAX_MOUNT:
            raise bad("mount", f"expected each sensor within {MAX_MOUNT:g} m (x, y) and rad (yaw) of the robot, "
                               f"got {np.abs(mount).max():g}")
        return self

    def as_dict(self) -> dict:
        return {
            "kind": self.kind,
            "beam_width": float(self.beam_width),
            "min_range": float(self.min_range),
            "max_range": float(self.max_range),
            "noise_sigma": float(self.noise_sigma),
        }


def sensor_names(indices) -> str:
    """Sensors by index as people read them: "sensor 3", "sensors 8-15", "sensors 0, 2, 8-15"."""
    idx = sorted({int(i) for i in indices})
    runs: list[list[int]] = []
    for i in idx:
        if runs and i == runs[-1][1] + 1:
            runs[-1][1] = i
        else:
            runs.append([i, i])
    text = ", ".join(f"{a}" if a == b else f"{a}-{b}" for a, b in runs)
    return f"sensor {text}" if len(idx) == 1 else f"sensors {text}"


CHECK_KINDS = ("passable", "blocked")  # a world check's key beside its name: a path must exist / must not


def check_kind(check: dict) -> str:
    """Which of ``CHECK_KINDS`` a check (a JSON dict as in the world file) is."""
    return next(k for k in CHECK_KINDS if k in check)


@dataclass(frozen=True)
class Truth:
    """Ground truth of a simulated log: occupancy on ``grid``, and per reading its cause and ideal range."""

    grid: GridSpec
    occupancy: np.ndarray  # (H, W) uint8
    cause: np.ndarray  # (T, S) int8
    ideal_range: np.ndarray  # (T, S) float32
    world: str = ""  # the world file's text
    checks: tuple[dict, ...] = ()  # JSON-able checks, as in the world file

    def world_mapping(self) -> dict | None:
        """The world file's text parsed (None without it, or when it is not a YAML mapping)."""
        if not self.world:
            return None
        try:
            raw = yaml.safe_load(self.world)
        except yaml.YAMLError:
            return None
        return raw if isinstance(raw, dict) else None

    def world_name(self) -> str | None:
        """The world file's ``name:`` (None without one)."""
        name = (self.world_mapping() or {}).get("name")
        return name.strip() if isinstance(name, str) and name.strip() else None


@dataclass(frozen=True)
class Log:
    """A whole log in memory: scan times (T,), poses (T, 3), ranges (T, S) and the sensor."""

    time: np.ndarray
    pose: np.ndarray
    ranges: np.ndarray
    sensor: SensorSpec
    source: str
    truth: Truth | None = None
    seed: int | None = None

    path = ""  # an in-memory log has no file (a log source, like ``io.logfile.LogReader``)

    @property
    def n_scans(self) -> int:
        return int(self.time.shape[0])

    def truth_grid(self) -> GridSpec | None:
        return None if self.truth is None else self.truth.grid

    def poses(self) -> np.ndarray:
        return self.pose

    def chunks(self, size: int = 4096) -> Iterator[tuple[int, np.ndarray, np.ndarray, np.ndarray]]:
        """(first scan index, time, pose, ranges) for consecutive chunks of ``size`` scans."""
        for start in range(0, self.n_scans, size):
            stop = min(self.n_scans, start + size)
            yield start, self.time[start:stop], self.pose[start:stop], self.ranges[start:stop]

    def scan_ranges(self, start: int, stop: int) -> np.ndarray:
        """Ranges of scans start:stop (as ``io.logfile.LogReader.scan_ranges``)."""
        return self.ranges[start:stop]

    def read(self) -> Log:
        return self
