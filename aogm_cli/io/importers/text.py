"""Plain-text range logs (whitespace or CSV columns) -> an aogm log, e.g. a course or lab sonar log.

One row per scan; chosen columns hold the readings, the pose (x, y, yaw) and optionally the time,
in the units the user names. Parsing is pure functions on text lines (``table.parse_table``,
``build_text_log``); ``import_text`` only opens the files.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from aogm_cli.core.errors import InputError
from aogm_cli.core.log import Log, SensorSpec
from aogm_cli.io.importers import Progress, clean_ranges, interpolate_poses, wrap_angle
from aogm_cli.io.importers.mounts import load_mounts
from aogm_cli.io.importers.table import ANGLE_UNITS, LENGTH_UNITS, TIME_UNITS, Table, read_table, unit_scale


@dataclass(frozen=True)
class TextOptions:
    """How to read the columns. Column specs are 1-based numbers, ranges "4-19" / "4-", or header
    names, comma-separated. ``range_columns`` None = every column not used for the pose or time.

    ``bearings``: "ring" (as many sensors as range columns, evenly spaced from 0), "ring:N[:START[:STEP]]"
    or a comma-separated list, in ``bearing_unit``; each sensor sits at ``sensor_radius`` (m) along its
    bearing. ``no_echo``: reading values (in the file's unit) that mean no echo. Readings >= ``max_range``
    (m) become +inf, negative ones NaN. Without time columns, scan k is at time k * ``period``.
    The beam's defaults are ``SensorSpec``'s (a sonar's).
    """

    range_columns: str | None = None
    pose_columns: str = "1,2,3"
    range_time_column: str | None = None
    pose_time_column: str | None = None
    range_unit: str = "m"
    position_unit: str = "m"
    angle_unit: str = "rad"
    time_unit: str = "s"
    bearing_unit: str = "deg"
    no_echo: tuple[float, ...] = ()
    bearings: str = "ring"
    sensor_radius: float = 0.0
    kind: str = "sonar"
    beam_width: float = SensorSpec.beam_width
    min_range: float = SensorSpec.min_range
    max_range: float = SensorSpec.max_range
    noise_sigma: float = SensorSpec.noise_sigma
    period: float = 1.0
    delimiter: str = "auto"


@dataclass(frozen=True)
class TextImport:
    """The imported log; ``outside`` scans fell outside the poses' time span and were dropped."""

    log: Log
    outside: int = 0
    notes: tuple[str, ...] = ()


def resolve_columns(spec: str, table: Table, key: str) -> list[int]:
    """0-based column indices of a spec such as "3", "4-19", "4-", "x,y,theta" (header names)."""
    names = {name: i for i, name in enumerate(table.header or ()) if name}
    out: list[int] = []
    for item in (s.strip() for s in spec.split(",")):
        if not item:
            raise InputError(f"empty item in column list {spec!r}", file=table.file, key=key)
        if item in names:
            out.append(names[item])
            continue
        lo, dash, hi = item.partition("-")
        try:
            first = int(lo)
            last = (int(hi) if hi else table.width) if dash else first
        except ValueError:
            known = f"; the header names {', '.join(names)}" if names else " (the file has no header row)"
            raise InputError(
                f"expected a column number (1-based), a range such as 4-19, or a header name, got {item!r}{known}",
                file=table.file,
                key=key,
            ) from None
        if not (1 <= first <= last <= table.width):
            raise InputError(f"column {item!r} is outside 1..{table.width}", file=table.file, key=key)
        out.extend(range(first - 1, last))
    return out


def parse_bearings(spec: str, count: int, unit: str = "deg") -> np.ndarray:
    """(count,) sensor bearings (rad) from "ring", "ring:N[:START[:STEP]]" or a list "90,50,30,..."."""
    scale = unit_scale(ANGLE_UNITS, unit, "bearing_unit")
    spec = spec.strip()
    if spec == "ring" or spec.startswith("ring:"):
        parts = spec.split(":")[1:]
        try:
            values = [float(p) for p in parts]
        except ValueError:
            raise InputError(f"expected ring:N[:START[:STEP]] with numbers, got {spec!r}", key="bearings") from None
        if len(values) > 3:
            raise InputError(f"expected ring:N[:START[:STEP]], got {spec!r}", key="bearings")
        n = int(values[0]) if values else count
        if values and (values[0] != n or n < 1):
            raise InputError(f"expected a whole number of sensors >= 1 in {spec!r}", key="bearings")
        start = values[1] * scale if len(values) > 1 else 0.0
        step = values[2] * scale if len(values) > 2 else 2 * math.pi / n
        bearings = start + step * np.arange(n)
    else:
        try:
            bearings = np.array([float(v) for v in spec.split(",")]) * scale
        except ValueError:
            raise InputError(
                f"expected 'ring', 'ring:N[:START[:STEP]]' or a comma-separated list of numbers, got {spec!r}",
                key="bearings",
            ) from None
    if not np.isfinite(bearings).all():
        raise InputError(f"expected finite bearings, got {spec!r}", key="bearings")
    if bearings.size != count:
        raise InputError(
            f"{bearings.size} bearings for {count} range columns; give one bearing per range column", key="bearings"
        )
    return wrap_angle(bearings)


def _one_column(spec: str | None, table: Table, key: str) -> int | None:
    if spec is None:
        return None
    cols = resolve_columns(spec, table, key)
    if len(cols) != 1:
        raise InputError(f"expected one column, got {len(cols)} from {spec!r}", file=table.file, key=key)
    return cols[0]


def build_text_log(
    range_table: Table,
    pose_table: Table | None = None,
    options: TextOptions = TextOptions(),
    mounts: np.ndarray | None = None,
    source: str = "aogm import text",
) -> TextImport:
    """A ``Log`` from a table of readings and a table of poses (None: the poses are columns of
    ``range_table``). Rows pair up one to one, or by time when both tables have a time column.

    ``mounts`` (S, 3): each sensor's x, y (m), yaw (rad) in the robot frame, instead of
    ``options.bearings`` and ``options.sensor_radius``.
    """
    o = options
    length = unit_scale(LENGTH_UNITS, o.range_unit, "range_unit")
    position = unit_scale(LENGTH_UNITS, o.position_unit, "position_unit")
    angle = unit_scale(ANGLE_UNITS, o.angle_unit, "angle_unit")
    time_scale = unit_scale(TIME_UNITS, o.time_unit, "time_unit")
    _check_sensor(o)
    poses_from = range_table if pose_table is None else pose_table
    cols = _columns(range_table, pose_table, o)

    raw = np.column_stack([range_table.column(c, missing_ok=True) for c in cols.ranges])
    ranges = raw * length
    if o.no_echo:
        ranges[np.isin(raw, np.asarray(o.no_echo, dtype=np.float64))] = np.inf
    n = raw.shape[0]
    time = range_table.column(cols.range_time) * time_scale if cols.range_time is not None else o.period * np.arange(n)

    pose_raw = np.column_stack([poses_from.column(c) for c in cols.pose])
    pose = np.column_stack([pose_raw[:, :2] * position, wrap_angle(pose_raw[:, 2] * angle)])
    pose, keep, notes = _pair_poses(range_table, pose_table, cols, pose, time, time_scale)

    sensor = SensorSpec(
        _mounts(mounts, len(cols.ranges), o),
        o.kind,
        float(o.beam_width),
        float(o.min_range),
        float(o.max_range),
        float(o.noise_sigma),
    )
    log = Log(
        time=time[keep], pose=pose[keep], ranges=clean_ranges(ranges[keep], o.max_range), sensor=sensor, source=source
    )
    return TextImport(log, int((~keep).sum()), tuple(notes))


def _check_sensor(o: TextOptions) -> None:
    """The sensor's kind and beam, and the scan period, are ones a log can hold."""
    if o.kind not in ("sonar", "laser"):
        raise InputError(f"expected sonar or laser, got {o.kind!r}", key="kind")
    for key in ("beam_width", "max_range", "period"):
        v = getattr(o, key)
        if not (math.isfinite(v) and v > 0):
            raise InputError(f"expected a positive number, got {v}", key=key)
    if not (0 <= o.min_range < o.max_range):
        raise InputError(f"expected 0 <= min_range < max_range ({o.max_range}), got {o.min_range}", key="min_range")
    if not o.beam_width < math.pi:
        raise InputError(f"expected a beam width under 180 deg, got {math.degrees(o.beam_width):g} deg", key="beam_width")
    for key in ("noise_sigma", "sensor_radius"):
        v = getattr(o, key)
        if not (math.isfinite(v) and v >= 0):
            raise InputError(f"expected a finite number >= 0, got {v}", key=key)
    bad_echo = [v for v in o.no_echo if not math.isfinite(v)]
    if bad_echo:
        raise InputError(f"expected finite reading values, got {bad_echo[0]}", key="no_echo")


@dataclass(frozen=True)
class Columns:
    """Which columns (0-based) hold what: the readings of ``range_table``, the x, y, yaw of the
    pose table, and each table's time column (None: none)."""

    ranges: list[int]
    pose: list[int]
    range_time: int | None
    pose_time: int | None


def _columns(range_table: Table, pose_table: Table | None, o: TextOptions) -> Columns:
    """Resolve the options' column specs; readings default to every column not used for the pose or time."""
    same = pose_table is None
    poses_from = range_table if same else pose_table
    pose_cols = resolve_columns(o.pose_columns, poses_from, "pose_columns")
    if len(pose_cols) != 3:
        raise InputError(
            f"expected 3 pose columns (x, y, yaw), got {len(pose_cols)} from {o.pose_columns!r}",
            file=poses_from.file,
            key="pose_columns",
        )
    range_time = _one_column(o.range_time_column, range_table, "range_time_column")
    pose_time = _one_column(o.pose_time_column, poses_from, "pose_time_column")
    if same and range_time is None:
        range_time = pose_time
    used = {range_time} | (set(pose_cols) | {pose_time} if same else set())
    if o.range_columns is not None:
        range_cols = resolve_columns(o.range_columns, range_table, "range_columns")
    else:
        range_cols = [c for c in range(range_table.width) if c not in used]
    if not range_cols:
        raise InputError(
            "no range columns left; name them with range_columns", file=range_table.file, key="range_columns"
        )
    clash = sorted(set(range_cols) & used)
    if clash:
        raise InputError(
            f"{range_table.column_name(clash[0])} is both a range column and a pose or time column",
            file=range_table.file,
            key="range_columns",
        )
    return Columns(range_cols, pose_cols, range_time, pose_time)


def _pair_poses(
    range_table: Table,
    pose_table: Table | None,
    cols: Columns,
    pose: np.ndarray,
    time: np.ndarray,
    time_scale: float,
) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """(a pose per scan, kept scans, notes): poses of a separate table with a time column are
    interpolated at the scan times (scans outside their span dropped), others pair up row by row."""
    n = time.shape[0]
    keep = np.ones(n, dtype=bool)
    notes: list[str] = []
    if pose_table is not None and cols.pose_time is not None:
        if cols.range_time is None:
            raise InputError(
                "poses have a time column but readings do not: name range_time_column too",
                file=range_table.file,
                key="range_time_column",
            )
        pose, keep = interpolate_poses(pose_table.column(cols.pose_time) * time_scale, pose, time)
        if not keep.any():
            raise InputError(
                "no scan lies within the time span of the poses", file=pose_table.file, key="pose_time_column"
            )
        if (~keep).any():
            notes.append(f"dropped {int((~keep).sum())} scans outside the time span of the poses")
    elif pose.shape[0] != n:
        raise InputError(
            f"{pose.shape[0]} pose rows for {n} range rows; give as many, or time columns in both files to match by time",
            file=pose_table.file,
            key="poses",
        )
    return pose, keep, notes


def _mounts(mounts: np.ndarray | None, count: int, o: TextOptions) -> np.ndarray:
    """(count, 3) sensor mounts: the given ones, checked, else at ``o.sensor_radius`` along ``o.bearings``."""
    if mounts is not None:
        mount = np.asarray(mounts, dtype=np.float64)
        if mount.shape != (count, 3):
            raise InputError(
                f"expected {count} sensor mounts (one per range column) of x y yaw, got shape {mount.shape}", key="mounts"
            )
        return mount
    bearings = parse_bearings(o.bearings, count, o.bearing_unit)
    return np.column_stack([o.sensor_radius * np.cos(bearings), o.sensor_radius * np.sin(bearings), bearings])


def import_text(
    ranges_path: str | Path,
    poses_path: str | Path | None = None,
    options: TextOptions = TextOptions(),
    mounts_path: str | Path | None = None,
    progress: Progress | None = None,
) -> TextImport:
    """Read readings (and poses, from the same file when ``poses_path`` is None) into a ``Log``;
    ``mounts_path``: a mounts table (``mounts.read_mounts``) or a preset's name (``importers.mounts``).

    The log's ``source`` reads ``aogm import text <ranges file> [<poses file>]``.
    """
    delimiter = options.delimiter
    range_table = read_table(ranges_path, delimiter, progress)
    same = poses_path is None or Path(poses_path) == Path(ranges_path)
    pose_table = None if same else read_table(poses_path, delimiter)
    mounts = None
    if mounts_path:  # a file (in the options' units) or a packaged preset's name
        mounts = load_mounts(str(mounts_path), options.position_unit, options.bearing_unit, delimiter)[0]
    source = f"aogm import text {Path(ranges_path).name}" + ("" if same else f" {Path(poses_path).name}")
    try:
        return build_text_log(range_table, pose_table, options, mounts, source=source)
    except InputError as exc:
        if exc.key == "mounts" and mounts_path:  # the wrong number of rows: name the mounts file (or preset)
            raise exc.in_file(str(mounts_path)) from None
        raise
