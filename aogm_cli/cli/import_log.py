"""``aogm import carmen``, ``text`` and ``rosbag``: real range logs -> an aogm log (HDF5). Thin: the
options (the sensor's from ``cli.options.sensor_options``) become ``CarmenOptions`` /
``TextOptions`` / ``RosbagOptions``; parsing lives in ``aogm_cli.io.importers``.
"""

from __future__ import annotations

import math
from contextlib import contextmanager
from pathlib import Path

import click

from aogm_cli.cli.options import (
    ANGLE_DEG,
    FINITE,
    NON_NEGATIVE,
    POSITIVE,
    degrees_shown,
    output_option,
    progress_bar,
    quiet_option,
    sensor_options,
)
from aogm_cli.core.errors import InputError
from aogm_cli.io.importers.carmen import (
    LASER_MAX_RANGE,
    LASER_MIN_RANGE,
    LASER_NOISE_SIGMA,
    POSE_SOURCES,
    SCAN_MESSAGES,
    SONAR_MAX_RANGE,
    SONAR_MIN_RANGE,
    SONAR_NOISE_SIGMA,
    CarmenOptions,
)
from aogm_cli.io.importers.rosbag import RosbagOptions
from aogm_cli.io.importers.table import ANGLE_UNITS, DELIMITERS, LENGTH_UNITS, TIME_UNITS
from aogm_cli.io.importers.text import TextOptions
from aogm_cli.io.outputs import resolve_outputs


@click.group("import")
def import_log() -> None:
    """Bring a real range log into the aogm log format (no truth group).

    \b
    aogm import carmen intel-corrected.log.gz -o intel.h5
    aogm import text --ranges sonar.csv --range-unit mm --angle-unit deg -o lab.h5
    aogm import rosbag run.bag --ranges '/sonar/*' --pose tf:map.base_link -o run.h5
    """


@contextmanager
def _option_names(names: tuple[str, ...]):
    """Name options in errors as on the command line: key "max_range" -> "--max-range"."""
    try:
        yield
    except InputError as exc:
        if exc.key in names:
            raise InputError(exc.message, file=exc.file, key="--" + exc.key.replace("_", "-")) from None
        raise


def _report(output: str, log, what: str, origin: str, extra: list[str], quiet: bool) -> None:
    """What was imported (unless quiet), then ``aogm check``'s summary of the log (quiet: its warnings only)."""
    from aogm_cli.report.log_check import check_log

    s = log.sensor
    if not quiet:
        click.echo(f"{output}: {log.n_scans} {what} x {s.count} {s.kind} beams from {origin}", err=True)
        for line in extra:
            click.echo(f"  {line}", err=True)
    result = check_log(log, name=output)
    for line in (result.lines()[1:] if not quiet else []):
        click.echo(line, err=True)
    for w in (result.warnings if quiet else []):
        click.echo(f"aogm: warning: {output}: {w['message']}", err=True)


@import_log.command("carmen")
@click.argument("log_file", metavar="LOG[.gz]", type=click.Path(dir_okay=False))
@output_option("Log file to write (HDF5).")
@click.option(
    "--message",
    type=click.Choice(SCAN_MESSAGES, case_sensitive=False),
    help="Which scan message to import. Default: the only scan message type in the log (a log with several is an error).",
)
@click.option(
    "--pose-from",
    type=click.Choice(POSE_SOURCES),
    default=CarmenOptions.pose_from,
    show_default=True,
    help="line: the pose in the scan line (FLASER/RLASER laser pose, ROBOTLASER robot pose); odom/truepos: "
    "interpolated by time from ODOM/TRUEPOS lines; auto: line where there is one, else TRUEPOS if present, else ODOM.",
)
@click.option(
    "--start-angle",
    type=FINITE,
    default=degrees_shown(CarmenOptions.start_angle),
    show_default=True,
    help="First beam's bearing (deg) of FLASER/RLASER, whose lines do not store it.",
)
@click.option(
    "--angular-res",
    type=POSITIVE,
    help="Beam spacing (deg) of FLASER/RLASER. Default: 1 deg for 180/181 beams, 0.5 for 360/361, 0.25 for 400/401 (as CARMEN guesses).",
)
@sensor_options(
    max_range="Max range (m); readings at or beyond it become +inf (no echo). Default: the line's own (RAWLASER, "
    f"ROBOTLASER), else {LASER_MAX_RANGE:g} m for lasers, {SONAR_MAX_RANGE:g} m for SONAR.",
    min_range=f"Min range (m) of the sensor. Default {LASER_MIN_RANGE:g} for lasers, {SONAR_MIN_RANGE:g} for SONAR.",
    beam_width="Beam (cone) width (deg). Default 0.5 for lasers, the cone_angle of SONAR lines.",
    noise_sigma=f"Range noise (m) recorded in the log. Default {LASER_NOISE_SIGMA:g} for lasers, {SONAR_NOISE_SIGMA:g} "
    "for SONAR.",
)
@click.option(
    "--mount",
    type=(FINITE, FINITE, FINITE),
    metavar="X Y YAW",
    help="Laser mount in the robot frame (m, m, deg) for FLASER, RLASER, RAWLASER. Default 0 0 0.",
)
@quiet_option
def carmen(
    log_file: str,
    output: str,
    message: str | None,
    pose_from: str,
    start_angle: float,
    angular_res: float | None,
    max_range: float | None,
    min_range: float | None,
    beam_width: float | None,
    noise_sigma: float | None,
    mount: tuple[float, float, float] | None,
    quiet: bool,
) -> None:
    """Import a CARMEN text log (plain or .gz): one laser or sonar message type becomes the scans.

    Scan time is each line's ipc_timestamp. Each beam is a sensor at the laser's mount with yaw =
    its bearing. FLASER/RLASER lines carry the (corrected) laser pose, stored as the robot pose
    with the mount at 0; ROBOTLASER lines carry robot and laser pose: the robot pose is stored and
    the laser offset goes into the mount (if the offset varies, the laser pose is stored with the
    mount at 0). RAWLASER and SONAR poses are interpolated by time. Other messages are skipped and
    counted; a malformed line is an error naming its line number.

    \b
    Example:
      aogm import carmen intel-corrected.log.gz -o intel.h5
      aogm import carmen robot.log --message SONAR --pose-from odom --max-range 4.5 -o sonar.h5
    """
    from aogm_cli.io.importers import file_kilobytes
    from aogm_cli.io.importers.carmen import import_carmen
    from aogm_cli.io.logfile import write_log
    from aogm_cli.io.provenance import provenance

    options = CarmenOptions(
        message=message,
        pose_from=pose_from,
        start_angle=math.radians(start_angle),
        angular_res=None if angular_res is None else math.radians(angular_res),
        max_range=max_range,
        min_range=min_range,
        beam_width=None if beam_width is None else math.radians(beam_width),
        noise_sigma=noise_sigma,
        mount=None if mount is None else (mount[0], mount[1], math.radians(mount[2])),
    )
    resolve_outputs([log_file], [("-o", output)])
    made = provenance([log_file])  # the inputs as read, the time the run starts
    with (
        _option_names(tuple(CarmenOptions.__dataclass_fields__)),
        progress_bar(file_kilobytes(log_file), "import", quiet, unit="kB") as advance,
    ):
        result = import_carmen(log_file, options, progress=advance)
    write_log(output, result.log, made)
    if result.skipped:
        click.echo(f"aogm: note: {log_file}: {result.skipped_summary()}", err=True)
    extra = [f"poses from {result.pose_source if result.pose_source != 'line' else result.message + ' lines'}"]
    extra.extend(result.notes)
    _report(output, result.log, f"{result.message} scans", Path(log_file).name, extra, quiet)


def _unit_option(flag: str, units, help_text: str):
    """A unit option of ``import text``: one of ``units``, by default ``TextOptions``' value."""
    default = getattr(TextOptions, flag.removeprefix("--").replace("-", "_"))
    return click.option(flag, type=click.Choice(list(units)), default=default, show_default=True, help=help_text)


@import_log.command("text")
@click.option(
    "--ranges",
    "ranges_file",
    required=True,
    type=click.Path(dir_okay=False),
    help="Table of readings: one row per scan (whitespace, comma or semicolon separated).",
)
@click.option(
    "--poses",
    "poses_file",
    type=click.Path(dir_okay=False),
    help="Table of poses (x, y, yaw). Default: pose columns of the --ranges file.",
)
@output_option("Log file to write (HDF5).")
@click.option(
    "--range-columns",
    help="Reading columns: 1-based numbers, ranges (4-19, 4-) or header names. Default: every column not used for pose or time.",
)
@click.option("--pose-columns", default=TextOptions.pose_columns, show_default=True, help="The x, y, yaw columns of the pose table.")
@click.option("--range-time-column", help="Time column of the ranges table. Without one, scan k is at k * --period.")
@click.option(
    "--pose-time-column",
    help="Time column of the pose table; with --range-time-column, poses are interpolated by time instead of paired row by row.",
)
@_unit_option("--range-unit", LENGTH_UNITS, "Unit of the readings.")
@_unit_option("--position-unit", LENGTH_UNITS, "Unit of pose x, y (and of --mounts).")
@_unit_option("--angle-unit", ANGLE_UNITS, "Unit of pose yaw (ddeg = tenths of a degree).")
@_unit_option("--time-unit", TIME_UNITS, "Unit of the time columns.")
@click.option(
    "--no-echo",
    type=FINITE,
    multiple=True,
    help="A reading value (in --range-unit) that means no echo; repeatable. Stored as +inf.",
)
@click.option(
    "--bearings",
    help="Sensor bearings: 'ring' (evenly spaced from 0), 'ring:N[:START[:STEP]]' or a list such as 90,50,30,10,-10,-30,-50,-90. "
    f"[default: {TextOptions.bearings}]",
)
@_unit_option("--bearing-unit", ANGLE_UNITS, "Unit of --bearings and of the yaw in --mounts.")
@click.option(
    "--sensor-radius",
    type=NON_NEGATIVE,
    default=TextOptions.sensor_radius,
    show_default=True,
    help="Distance (m) of each sensor from the robot centre along its bearing.",
)
@click.option(
    "--mounts",
    "mounts_file",
    type=click.Path(dir_okay=False),
    metavar="FILE|PRESET",
    help="Table of sensor mounts x y yaw (one row per range column) instead of --bearings, or a robot preset "
    "(p3dx, p3at, peoplebot, nomad200: in m and deg whatever the units).",
)
@sensor_options(
    TextOptions,
    kind=None,
    beam_width="Beam (cone) width in degrees.",
    min_range="Min range (m).",
    max_range="Max range (m); readings at or beyond it become +inf.",
    noise_sigma="Range noise (m) recorded in the log.",
)
@click.option(
    "--period",
    type=POSITIVE,
    default=TextOptions.period,
    show_default=True,
    help="Seconds between scans when there is no time column.",
)
@click.option("--delimiter", type=click.Choice(list(DELIMITERS)), default=TextOptions.delimiter, show_default=True)
@quiet_option
def text(
    ranges_file: str,
    poses_file: str | None,
    output: str,
    bearings: str | None,
    mounts_file: str | None,
    beam_width: float,
    quiet: bool,
    **columns,
) -> None:
    """Import readings and poses from text tables (whitespace or CSV, optional header row).

    Each row is one scan. Readings become metres: negative ones NaN (invalid), --no-echo values
    and readings >= --max-range +inf. Lines starting with #, % or // are comments.

    \b
    Example (one file: x y theta then 16 sonars in mm, yaw in degrees, 5000 = no echo):
      aogm import text --ranges lab.txt --position-unit mm --range-unit mm --angle-unit deg \\
          --no-echo 5000 --max-range 4.9 --sensor-radius 0.2 -o lab.h5
    """
    from aogm_cli.io.importers import file_kilobytes
    from aogm_cli.io.importers.mounts import mounts_path
    from aogm_cli.io.importers.text import import_text
    from aogm_cli.io.logfile import write_log
    from aogm_cli.io.provenance import provenance

    if mounts_file and bearings:
        raise click.UsageError("give --bearings or --mounts, not both")
    columns["no_echo"] = tuple(columns["no_echo"])
    options = TextOptions(bearings=bearings or TextOptions.bearings, beam_width=math.radians(beam_width), **columns)
    names = tuple(TextOptions.__dataclass_fields__) + ("poses", "mounts")
    with _option_names(names):
        table = mounts_path(mounts_file)[0] if mounts_file else None  # a file, or a preset's packaged table
    resolve_outputs([ranges_file, poses_file, table], [("-o", output)])
    made = provenance([ranges_file, poses_file, table])  # the inputs as read, the time the run starts
    with _option_names(names), progress_bar(file_kilobytes(ranges_file), "import", quiet, unit="kB") as advance:
        result = import_text(ranges_file, poses_file, options, mounts_path=mounts_file, progress=advance)
    write_log(output, result.log, made)
    _report(output, result.log, "scans", Path(ranges_file).name, list(result.notes), quiet)


@import_log.command("rosbag")
@click.argument("bag", metavar="BAG", type=click.Path())
@output_option("Log file to write (HDF5).")
@click.option("--ranges", "ranges", multiple=True, required=True, metavar="TOPIC",
              help="Range topics: names, comma-separated lists or globs ('/sonar/*'); repeatable. Several "
              "sensor_msgs/Range topics (one sensor each, in the order given, a glob's matches in natural "
              "order), or one LaserScan, PointCloud, PointCloud2 or p2os_msgs/SonarArray topic.")
@click.option("--pose", default=RosbagOptions.pose, show_default=True, metavar="tf:PARENT.CHILD|TOPIC",
              help="Robot poses: tf:map.base_link (the chain of /tf and /tf_static frames, e.g. through odom, "
              "interpolated in time) or a nav_msgs/Odometry, geometry_msgs/PoseStamped or "
              "PoseWithCovarianceStamped topic.")
@sensor_options(kind="Sensor kind. Default: laser for a LaserScan (--kind sonar: a sonar ring published as a scan), "
                "sonar otherwise.")
@click.option("--base-frame", help="The robot's frame for the mounts. Default: the CHILD of --pose tf:..., an "
              "Odometry's child_frame_id, else base_link.")
@click.option("--mounts", "mounts_file", type=click.Path(dir_okay=False), metavar="FILE|PRESET",
              help="Table of sensor mounts x y yaw (m, m, deg), one row per sensor (a LaserScan: one row for "
              "the scanner, or one per beam), instead of /tf_static; or a robot preset: p3dx, p3at, peoplebot "
              "(ARIA's tables), nomad200 (a 16-sonar ring). Needed for PointCloud and SonarArray.")
@click.option("--start", type=NON_NEGATIVE, help="Import readings from this many seconds after the bag's first message.")
@click.option("--end", type=POSITIVE, help="Import readings up to this many seconds after the bag's first message.")
@click.option("--window", type=POSITIVE, default=RosbagOptions.window, show_default=True,
              help="Longest firing cycle (s) of a ring of Range topics: readings grouped into one scan.")
@click.option("--max-gap", type=POSITIVE, default=RosbagOptions.max_gap, show_default=True,
              help="Poses further apart in time (s) do not cover the readings between them.")
@click.option("--drop-uncovered", is_flag=True,
              help="Drop readings that the poses do not cover (counted in the summary) instead of an error.")
@click.option("--tilt-tolerance", type=ANGLE_DEG, default=degrees_shown(RosbagOptions.tilt_tolerance), show_default=True,
              help="Largest tilt (deg) of a sensor's beam out of the base frame's plane.")
@sensor_options(
    max_range=f"Max range (m). Default: the messages' own (Range, LaserScan), else {SONAR_MAX_RANGE:g} m. Readings "
    "at or beyond it become +inf (no echo).",
    min_range=f"Min range (m). Default: the messages' own, else {SONAR_MIN_RANGE:g} m.",
    beam_width="Beam (cone) width (deg). Default: a Range's field_of_view, 0.5 for a laser, 30 for a sonar.",
    noise_sigma=f"Range noise (m) recorded in the log. Default {LASER_NOISE_SIGMA:g} for lasers, {SONAR_NOISE_SIGMA:g} "
    "for sonar.",
)
@quiet_option
def rosbag(bag: str, output: str, ranges: tuple[str, ...], mounts_file: str | None, tilt_tolerance: float,
           beam_width: float | None, quiet: bool, **settings) -> None:
    """Import a ROS bag (ROS 1 .bag, ROS 2 folder with sqlite3 or MCAP storage; no ROS needed).

    Readings follow REP-117: +inf no echo, -inf too close (stored as invalid), NaN invalid, and
    values at or beyond max range no echo. A Range's field_of_view and min/max range become the
    sensor's; radiation_type must be ultrasound or infrared. Mounts: each sensor frame's static
    transform in the base frame (yaw only; a tilted one is an error), or --mounts. Range readings
    of a ring are grouped into scans: a firing cycle (no sensor twice, within --window s) whose
    readings were taken within 1 mm and 0.05 deg of the pose at its first reading; otherwise the
    cycle is split, so each reading is mapped from its own interpolated pose. A missing topic, a
    topic of the wrong type, a sensor frame without tf, or poses that do not cover the readings
    are errors naming the topic or frame. The log's source records the topics and the pose source.

    \b
    Example:
      aogm import rosbag run.bag --ranges '/sonar/*' --pose tf:map.base_link -o run.h5
      aogm import rosbag run_ros2/ --ranges /scan --kind sonar --pose /odom -o run.h5
      aogm import rosbag pioneer.bag --ranges /RosAria/sonar --pose /RosAria/pose --mounts p3dx -o p3dx.h5
    """
    from aogm_cli.io.importers.mounts import load_mounts, mounts_path
    from aogm_cli.io.importers.rosbag import read_bag
    from aogm_cli.io.logfile import write_log
    from aogm_cli.io.provenance import provenance

    options = RosbagOptions(ranges=ranges, tilt_tolerance=math.radians(tilt_tolerance),
                            beam_width=None if beam_width is None else math.radians(beam_width), **settings)
    with _option_names(tuple(RosbagOptions.__dataclass_fields__) + ("mounts",)):
        table = mounts_path(mounts_file)[0] if mounts_file else None  # a file, or a preset's packaged table
        resolve_outputs([bag, table], [("-o", output)])
        made = provenance([bag, table])  # the inputs as read (a folder's files), the time the run starts
        mounts, mounts_source = load_mounts(mounts_file) if mounts_file else (None, "")
        with progress_bar(None, "import", quiet, unit="msg") as advance:
            result = read_bag(bag, options, mounts, mounts_source, progress=advance)
    write_log(output, result.log, made)
    _report(output, result.log, "scans", Path(bag).name, result.summary(), quiet)
