"""CARMEN importer: each scan message on hand-written lines, pose interpolation, bad lines, the intel log."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest
from click.testing import CliRunner
from numpy.testing import assert_allclose, assert_array_equal

from aogm_cli.cli import main
from aogm_cli.core.errors import InputError
from aogm_cli.core.log import SensorSpec
from aogm_cli.io.importers import clean_ranges, interpolate_poses
from aogm_cli.io.importers.carmen import (
    CarmenOptions,
    guess_angular_res,
    import_carmen,
    parse_carmen,
    parse_pose_line,
    parse_scan_line,
)
from aogm_cli.io.logfile import read_log

INTEL = "data/carmen/intel-corrected.log.gz"  # in ../shared
HALF_PI = math.pi / 2

# FLASER num_readings r1..rn x y theta odom_x odom_y odom_theta ipc_timestamp host logger_timestamp
FLASER = "FLASER 3 1.0 2.5 80.0 1.0 2.0 0.5 0.9 1.9 0.4 10.0 host 10.01"
# RAWLASER1 type start fov res max accuracy remission_mode n r1..rn m rem1..remm ipc host logger
RAWLASER = "RAWLASER1 0 -1.5707963 3.1415927 1.5707963 8.0 0.01 0 3 1.0 -1.0 9.0 2 5.0 6.0 {t} host {t}"
# ROBOTLASER1 ... n r.. m rem.. laser_x laser_y laser_theta robot_x robot_y robot_theta tv rv fs ss ta ipc host logger
ROBOTLASER = "ROBOTLASER1 0 -1.5707963 3.1415927 1.5707963 20.0 0.01 0 3 1 2 3 0 {laser} {robot} 0 0 0 0 0 {t} host {t}"
# SONAR cone_angle n r1..rn (x y theta)*n ipc host logger
SONAR = "SONAR 0.5236 2 1.5 6.0 0.1 0.0 0.0 -0.1 0.0 3.1415927 {t} host {t}"


def error_of(lines, **options) -> InputError:
    with pytest.raises(InputError) as info:
        parse_carmen(lines, CarmenOptions(**options))
    return info.value


def test_flaser_line_gives_ranges_pose_time_and_bearings():
    scan = parse_scan_line(FLASER, 7)
    assert (scan.message, scan.line, scan.time) == ("FLASER", 7, 10.0)
    assert_array_equal(scan.ranges, [1.0, 2.5, 80.0])
    assert_array_equal(scan.pose, [1.0, 2.0, 0.5])
    assert_allclose(scan.beams[:, 2], [-HALF_PI, 0.0, HALF_PI])  # 3 beams over 180 deg


def test_flaser_log_is_a_laser_with_the_line_pose_and_inf_at_max_range():
    result = parse_carmen(["# a comment", "", FLASER, "PARAM robot_frontlaser_offset 0.0 nohost 0"])
    log = result.log
    assert (result.message, result.pose_source, result.skipped) == ("FLASER", "line", {"PARAM": 1})
    assert_array_equal(log.time, [10.0])
    assert_allclose(log.pose, [[1.0, 2.0, 0.5]])
    assert_array_equal(log.ranges, np.array([[1.0, 2.5, np.inf]], dtype=np.float32))
    assert_allclose(log.sensor.mount, [[0, 0, -HALF_PI], [0, 0, 0], [0, 0, HALF_PI]], atol=1e-12)
    s = log.sensor
    assert (s.kind, s.max_range, s.min_range, s.noise_sigma) == ("laser", 80.0, 0.0, 0.01)
    assert s.beam_width == pytest.approx(math.radians(0.5))
    assert log.truth is None


def test_flaser_options_start_angle_resolution_mount_and_max_range():
    opts = dict(
        start_angle=0.0, angular_res=0.1, mount=(0.5, 0.0, HALF_PI), max_range=2.0, beam_width=0.02, noise_sigma=0.05
    )
    log = parse_carmen([FLASER], CarmenOptions(**opts)).log
    assert_allclose(log.sensor.mount, [[0.5, 0, HALF_PI], [0.5, 0, HALF_PI + 0.1], [0.5, 0, HALF_PI + 0.2]])
    assert_array_equal(log.ranges, np.array([[1.0, np.inf, np.inf]], dtype=np.float32))
    assert (log.sensor.max_range, log.sensor.beam_width, log.sensor.noise_sigma) == (2.0, 0.02, 0.05)


def test_180_beams_are_one_degree_apart_from_minus_90():
    assert guess_angular_res(180) == pytest.approx(math.radians(1))
    assert guess_angular_res(361) == pytest.approx(math.radians(0.5))
    line = "FLASER 180 " + " ".join(["1.0"] * 180) + " 0 0 0 0 0 0 1.0 h 1.0"
    yaw = parse_scan_line(line, 1).beams[:, 2]
    assert_allclose(np.degrees(yaw[[0, 1, 90, 179]]), [-90, -89, 0, 89])


def test_rlaser_has_the_flaser_layout():
    scan = parse_scan_line(FLASER.replace("FLASER", "RLASER"), 1)
    assert scan.message == "RLASER"
    assert_array_equal(scan.pose, [1.0, 2.0, 0.5])
    log = parse_carmen([FLASER.replace("FLASER", "RLASER")], CarmenOptions(message="RLASER")).log
    assert log.sensor.count == 3


def test_rawlaser_takes_geometry_and_max_range_from_the_line_and_pose_from_odom():
    lines = ["ODOM 0 0 0 0 0 0 1.0 h 1.0", RAWLASER.format(t=2.0), "ODOM 2 4 1.0 0 0 0 3.0 h 3.0"]
    result = parse_carmen(lines)
    log = result.log
    assert result.pose_source == "odom"
    assert_allclose(log.pose, [[1.0, 2.0, 0.5]])  # halfway between the two ODOM poses
    assert_array_equal(log.ranges[0, 0], np.float32(1.0))
    assert np.isnan(log.ranges[0, 1]) and np.isinf(log.ranges[0, 2])  # -1 invalid, 9 >= 8 m
    assert log.sensor.max_range == 8.0
    assert_allclose(log.sensor.mount[:, 2], [-HALF_PI, 0, HALF_PI], atol=1e-6)
    for k in (2, 3, 4):
        assert parse_scan_line(RAWLASER.format(t=2.0).replace("RAWLASER1", f"RAWLASER{k}"), 1).message == f"RAWLASER{k}"


def test_robotlaser_stores_robot_pose_and_puts_the_constant_laser_offset_in_the_mount():
    lines = [
        ROBOTLASER.format(laser="1.0 1.2 1.5707963", robot="1.0 1.0 1.5707963", t=5.0),
        ROBOTLASER.format(laser="2.2 0.0 0.0", robot="2.0 0.0 0.0", t=6.0),
    ]
    result = parse_carmen(lines)
    log = result.log
    assert result.pose_source == "line" and not result.notes
    assert_allclose(log.pose, [[1.0, 1.0, HALF_PI], [2.0, 0.0, 0.0]], atol=1e-7)
    assert_allclose(log.sensor.mount, [[0.2, 0, -HALF_PI], [0.2, 0, 0], [0.2, 0, HALF_PI]], atol=1e-6)
    assert log.sensor.max_range == 20.0
    scan = parse_scan_line(lines[0].replace("ROBOTLASER1", "ROBOTLASER2"), 1)
    assert scan.message == "ROBOTLASER2"
    assert_allclose(scan.laser_pose, [1.0, 1.2, 1.5707963])


def test_robotlaser_with_a_varying_offset_stores_the_laser_pose_with_mount_zero():
    lines = [
        ROBOTLASER.format(laser="1.0 1.2 1.5707963", robot="1.0 1.0 1.5707963", t=5.0),
        ROBOTLASER.format(laser="2.5 0.0 0.0", robot="2.0 0.0 0.0", t=6.0),
    ]
    result = parse_carmen(lines)
    assert_allclose(result.log.pose, [[1.0, 1.2, HALF_PI], [2.5, 0.0, 0.0]], atol=1e-7)
    assert_allclose(result.log.sensor.mount[:, :2], 0.0)
    assert any("varies" in note for note in result.notes)
    odom = ["ODOM 0 0 0 0 0 0 4.0 h 4.0", "ODOM 0 0 0 0 0 0 7.0 h 7.0"]
    assert "--pose-from line" in str(error_of(lines + odom, pose_from="odom"))


def test_sonar_mounts_cone_and_pose_interpolated_from_truepos():
    lines = [
        "TRUEPOS 0 0 0 9 9 9 6.0 h 6.0",
        "ODOM 5 5 0 0 0 0 6.5 h 6.5",
        SONAR.format(t=7.0),
        "TRUEPOS 2 0 0 9 9 9 8.0 h 8.0",
    ]
    result = parse_carmen(lines)
    log = result.log
    assert (result.message, result.pose_source, result.skipped) == ("SONAR", "truepos", {"ODOM": 1})
    assert_allclose(log.pose, [[1.0, 0.0, 0.0]])
    assert_allclose(log.sensor.mount, [[0.1, 0, 0], [-0.1, 0, -math.pi]], atol=1e-6)
    assert log.sensor.kind == "sonar" and log.sensor.beam_width == pytest.approx(0.5236)
    assert (log.sensor.max_range, log.sensor.noise_sigma) == (5.0, 0.02)
    assert_array_equal(log.ranges, np.array([[1.5, np.inf]], dtype=np.float32))
    err = error_of(lines, pose_from="odom")  # the one ODOM line (t=6.5) is before the scan (t=7)
    assert err.key == "ODOM" and "no SONAR scan lies within the time span" in err.message


def test_a_sonar_line_without_cone_angle_has_the_sonar_defaults_of_every_log(tmp_path):
    """Defaults written once, as ``SensorSpec``'s: parse_carmen's and the command's are the same."""
    lines = ["TRUEPOS 0 0 0 9 9 9 6.0 h 6.0", SONAR.format(t=7.0).replace("SONAR 0.5236", "SONAR 0"), "TRUEPOS 2 0 0 9 9 9 8.0 h 8.0"]
    sensors = [parse_carmen(lines).log.sensor]
    path, out = tmp_path / "sonar.log", tmp_path / "sonar.h5"
    path.write_text("\n".join(lines) + "\n")
    res = CliRunner().invoke(main, ["import", "carmen", str(path), "-o", str(out), "-q"])
    assert res.exit_code == 0, res.output
    sensors.append(read_log(out).sensor)
    for s in sensors:
        assert s.kind == "sonar"
        for key in ("beam_width", "min_range", "max_range", "noise_sigma"):
            assert getattr(s, key) == getattr(SensorSpec, key), key


def test_pose_interpolation_takes_the_short_way_round_and_flags_times_outside():
    pose, inside = interpolate_poses([0.0, 1.0], [[0, 0, 3.0], [1, 2, -3.0]], [-1.0, 0.25, 0.5, 1.0, 2.0])
    assert_array_equal(inside, [False, True, True, True, False])
    assert_allclose(pose[1, :2], [0.25, 0.5])
    assert math.cos(pose[2, 2]) == pytest.approx(-1.0)  # through pi, not through 0
    assert pose[3, 2] == pytest.approx(-3.0)
    # unsorted sources are sorted by time
    pose, _ = interpolate_poses([2.0, 0.0], [[2, 0, 0], [0, 0, 0]], [1.0])
    assert_allclose(pose, [[1, 0, 0]])


def test_scans_outside_the_odometry_span_are_dropped_and_counted():
    lines = [
        RAWLASER.format(t=0.5),
        "ODOM 0 0 0 0 0 0 1.0 h 1.0",
        RAWLASER.format(t=2.0),
        "ODOM 2 4 1.0 0 0 0 3.0 h 3.0",
    ]
    result = parse_carmen(lines)
    assert result.outside == 1 and result.log.n_scans == 1
    assert_array_equal(result.log.time, [2.0])
    assert "no RAWLASER1 scan" in str(error_of([RAWLASER.format(t=9.0)] + lines[1:2]))


def test_clean_ranges_marks_no_echo_and_invalid():
    out = clean_ranges(np.array([[0.0, 1.0, 5.0, 7.0, -0.5, np.nan]]), 5.0)
    assert_array_equal(out, np.array([[0.0, 1.0, np.inf, np.inf, np.nan, np.nan]], dtype=np.float32))
    assert out.dtype == np.float32


def test_pose_lines_and_their_errors():
    t, p = parse_pose_line("ODOM 1 2 3 0 0 0 4.5 h 4.6", 1)
    assert t == 4.5 and list(p) == [1, 2, 3]
    with pytest.raises(InputError, match=r"^ODOM: line 3: expected 9 fields"):
        parse_pose_line("ODOM 1 2 3 4.5 h 4.6", 3)


@pytest.mark.parametrize(
    ("line", "match"),
    [
        ("FLASER 3 1.0 2.5 1.0 2.0 0.5 0.9 1.9 0.4 10.0 host 10.01", r"line 4: expected 13 fields after FLASER"),
        (
            "FLASER 3 1.0 oops 80 1 2 0.5 0.9 1.9 0.4 10.0 host 10.01",
            r"line 4: field 3 \(range reading\): expected a number, got 'oops'",
        ),
        ("FLASER x", r"line 4: field 1 \(num_readings\): expected a whole number"),
        ("FLASER -2 1 h 1", r"line 4: field 1 \(num_readings\): expected a count >= 0"),
        ("SONAR 0.5 2 1.0 2.0 0 0 0 1 h 1", r"line 4: expected 13 fields after SONAR"),
        ("RAWLASER2 0 -1.57 3.14 1.57 8.0 0.01 0 3 1 2", r"line 4: expected num_remissions, but the line ends"),
        ("FLASER 3 1.0 2.5 80.0 1.0 2.0 0.5 0.9 1.9 0.4 later host 10.01", r"field 11 \(ipc_timestamp\)"),
    ],
)
def test_malformed_scan_lines_are_errors_with_the_line_number(line, match):
    err = error_of(["# header", "ODOM 0 0 0 0 0 0 0 h 0", "NEFF 3", line])
    assert err.key == line.split()[0]
    assert err.message.startswith("line 4: ")
    assert re.search(match, str(err))


def test_a_malformed_odom_line_matters_only_when_poses_come_from_odom():
    lines = [FLASER, "ODOM 1 2", "ODOM 0 0 0 0 0 0 11.0 h 11.0"]
    assert parse_carmen(lines).skipped == {"ODOM": 2}
    err = error_of(lines, pose_from="odom")
    assert (err.key, err.message[:7]) == ("ODOM", "line 2:")


def test_unknown_messages_are_skipped_and_counted():
    result = parse_carmen(["NEFF 15", "FOO 1 2 3", "NEFF 14.8", FLASER, "SYNC tag 1 h 1"])
    assert result.skipped == {"FOO": 1, "NEFF": 2, "SYNC": 1}


def test_different_beam_counts_or_message_types_are_errors_naming_the_line():
    four = "FLASER 4 1 1 1 1 0 0 0 0 0 0 11.0 h 11.0"
    err = error_of([FLASER, "NEFF 1", four])
    assert err.key == "FLASER" and err.message.startswith(
        "line 3: 4 readings, but the first FLASER scan (line 1) has 3"
    )
    mixed = [FLASER, FLASER.replace("FLASER", "RLASER")]
    err = error_of(mixed)
    assert err.message.startswith("line 2: a RLASER scan") and "--message" in err.message
    picked = parse_carmen(mixed, CarmenOptions(message="RLASER"))
    assert picked.log.n_scans == 1 and picked.skipped == {"FLASER": 1}
    raw = [RAWLASER.format(t=2.0), RAWLASER.format(t=2.5).replace("-1.5707963", "-1.0", 1), "ODOM 0 0 0 0 0 0 1 h 1"]
    assert "start angle or angular resolution" in str(error_of(raw))


def test_option_errors():
    assert "carry no pose" in str(error_of([RAWLASER.format(t=1.0), "ODOM 0 0 0 0 0 0 1 h 1"], pose_from="line"))
    assert error_of([SONAR.format(t=1.0)]).key == "ODOM"  # no ODOM or TRUEPOS to take poses from
    assert error_of([SONAR.format(t=1.0), "ODOM 0 0 0 0 0 0 1 h 1"], mount=(0, 0, 0)).key == "mount"
    assert "no FLASER" in str(error_of(["ODOM 0 0 0 0 0 0 1 h 1"], message="FLASER"))


def test_import_carmen_reads_gzip_and_names_the_file(tmp_path):
    import gzip

    path = tmp_path / "tiny.log.gz"
    with gzip.open(path, "wt") as f:
        f.write(FLASER + "\nFLASER 3 1 2\n")
    with pytest.raises(InputError) as info:
        import_carmen(path)
    assert str(info.value).startswith(f"{path}: FLASER: line 2: ")


def test_cli_writes_the_log_and_reports_errors_with_exit_2(tmp_path):
    log_path = tmp_path / "tiny.log"
    log_path.write_text(
        "\n".join(["ODOM 0 0 0 0 0 0 1.0 h 1.0", RAWLASER.format(t=2.0), "ODOM 2 4 1.0 0 0 0 3.0 h 3.0"]) + "\n"
    )
    out = tmp_path / "tiny.h5"
    runner = CliRunner()
    res = runner.invoke(
        main, ["import", "carmen", str(log_path), "-o", str(out), "--max-range", "5", "--beam-width", "1"]
    )
    assert res.exit_code == 0, res.output
    log = read_log(out)
    assert log.source == "aogm import carmen tiny.log"
    assert log.sensor.max_range == 5.0 and log.sensor.beam_width == pytest.approx(math.radians(1))
    assert_allclose(log.pose, [[1.0, 2.0, 0.5]])
    bad = tmp_path / "bad.log"
    bad.write_text(FLASER + "\nFLASER 3 1 2 3\n")
    out2 = tmp_path / "bad.h5"
    res = runner.invoke(main, ["import", "carmen", str(bad), "-o", str(out2)])
    assert res.exit_code == 2
    assert "bad.log: FLASER: line 2:" in res.output
    assert not out2.exists() and not list(tmp_path.glob(".bad.h5*"))
    res = runner.invoke(main, ["import", "carmen", str(log_path), "-o", str(out2), "--mount", "0", "0", "0"])
    assert res.exit_code == 0  # RAWLASER takes a mount
    res = runner.invoke(main, ["import", "carmen", str(log_path), "-o", str(out2), "--pose-from", "line"])
    assert res.exit_code == 2 and "--pose-from" in res.output


def test_intel_log_imports_910_scans_of_180_beams(tmp_path, require):
    intel = require.shared(INTEL)
    result = import_carmen(intel)
    log = result.log
    assert (result.message, log.n_scans, log.sensor.count) == ("FLASER", 910, 180)
    assert log.ranges.shape == (910, 180) and log.ranges.dtype == np.float32
    assert result.skipped == {"NEFF": 910, "ODOM": 14541, "PARAM": 2}
    assert log.source.startswith("aogm import carmen intel-corrected.log.gz; skipped 15453 lines (first: line 3: PARAM")
    assert np.isfinite(log.time).all() and np.isfinite(log.pose).all()
    assert int(np.sum(np.diff(log.time) <= 0)) == 4  # file order is kept; 4 FLASER lines are out of time order
    assert_allclose(np.degrees(log.sensor.mount[[0, 179], 2]), [-90, 89])
    assert np.isinf(log.ranges).any() and not np.isnan(log.ranges).any()
    assert float(np.max(log.ranges[np.isfinite(log.ranges)])) < 80.0
    # the same scans with poses interpolated from the raw odometry
    odom = import_carmen(intel, CarmenOptions(pose_from="odom")).log
    assert odom.n_scans == 910 and not np.allclose(odom.pose, log.pose)


@pytest.mark.parametrize("option", [
    ["--max-range", "nan"], ["--max-range", "inf"], ["--max-range", "0"], ["--max-range", "-1"],
    ["--min-range", "9", "--max-range", "8"], ["--mount", "nan", "0", "0"], ["--beam-width", "0"],
    ["--beam-width", "180"], ["--noise-sigma", "nan"], ["--noise-sigma", "-1"], ["--start-angle", "nan"],
])
def test_bad_options_are_refused_naming_the_option(tmp_path, option):
    log = tmp_path / "tiny.log"
    log.write_text(FLASER + "\n")
    r = CliRunner().invoke(main, ["import", "carmen", str(log), "-o", str(tmp_path / "x.h5"), *option])
    assert r.exit_code == 2, r.output
    assert option[0] in r.output and "Traceback" not in r.output and not (tmp_path / "x.h5").exists()


def test_bad_options_are_refused_by_the_library():
    for options in ({"max_range": float("nan")}, {"min_range": 5.0, "max_range": 4.0}, {"mount": (float("nan"), 0, 0)},
                    {"beam_width": math.pi}, {"noise_sigma": -1.0}):
        assert error_of([FLASER], **options).key in options


def test_a_byte_order_mark_keeps_the_first_line(tmp_path):
    log = tmp_path / "bom.log"
    log.write_bytes(b"\xef\xbb\xbf" + "\n".join(FLASER.replace("10.0 host", f"{10 + k}.0 host") for k in range(3)).encode())
    r = CliRunner().invoke(main, ["import", "carmen", str(log), "-o", str(tmp_path / "x.h5")])
    assert r.exit_code == 0, r.output
    assert read_log(tmp_path / "x.h5").n_scans == 3 and "skipped" not in r.output


def test_skipped_lines_are_reported_with_the_first_line(tmp_path):
    log = tmp_path / "odd.log"
    log.write_text("\n".join([FLASER, "NEFF 1 2 3", "PARAM robot_x 1", FLASER.replace("10.0 host", "11.0 host")]))
    r = CliRunner().invoke(main, ["import", "carmen", str(log), "-o", str(tmp_path / "x.h5"), "-q"])
    assert r.exit_code == 0
    assert "aogm: note:" in r.stderr and "skipped 2 lines (first: line 2: NEFF" in r.stderr
    assert "skipped 2 lines" in read_log(tmp_path / "x.h5").source


def test_a_non_finite_pose_in_the_file_is_reported_with_its_line():
    err = error_of([FLASER, FLASER.replace("1.0 2.0 0.5", "nan 2.0 0.5").replace("10.0 host", "11.0 host")])
    assert "line 2: expected a finite pose" in str(err)
