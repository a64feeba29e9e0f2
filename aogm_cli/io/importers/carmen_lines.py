"""CARMEN log lines, one at a time: the field layout of each scan message (FLASER/RLASER,
RAWLASERn/ROBOTLASERn, SONAR) and of the pose messages (ODOM, TRUEPOS), as pure functions on text.

Every line ends with ``ipc_timestamp ipc_hostname logger_timestamp``; a scan's time is its
ipc_timestamp. ``importers.carmen`` assembles the parsed lines into a log. ``CarmenOptions``
lives here because the FLASER/RLASER beam angles, which those lines do not store, are among its choices.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from aogm_cli.core.errors import InputError

LASER_MESSAGES = (
    "FLASER",
    "RLASER",
    "RAWLASER1",
    "RAWLASER2",
    "RAWLASER3",
    "RAWLASER4",
    "ROBOTLASER1",
    "ROBOTLASER2",
)
SCAN_MESSAGES = LASER_MESSAGES + ("SONAR",)
POSE_MESSAGES = ("ODOM", "TRUEPOS")
# messages whose line carries the pose to use: FLASER/RLASER the (corrected) laser pose, ROBOTLASER the robot pose
CARRIES_POSE = ("FLASER", "RLASER", "ROBOTLASER1", "ROBOTLASER2")
_TRAILER = 3  # ipc_timestamp ipc_hostname logger_timestamp


@dataclass(frozen=True)
class CarmenOptions:
    """What to import and how. Angles in radians, lengths in metres; None = from the log or a default.

    ``message``: one of SCAN_MESSAGES, or None for "the only scan message type in the log".
    ``pose_from``: "line" (the pose the line carries), "odom" / "truepos" (interpolated by time
    from ODOM / TRUEPOS lines) or "auto" (line where the message has one, else TRUEPOS when the log
    has it, else ODOM). ``start_angle`` and ``angular_res`` are for FLASER/RLASER, whose lines do
    not store them (``angular_res`` None = CARMEN's guess from the beam count). ``mount`` is the
    laser's (x, y, yaw) in the robot frame for FLASER, RLASER and RAWLASER.
    """

    message: str | None = None
    pose_from: str = "auto"
    start_angle: float = -math.pi / 2
    angular_res: float | None = None
    max_range: float | None = None
    min_range: float | None = None
    beam_width: float | None = None
    noise_sigma: float | None = None
    mount: tuple[float, float, float] | None = None


@dataclass(frozen=True)
class CarmenScan:
    """One parsed scan line.

    ``beams`` (n, 3) is each beam's (x, y, yaw) in the sensor's frame: (0, 0, bearing) for a laser,
    the sonar's offset for SONAR. ``pose`` is the pose the line carries (None for RAWLASER and
    SONAR): the laser pose for FLASER/RLASER, the robot pose for ROBOTLASER, whose laser pose is
    ``laser_pose``. ``max_range`` is the line's own (RAWLASER, ROBOTLASER) or None.
    """

    message: str
    line: int
    time: float
    ranges: np.ndarray
    beams: np.ndarray
    pose: np.ndarray | None = None
    laser_pose: np.ndarray | None = None
    max_range: float | None = None
    cone_angle: float | None = None

    @property
    def count(self) -> int:
        return int(self.ranges.shape[0])


class _Fields:
    """The whitespace-separated fields of one line, with errors that name the line and message."""

    def __init__(self, tokens: list[str], line: int):
        self.tokens = tokens
        self.line = line
        self.name = tokens[0]

    def error(self, message: str) -> InputError:
        return InputError(f"line {self.line}: {message}", key=self.name)

    def need(self, n: int, what: str) -> None:
        if len(self.tokens) < n:
            raise self.error(f"expected {what}, but the line ends after {len(self.tokens) - 1} fields")

    def number(self, i: int, what: str) -> float:
        self.need(i + 1, what)
        try:
            return float(self.tokens[i])
        except ValueError:
            raise self.error(f"field {i} ({what}): expected a number, got {self.tokens[i]!r}") from None

    def count(self, i: int, what: str) -> int:
        self.need(i + 1, what)
        try:
            n = int(self.tokens[i])
        except ValueError:
            raise self.error(f"field {i} ({what}): expected a whole number, got {self.tokens[i]!r}") from None
        if n < 0:
            raise self.error(f"field {i} ({what}): expected a count >= 0, got {n}")
        return n

    def numbers(self, start: int, stop: int, what: str) -> np.ndarray:
        self.need(stop, what)
        try:
            return np.array(self.tokens[start:stop], dtype=np.float64)
        except ValueError:
            for i in range(start, stop):
                self.number(i, what)
            raise  # pragma: no cover - number() raised already

    def exact_length(self, n: int, layout: str) -> None:
        if len(self.tokens) != n:
            raise self.error(f"expected {n - 1} fields after {self.name} ({layout}), got {len(self.tokens) - 1}")

    def time(self) -> float:
        """The ipc_timestamp: third field from the end."""
        return self.number(len(self.tokens) - _TRAILER, "ipc_timestamp")


def guess_angular_res(n: int) -> float:
    """Beam spacing (rad) of an n-beam FLASER/RLASER scan, as CARMEN's own log reader guesses it."""
    if n in (180, 181):
        return math.pi / 180
    if n in (360, 361):
        return math.pi / 360
    if n in (400, 401):
        return math.pi / 720
    return math.pi / (n - 1) if n > 1 else 0.0


def laser_beams(n: int, start_angle: float, angular_res: float) -> np.ndarray:
    """(n, 3) beams (0, 0, start_angle + i * angular_res) of a laser in its own frame."""
    beams = np.zeros((n, 3))
    beams[:, 2] = start_angle + angular_res * np.arange(n)
    return beams


def parse_scan_line(line: str, line_no: int, options: CarmenOptions = CarmenOptions()) -> CarmenScan:
    """Parse one FLASER, RLASER, RAWLASERn, ROBOTLASERn or SONAR line (counts decide the layout)."""
    f = _Fields(line.split(), line_no)
    name = f.name
    if name in ("FLASER", "RLASER"):
        return _flaser(f, options)
    if name.startswith("RAWLASER") or name.startswith("ROBOTLASER"):
        return _rawlaser(f)
    if name == "SONAR":
        return _sonar(f)
    raise f.error(f"not a scan message; expected one of {', '.join(SCAN_MESSAGES)}")


def _flaser(f: _Fields, options: CarmenOptions) -> CarmenScan:
    """FLASER/RLASER: readings, then the laser pose (the line does not store the beam angles)."""
    n = f.count(1, "num_readings")
    f.exact_length(
        2 + n + 6 + _TRAILER, f"num_readings, {n} readings, x y theta odom_x odom_y odom_theta, 3 trailer fields"
    )
    ranges = f.numbers(2, 2 + n, "range reading")
    pose = f.numbers(2 + n, 2 + n + 3, "x y theta")
    res = options.angular_res if options.angular_res is not None else guess_angular_res(n)
    return CarmenScan(f.name, f.line, f.time(), ranges, laser_beams(n, options.start_angle, res), pose=pose)


def _rawlaser(f: _Fields) -> CarmenScan:
    """RAWLASERn (config, readings, remissions) or ROBOTLASERn (the same, then laser and robot pose)."""
    name = f.name
    robot = name.startswith("ROBOTLASER")
    start = f.number(2, "start_angle")
    f.number(3, "field_of_view")
    res = f.number(4, "angular_resolution")
    max_range = f.number(5, "maximum_range")
    f.number(6, "accuracy")
    n = f.count(8, "num_readings")
    m = f.count(9 + n, "num_remissions")
    tail = 6 + 5 if robot else 0
    after = "laser and robot pose, tv rv forward_safety side_safety turn_axis, " if robot else ""
    f.exact_length(
        10 + n + m + tail + _TRAILER,
        f"7 config fields, num_readings, {n} readings, num_remissions, {m} remissions, {after}3 trailer fields",
    )
    ranges = f.numbers(9, 9 + n, "range reading")
    f.numbers(10 + n, 10 + n + m, "remission")
    laser_pose = pose = None
    if robot:
        laser_pose = f.numbers(10 + n + m, 13 + n + m, "laser_x laser_y laser_theta")
        pose = f.numbers(13 + n + m, 16 + n + m, "robot_x robot_y robot_theta")
    return CarmenScan(
        name,
        f.line,
        f.time(),
        ranges,
        laser_beams(n, start, res),
        pose=pose,
        laser_pose=laser_pose,
        max_range=max_range,
    )


def _sonar(f: _Fields) -> CarmenScan:
    """SONAR: cone angle, readings, then each sonar's x y theta offset."""
    cone = f.number(1, "cone_angle")
    n = f.count(2, "num_sonars")
    f.exact_length(
        3 + 4 * n + _TRAILER, f"cone_angle, num_sonars, {n} readings, {n} x y theta offsets, 3 trailer fields"
    )
    ranges = f.numbers(3, 3 + n, "range reading")
    beams = f.numbers(3 + n, 3 + 4 * n, "sonar offset x y theta").reshape(n, 3)
    return CarmenScan(f.name, f.line, f.time(), ranges, beams, cone_angle=cone)


def parse_pose_line(line: str, line_no: int) -> tuple[float, np.ndarray]:
    """(ipc_timestamp, (x, y, theta)) of an ODOM or TRUEPOS line (TRUEPOS: the true pose)."""
    f = _Fields(line.split(), line_no)
    if f.name not in POSE_MESSAGES:
        raise f.error(f"not a pose message; expected one of {', '.join(POSE_MESSAGES)}")
    layout = "x y theta tv rv accel" if f.name == "ODOM" else "true_x true_y true_theta odom_x odom_y odom_theta"
    f.exact_length(1 + 6 + _TRAILER, f"{layout}, 3 trailer fields")
    return f.time(), f.numbers(1, 4, "x y theta")
