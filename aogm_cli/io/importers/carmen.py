"""CARMEN text logs -> an aogm log: scans of FLASER, RLASER, RAWLASER1-4, ROBOTLASER1-2 or SONAR.

``parse_carmen`` assembles the lines that ``importers.carmen_lines`` parses into a ``Log``: which
lines it uses, where the poses come from, the sensor's mounts and its beam; ``import_carmen``
only opens the (optionally gzipped) file. The line parsers are importable from here too.
"""

from __future__ import annotations

import dataclasses
import math
from collections import Counter
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from aogm_cli.core.errors import InputError
from aogm_cli.core.log import Log, SensorSpec
from aogm_cli.io.importers import Progress, clean_ranges, interpolate_poses, read_lines, wrap_angle
from aogm_cli.io.importers.carmen_lines import (
    CARRIES_POSE,
    LASER_MESSAGES,
    POSE_MESSAGES,
    SCAN_MESSAGES,
    CarmenOptions,
    CarmenScan,
    guess_angular_res,
    laser_beams,
    parse_pose_line,
    parse_scan_line,
)

__all__ = [
    "CARRIES_POSE",
    "LASER_MESSAGES",
    "POSE_MESSAGES",
    "POSE_SOURCES",
    "SCAN_MESSAGES",
    "CarmenImport",
    "CarmenOptions",
    "CarmenScan",
    "guess_angular_res",
    "import_carmen",
    "laser_beams",
    "parse_carmen",
    "parse_pose_line",
    "parse_scan_line",
]

POSE_SOURCES = ("auto", "line", "odom", "truepos")

# the defaults of each sensor kind when neither the options nor the line say; SONAR's are SensorSpec's
LASER_MAX_RANGE = 80.0  # m; CARMEN's own reader assumes this for FLASER/RLASER
SONAR_MAX_RANGE = SensorSpec.max_range
LASER_BEAM_WIDTH = math.radians(0.5)
SONAR_BEAM_WIDTH = SensorSpec.beam_width  # when a SONAR line's cone_angle is not positive
LASER_MIN_RANGE = 0.0
SONAR_MIN_RANGE = SensorSpec.min_range
LASER_NOISE_SIGMA = 0.01
SONAR_NOISE_SIGMA = SensorSpec.noise_sigma
OFFSET_TOLERANCE = 1e-3  # m and rad: a ROBOTLASER laser offset within this counts as constant
_DEFAULT_OPTIONS = CarmenOptions()


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
    first_skipped: tuple[int, str] | None = None  # (line number, message name) of the first skipped line

    def skipped_summary(self) -> str | None:
        """``skipped 3 lines (first: line 17: NEFF, not imported)``, or None when none was skipped."""
        if not self.skipped:
            return None
        n = sum(self.skipped.values())
        line, name = self.first_skipped or (0, "?")
        kinds = ", ".join(f"{k} {v}" for k, v in self.skipped.items())
        return f"skipped {n} line{'s' if n != 1 else ''} (first: line {line}: {name}, not imported; {kinds})"


def parse_carmen(
    lines: Iterable[str], options: CarmenOptions = _DEFAULT_OPTIONS, source: str = "aogm import carmen"
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
    check_options(options)
    scans, pose_lines, skipped, first_line = _sort_lines(lines, options)
    first = scans[0]
    message = first.message
    if first.count == 0:
        raise InputError(f"line {first.line}: a scan without readings; nothing to import", key=message)
    source_kind = _pose_source(options.pose_from, message, pose_lines)
    for name, entries in pose_lines.items():
        if name.lower() != source_kind and entries:
            skipped[name] += len(entries)
            first_line.setdefault(name, entries[0][0])

    time = np.array([s.time for s in scans])
    offset, line_pose, notes = _sensor_frame(scans, source_kind, options)
    pose, keep = _scan_poses(message, source_kind, pose_lines, line_pose, time)
    _check_finite(scans, time, pose, message)
    outside = int((~keep).sum())
    if outside:
        notes.append(f"dropped {outside} scans outside the time span of the {source_kind.upper()} lines")

    kept = [s for s, k in zip(scans, keep, strict=True) if k]
    ranges = np.array([s.ranges for s in kept])
    row_max, max_range = _max_ranges(kept, options)
    log = Log(
        time=time[keep],
        pose=np.column_stack([pose[keep, :2], wrap_angle(pose[keep, 2])]),
        ranges=clean_ranges(ranges, row_max),
        sensor=_sensor_spec(first, offset, max_range, options),
        source=source,
    )
    first = min(((n, name) for name, n in first_line.items()), default=None)
    result = CarmenImport(log, message, source_kind, dict(sorted(skipped.items())), outside, tuple(notes), first)
    summary = result.skipped_summary()
    if summary:  # the log says what was left out of it
        log = dataclasses.replace(log, source=f"{source}; {summary}")
        result = dataclasses.replace(result, log=log)
    return result


# -- which lines ----------------------------------------------------------------------------


def check_options(o: CarmenOptions) -> None:
    """Every option given is finite and in range (errors name the option's key)."""
    def bad(key: str, expected: str, value) -> InputError:
        return InputError(f"expected {expected}, got {value}", key=key)

    finite = {"start_angle": o.start_angle, "angular_res": o.angular_res, "max_range": o.max_range,
              "min_range": o.min_range, "beam_width": o.beam_width, "noise_sigma": o.noise_sigma}
    for key, v in finite.items():
        if v is not None and not math.isfinite(v):
            raise bad(key, "a finite number", v)
    for key in ("angular_res", "max_range"):
        if finite[key] is not None and not finite[key] > 0:
            raise bad(key, "a positive number", finite[key])
    for key in ("min_range", "noise_sigma"):
        if finite[key] is not None and finite[key] < 0:
            raise bad(key, "a number >= 0", finite[key])
    if o.beam_width is not None and not 0 < o.beam_width < math.pi:
        raise bad("beam_width", "a beam width between 0 and 180 deg", f"{math.degrees(o.beam_width):g} deg")
    if o.min_range is not None and o.max_range is not None and not o.min_range < o.max_range:
        raise bad("min_range", f"min_range < max_range ({o.max_range:g})", o.min_range)
    if o.mount is not None and not (len(o.mount) == 3 and all(math.isfinite(v) for v in o.mount)):
        raise bad("mount", "three finite numbers (x, y, yaw)", list(o.mount))


def _check_finite(scans: list[CarmenScan], time: np.ndarray, pose: np.ndarray, message: str) -> None:
    """A scan's time and pose must be finite numbers (its ranges may be NaN: invalid readings)."""
    bad = ~(np.isfinite(time) & np.isfinite(pose).all(axis=1))
    if bad.any():
        i = int(np.argmax(bad))
        what = "timestamp" if not np.isfinite(time[i]) else "pose"
        raise InputError(f"line {scans[i].line}: expected a finite {what}, got {time[i] if what == 'timestamp' else [float(v) for v in pose[i]]}"
                         f" ({int(bad.sum())} such scans)", key=message)


def _sort_lines(
    lines: Iterable[str], options: CarmenOptions
) -> tuple[list[CarmenScan], dict[str, list[tuple[int, str]]], Counter[str], dict[str, int]]:
    """The parsed scans of the chosen type, the (line number, text) of each pose message kind,
    the count of every other line by message name and the first line of each; an error when no
    scan is left."""
    picked = options.message is not None
    scans: list[CarmenScan] = []
    pose_lines: dict[str, list[tuple[int, str]]] = {name: [] for name in POSE_MESSAGES}
    skipped: Counter[str] = Counter()
    first_line: dict[str, int] = {}
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
            first_line.setdefault(name, n)
    if not scans:
        wanted = options.message or " or ".join(SCAN_MESSAGES)
        raise InputError(f"no {wanted} lines: nothing to import", key=options.message)
    return scans, pose_lines, skipped, first_line


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


# -- where the poses come from ------------------------------------------------------------


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


def _sensor_frame(
    scans: list[CarmenScan], source_kind: str, options: CarmenOptions
) -> tuple[np.ndarray, np.ndarray | None, list[str]]:
    """(the sensor's (x, y, yaw) in the robot frame, the (T, 3) robot poses the lines carry or
    None, notes): ``options.mount`` for FLASER, RLASER and RAWLASER, the laser offset of ROBOTLASER."""
    message = scans[0].message
    offset = np.zeros(3)
    if message in ("FLASER", "RLASER") or message.startswith("RAWLASER"):
        if options.mount is not None:
            offset = np.asarray(options.mount, dtype=np.float64)
    elif options.mount is not None:
        raise InputError(
            f"{message} lines carry their own sensor mounts; mount applies to FLASER, RLASER and RAWLASER", key="mount"
        )
    if message.startswith("ROBOTLASER"):
        return _robotlaser_frame(scans, source_kind, offset)
    line_pose = np.array([s.pose for s in scans]) if message in CARRIES_POSE else None
    return offset, line_pose, []


def _robotlaser_frame(
    scans: list[CarmenScan], source_kind: str, offset: np.ndarray
) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """A constant laser offset becomes the mount under the robot poses; a varying one is kept only
    with poses from the lines, storing the laser pose as the robot pose (mount ``offset``)."""
    offsets = _laser_offsets(scans)
    spread = np.abs(offsets - offsets[0])
    spread[:, 2] = np.abs(wrap_angle(offsets[:, 2] - offsets[0, 2]))
    if float(spread.max(initial=0.0)) <= OFFSET_TOLERANCE:
        return offsets[0], np.array([s.pose for s in scans]), []
    if source_kind == "line":
        note = "the laser offset from the robot pose varies between lines: stored the laser pose as the robot pose, mount at 0"
        return offset, np.array([s.laser_pose for s in scans]), [note]
    raise InputError(
        f"the laser offset from the robot pose varies between lines (by up to {float(spread.max()):.3g}); "
        "poses interpolated from ODOM/TRUEPOS need a constant offset: import with --pose-from line",
        key=scans[0].message,
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


def _scan_poses(
    message: str,
    source_kind: str,
    pose_lines: dict[str, list[tuple[int, str]]],
    line_pose: np.ndarray | None,
    time: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """(poses (T, 3), kept (T,)): the lines' own poses, or ODOM/TRUEPOS interpolated at the scan
    times, dropping scans outside their time span (an error when none is left)."""
    if source_kind == "line":
        return line_pose, np.ones(len(time), dtype=bool)
    name = source_kind.upper()
    parsed = [parse_pose_line(text, n) for n, text in pose_lines[name]]
    src_time = np.array([t for t, _ in parsed])
    src_pose = np.array([p for _, p in parsed]).reshape(-1, 3)
    pose, keep = interpolate_poses(src_time, src_pose, time)
    if not keep.any():
        span = f"[{src_time.min():.6g}, {src_time.max():.6g}] s"
        raise InputError(f"no {message} scan lies within the time span of the {name} lines {span}", key=name)
    return pose, keep


# -- the sensor -----------------------------------------------------------------------------


def _max_ranges(kept: list[CarmenScan], options: CarmenOptions) -> tuple[float | np.ndarray, float]:
    """(the max range of each kept scan or one for all, the sensor's max range): the option, else
    each line's own (RAWLASER, ROBOTLASER), else the default of the sensor kind."""
    default_max = SONAR_MAX_RANGE if kept[0].message == "SONAR" else LASER_MAX_RANGE
    if options.max_range is not None:
        return float(options.max_range), float(options.max_range)
    row_max = np.array([s.max_range if s.max_range and s.max_range > 0 else default_max for s in kept])
    return row_max, float(row_max.max())


def _sensor_spec(first: CarmenScan, offset: np.ndarray, max_range: float, options: CarmenOptions) -> SensorSpec:
    """The sensor: the first scan's beams at ``offset``, and each property from the options, else
    the line (a SONAR line's positive cone angle), else the default of the sensor kind."""
    sonar = first.message == "SONAR"
    if sonar:
        cone = first.cone_angle if first.cone_angle and first.cone_angle > 0 else SONAR_BEAM_WIDTH
        beam_width = options.beam_width if options.beam_width is not None else cone
    else:
        beam_width = options.beam_width if options.beam_width is not None else LASER_BEAM_WIDTH
    return SensorSpec(
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


def _compose(offset: np.ndarray, beams: np.ndarray) -> np.ndarray:
    """Beams (n, 3) in a sensor frame at ``offset`` (x, y, yaw) in the robot frame -> robot frame."""
    ox, oy, oyaw = (float(v) for v in offset)
    c, s = math.cos(oyaw), math.sin(oyaw)
    out = np.empty_like(beams, dtype=np.float64)
    out[:, 0] = ox + c * beams[:, 0] - s * beams[:, 1]
    out[:, 1] = oy + s * beams[:, 0] + c * beams[:, 1]
    out[:, 2] = wrap_angle(oyaw + beams[:, 2])
    return out


def import_carmen(
    path: str | Path, options: CarmenOptions = _DEFAULT_OPTIONS, progress: Progress | None = None
) -> CarmenImport:
    """Read the CARMEN log at ``path`` (plain or gzipped) into a ``Log``; errors name the file.

    The log's ``source`` reads ``aogm import carmen <file name>``.
    """
    source = f"aogm import carmen {Path(path).name}"
    try:
        return parse_carmen(read_lines(path, progress), options, source=source)
    except InputError as exc:
        raise exc.in_file(str(path)) from None
