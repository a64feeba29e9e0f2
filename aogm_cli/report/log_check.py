"""What a log holds before it is mapped (``aogm check``, and the summary at the end of every import):
per-sensor shares and findings, time and pose findings over the scans, and the grid and memory a map
of it would need; each finding over its threshold (``CheckLimits``) is a warning."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

import numpy as np

from aogm_cli.core.budget import DEFAULT_MAX_MEMORY, format_bytes
from aogm_cli.core.log import sensor_names
from aogm_cli.mapping.params import MapParams

# Per sensor: the share of no-echo and invalid readings, a sensor that never gave a valid echo
# (disabled?) or whose readings never change (stuck), readings closer than its minimum range or inside
# the robot (not farther from the sensor than the sensor is from the robot's centre). Over the scans:
# poses that move or turn faster than a robot does between two scans, gaps in time (several median
# periods), time running backwards, poses that are not finite.
INSIDE_TOLERANCE = 1e-3  # m: a reading this little beyond its sensor's distance from the centre is still inside
STUCK_MIN_READINGS = 10  # valid readings before a sensor that never changes is called stuck
MOVED = (0.1, 0.1)  # m, rad: a robot that moved less over the whole log may well read the same


@dataclass(frozen=True)
class CheckLimits:
    """Thresholds of the warnings (the command's options)."""

    max_speed: float = 2.0  # m/s between consecutive scans
    max_turn: float = 3.0  # rad/s between consecutive scans
    gap_factor: float = 5.0  # a time step this many median periods long is a gap
    below_min_share: float = 0.01  # of a sensor's valid readings closer than its min range
    inside_share: float = 0.5  # of a sensor's valid readings inside the robot
    resolution: float = MapParams.resolution  # m per cell of the grid a map would need
    max_memory: float = DEFAULT_MAX_MEMORY  # bytes a standard map may take


@dataclass
class SensorStats:
    """One sensor's readings: counts of each kind, and the range of its valid readings."""

    sensor: int
    readings: int = 0
    no_echo: int = 0
    invalid: int = 0
    valid: int = 0
    below_min_range: int = 0
    inside_robot: int = 0
    lowest: float = math.inf
    highest: float = -math.inf

    @property
    def never_changes(self) -> bool:
        return self.valid >= STUCK_MIN_READINGS and self.lowest == self.highest

    def share(self, count: int, of: int | None = None) -> float:
        total = self.readings if of is None else of
        return count / total if total else 0.0


@dataclass
class LogCheck:
    """What ``check_log`` found; ``warnings`` is a list of {kind, message} (and ``sensors``)."""

    path: str
    scans: int
    sensor_kind: str
    sensors: list[SensorStats]
    time: dict
    poses: dict
    grid: dict
    limits: CheckLimits
    warnings: list[dict] = field(default_factory=list)

    def as_dict(self) -> dict:
        return {
            "format": "aogm-check",
            "log": self.path,
            "scans": self.scans,
            "sensor_kind": self.sensor_kind,
            "sensors": [{**asdict(s), "lowest": _finite_or_none(s.lowest), "highest": _finite_or_none(s.highest),
                         "never_changes": s.never_changes} for s in self.sensors],
            "time": self.time,
            "poses": self.poses,
            "grid": self.grid,
            "limits": asdict(self.limits),
            "warnings": self.warnings,
        }

    def lines(self, all_sensors: bool = False) -> list[str]:
        """The report as text lines: a table of the sensors (of more than 32, only those with a
        finding, unless ``all_sensors``), the scans' times and poses, the grid, the warnings."""
        kinds = f"{len(self.sensors)} {self.sensor_kind} sensors"
        out = [f"{self.path or 'log'}: {self.scans} scans x {kinds}"]
        shown = self.sensors if self.scans else []
        if len(shown) > 32 and not all_sensors:
            flagged = {i for w in self.warnings for i in w.get("sensors", [])}
            shown = [s for s in self.sensors if s.sensor in flagged][:32]
        if shown:
            out.append(f"  {'sensor':>6} {'readings':>8} {'no echo':>8} {'invalid':>8} {'< min':>6} {'inside':>6}  "
                       f"{'valid range (m)':<16} note")
            for s in shown:
                span = f"{s.lowest:.3f}-{s.highest:.3f}" if s.valid else "-"
                note = "never changes" if s.never_changes else ("no valid echo" if s.readings and not s.valid else "")
                out.append(f"  {s.sensor:>6} {s.readings:>8} {s.share(s.no_echo):>8.1%} {s.share(s.invalid):>8.1%} "
                           f"{s.below_min_range:>6} {s.inside_robot:>6}  {span:<16} {note}".rstrip())
        if 0 < len(shown) < len(self.sensors) or (self.scans and not shown):
            out.append(f"  ({len(self.sensors) - len(shown)} more sensors without a finding; --json lists all)")
        t, p, g = self.time, self.poses, self.grid
        if self.scans > 1:
            out.append(f"  time: {t['first']:.3f} to {t['last']:.3f} s, median period {t['median_period']:.3g} s; "
                       f"{t['gaps']} gaps (> {self.limits.gap_factor:g} periods; longest step {t['longest_step']:.3g} s),"
                       f" {t['backwards']} steps backwards")
            out.append(f"  poses: fastest {p['fastest_speed']:.3g} m/s and {p['fastest_turn']:.3g} rad/s between scans;"
                       f" {p['jumps']} steps over {self.limits.max_speed:g} m/s, {p['turns']} over "
                       f"{self.limits.max_turn:g} rad/s; {p['not_finite']} not finite")
        if g:
            out.append(f"  grid: {g['height']:.0f} x {g['width']:.0f} cells at {g['resolution']:g} m ({g['what']}), "
                       f"a standard map needs about {format_bytes(g['memory'])}")
        out.append(f"  warnings: {len(self.warnings) or 'none'}")
        out.extend(f"  warning: {w['message']}" for w in self.warnings)
        return out


def _finite_or_none(v: float) -> float | None:
    return float(v) if math.isfinite(v) else None


def check_log(source, limits: CheckLimits = CheckLimits(), name: str | None = None) -> LogCheck:
    """Check a log source (an open ``io.logfile.LogReader`` or a ``core.log.Log``), reading its
    ranges chunk by chunk; ``name``: what the report calls it (default: its path)."""
    sensor = source.sensor
    distance = np.hypot(sensor.mount[:, 0], sensor.mount[:, 1])
    stats = [SensorStats(i) for i in range(sensor.count)]
    times = []
    for _start, time, _pose, ranges in source.chunks():
        times.append(np.asarray(time, dtype=np.float64))
        _count(stats, np.asarray(ranges, dtype=np.float64), sensor.min_range, distance)
    time = np.concatenate(times) if times else np.zeros(0)
    pose = np.asarray(source.poses(), dtype=np.float64).reshape(-1, 3)
    result = LogCheck(name or getattr(source, "path", "") or "", int(time.size), sensor.kind, stats,
                      _time(time, limits), _poses(time, pose, limits), grid_need(source, limits.resolution, pose),
                      limits)
    result.warnings = _warnings(result, pose)
    return result


def _count(stats: list[SensorStats], r: np.ndarray, min_range: float, distance: np.ndarray) -> None:
    finite = np.isfinite(r)
    with np.errstate(invalid="ignore"):
        below = finite & (r < min_range)
        inside = finite & (r <= distance[None, :] + INSIDE_TOLERANCE)
    lowest = np.where(finite, r, np.inf).min(axis=0, initial=np.inf)
    highest = np.where(finite, r, -np.inf).max(axis=0, initial=-np.inf)
    counts = zip(np.isposinf(r).sum(axis=0), np.isnan(r).sum(axis=0), finite.sum(axis=0), below.sum(axis=0),
                 inside.sum(axis=0), lowest, highest, strict=True)
    for s, (no_echo, invalid, valid, b, i, lo, hi) in zip(stats, counts, strict=True):
        s.readings += r.shape[0]
        s.no_echo += int(no_echo)
        s.invalid += int(invalid)
        s.valid += int(valid)
        s.below_min_range += int(b)
        s.inside_robot += int(i)
        s.lowest, s.highest = min(s.lowest, float(lo)), max(s.highest, float(hi))


def _steps(time: np.ndarray) -> np.ndarray:
    with np.errstate(invalid="ignore"):
        return np.diff(time)


def _first(found: np.ndarray) -> int | None:
    """The first index found, None for none."""
    return int(found[0]) if found.size else None


def _largest(values: np.ndarray) -> float:
    """The largest finite value, 0 for none (a step in no time is infinitely fast: counted, not shown)."""
    finite = values[np.isfinite(values)]
    return float(finite.max()) if finite.size else 0.0


def _time(time: np.ndarray, limits: CheckLimits) -> dict:
    dt = _steps(time)
    forward = dt[dt > 0]
    median = float(np.median(forward)) if forward.size else 0.0
    gaps = np.flatnonzero(dt > limits.gap_factor * median) if median > 0 else np.zeros(0, dtype=np.int64)
    backwards = np.flatnonzero(dt < 0)
    return {
        "first": float(time[0]) if time.size else 0.0,
        "last": float(time[-1]) if time.size else 0.0,
        "median_period": median,
        "longest_step": _largest(dt),
        "gaps": int(gaps.size),
        "first_gap": _first(gaps),
        "backwards": int(backwards.size),
        "first_backwards": _first(backwards),
        "not_finite": int((~np.isfinite(time)).sum()),
    }


def _poses(time: np.ndarray, pose: np.ndarray, limits: CheckLimits) -> dict:
    """The fastest motion between consecutive scans; steps in no time that move count as infinitely fast."""
    dt = _steps(time)
    with np.errstate(invalid="ignore", divide="ignore"):
        step = np.hypot(*np.diff(pose[:, :2], axis=0).T) if pose.shape[0] > 1 else np.zeros(0)
        turn = np.abs((np.diff(pose[:, 2]) + math.pi) % (2 * math.pi) - math.pi)
        forward = dt >= 0  # backwards steps are time's finding, not the poses'
        speed = np.where(forward & (step > 0), step / np.where(dt > 0, dt, 0.0), 0.0)
        rate = np.where(forward & (turn > 0), turn / np.where(dt > 0, dt, 0.0), 0.0)
        jumps = np.flatnonzero(speed > limits.max_speed)
        turns = np.flatnonzero(rate > limits.max_turn)
    return {
        "fastest_speed": _largest(speed),
        "fastest_turn": _largest(rate),
        "jumps": int(jumps.size),
        "first_jump": _first(jumps),
        "turns": int(turns.size),
        "first_turn": _first(turns),
        "not_finite": int((~np.isfinite(pose).all(axis=1)).sum()),
    }


def grid_need(source, resolution: float, pose: np.ndarray | None = None) -> dict:
    """The grid a map of the log source would use (the truth grid of a simulated log, else the poses'
    bounds plus the sensor's reach at ``resolution``, as ``mapping.pipeline.log_grid``, in floats
    so that no absurd log overflows) and about how much memory a standard map of it needs (at
    least ``BYTES_PER_CELL`` a cell); {} without a finite pose."""
    from aogm_cli.mapping.map_cost import BYTES_PER_CELL, map_estimate

    pose = np.asarray(source.poses(), dtype=np.float64).reshape(-1, 3) if pose is None else pose
    truth = source.truth_grid()
    if truth is not None:
        height, width, res, what = float(truth.height), float(truth.width), truth.resolution, "the truth grid"
    else:
        finite = np.isfinite(pose).all(axis=1)
        if not finite.any():
            return {}
        sensor = source.sensor
        reach = sensor.max_range + float(np.hypot(sensor.mount[:, 0], sensor.mount[:, 1]).max())
        res, what = resolution, "the poses plus the sensor's reach"
        with np.errstate(over="ignore", invalid="ignore"):  # in floats: an absurd log's grid overflows no integer
            lo = np.floor((pose[finite, :2].min(axis=0) - reach) / res) * res
            cells = np.ceil((pose[finite, :2].max(axis=0) + reach - lo) / res - 1e-9)
        width, height = (max(1.0, float(v)) for v in cells)
    memory = height * width * BYTES_PER_CELL
    if height * width < 1e11 and math.isfinite(memory):
        memory = map_estimate(source, "standard", MapParams(resolution=res)).memory
    return {"height": height, "width": width, "resolution": float(res), "what": what, "cells": height * width,
            "memory": memory}


def _warnings(c: LogCheck, pose: np.ndarray) -> list[dict]:
    out: list[dict] = []
    lim = c.limits

    def warn(kind: str, message: str, sensors=None):
        entry = {"kind": kind, "message": message}
        if sensors is not None:
            entry["sensors"] = [int(s) for s in sensors]
        out.append(entry)

    if c.scans == 0:
        warn("no_scans", "the log has no scans")
        return out
    moved = pose.shape[0] > 1 and np.isfinite(pose).all() and (
        np.ptp(pose[:, 0]) > MOVED[0] or np.ptp(pose[:, 1]) > MOVED[0] or np.ptp(np.unwrap(pose[:, 2])) > MOVED[1])
    for kind, test, text in (
        ("disabled", lambda s: s.valid == 0, lambda s: f"no valid echo in {c.scans} scans: disabled?"),
        ("stuck", lambda s: s.never_changes and moved,
         lambda s: f"every valid reading is {s.lowest:.4g} m while the robot moves: stuck or disabled?"),
        ("below_min_range", lambda s: s.share(s.below_min_range, s.valid) > lim.below_min_share,
         lambda s: f"{s.share(s.below_min_range, s.valid):.0%} of the valid readings closer than the min range "
                   f"({s.below_min_range})"),
        ("inside_robot", lambda s: s.share(s.inside_robot, s.valid) > lim.inside_share,
         lambda s: f"{s.share(s.inside_robot, s.valid):.0%} of the valid readings inside the robot (no farther than "
                   f"the sensor is from its centre; {s.inside_robot})"),
    ):
        _sensor_warnings(c.sensors, kind, test, text, warn)
    t, p = c.time, c.poses
    if t["backwards"]:
        warn("time_backwards", f"time runs backwards {_times(t['backwards'])} (first from scan {t['first_backwards']} "
                               f"to {t['first_backwards'] + 1})")
    if t["gaps"]:
        warn("time_gap", f"{t['gaps']} gaps in time over {lim.gap_factor:g} x the median period "
                         f"{t['median_period']:.3g} s (first after scan {t['first_gap']}; longest step "
                         f"{t['longest_step']:.3g} s)")
    if t["not_finite"]:
        warn("time_not_finite", f"{t['not_finite']} scan times are not finite")
    if p["jumps"]:
        warn("pose_jump", f"the pose jumps faster than {lim.max_speed:g} m/s {_times(p['jumps'])} (first from scan "
                          f"{p['first_jump']} to {p['first_jump'] + 1}; fastest {p['fastest_speed']:.3g} m/s)")
    if p["turns"]:
        warn("turn_jump", f"the heading turns faster than {lim.max_turn:g} rad/s {_times(p['turns'])} (first from "
                          f"scan {p['first_turn']} to {p['first_turn'] + 1}; fastest {p['fastest_turn']:.3g} rad/s)")
    if p["not_finite"]:
        warn("pose_not_finite", f"{p['not_finite']} poses are not finite")
    g = c.grid
    if g and not g["memory"] <= lim.max_memory:
        warn("grid_memory", f"a standard map would need {g['height']:.3g} x {g['width']:.3g} cells at "
                            f"{g['resolution']:g} m, about {format_bytes(g['memory'])} (over "
                            f"{format_bytes(lim.max_memory)}): poses or max range in the wrong unit, or map at a "
                            "coarser resolution")
    return out


def _times(n: int) -> str:
    return "once" if n == 1 else f"{n} times"


def _sensor_warnings(sensors: list[SensorStats], kind: str, test, text, warn) -> None:
    """One warning per run of sensors with the same finding and message ("sensors 8-15: ...")."""
    groups: dict[str, list[int]] = {}
    for s in sensors:
        if s.readings and test(s):
            groups.setdefault(text(s), []).append(s.sensor)
    for message, members in groups.items():
        warn(kind, f"{sensor_names(members)}: {message}", members)
