"""ROS bags -> an aogm log: ROS 1 ``.bag``, ROS 2 sqlite3 and MCAP, read with ``rosbags`` (no ROS).

Ranges from sensor_msgs/Range topics (one sensor each), a LaserScan, a PointCloud/PointCloud2 of
sonar echo points in the robot frame (RosAria) or a p2os_msgs/SonarArray; poses from tf, an
Odometry or a PoseStamped/PoseWithCovarianceStamped topic (``rosbag_tf`` does the frames);
asynchronous Range readings grouped into scans by the rule of ``group_readings``.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from aogm_cli.core.errors import InputError
from aogm_cli.core.log import Log, SensorSpec, sensor_names
from aogm_cli.io.importers import clean_ranges
from aogm_cli.io.importers.carmen import (
    LASER_BEAM_WIDTH,
    LASER_MIN_RANGE,
    LASER_NOISE_SIGMA,
    SONAR_BEAM_WIDTH,
    SONAR_MAX_RANGE,
    SONAR_MIN_RANGE,
    SONAR_NOISE_SIGMA,
)
from aogm_cli.io.importers.rosbag_messages import (
    LASER_SCAN,
    NOT_ECHO,
    ODOMETRY,
    POINT_CLOUD,
    POINT_CLOUD2,
    POINT_TOLERANCE,
    POSE_TYPES,
    RADIATION,
    RANGE,
    SONAR_ARRAY,
    SONAR_ARRAY_MSG,
    TF_TYPES,
    Readings,
    collect_ranges,
    group_readings,
    natural_order,
    not_echoes,
    pose_of_message,
    resolve_topics,
    ros_name,
)
from aogm_cli.io.importers.rosbag_tf import PoseSeries, TfTree, frame_name, planar_mounts, stamp

PROGRESS_EVERY = 100  # messages read between two calls of the progress callback


@dataclass(frozen=True)
class RosbagOptions:
    """What to import: ``ranges`` topics (names or globs), ``pose`` ("tf:PARENT.CHILD" or a topic),
    the base frame of the mounts, the grouping of asynchronous readings and sensor overrides
    (None: the messages' own values, else the sensor kind's defaults)."""

    ranges: tuple[str, ...]
    pose: str = "tf:map.base_link"
    kind: str | None = None  # sonar or laser; None: laser for LaserScan, sonar for the others
    base_frame: str | None = None  # None: the child of a tf pose, an Odometry's child_frame_id, else base_link
    start: float | None = None  # s from the bag's first message
    end: float | None = None
    window: float = 0.5  # s: the longest firing cycle of a ring of Range topics
    pose_tolerance: tuple[float, float] = (1e-3, math.radians(0.05))  # m, rad: readings sharing a scan
    max_gap: float = 1.0  # s: poses further apart than this do not cover the time between them
    tilt_tolerance: float = math.radians(5.0)
    drop_uncovered: bool = False  # readings the poses do not cover: dropped (counted) instead of an error
    max_range: float | None = None
    min_range: float | None = None
    beam_width: float | None = None
    noise_sigma: float | None = None


@dataclass(frozen=True)
class RosbagImport:
    """The imported log, the topics read (topic -> (type, messages)), skipped messages per reason,
    how many Range readings went into how many scans, and notes on choices made."""

    log: Log
    topics: dict[str, tuple[str, int]]
    pose_source: str
    mount_source: str
    skipped: dict[str, int] = field(default_factory=dict)
    notes: tuple[str, ...] = ()
    not_echoes: dict[str, np.ndarray] = field(default_factory=dict)  # why -> echo points per sensor stored as invalid

    def summary(self) -> list[str]:
        """Lines: the topics read and their message counts (a ring of Range topics on one line),
        the pose and mount sources, skipped messages and why, notes."""
        ring = [t for t, (kind, _) in self.topics.items() if kind == RANGE]
        lines = []
        if len(ring) > 1:
            n = sum(self.topics[t][1] for t in ring)
            lines.append(f"{ring[0]}..{ring[-1]}: {len(ring)} topics, {n} sensor_msgs/Range messages")
        lines += [f"{topic}: {count} {ros_name(kind)} messages"
                  for topic, (kind, count) in self.topics.items() if len(ring) < 2 or topic not in ring]
        lines.append(f"poses from {self.pose_source}; mounts from {self.mount_source}")
        lines.extend(f"skipped {n}: {why}" for why, n in self.skipped.items())
        return lines + list(self.notes)


def check_options(o: RosbagOptions) -> None:
    """Every option is in range (errors name the option's key)."""
    if o.kind is not None and o.kind not in ("sonar", "laser"):
        raise InputError(f"expected sonar or laser, got {o.kind!r}", key="kind")
    for key in ("window", "max_gap", "tilt_tolerance", "max_range", "beam_width"):
        v = getattr(o, key)
        if v is not None and not (math.isfinite(v) and v > 0):
            raise InputError(f"expected a positive number, got {v}", key=key)
    for key in ("min_range", "noise_sigma"):
        v = getattr(o, key)
        if v is not None and not (math.isfinite(v) and v >= 0):
            raise InputError(f"expected a number >= 0, got {v}", key=key)
    if o.start is not None and o.end is not None and not o.start < o.end:
        raise InputError(f"expected start < end, got {o.start} and {o.end}", key="start")


def parse_pose(spec: str) -> tuple[str, str] | str:
    """``tf:PARENT.CHILD`` -> (parent, child); anything else is a topic name."""
    if not spec.startswith("tf:"):
        return spec
    parent, dot, child = spec[3:].partition(".")
    if not (parent and dot and child):
        raise InputError(f"expected tf:PARENT.CHILD such as tf:map.base_link, got {spec!r}", key="pose")
    return frame_name(parent), frame_name(child)


# -- reading the bag --------------------------------------------------------------------------


def _open(path: Path):
    """An open ``rosbags`` AnyReader of a ROS 1 .bag or a ROS 2 folder (or a file inside one), with
    p2os_msgs/SonarArray known; errors name the file."""
    from rosbags.highlevel import AnyReader, AnyReaderError
    from rosbags.typesys import get_types_from_msg

    if path.is_file() and path.suffix != ".bag" and (path.parent / "metadata.yaml").is_file():
        path = path.parent  # a .db3 or .mcap file of a ROS 2 bag: its folder
    if not path.exists():
        raise InputError("no such file or folder", file=str(path))
    try:
        reader = AnyReader([path])
        reader.open()
    except Exception as exc:
        if not (isinstance(exc, (AnyReaderError, OSError, ValueError, KeyError))
                or type(exc).__module__.startswith("rosbags")):
            raise
        what = "a ROS 1 .bag file or a ROS 2 bag folder (metadata.yaml with sqlite3 or MCAP storage)"
        raise InputError(f"cannot read as a ROS bag ({exc}); expected {what}", file=str(path)) from None
    if SONAR_ARRAY not in reader.typestore.fielddefs:
        reader.typestore.register(get_types_from_msg(SONAR_ARRAY_MSG, SONAR_ARRAY))
    return reader


def _deserialize(reader, raw, connection):
    try:
        return reader.deserialize(raw, connection.msgtype), None
    except Exception as exc:  # noqa: BLE001 - a message rosbags cannot decode is skipped and counted
        return None, f"{connection.topic}: cannot decode a {connection.msgtype} message ({exc.__class__.__name__})"


def read_bag(path: str | Path, options: RosbagOptions, mounts: np.ndarray | None = None,
             mounts_source: str = "--mounts", progress: Callable[..., object] | None = None) -> RosbagImport:
    """Import the bag at ``path`` (ROS 1 .bag, ROS 2 folder with sqlite3 or MCAP storage) into a
    ``Log``. ``mounts`` (S, 3): the sensors' x, y, yaw in the robot frame instead of /tf_static
    (``mounts_source`` says where they came from, for the log's source). ``progress(n, total)``
    is called as messages are read (n read since the last call, of ``total`` to read). Errors are
    InputErrors naming the bag and the topic, frame or option."""
    path = Path(path)
    check_options(options)
    pose_spec = parse_pose(options.pose)
    reader = _open(path)
    try:
        types = {name: info.msgtype for name, info in reader.topics.items()}
        topics = resolve_topics(options.ranges, types)
        kind = types[topics[0]]
        if isinstance(pose_spec, str):
            if pose_spec not in types:
                raise InputError(f"no such pose topic in the bag (topics: {', '.join(sorted(types))})", key=pose_spec)
            if types[pose_spec] not in POSE_TYPES:
                expected = ", ".join(ros_name(k) for k in POSE_TYPES)
                raise InputError(f"a topic of type {ros_name(types[pose_spec])}; expected one of {expected}",
                                 key=pose_spec)
        if mounts is None and kind in (POINT_CLOUD, POINT_CLOUD2, SONAR_ARRAY):
            raise InputError(f"{ros_name(kind)} carries no sensor mounts: give --mounts FILE", key="mounts")
        collected = _read_messages(reader, types, topics, kind, pose_spec, options, mounts, progress)
    except InputError as exc:
        raise exc.in_file(str(path)) from None
    except Exception as exc:
        if type(exc).__module__.startswith("rosbags"):  # a damaged or truncated bag, read message by message
            raise InputError(f"cannot read the bag ({exc})", file=str(path)) from None
        raise
    finally:
        reader.close()
    try:
        return _assemble(collected, topics, kind, pose_spec, options, mounts,
                         f"aogm import rosbag {path.name}", mounts_source)
    except InputError as exc:
        raise exc.in_file(str(path)) from None


@dataclass
class _Collected:
    types: dict[str, str]
    readings: Readings
    tree: TfTree
    pose_series: PoseSeries | None
    base_frame: str | None
    counts: Counter
    skipped: Counter


def _read_messages(reader, types, topics, kind, pose_spec, o: RosbagOptions, mounts, progress=None) -> _Collected:
    """One pass over the bag: range messages in the time window, every pose and tf message
    (``progress(n, total)`` every ``PROGRESS_EVERY`` messages)."""
    index = {t: i for i, t in enumerate(topics)}
    label = topics[0] if len(topics) == 1 else f"{topics[0]}..{topics[-1]}"
    wanted = set(topics) | {t for t in ("/tf", "/tf_static", "tf", "tf_static") if types.get(t) in TF_TYPES}
    if isinstance(pose_spec, str):
        wanted.add(pose_spec)
    first = reader.start_time / 1e9
    lo = -math.inf if o.start is None else first + o.start
    hi = math.inf if o.end is None else first + o.end
    out = _Collected(types, Readings(), TfTree(), PoseSeries(pose_spec) if isinstance(pose_spec, str) else None,
                     None, Counter(), Counter())
    connections = [c for c in reader.connections if c.topic in wanted]
    total, done = sum(int(getattr(c, "msgcount", 0) or 0) for c in connections), 0
    for connection, _received, raw in reader.messages(connections=connections):
        done += 1
        if progress is not None and done % PROGRESS_EVERY == 0:
            progress(PROGRESS_EVERY, total)
        topic = connection.topic
        msg, why = _deserialize(reader, raw, connection)
        if msg is None:
            out.skipped[why] += 1
            continue
        out.counts[topic] += 1
        if topic in index:
            t = stamp(msg)
            if not lo <= t <= hi:
                out.skipped[f"{label}: outside --start/--end"] += 1
                continue
            try:
                collect_ranges(msg, kind, index[topic], t, out.readings, mounts)
            except ValueError as exc:
                out.skipped[f"{label}: {exc}"] += 1
        elif topic == pose_spec:
            out.pose_series.add(stamp(msg), pose_of_message(msg, types[topic]))
            if types[topic] == ODOMETRY and out.base_frame is None and msg.child_frame_id:
                out.base_frame = frame_name(msg.child_frame_id)
        else:
            out.tree.add(msg, static=topic.endswith("tf_static"))
    if progress is not None:
        progress(done % PROGRESS_EVERY, total)
    for series in [out.pose_series, *out.tree.dynamic.values()]:
        if series is not None and series.not_finite:
            out.skipped[f"{series.name}: a pose or time that is not finite"] += series.not_finite
    if out.tree.reparented:
        out.skipped[f"tf: {out.tree.reparented} transforms giving a frame a second parent"] += out.tree.reparented
    if not out.readings.time:
        why = "; ".join(f"{k} ({n})" for k, n in out.skipped.items() if k.startswith(label)) or "no messages"
        raise InputError(f"no readings to import: {why}", key=topics[0])
    return out


# -- the log ------------------------------------------------------------------------------------


def _poses(c: _Collected, pose_spec, time: np.ndarray, o: RosbagOptions) -> tuple[np.ndarray, np.ndarray, str, str]:
    """(poses (T, 3) at ``time``, covered (T,), what failed to cover, the description for ``source``)."""
    if isinstance(pose_spec, str):
        if not c.pose_series.time:
            raise InputError("no pose messages", key=pose_spec)
        pose, covered = c.pose_series.at(time, o.max_gap)
        return pose, covered, pose_spec, f"{ros_name(c.types[pose_spec])} topic {pose_spec}"
    parent, child = pose_spec
    pose, covered, edge = c.tree.poses(parent, child, time, o.max_gap, key=f"tf:{parent}.{child}")
    return pose, covered, f"tf {edge}", f"tf {parent} -> {child}"


def _check_covered(covered: np.ndarray, time: np.ndarray, what: str, o: RosbagOptions, skipped: Counter) -> None:
    """Readings the poses do not cover: an error naming ``what`` (the topic or tf edge), or dropped."""
    if covered.all():
        return
    n = int((~covered).sum())
    if o.drop_uncovered and covered.any():
        skipped[f"readings not covered by the poses of {what}"] += n
        return
    t = float(time[~covered][0])
    raise InputError(f"the poses do not cover {n} of {time.size} readings (first at t = {t:.3f} s: outside the "
                     f"poses' time span or in a gap over {o.max_gap:g} s); trim with --start/--end or "
                     "--drop-uncovered", key=what)


def _sensor_mounts(c: _Collected, topics, kind, base: str, o: RosbagOptions, mounts) -> np.ndarray:
    """Each sensor's mount (S, 3): the mounts file, else each frame's static transform in ``base``."""
    count = len(topics) if kind == RANGE else c.readings.rows[0].size
    if kind == LASER_SCAN:
        a0, da, n = c.readings.geometry[:3]
        bearings = a0 + da * np.arange(n)
    else:
        bearings = np.zeros(1)
    if mounts is not None:
        m = np.asarray(mounts, dtype=np.float64).reshape(-1, 3)
        if kind == LASER_SCAN and m.shape[0] == 1:  # the scanner's own mount: its beams from there
            return np.column_stack([np.full((count, 2), m[0, :2]), m[0, 2] + bearings])
        if m.shape[0] != count:
            raise InputError(f"{m.shape[0]} mounts for {count} sensors; give one row x y yaw per sensor"
                             + (" (or one for the scanner)" if kind == LASER_SCAN else ""), key="mounts")
        return m
    rows = []
    for i, topic in enumerate(topics if kind == RANGE else topics[:1]):
        frame = frame_name(c.readings.frames.get(i, ""))
        key = f"{topic} (frame {frame!r})"
        if not frame:
            raise InputError("the messages name no frame_id; give --mounts FILE", key=topic)
        t, r = c.tree.static_transform(base, frame, key) if frame != base else (np.zeros(3), np.eye(3))
        rows.append(planar_mounts(t, r, bearings, o.tilt_tolerance, key))
    return np.vstack(rows)


def _range_fields(c: _Collected, topics) -> tuple[list[str], np.ndarray, np.ndarray, np.ndarray]:
    """Range topics: (radiation types, field of view, min range, max range) per topic, checked."""
    radiation, fov, lo, hi = [], [], [], []
    for i, topic in enumerate(topics):
        if i not in c.readings.fields:
            raise InputError("no messages in the time window", key=topic)
        rad, f, mn, mx = c.readings.fields[i]
        if rad not in RADIATION:
            raise InputError(f"radiation_type {rad}: expected 0 (ULTRASOUND) or 1 (INFRARED)", key=topic)
        if not (0 < f < math.pi):
            raise InputError(f"field_of_view {f}: expected an angle between 0 and pi rad", key=topic)
        if not (math.isfinite(mx) and 0 <= mn < mx):
            raise InputError(f"min_range {mn}, max_range {mx}: expected 0 <= min_range < max_range", key=topic)
        radiation.append(RADIATION[rad])
        fov.append(f)
        lo.append(mn)
        hi.append(mx)
    return radiation, np.array(fov), np.array(lo), np.array(hi)


def _ring_scans(c: _Collected, topics, time, pose, order, o: RosbagOptions):
    """A ring of Range topics: (scan times, poses, ranges (T, S), each sensor's max range, the sensor's
    fields, what was read, a note), the readings grouped by ``group_readings``."""
    radiation, fov, lo, hi = _range_fields(c, topics)
    if o.beam_width is None and np.ptp(fov) > 1e-6:
        raise InputError(f"the topics' field_of_view differ ({np.degrees(fov.min()):.3g} to "
                         f"{np.degrees(fov.max()):.3g} deg); a log has one beam width: give --beam-width",
                         key=topics[int(np.argmax(fov))])
    sensor = np.asarray(c.readings.sensor)[order]
    row = group_readings(time, sensor, pose, o.window, o.pose_tolerance)
    first = np.flatnonzero(np.r_[True, row[1:] != row[:-1]])
    ranges = np.full((first.size, len(topics)), np.nan)  # a sensor that did not fire in a scan: invalid
    ranges[row, sensor] = np.asarray(c.readings.values)[order]
    limit = np.full(len(topics), o.max_range) if o.max_range is not None else hi
    spec = dict(beam_width=float(fov[0]), min_range=float(lo.min()), max_range=float(limit.max()))
    kinds = "/".join(sorted(set(radiation)))
    what = (f"{len(topics)} sensor_msgs/Range topics ({kinds}) {topics[0]}..{topics[-1]}" if len(topics) > 1
            else f"sensor_msgs/Range topic {topics[0]} ({kinds})")
    note = (f"{order.size} readings grouped into {first.size} scans (one firing cycle within {o.window:g} s "
            "and the pose tolerance)")
    return time[first], pose[first], ranges, limit, spec, what, note


def _message_scans(c: _Collected, kind: str, sensor_kind: str, order, o: RosbagOptions):
    """A scan, cloud or sonar array: (ranges (T, S), max range per sensor, the sensor's fields)."""
    ranges = np.vstack(c.readings.rows)[order]
    spec = dict(beam_width=SONAR_BEAM_WIDTH, min_range=SONAR_MIN_RANGE, max_range=SONAR_MAX_RANGE)
    if kind == LASER_SCAN:
        mn, mx = c.readings.geometry[3:]
        spec = dict(beam_width=LASER_BEAM_WIDTH if sensor_kind == "laser" else SONAR_BEAM_WIDTH,
                    min_range=mn if math.isfinite(mn) and mn >= 0 else LASER_MIN_RANGE, max_range=mx)
    limit = np.full(ranges.shape[1], o.max_range if o.max_range is not None else spec["max_range"])
    if kind in (POINT_CLOUD, POINT_CLOUD2):  # points in float32: max range to within their precision
        limit = limit - POINT_TOLERANCE
    return ranges, limit, spec


def _not_echo_note(counts: dict[str, np.ndarray]) -> str:
    """The echo points stored as invalid, per reason and sensor: "663 at the robot's origin (sensors
    8-15: 663 each)"."""
    parts = []
    for why, per_sensor in counts.items():
        groups: dict[int, list[int]] = {}
        for sensor, n in enumerate(per_sensor.tolist()):
            if n:
                groups.setdefault(n, []).append(sensor)
        detail = "; ".join(f"{sensor_names(s)}: {n}" + (" each" if len(s) > 1 else "") for n, s in groups.items())
        parts.append(f"{int(per_sensor.sum())} {why}" + (f" ({detail})" if detail else ""))
    return "echo points that are no echo, stored as invalid: " + ", ".join(parts)


def _assemble(c: _Collected, topics, kind, pose_spec, o: RosbagOptions, mounts, source: str,
              mounts_source: str = "--mounts") -> RosbagImport:
    """The log: readings in time order at poses that cover them, grouped into scans, cleaned (REP-117),
    with the sensor's fields and mounts; ``source`` records what was read."""
    time = np.asarray(c.readings.time, dtype=np.float64)
    order = np.argsort(time, kind="stable")
    time = time[order]
    pose, covered, what, pose_text = _poses(c, pose_spec, time, o)
    _check_covered(covered, time, what, o, c.skipped)
    time, pose, order = time[covered], pose[covered], order[covered]
    base = frame_name(o.base_frame or (pose_spec[1] if not isinstance(pose_spec, str) else c.base_frame or "base_link"))
    sensor_kind = o.kind or ("laser" if kind == LASER_SCAN else "sonar")
    notes: list[str] = []
    if kind == RANGE:
        time, pose, ranges, limit, spec, what, note = _ring_scans(c, topics, time, pose, order, o)
        notes.append(note)
    else:
        ranges, limit, spec = _message_scans(c, kind, sensor_kind, order, o)
        what = f"{ros_name(kind)} topic {topics[0]}"
    too_close, invalid = int(np.isneginf(ranges).sum()), int(np.isnan(ranges).sum())
    cleaned = clean_ranges(ranges, limit[None, :])
    notes.append(f"REP-117: {int(np.isposinf(cleaned).sum())} no echo (+inf or >= max range), {too_close} too "
                 f"close (-inf, stored as invalid), {invalid} NaN or not fired (invalid)")
    not_echo: dict[str, np.ndarray] = {}
    if kind in (POINT_CLOUD, POINT_CLOUD2, SONAR_ARRAY):
        why = not_echoes(np.vstack(c.readings.off_axis)[order], np.vstack(c.readings.at_origin)[order],
                         o.beam_width if o.beam_width is not None else spec["beam_width"])
        cleaned[why > 0] = np.nan
        not_echo = {text: (why == code).sum(axis=0) for code, text in enumerate(NOT_ECHO, start=1)}
        notes.append(_not_echo_note(not_echo))
    for key, value in (("max_range", o.max_range), ("min_range", o.min_range), ("beam_width", o.beam_width)):
        if value is not None:
            spec[key] = float(value)
    noise = o.noise_sigma if o.noise_sigma is not None else (
        LASER_NOISE_SIGMA if sensor_kind == "laser" else SONAR_NOISE_SIGMA)
    mount_source = mounts_source if mounts is not None else f"/tf_static in {base!r}"
    sensor_mounts = _sensor_mounts(c, topics, kind, base, o, mounts)
    try:
        sensor = SensorSpec(mount=sensor_mounts, kind=sensor_kind, noise_sigma=float(noise), **spec).validate()
    except InputError as exc:
        raise InputError(exc.message, key="mounts" if exc.key == "mount" else exc.key) from None
    skipped = dict(sorted(c.skipped.items()))
    text = f"{source}: {what}; poses from {pose_text}; mounts from {mount_source}"
    if skipped:
        text += f"; skipped {sum(skipped.values())} messages or readings"
    log = Log(time=time, pose=pose, ranges=cleaned, sensor=sensor, source=text)
    counts = {t: (c.types[t], c.counts[t]) for t in sorted(c.counts, key=natural_order)}
    return RosbagImport(log, counts, pose_text, mount_source, skipped, tuple(notes), not_echo)
