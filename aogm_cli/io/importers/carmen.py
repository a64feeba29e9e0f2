"""CARMEN text logs -> an aogm log: scans of FLASER, RLASER, RAWLASER1-4, ROBOTLASER1-2 or SONAR.

Parsing is pure functions on text lines (``parse_scan_line``, ``parse_pose_line``, ``parse_carmen``);
``import_carmen`` only opens the (optionally gzipped) file. Every line ends with
``ipc_timestamp ipc_hostname logger_timestamp``; a scan's time is its ipc_timestamp.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from aogm_cli.core.errors import InputError
from aogm_cli.core.log import Log, SensorSpec
from aogm_cli.io.importers import Progress, clean_ranges, interpolate_poses, read_lines, wrap_angle

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
POSE_SOURCES = ("auto", "line", "odom", "truepos")
# messages whose line carries the pose to use: FLASER/RLASER the (corrected) laser pose, ROBOTLASER the robot pose
CARRIES_POSE = ("FLASER", "RLASER", "ROBOTLASER1", "ROBOTLASER2")

LASER_MAX_RANGE = 80.0  # m; CARMEN's own reader assumes this for FLASER/RLASER
SONAR_MAX_RANGE = 5.0  # m
LASER_BEAM_WIDTH = math.radians(0.5)
SONAR_BEAM_WIDTH = math.radians(30.0)  # when a SONAR line's cone_angle is not positive
LASER_MIN_RANGE = 0.0
SONAR_MIN_RANGE = 0.15
LASER_NOISE_SIGMA = 0.01
SONAR_NOISE_SIGMA = 0.02
OFFSET_TOLERANCE = 1e-3  # m and rad: a ROBOTLASER laser offset within this counts as constant
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


@dataclass(frozen=True)
class CarmenImport:
    """The imported log and what was left out: ``skipped`` lines per message name, scans ``outside``
    the time span of the pose messages (dropped), and ``notes`` on choices made."""

    log: Log
    message: str
    pose_source: str
    skipped: dict[str, int] = field(default_factory=dict)
    outside: int = 0
    notes: tuple[str, ...] = ()


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
        n = f.count(1, "num_readings")
        f.exact_length(
            2 + n + 6 + _TRAILER, f"num_readings, {n} readings, x y theta odom_x odom_y odom_theta, 3 trailer fields"
        )
        ranges = f.numbers(2, 2 + n, "range reading")
        pose = f.numbers(2 + n, 2 + n + 3, "x y theta")
        res = options.angular_res if options.angular_res is not None else guess_angular_res(n)
        return CarmenScan(name, line_no, f.time(), ranges, laser_beams(n, options.start_angle, res), pose=pose)
    if name.startswith("RAWLASER") or name.startswith("ROBOTLASER"):
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
            line_no,
            f.time(),
            ranges,
            laser_beams(n, start, res),
            pose=pose,
            laser_pose=laser_pose,
            max_range=max_range,
        )
    if name == "SONAR":
        cone = f.number(1, "cone_angle")
        n = f.count(2, "num_sonars")
        f.exact_length(
            3 + 4 * n + _TRAILER, f"cone_angle, num_sonars, {n} readings, {n} x y theta offsets, 3 trailer fields"
        )
        ranges = f.numbers(3, 3 + n, "range reading")
        beams = f.numbers(3 + n, 3 + 4 * n, "sonar offset x y theta").reshape(n, 3)
        return CarmenScan(name, line_no, f.time(), ranges, beams, cone_angle=cone)
    raise f.error(f"not a scan message; expected one of {', '.join(SCAN_MESSAGES)}")


def parse_pose_line(line: str, line_no: int) -> tuple[float, np.ndarray]:
    """(ipc_timestamp, (x, y, theta)) of an ODOM or TRUEPOS line (TRUEPOS: the true pose)."""
    f = _Fields(line.split(), line_no)
    if f.name not in POSE_MESSAGES:
        raise f.error(f"not a pose message; expected one of {', '.join(POSE_MESSAGES)}")
    layout = "x y theta tv rv accel" if f.name == "ODOM" else "true_x true_y true_theta odom_x odom_y odom_theta"
    f.exact_length(1 + 6 + _TRAILER, f"{layout}, 3 trailer fields")
    return f.time(), f.numbers(1, 4, "x y theta")


def _same_geometry(a: CarmenScan, b: CarmenScan) -> bool:
    if not np.allclose(a.beams, b.beams, rtol=0.0, atol=1e-6):
        return False
    return a.cone_angle == b.cone_angle or np.isclose(a.cone_angle, b.cone_angle, rtol=0.0, atol=1e-6)


def _check_consistent(first: CarmenScan, scan: CarmenScan, picked: bool) -> None:
    """One log holds one message type and one beam geometry: error naming the line otherwise."""
    if scan.message != first.message:
        raise InputError(
            f"line {scan.line}: a {scan.message} scan, but the log's scans so far are {first.message} "
            f"(first at line {first.line}); choose one message type with --message",
            key=scan.message,
        )
    hint = "" if picked else "; choose another message type with --message"
    if scan.count != first.count:
        raise InputError(
            f"line {scan.line}: {scan.count} readings, but the first {first.message} scan (line {first.line}) "
            f"has {first.count}; a log holds scans of one beam count{hint}",
            key=scan.message,
        )
    if not _same_geometry(first, scan):
        what = "sonar offsets or cone angle" if scan.message == "SONAR" else "start angle or angular resolution"
        raise InputError(
            f"line {scan.line}: the {what} differ from the first {first.message} scan (line {first.line}); "
            f"a log holds one sensor geometry{hint}",
            key=scan.message,
        )


def _laser_offsets(scans: list[CarmenScan]) -> np.ndarray:
    """(T, 3) each ROBOTLASER laser pose in its robot pose's frame."""
    laser = np.array([s.laser_pose for s in scans])
    robot = np.array([s.pose for s in scans])
    d = laser[:, :2] - robot[:, :2]
    c, s = np.cos(robot[:, 2]), np.sin(robot[:, 2])
    return np.column_stack(
        [c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1], wrap_angle(laser[:, 2] - robot[:, 2])]
    )


def _compose(offset: np.ndarray, beams: np.ndarray) -> np.ndarray:
    """Beams (n, 3) in a sensor frame at ``offset`` (x, y, yaw) in the robot frame -> robot frame."""
    ox, oy, oyaw = (float(v) for v in offset)
    c, s = math.cos(oyaw), math.sin(oyaw)
    out = np.empty_like(beams, dtype=np.float64)
    out[:, 0] = ox + c * beams[:, 0] - s * beams[:, 1]
    out[:, 1] = oy + s * beams[:, 0] + c * beams[:, 1]
    out[:, 2] = wrap_angle(oyaw + beams[:, 2])
    return out


def parse_carmen(
    lines: Iterable[str], options: CarmenOptions = CarmenOptions(), source: str = "aogm import carmen"
) -> CarmenImport:
    """Turn the lines of a CARMEN log into a ``Log`` (errors name the line but not the file).

    Scan lines of the chosen type are parsed as they come; ODOM/TRUEPOS lines are parsed only
    when poses come from them. Comment (#) and blank lines are ignored; every other line that is
    not used is counted in ``skipped`` by its message name.
    """
    if options.message is not None and options.message not in SCAN_MESSAGES:
        raise InputError(f"expected one of {', '.join(SCAN_MESSAGES)}, got {options.message!r}", key="message")
    if options.pose_from not in POSE_SOURCES:
        raise InputError(f"expected one of {', '.join(POSE_SOURCES)}, got {options.pose_from!r}", key="pose_from")
    picked = options.message is not None
    scans: list[CarmenScan] = []
    pose_lines: dict[str, list[tuple[int, str]]] = {name: [] for name in POSE_MESSAGES}
    skipped: Counter[str] = Counter()
    for n, line in enumerate(lines, start=1):
        head = line.lstrip()
        if not head or head.startswith("#"):
            continue
        name = head.split(None, 1)[0]
        if name in SCAN_MESSAGES and (not picked or name == options.message):
            scan = parse_scan_line(head, n, options)
            if scans:
                _check_consistent(scans[0], scan, picked)
            scans.append(scan)
        elif name in pose_lines:
            pose_lines[name].append((n, head))
        else:
            skipped[name] += 1
    if not scans:
        wanted = options.message or " or ".join(SCAN_MESSAGES)
        raise InputError(f"no {wanted} lines: nothing to import", key=options.message)

    first = scans[0]
    message = first.message
    if first.count == 0:
        raise InputError(f"line {first.line}: a scan without readings; nothing to import", key=message)
    source_kind = _pose_source(options.pose_from, message, pose_lines)
    for name, entries in pose_lines.items():
        if name.lower() != source_kind and entries:
            skipped[name] += len(entries)

    notes: list[str] = []
    time = np.array([s.time for s in scans])
    offset = np.zeros(3)
    if message in ("FLASER", "RLASER") or message.startswith("RAWLASER"):
        if options.mount is not None:
            offset = np.asarray(options.mount, dtype=np.float64)
    elif options.mount is not None:
        raise InputError(
            f"{message} lines carry their own sensor mounts; mount applies to FLASER, RLASER and RAWLASER", key="mount"
        )

    line_pose = None
    if message.startswith("ROBOTLASER"):
        offsets = _laser_offsets(scans)
        spread = np.abs(offsets - offsets[0])
        spread[:, 2] = np.abs(wrap_angle(offsets[:, 2] - offsets[0, 2]))
        if float(spread.max(initial=0.0)) <= OFFSET_TOLERANCE:
            offset = offsets[0]
            line_pose = np.array([s.pose for s in scans])
        elif source_kind == "line":
            line_pose = np.array([s.laser_pose for s in scans])
            notes.append(
                "the laser offset from the robot pose varies between lines: stored the laser pose as the robot pose, mount at 0"
            )
        else:
            raise InputError(
                f"the laser offset from the robot pose varies between lines (by up to {float(spread.max()):.3g}); "
                "poses interpolated from ODOM/TRUEPOS need a constant offset: import with --pose-from line",
                key=message,
            )
    elif message in CARRIES_POSE:
        line_pose = np.array([s.pose for s in scans])

    if source_kind == "line":
        pose = line_pose
        keep = np.ones(len(scans), dtype=bool)
    else:
        name = source_kind.upper()
        parsed = [parse_pose_line(text, n) for n, text in pose_lines[name]]
        src_time = np.array([t for t, _ in parsed])
        src_pose = np.array([p for _, p in parsed]).reshape(-1, 3)
        pose, keep = interpolate_poses(src_time, src_pose, time)
        if not keep.any():
            span = f"[{src_time.min():.6g}, {src_time.max():.6g}] s"
            raise InputError(f"no {message} scan lies within the time span of the {name} lines {span}", key=name)
    outside = int((~keep).sum())
    if outside:
        notes.append(f"dropped {outside} scans outside the time span of the {source_kind.upper()} lines")

    kept = [s for s, k in zip(scans, keep, strict=True) if k]
    ranges = np.array([s.ranges for s in kept])
    sonar = message == "SONAR"
    default_max = SONAR_MAX_RANGE if sonar else LASER_MAX_RANGE
    if options.max_range is not None:
        row_max: float | np.ndarray = float(options.max_range)
        max_range = float(options.max_range)
    else:
        row_max = np.array([s.max_range if s.max_range and s.max_range > 0 else default_max for s in kept])
        max_range = float(row_max.max())
    if sonar:
        cone = first.cone_angle if first.cone_angle and first.cone_angle > 0 else SONAR_BEAM_WIDTH
        beam_width = options.beam_width if options.beam_width is not None else cone
    else:
        beam_width = options.beam_width if options.beam_width is not None else LASER_BEAM_WIDTH
    sensor = SensorSpec(
        mount=_compose(offset, first.beams),
        kind="sonar" if sonar else "laser",
        beam_width=float(beam_width),
        min_range=float(
            options.min_range if options.min_range is not None else (SONAR_MIN_RANGE if sonar else LASER_MIN_RANGE)
        ),
        max_range=max_range,
        noise_sigma=float(
            options.noise_sigma
            if options.noise_sigma is not None
            else (SONAR_NOISE_SIGMA if sonar else LASER_NOISE_SIGMA)
        ),
    )
    log = Log(
        time=time[keep],
        pose=np.column_stack([pose[keep, :2], wrap_angle(pose[keep, 2])]),
        ranges=clean_ranges(ranges, row_max),
        sensor=sensor,
        source=source,
    )
    return CarmenImport(log, message, source_kind, dict(sorted(skipped.items())), outside, tuple(notes))


def _pose_source(pose_from: str, message: str, pose_lines: dict[str, list]) -> str:
    """Resolve "auto" and check that the chosen source exists: "line", "odom" or "truepos"."""
    if pose_from == "auto":
        if message in CARRIES_POSE:
            return "line"
        pose_from = "truepos" if pose_lines["TRUEPOS"] else "odom"
    if pose_from == "line" and message not in CARRIES_POSE:
        raise InputError(f"{message} lines carry no pose; take poses from odom or truepos", key="pose_from")
    if pose_from != "line" and not pose_lines[pose_from.upper()]:
        raise InputError(f"no {pose_from.upper()} lines to take {message} poses from", key=pose_from.upper())
    return pose_from


def import_carmen(
    path: str | Path, options: CarmenOptions = CarmenOptions(), progress: Progress | None = None
) -> CarmenImport:
    """Read the CARMEN log at ``path`` (plain or gzipped) into a ``Log``; errors name the file.

    The log's ``source`` reads ``aogm import carmen <file name>``.
    """
    source = f"aogm import carmen {Path(path).name}"
    try:
        return parse_carmen(read_lines(path, progress), options, source=source)
    except InputError as exc:
        raise exc.in_file(str(path)) from None
