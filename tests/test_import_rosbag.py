"""ROS bag importer: bags written with rosbags' own writers (ROS 1, ROS 2 sqlite3 and MCAP) from
corridor_door's simulated log come back as the log (ranges, poses, the standard map); bad bags exit 2."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from bag_writer import T0, Bag
from click.testing import CliRunner
from numpy.testing import assert_allclose, assert_array_equal

from aogm_cli.cli import main
from aogm_cli.core.errors import InputError
from aogm_cli.core.log import Log
from aogm_cli.io.importers import wrap_angle
from aogm_cli.io.importers.rosbag import RosbagOptions, _open, read_bag
from aogm_cli.io.importers.rosbag_messages import SONAR_ARRAY, group_readings
from aogm_cli.io.importers.rosbag_tf import PoseSeries, TfTree, compose, invert, planar_mounts
from aogm_cli.io.logfile import read_log
from aogm_cli.mapping.modes import map_in_mode
from aogm_cli.mapping.params import MapParams

ODOM = np.array([0.3, -0.2, 0.1])  # map -> odom


@pytest.fixture(scope="module")
def original(corridor_door_log) -> Log:
    """corridor_door (seed 1) without truth, with no-echo and invalid readings added, as a bag can
    carry it: its poses moved by one rigid motion (the world seen in another map frame) and its beam
    width a float32.

    Why: the simulated trajectory puts poses exactly on cell boundaries of the grid (x = 1.15 at
    0.05 m), where a pose 1e-15 m off (tf composition, a quaternion's yaw) moves the grid by a row
    or a cone's cell in or out; and sensor_msgs/Range's field_of_view is a float32.
    """
    log = read_log(corridor_door_log)
    ranges = log.ranges.copy()
    ranges[::7, 3] = np.inf  # no echo: written as +inf, or as max_range as many drivers do
    ranges[::5, 10] = np.nan  # invalid: written as NaN, or as -inf (too close)
    sensor = dataclasses.replace(log.sensor, beam_width=float(str(np.float32(log.sensor.beam_width))))
    pose = compose(np.array([0.123456789, -0.0876543, 0.0314159]), log.pose)
    return dataclasses.replace(log, pose=pose, ranges=ranges, sensor=sensor, truth=None)


def standard_map(log):
    return map_in_mode(log, "standard", MapParams())


def bag_value(r: float, k: int, max_range: float) -> float:
    """What a driver writes for the log's reading ``r``: no echo as +inf or max range, invalid as NaN or -inf."""
    if np.isposinf(r):
        return max_range if k % 2 else math.inf
    if np.isnan(r):
        return -math.inf if k % 2 else math.nan
    return float(r)


def write_ring_bag(path: Path, kind: str, log: Log, skip_static: str | None = None, tilt: float = 0.0,
                   pose_until: float | None = None, radiation: int = 0) -> None:
    """A sonar ring of Range topics /sonar/0../sonar/23 (frames sonar_i in /tf_static) and poses on
    /tf as map -> odom (1 Hz) and odom -> base_link (at each scan)."""
    s = log.sensor
    with Bag(path, kind) as bag:
        static = []
        for i, m in enumerate(s.mount):
            if f"sonar_{i}" == skip_static:
                continue
            rotation = None
            if tilt:  # pitch the sonar down by ``tilt`` rad about its own y axis, then yaw
                qy = (0.0, math.sin(tilt / 2), 0.0, math.cos(tilt / 2))
                qz = (0.0, 0.0, math.sin(m[2] / 2), math.cos(m[2] / 2))
                x = qz[3] * qy[0] - qz[2] * qy[1]
                y = qz[3] * qy[1] + qz[2] * qy[0]
                z = qz[2] * qy[3]
                w = qz[3] * qy[3]
                rotation = bag.msg("geometry_msgs/msg/Quaternion", x=x, y=y, z=z, w=w)
            static.append(bag.transform(T0, "base_link", f"sonar_{i}", m, z=0.3, rotation=rotation))
        bag.tf("/tf_static", T0, static)
        for t in np.arange(T0 - 1, T0 + log.time[-1] + 2):
            bag.tf("/tf", t, [bag.transform(t, "map", "odom", ODOM)])
        for k, (t, pose, row) in enumerate(zip(log.time, log.pose, log.ranges, strict=True)):
            stamp = T0 + t
            if pose_until is None or t <= pose_until:
                odom_pose = compose(invert(ODOM), pose)[0]
                bag.tf("/tf", stamp, [bag.transform(stamp, "odom", "base_link", odom_pose)])
            for i, r in enumerate(row):
                msg = bag.msg("sensor_msgs/msg/Range", header=bag.header(stamp, f"sonar_{i}"), radiation_type=radiation,
                              field_of_view=s.beam_width, min_range=s.min_range, max_range=s.max_range,
                              range=bag_value(r, k + i, s.max_range))
                bag.write(f"/sonar/{i}", "sensor_msgs/msg/Range", stamp, msg)


def write_scan_bag(path: Path, kind: str, log: Log, odom_until: float | None = None) -> None:
    """The ring as one LaserScan /scan (frame sonar_ring at the robot's centre) with nav_msgs/Odometry /odom."""
    s = log.sensor
    n = s.count
    with Bag(path, kind) as bag:
        bag.tf("/tf_static", T0, [bag.transform(T0, "base_link", "sonar_ring", (0.0, 0.0, 0.0), z=0.3)])
        for k, (t, pose, row) in enumerate(zip(log.time, log.pose, log.ranges, strict=True)):
            stamp = T0 + t
            if odom_until is None or t <= odom_until:
                bag.write("/odom", "nav_msgs/msg/Odometry", stamp, bag.odometry(stamp, pose))
            values = np.array([bag_value(r, k + i, s.max_range) for i, r in enumerate(row)], dtype=np.float32)
            bag.write("/scan", "sensor_msgs/msg/LaserScan", stamp, bag.msg(
                "sensor_msgs/msg/LaserScan", header=bag.header(stamp, "sonar_ring"), angle_min=0.0,
                angle_max=2 * math.pi * (n - 1) / n, angle_increment=2 * math.pi / n, time_increment=0.0,
                scan_time=0.0, range_min=s.min_range, range_max=s.max_range, ranges=values,
                intensities=np.zeros(0, dtype=np.float32)))


def write_rosaria_bag(path: Path, kind: str, log: Log) -> None:
    """RosAria: /RosAria/sonar (PointCloud: each sonar's echo point in the robot frame, at max range
    when there is none), /RosAria/sonar_pointcloud2, /p2os/sonar (p2os_msgs/SonarArray) and the pose
    as PoseStamped /RosAria/pose and PoseWithCovarianceStamped /amcl_pose."""
    s = log.sensor
    with Bag(path, kind) as bag:
        for t, pose, row in zip(log.time, log.pose, log.ranges, strict=True):
            stamp = T0 + t
            head = bag.header(stamp, "map")
            bag.write("/RosAria/pose", "geometry_msgs/msg/PoseStamped", stamp,
                      bag.msg("geometry_msgs/msg/PoseStamped", header=head, pose=bag.pose(pose)))
            cov = bag.msg("geometry_msgs/msg/PoseWithCovariance", pose=bag.pose(pose), covariance=np.zeros(36))
            bag.write("/amcl_pose", "geometry_msgs/msg/PoseWithCovarianceStamped", stamp,
                      bag.msg("geometry_msgs/msg/PoseWithCovarianceStamped", header=head, pose=cov))
            reach = np.where(np.isfinite(row), row, s.max_range).astype(np.float64)
            px = s.mount[:, 0] + reach * np.cos(s.mount[:, 2])
            py = s.mount[:, 1] + reach * np.sin(s.mount[:, 2])
            points = [bag.msg("geometry_msgs/msg/Point32", x=float(x), y=float(y), z=0.0) for x, y in zip(px, py, strict=True)]
            bag.write("/RosAria/sonar", "sensor_msgs/msg/PointCloud", stamp,
                      bag.msg("sensor_msgs/msg/PointCloud", header=bag.header(stamp, "base_link"), points=points,
                              channels=[]))
            xyz = np.column_stack([px, py, np.zeros_like(px)]).astype("<f4")
            fields = [bag.msg("sensor_msgs/msg/PointField", name=c, offset=4 * j, datatype=7, count=1)
                      for j, c in enumerate("xyz")]
            bag.write("/RosAria/sonar_pointcloud2", "sensor_msgs/msg/PointCloud2", stamp, bag.msg(
                "sensor_msgs/msg/PointCloud2", header=bag.header(stamp, "base_link"), height=1, width=len(px),
                fields=fields, is_bigendian=False, point_step=12, row_step=12 * len(px),
                data=np.frombuffer(xyz.tobytes(), dtype=np.uint8), is_dense=True))
            values = np.where(np.isnan(row), -1.0, np.where(np.isinf(row), s.max_range, row)).astype(np.float64)
            bag.write("/p2os/sonar", SONAR_ARRAY, stamp, bag.msg(SONAR_ARRAY, header=bag.header(stamp, "base_link"),
                                                                ranges_count=len(values), ranges=values))


@pytest.fixture(scope="module")
def bags(tmp_path_factory, original):
    folder = tmp_path_factory.mktemp("bags")
    paths = {"ring": folder / "ring.bag", "scan": folder / "scan_sqlite3", "rosaria": folder / "rosaria_mcap",
             "ring_mcap": folder / "ring_mcap"}
    write_ring_bag(paths["ring"], "ros1", original)
    write_ring_bag(paths["ring_mcap"], "mcap", original)
    write_scan_bag(paths["scan"], "sqlite3", original)
    write_rosaria_bag(paths["rosaria"], "mcap", original)
    mounts = folder / "p3dx.txt"
    m = original.sensor.mount
    mounts.write_text("".join(f"{float(x)!r} {float(y)!r} {math.degrees(yaw)!r}\n" for x, y, yaw in m))
    paths["mounts"] = mounts
    return paths


def run(*args):
    return CliRunner().invoke(main, ["import", "rosbag", *map(str, args)])


def assert_same_log(imported: Log, original: Log, mount=None, atol_range=0.0):
    assert_allclose(imported.time, T0 + original.time, rtol=0, atol=1e-6)
    assert_allclose(imported.pose[:, :2], original.pose[:, :2], rtol=0, atol=1e-6)
    assert_allclose(wrap_angle(imported.pose[:, 2] - original.pose[:, 2]), 0, atol=1e-6)
    if atol_range:
        assert_array_equal(np.isposinf(imported.ranges), np.isposinf(original.ranges))
        assert_array_equal(np.isnan(imported.ranges), np.isnan(original.ranges))
        assert_allclose(imported.ranges, original.ranges, rtol=0, atol=atol_range)
    else:
        assert_array_equal(imported.ranges, original.ranges)  # +inf kept as +inf, NaN as NaN
    expected = original.sensor.mount if mount is None else mount
    assert_allclose(imported.sensor.mount[:, :2], expected[:, :2], rtol=0, atol=1e-6)
    assert_allclose(wrap_angle(imported.sensor.mount[:, 2] - expected[:, 2]), 0, atol=1e-6)


@pytest.mark.parametrize("which", ["ring", "ring_mcap"])
def test_ring_of_range_topics_with_tf_comes_back_as_the_log_and_its_map(bags, original, tmp_path, which):
    out = tmp_path / "ring.h5"
    result = run(bags[which], "--ranges", "/sonar/*", "--pose", "tf:map.base_link", "-o", out)
    assert result.exit_code == 0, result.output
    assert "/sonar/0../sonar/23: 24 topics, 2904 sensor_msgs/Range messages" in result.output
    log = read_log(out)
    assert_same_log(log, original)
    s = log.sensor
    assert (s.kind, s.min_range, s.max_range, s.beam_width) == ("sonar", 0.15, 5.0, original.sensor.beam_width)
    assert "sensor_msgs/Range topics (ultrasound) /sonar/0../sonar/23" in log.source
    assert "poses from tf map -> base_link" in log.source
    assert_array_equal(standard_map(log).probability, standard_map(original).probability)


def test_laser_scan_as_sonar_with_odometry_from_a_ros2_sqlite3_bag(bags, original, tmp_path):
    out = tmp_path / "scan.h5"
    result = run(bags["scan"], "--ranges", "/scan", "--kind", "sonar", "--pose", "/odom", "-o", out)
    assert result.exit_code == 0, result.output
    log = read_log(out)
    n = original.sensor.count
    ring = np.column_stack([np.zeros((n, 2)), wrap_angle(np.float32(2 * math.pi / n) * np.arange(n))])
    assert_same_log(log, original, mount=ring)
    assert (log.sensor.kind, log.sensor.beam_width) == ("sonar", pytest.approx(math.radians(30)))
    assert "nav_msgs/Odometry topic /odom" in log.source
    # a scan carries neither the sonars' positions nor their beam width: the map of the same
    # readings from the scan's geometry (asserted above) is the one to compare with
    scan_original = dataclasses.replace(original, sensor=log.sensor)
    assert_array_equal(standard_map(log).probability, standard_map(scan_original).probability)


@pytest.mark.parametrize(("topic", "pose"), [("/RosAria/sonar", "/RosAria/pose"),
                                             ("/RosAria/sonar_pointcloud2", "/amcl_pose"),
                                             ("/p2os/sonar", "/RosAria/pose")])
def test_rosaria_point_clouds_and_p2os_sonar_array_with_mounts_file(bags, original, tmp_path, topic, pose):
    out = tmp_path / "p3dx.h5"
    result = run(bags["rosaria"], "--ranges", topic, "--pose", pose, "--mounts", bags["mounts"], "-o", out)
    assert result.exit_code == 0, result.output
    log = read_log(out)
    exact = topic == "/p2os/sonar"
    if not exact:  # a cloud has a point for every sonar, at max range without an echo: no invalid readings
        original = dataclasses.replace(original, ranges=np.where(np.isnan(original.ranges), np.inf, original.ranges))
    assert_same_log(log, original, atol_range=0 if exact else 1e-5)  # echo points are float32
    assert log.sensor.max_range == 5.0
    if exact:  # a SonarArray carries no beam width: the default's
        assert log.sensor.beam_width == pytest.approx(original.sensor.beam_width)
        same_beam = dataclasses.replace(original.sensor, beam_width=log.sensor.beam_width)
        assert_array_equal(standard_map(log).probability,
                           standard_map(dataclasses.replace(original, sensor=same_beam)).probability)


def test_a_moving_ring_firing_one_sonar_at_a_time_is_split_so_each_reading_keeps_its_pose():
    time = np.array([0.0, 0.1, 0.2, 0.3, 1.0, 1.1])
    sensor = np.array([0, 1, 2, 0, 1, 2])
    still = np.zeros((6, 3))
    assert_array_equal(group_readings(time, sensor, still, 0.5, (1e-3, 1e-3)), [0, 0, 0, 1, 2, 2])
    moving = np.column_stack([time, np.zeros(6), np.zeros(6)])  # 1 m/s
    assert_array_equal(group_readings(time, sensor, moving, 0.5, (1e-3, 1e-3)), [0, 1, 2, 3, 4, 5])


def test_start_end_and_drop_uncovered(bags, original, tmp_path):
    out = tmp_path / "part.h5"
    result = run(bags["ring"], "--ranges", "/sonar/*", "--start", "10", "--end", "20", "-o", out)
    assert result.exit_code == 0, result.output
    log = read_log(out)
    keep = (original.time >= 9) & (original.time <= 19)  # the bag starts with /tf at T0 - 1
    assert "skipped 2400: /sonar/0../sonar/23: outside --start/--end" in result.output
    assert_array_equal(log.ranges, original.ranges[keep])
    assert "outside --start/--end" in result.output


def errors_of(result, out: Path) -> str:
    assert result.exit_code == 2, result.output
    assert not out.exists() and not list(out.parent.glob(f".{out.name}*"))
    return result.output


def test_missing_topic_and_wrong_type_exit_2_naming_the_topic(bags, tmp_path):
    out = tmp_path / "x.h5"
    assert "/sonar/99: no such topic in the bag" in errors_of(run(bags["ring"], "--ranges", "/sonar/99", "-o", out), out)
    assert "/tf: a topic of type tf2_msgs/TFMessage; expected one of sensor_msgs/Range" in errors_of(run(bags["ring"], "--ranges", "/tf", "-o", out), out)
    text = errors_of(run(bags["scan"], "--ranges", "/scan", "--pose", "/scan", "-o", out), out)
    assert "/scan: a topic of type sensor_msgs/LaserScan; expected one of nav_msgs/Odometry" in text
    assert "/nope: no such pose topic" in errors_of(run(bags["scan"], "--ranges", "/scan", "--pose", "/nope", "-o", out), out)
    assert "'/x*'" in errors_of(run(bags["ring"], "--ranges", "/x*", "-o", out), out)


def test_no_tf_for_a_sensor_frame_or_a_tilted_sonar_exit_2_naming_the_frame(original, bags, tmp_path):
    short = dataclasses.replace(original, time=original.time[:4], pose=original.pose[:4], ranges=original.ranges[:4])
    bag, out = tmp_path / "no_tf.bag", tmp_path / "x.h5"
    write_ring_bag(bag, "ros1", short, skip_static="sonar_5")
    text = errors_of(run(bag, "--ranges", "/sonar/*", "-o", out), out)
    assert "/sonar/5 (frame 'sonar_5')" in text and "no static transform from 'base_link' to 'sonar_5'" in text
    mounted = tmp_path / "mounted.h5"  # a mounts file instead of /tf_static
    assert run(bag, "--ranges", "/sonar/*", "--mounts", bags["mounts"], "-o", mounted).exit_code == 0
    assert_allclose(read_log(mounted).sensor.mount[:, :2], original.sensor.mount[:, :2], atol=1e-12)
    assert "mounts from --mounts" in read_log(mounted).source
    tilted = tmp_path / "tilted.bag"
    write_ring_bag(tilted, "ros1", short, tilt=math.radians(20))
    assert "tilted 20.0 deg" in errors_of(run(tilted, "--ranges", "/sonar/*", "-o", out), out)
    assert run(tilted, "--ranges", "/sonar/*", "--tilt-tolerance", "25", "-o", out).exit_code == 0


def test_radiation_type_is_recorded_and_checked(original, tmp_path):
    short = dataclasses.replace(original, time=original.time[:3], pose=original.pose[:3], ranges=original.ranges[:3])
    infrared, odd, out = tmp_path / "ir.bag", tmp_path / "odd.bag", tmp_path / "x.h5"
    write_ring_bag(infrared, "ros1", short, radiation=1)
    assert run(infrared, "--ranges", "/sonar/*", "-o", out).exit_code == 0
    assert "(infrared)" in read_log(out).source
    write_ring_bag(odd, "ros1", short, radiation=7)
    out = tmp_path / "y.h5"
    assert "/sonar/0: radiation_type 7: expected 0 (ULTRASOUND) or 1 (INFRARED)" in errors_of(
        run(odd, "--ranges", "/sonar/*", "-o", out), out)


def test_a_file_that_is_not_a_bag_exits_2_naming_it(tmp_path):
    bag, out = tmp_path / "junk.bag", tmp_path / "x.h5"
    bag.write_bytes(b"#ROSBAG V2.0\n" + bytes(100))
    assert "junk.bag: cannot read" in errors_of(run(bag, "--ranges", "/sonar/*", "-o", out), out)
    assert "no such file or folder" in errors_of(run(tmp_path / "none", "--ranges", "/a", "-o", out), out)


def test_poses_that_do_not_cover_the_readings_exit_2_naming_the_frame_or_topic(original, bags, tmp_path):
    short = dataclasses.replace(original, time=original.time[:10], pose=original.pose[:10], ranges=original.ranges[:10])
    bag, out = tmp_path / "short_tf.bag", tmp_path / "x.h5"
    write_ring_bag(bag, "ros1", short, pose_until=2.0)
    text = errors_of(run(bag, "--ranges", "/sonar/*", "-o", out), out)
    assert "tf odom -> base_link: the poses do not cover 120 of 240 readings" in text
    result = run(bag, "--ranges", "/sonar/*", "--drop-uncovered", "-o", out)
    assert result.exit_code == 0 and read_log(out).n_scans == 5
    text = errors_of(run(bags["ring"], "--ranges", "/sonar/0", "--pose", "tf:world.base_link", "-o", tmp_path / "y.h5"),
                     tmp_path / "y.h5")
    assert "tf:world.base_link: no transform names frame 'world'" in text
    odom_bag = tmp_path / "short_odom"
    write_scan_bag(odom_bag, "sqlite3", short, odom_until=2.0)
    out = tmp_path / "z.h5"
    text = errors_of(run(odom_bag, "--ranges", "/scan", "--pose", "/odom", "-o", out), out)
    assert "/odom: the poses do not cover 5 of 10 readings" in text


def test_p2os_sonar_array_is_known_to_a_bag_without_its_definition(bags):
    reader = _open(bags["ring"])
    try:
        assert "ranges_count" in dict(reader.typestore.fielddefs[SONAR_ARRAY][1])
    finally:
        reader.close()


def test_library_reads_a_ros2_bag_file_inside_its_folder(bags, original):
    db = next(bags["scan"].glob("*.db3"))
    result = read_bag(db, RosbagOptions(ranges=("/scan",), pose="/odom", kind="sonar"))
    assert result.log.n_scans == original.n_scans
    assert result.topics["/scan"] == ("sensor_msgs/msg/LaserScan", original.n_scans)


def tf_message(*transforms):
    """A tf2_msgs/TFMessage-like object of (parent, child, (x, y, z), (qx, qy, qz, qw), stamp)."""
    ns = SimpleNamespace
    return ns(transforms=[
        ns(header=ns(frame_id=parent, stamp=ns(sec=int(t), nanosec=round((t - int(t)) * 1e9))), child_frame_id=child,
           transform=ns(translation=ns(x=p[0], y=p[1], z=p[2]), rotation=ns(x=q[0], y=q[1], z=q[2], w=q[3])))
        for parent, child, p, q, t in transforms])


def test_tf_chains_static_mounts_and_an_upside_down_scanner():
    yaw90 = (0.0, 0.0, math.sin(math.pi / 4), math.cos(math.pi / 4))
    level = (0.0, 0.0, 0.0, 1.0)
    tree = TfTree()
    tree.add(tf_message(("base_link", "mast", (0.1, 0.0, 0.5), yaw90, 0.0),
                        ("mast", "/laser", (0.2, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0), 0.0)), static=True)  # rolled by pi
    t, r = tree.static_transform("base_link", "laser", "k")
    assert_allclose(t, [0.1, 0.2, 0.5], atol=1e-12)
    mounts = planar_mounts(t, r, np.array([0.0, 0.5]), math.radians(5), "k")
    assert_allclose(mounts[:, 2], [math.pi / 2, math.pi / 2 - 0.5], atol=1e-12)  # bearings mirrored
    tree.add(tf_message(("odom", "base_link", (0.0, 0.0, 0.0), level, 0.0),
                        ("odom", "base_link", (2.0, 0.0, 0.0), yaw90, 2.0)), static=False)
    pose, covered, edge = tree.poses("odom", "laser", np.array([1.0, 3.0]), 5.0, "k")
    h = math.sqrt(0.5)  # halfway: base_link at x 1, yaw 45 deg; the mast 0.1 m ahead, yaw 135; the laser 0.2 m along it
    assert_allclose(pose[0], [1 + 0.1 * h - 0.2 * h, 0.1 * h + 0.2 * h, 3 * math.pi / 4], atol=1e-12)
    assert covered.tolist() == [True, False] and edge == "odom -> base_link"
    with pytest.raises(InputError, match="goes through 'base_link', which is only in /tf"):
        tree.static_transform("base_link", "odom", "k")
    with pytest.raises(InputError, match="no static transform from 'base_link' to 'sonar'"):
        tree.static_transform("base_link", "sonar", "k")


def test_pose_series_leaves_out_non_finite_samples_and_does_not_bridge_gaps():
    series = PoseSeries("/odom")
    for t, p in [(0.0, (0.0, 0.0, 0.0)), (1.0, (math.nan, 0.0, 0.0)), (2.0, (2.0, 0.0, 0.0)), (9.0, (9.0, 0.0, 0.0))]:
        series.add(t, p)
    assert series.not_finite == 1
    pose, covered = series.at(np.array([1.0, 2.0, 5.0, 9.0, 9.5]), max_gap=2.0)
    assert_allclose(pose[:2, 0], [1.0, 2.0])
    assert covered.tolist() == [True, True, False, True, False]  # 2 -> 9 is a gap; 9.5 after the end
