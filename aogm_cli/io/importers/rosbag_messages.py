"""ROS messages -> readings and poses: the message types the rosbag importer reads and the range
topics picked by them, what it takes from each message (REP-117 ranges, a Range's sensor fields, a
scan's geometry, a cloud's echo points), and the rule that groups a ring's readings into scans.
"""

from __future__ import annotations

import fnmatch
import math
import re
from dataclasses import dataclass, field

import numpy as np

from aogm_cli.core.errors import InputError
from aogm_cli.io.importers.rosbag_tf import pose_of

RANGE = "sensor_msgs/msg/Range"
LASER_SCAN = "sensor_msgs/msg/LaserScan"
POINT_CLOUD = "sensor_msgs/msg/PointCloud"
POINT_CLOUD2 = "sensor_msgs/msg/PointCloud2"
SONAR_ARRAY = "p2os_msgs/msg/SonarArray"
RANGE_TYPES = (RANGE, LASER_SCAN, POINT_CLOUD, POINT_CLOUD2, SONAR_ARRAY)
ODOMETRY = "nav_msgs/msg/Odometry"
POSE_STAMPED = "geometry_msgs/msg/PoseStamped"
POSE_COVARIANCE = "geometry_msgs/msg/PoseWithCovarianceStamped"
POSE_TYPES = (ODOMETRY, POSE_STAMPED, POSE_COVARIANCE)
TF_TYPES = ("tf2_msgs/msg/TFMessage", "tf/msg/tfMessage")  # tf2, and old ROS 1 tf
RADIATION = {0: "ultrasound", 1: "infrared"}  # sensor_msgs/Range ULTRASOUND, INFRARED
# p2os_msgs/SonarArray.msg, registered when a bag carries no definition of it (ROS 2 bags may not)
SONAR_ARRAY_MSG = "std_msgs/Header header\nint32 ranges_count\nfloat64[] ranges\n"
POINT_TOLERANCE = 1e-4  # m: a recovered echo point this close to max range is a max-range reading
ORIGIN_TOLERANCE = 1e-3  # m: an echo point this near the robot's origin is RosAria's disabled or unfired sonar
CONE_TOLERANCE = math.radians(5.0)  # an echo point further off its sonar's axis than half the beam plus this
NOT_ECHO = ("at the robot's origin", "outside its sonar's cone")  # why an echo point is not an echo (codes 1, 2)


def ros_name(msgtype: str | None) -> str:
    """sensor_msgs/msg/Range as ROS 1 and users write it: sensor_msgs/Range."""
    return str(msgtype).replace("/msg/", "/")


def natural_order(name: str) -> list:
    """Sort key putting /sonar/10 after /sonar/9."""
    return [int(p) if p.isdigit() else p for p in re.split(r"(\d+)", name)]


def resolve_topics(specs: tuple[str, ...], types: dict[str, str | None]) -> list[str]:
    """The range topics: each spec a topic name, a comma-separated list or a glob (its matches in
    natural order); an error naming a topic the bag does not have or one of another type."""
    out: list[str] = []
    for spec in (s.strip() for item in specs for s in item.split(",")):
        if not spec:
            continue
        if any(c in spec for c in "*?["):
            found = sorted((t for t in types if fnmatch.fnmatchcase(t, spec)), key=natural_order)
            if not found:
                raise InputError(f"no topic of the bag matches {spec!r} (topics: {', '.join(sorted(types))})", key=spec)
        elif spec in types:
            found = [spec]
        else:
            raise InputError(f"no such topic in the bag (topics: {', '.join(sorted(types)) or 'none'})", key=spec)
        out.extend(t for t in found if t not in out)
    if not out:
        raise InputError("expected at least one range topic", key="--ranges")
    kinds = {types[t] for t in out}
    for t in out:
        if types[t] not in RANGE_TYPES:
            expected = ", ".join(ros_name(k) for k in RANGE_TYPES)
            raise InputError(f"a topic of type {ros_name(types[t])}; expected one of {expected}", key=t)
    if len(kinds) > 1 or (kinds != {RANGE} and len(out) > 1):
        raise InputError(f"one log holds several Range topics or one topic of another type, got {len(out)} topics "
                         f"of types {', '.join(sorted(ros_name(k) for k in kinds))}", key=out[1])
    return out


@dataclass
class Readings:
    """Readings of the range topics as they come: a time, a sensor (or a whole row) and its range."""

    time: list[float] = field(default_factory=list)
    sensor: list[int] = field(default_factory=list)  # Range topics: the topic's index
    rows: list[np.ndarray] = field(default_factory=list)  # whole-message types: one row per message
    values: list[float] = field(default_factory=list)
    off_axis: list[np.ndarray] = field(default_factory=list)  # clouds, sonar arrays: each point's angle off its sonar's axis
    at_origin: list[np.ndarray] = field(default_factory=list)  # and whether it lies at the robot's origin
    frames: dict[int, str] = field(default_factory=dict)  # sensor (or 0) -> its message's frame_id
    fields: dict[int, tuple] = field(default_factory=dict)  # sensor -> (radiation, fov, min, max) of its first message
    geometry: tuple | None = None  # LaserScan: (angle_min, angle_increment, count, range_min, range_max)


def decimal(value: float) -> float:
    """A float32 message field as the decimal it was written as (0.15, not 0.15000000596)."""
    return float(str(np.float32(value)))


def group_readings(time: np.ndarray, sensor: np.ndarray, pose: np.ndarray, window: float,
                   tolerance: tuple[float, float]) -> np.ndarray:
    """Scan (row) index of each reading of a ring of Range topics, readings in time order.

    The rule: a scan is a firing cycle. It starts at a reading and takes the next ones in time
    while no sensor fires twice, each lies within ``window`` s of the scan's first reading, and the
    robot's pose at each reading's own time is within ``tolerance`` (m, rad) of its pose at the
    scan's first reading, which are the scan's time and pose. So a reading is mapped from its own
    pose to within the tolerance: when the robot moves during a cycle, the cycle becomes several
    scans, with NaN (no reading) for the sensors that did not fire in each.
    """
    row = np.empty(time.size, dtype=np.int64)
    n, first, seen = -1, 0, set()
    for i in range(time.size):
        d = pose[i] - pose[first]
        turn = abs((d[2] + math.pi) % (2 * math.pi) - math.pi)
        if (n < 0 or sensor[i] in seen or time[i] - time[first] > window
                or math.hypot(d[0], d[1]) > tolerance[0] or turn > tolerance[1]):
            n, first, seen = n + 1, i, set()
        seen.add(int(sensor[i]))
        row[i] = n
    return row


def cloud_points(msg, kind: str) -> np.ndarray:
    """(n, 2) x, y of a PointCloud's points, or of a PointCloud2's x and y fields."""
    if kind == POINT_CLOUD:
        return np.array([(p.x, p.y) for p in msg.points], dtype=np.float64).reshape(-1, 2)
    types = {1: "i1", 2: "u1", 3: "i2", 4: "u2", 5: "i4", 6: "u4", 7: "f4", 8: "f8"}  # sensor_msgs/PointField
    fields = {f.name: f for f in msg.fields}
    if "x" not in fields or "y" not in fields:
        raise ValueError(f"no x and y fields (fields: {', '.join(fields)})")
    order = ">" if msg.is_bigendian else "<"
    names = ("x", "y")
    dtype = np.dtype({"names": names, "formats": [order + types[fields[k].datatype] for k in names],
                      "offsets": [fields[k].offset for k in names], "itemsize": msg.point_step})
    n = msg.width * msg.height
    data = np.frombuffer(np.asarray(msg.data, dtype=np.uint8).tobytes(), dtype=dtype, count=n)
    return np.column_stack([data["x"], data["y"]]).astype(np.float64)


def _sonar_ranges(points: np.ndarray, mounts: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Echo points (n, 2) in the robot frame, one per sonar in mount order -> (each point's distance
    from its sonar (the range; its bearing is taken as the sonar's), its angle off the sonar's axis,
    whether it lies at the robot's origin). Whether those make it an echo: ``not_echoes``."""
    if points.shape[0] != mounts.shape[0]:
        raise ValueError(f"{points.shape[0]} points for {mounts.shape[0]} sonar mounts")
    dx, dy = points[:, 0] - mounts[:, 0], points[:, 1] - mounts[:, 1]
    off_axis = np.abs((np.arctan2(dy, dx) - mounts[:, 2] + math.pi) % (2 * math.pi) - math.pi)
    off_axis[np.hypot(dx, dy) == 0] = 0.0  # a point on the sonar itself: no bearing to judge
    return np.hypot(dx, dy), off_axis, np.hypot(points[:, 0], points[:, 1]) < ORIGIN_TOLERANCE


def not_echoes(off_axis: np.ndarray, at_origin: np.ndarray, beam_width: float) -> np.ndarray:
    """Why each echo point is not an echo (0: it is one; 1, 2: ``NOT_ECHO``): at the robot's origin
    (RosAria's point for a disabled or unfired sonar), or off its sonar's axis by more than half the
    beam width plus ``CONE_TOLERANCE`` (a sonar hears nothing there)."""
    with np.errstate(invalid="ignore"):
        outside = off_axis > 0.5 * beam_width + CONE_TOLERANCE
    return np.where(at_origin, 1, np.where(outside, 2, 0)).astype(np.int8)


def collect_ranges(msg, kind: str, sensor: int, t: float, into: Readings, mounts: np.ndarray | None) -> None:
    """Add one message's readings (raises ValueError for one to skip, with the reason)."""
    if kind == RANGE:
        into.frames.setdefault(sensor, msg.header.frame_id)
        into.fields.setdefault(sensor, (int(msg.radiation_type), decimal(msg.field_of_view),
                                        decimal(msg.min_range), decimal(msg.max_range)))
        r = float(msg.range)
        into.time.append(t)
        into.sensor.append(sensor)
        into.values.append(math.inf if r >= msg.max_range else r)
        return
    into.frames.setdefault(0, msg.header.frame_id)
    if kind == LASER_SCAN:
        geometry = (float(msg.angle_min), float(msg.angle_increment), len(msg.ranges),
                    decimal(msg.range_min), decimal(msg.range_max))
        if into.geometry is None:
            into.geometry = geometry
        elif geometry[:3] != into.geometry[:3]:
            raise ValueError("beam count or angles differ from the first scan's")
        row = np.asarray(msg.ranges, dtype=np.float64)
        row[row >= msg.range_max] = np.inf
    elif kind == SONAR_ARRAY:
        row = np.asarray(msg.ranges, dtype=np.float64)
        off_axis, at_origin = _array_points(row, mounts)
    else:
        row, off_axis, at_origin = _sonar_ranges(cloud_points(msg, kind), mounts)
    if into.rows and row.size != into.rows[0].size:
        raise ValueError(f"{row.size} readings, the first message has {into.rows[0].size}")
    into.time.append(t)
    into.rows.append(row)
    if kind != LASER_SCAN:
        into.off_axis.append(off_axis)
        into.at_origin.append(at_origin)


def _array_points(row: np.ndarray, mounts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A sonar array's readings as ``_sonar_ranges`` judges echo points: each lies on its sonar's
    axis (off by 0), at the robot's origin when the mount and the range put it there."""
    off_axis = np.zeros(row.size)
    if row.size != mounts.shape[0]:  # refused with the mounts (``rosbag._sensor_mounts``)
        return off_axis, np.zeros(row.size, dtype=bool)
    with np.errstate(invalid="ignore"):
        reach = np.where(np.isfinite(row) & (row > 0), row, 0.0)
    x = mounts[:, 0] + reach * np.cos(mounts[:, 2])
    y = mounts[:, 1] + reach * np.sin(mounts[:, 2])
    return off_axis, np.hypot(x, y) < ORIGIN_TOLERANCE




def pose_of_message(msg, kind: str) -> tuple[float, float, float]:
    p = msg.pose if kind == POSE_STAMPED else msg.pose.pose
    return pose_of(p.position, p.orientation)
