"""Text importer: tables (whitespace, CSV, header), units, no-echo values, bearings, pose matching, bad lines."""

from __future__ import annotations

import math

import numpy as np
import pytest
from click.testing import CliRunner
from numpy.testing import assert_allclose, assert_array_equal

from aogm_cli.cli import main
from aogm_cli.core.errors import InputError
from aogm_cli.core.log import SensorSpec
from aogm_cli.io.importers.table import parse_table
from aogm_cli.io.importers.text import (
    TextOptions,
    build_text_log,
    import_text,
    parse_bearings,
    resolve_columns,
)
from aogm_cli.io.logfile import read_log

HALF_PI = math.pi / 2
LAB_CSV = [
    "# lab sonar log: x, y in cm, theta in tenths of a degree, 4 sonars in mm",
    "x,y,theta,s1,s2,s3,s4",
    "100,200,900,1000,5000,-1,2500",
    "",
    "150, 200, -450, 6000, 20, 0, ",
]


def table(lines, **kw):
    return parse_table(lines, file="t.txt", **kw)


def test_parse_table_whitespace_and_csv_with_header_and_comments():
    t = table(["% matlab comment", "1 2  3", "4\t5 6", "// another"])
    assert t.header is None and t.rows == [["1", "2", "3"], ["4", "5", "6"]] and t.line_numbers == [2, 3]
    c = table(LAB_CSV)
    assert c.header == ("x", "y", "theta", "s1", "s2", "s3", "s4")
    assert c.line_numbers == [3, 5] and c.rows[1][6] == ""
    s = table(["1;2;3", "4;5;6"])
    assert s.rows[1] == ["4", "5", "6"]
    w = table(["a,b c", "1 2"], delimiter="whitespace")
    assert (w.header, w.rows) == (("a,b", "c"), [["1", "2"]])


def test_column_specs_are_one_based_ranges_or_header_names():
    c = table(LAB_CSV)
    assert resolve_columns("1,2,3", c, "k") == [0, 1, 2]
    assert resolve_columns("4-", c, "k") == [3, 4, 5, 6]
    assert resolve_columns("x,theta,5-6", c, "k") == [0, 2, 4, 5]
    with pytest.raises(InputError, match=r"t.txt: k: column '8' is outside 1..7"):
        resolve_columns("8", c, "k")
    with pytest.raises(InputError, match=r"header names x, y, theta"):
        resolve_columns("z", c, "k")


def test_units_no_echo_max_range_and_invalid_readings():
    opts = TextOptions(range_unit="mm", position_unit="cm", angle_unit="ddeg", no_echo=(5000.0,), max_range=5.0)
    log = build_text_log(table(LAB_CSV), options=opts).log
    assert_allclose(log.pose, [[1.0, 2.0, HALF_PI], [1.5, 2.0, -math.pi / 4]])
    expected = np.array([[1.0, np.inf, np.nan, 2.5], [np.inf, 0.02, 0.0, np.nan]], dtype=np.float32)
    assert_array_equal(log.ranges, expected)  # 5000 = no echo; 6000 mm >= 5 m; -1 and an empty cell invalid
    assert_array_equal(log.time, [0.0, 1.0])
    assert_allclose(log.sensor.mount[:, 2], [0, HALF_PI, -math.pi, -HALF_PI], atol=1e-12)  # default: ring of 4


@pytest.mark.parametrize(
    ("unit", "value", "expected"), [("rad", "1.5", 1.5), ("deg", "90", HALF_PI), ("ddeg", "-1800", -math.pi)]
)
def test_angle_units(unit, value, expected):
    log = build_text_log(table([f"0 0 {value} 1"]), options=TextOptions(angle_unit=unit)).log
    assert log.pose[0, 2] == pytest.approx(expected)


@pytest.mark.parametrize(("unit", "scale"), [("mm", 0.001), ("cm", 0.01), ("m", 1.0)])
def test_length_units(unit, scale):
    log = build_text_log(
        table(["10 20 0 300"]), options=TextOptions(range_unit=unit, position_unit=unit, max_range=1000)
    ).log
    assert_allclose(log.pose[0, :2], [10 * scale, 20 * scale])
    assert log.ranges[0, 0] == pytest.approx(300 * scale)


def test_bearings_ring_specs_lists_and_radius():
    assert_allclose(np.degrees(parse_bearings("ring:4:45", 4)), [45, 135, -135, -45])
    assert_allclose(np.degrees(parse_bearings("ring:3:-90:90", 3)), [-90, 0, 90])
    assert_allclose(parse_bearings("ring:4:0:900", 4, "ddeg"), [0, HALF_PI, -math.pi, -HALF_PI])
    assert_allclose(np.degrees(parse_bearings("90, 50,-90", 3)), [90, 50, -90])
    with pytest.raises(InputError, match=r"bearings: 3 bearings for 4 range columns"):
        parse_bearings("1,2,3", 4)
    with pytest.raises(InputError, match=r"bearings: expected 'ring'"):
        parse_bearings("north,south", 2)
    log = build_text_log(table(["0 0 0 1 1"]), options=TextOptions(bearings="90,-90", sensor_radius=0.2)).log
    assert_allclose(log.sensor.mount, [[0, 0.2, HALF_PI], [0, -0.2, -HALF_PI]], atol=1e-12)


def test_sensor_attributes_follow_the_options():
    opts = TextOptions(kind="laser", beam_width=0.01, min_range=0.05, max_range=30.0, noise_sigma=0.03)
    s = build_text_log(table(["0 0 0 1"]), options=opts).log.sensor
    assert (s.kind, s.beam_width, s.min_range, s.max_range, s.noise_sigma) == ("laser", 0.01, 0.05, 30.0, 0.03)


def test_without_options_the_sensor_has_the_sonar_defaults_of_every_log(tmp_path):
    """Defaults written once, as ``SensorSpec``'s: the options' and the command's are the same."""
    sensors = [build_text_log(table(["0 0 0 1 2"])).log.sensor]
    data, out = tmp_path / "plain.txt", tmp_path / "plain.h5"
    data.write_text("0 0 0 1 2\n")
    res = CliRunner().invoke(main, ["import", "text", "--ranges", str(data), "-o", str(out), "-q"])
    assert res.exit_code == 0, res.output
    sensors.append(read_log(out).sensor)
    for s in sensors:
        assert s.kind == "sonar"
        for key in ("beam_width", "min_range", "max_range", "noise_sigma"):
            assert getattr(s, key) == getattr(SensorSpec, key), key


def test_separate_pose_table_row_by_row_or_by_time():
    ranges = table(["t r1 r2", "1.0 1 2", "2.0 3 4", "9.0 1 1"])
    poses = table(["0.0 0 0 0", "4.0 4 8 2.0"])
    opts = TextOptions(range_time_column="t", pose_time_column="1", pose_columns="2-4")
    result = build_text_log(ranges, poses, opts)
    assert result.outside == 1 and result.notes
    assert_array_equal(result.log.time, [1.0, 2.0])
    assert_allclose(result.log.pose, [[1, 2, 0.5], [2, 4, 1.0]])
    assert_array_equal(result.log.ranges, np.array([[1, 2], [3, 4]], dtype=np.float32))
    rows = build_text_log(table(["1 2", "3 4"]), table(["0 0 0", "1 1 1"])).log
    assert_allclose(rows.pose[:, 0], [0, 1])
    with pytest.raises(InputError, match=r"poses: 1 pose rows for 2 range rows"):
        build_text_log(table(["1 2", "3 4"]), table(["0 0 0"]))


def test_time_column_and_units_in_one_file():
    log = build_text_log(
        table(["1500 0 0 0 1", "2500 1 0 0 1"]),
        options=TextOptions(pose_columns="2-4", pose_time_column="1", time_unit="ms"),
    ).log
    assert_array_equal(log.time, [1.5, 2.5])
    assert log.sensor.count == 1  # the time column is not a range column


def test_bad_lines_name_the_line_and_column():
    with pytest.raises(InputError) as info:
        build_text_log(table(["x y theta s1", "0 0 0 1", "0 zero 0 1"]))
    assert str(info.value) == "t.txt: y: line 3: expected a number, got 'zero'"
    with pytest.raises(InputError, match=r"^t.txt: column 4: line 1: expected a number, got 'far'$"):
        build_text_log(table(["0 0 0 far"]))
    with pytest.raises(InputError, match=r"^t.txt: line 3: expected 4 columns \(as on line 1\), got 3$"):
        table(["0 0 0 1", "# gap", "0 0 0"])
    with pytest.raises(InputError, match=r"^t.txt: y: line 2: expected a finite number, got 'nan'$"):
        build_text_log(table(["x,y,theta,s", "0,nan,0,1"]))
    with pytest.raises(InputError, match="no data rows"):
        table(["# only a comment", "x y"])


def test_option_errors():
    with pytest.raises(InputError, match=r"pose_columns: expected 3 pose columns"):
        build_text_log(table(["0 0 0 1"]), options=TextOptions(pose_columns="1,2"))
    with pytest.raises(InputError, match=r"range_columns: column 1 is both a range column and a pose"):
        build_text_log(table(["0 0 0 1"]), options=TextOptions(range_columns="1,4"))
    with pytest.raises(InputError, match=r"range_unit: expected one of mm, cm, m"):
        build_text_log(table(["0 0 0 1"]), options=TextOptions(range_unit="ft"))


def test_import_text_files_and_cli(tmp_path):
    data = tmp_path / "lab.csv"
    data.write_text("\n".join(LAB_CSV) + "\n")
    result = import_text(data, options=TextOptions(range_unit="mm", position_unit="cm", angle_unit="ddeg"))
    assert result.log.source == "aogm import text lab.csv" and result.log.n_scans == 2
    mounts = tmp_path / "mounts.txt"
    mounts.write_text("10 0 0\n0 10 90\n-10 0 180\n0 -10 -90\n")
    out = tmp_path / "lab.h5"
    args = [
        "import",
        "text",
        "--ranges",
        str(data),
        "-o",
        str(out),
        "--range-unit",
        "mm",
        "--position-unit",
        "cm",
        "--angle-unit",
        "ddeg",
        "--no-echo",
        "5000",
        "--mounts",
        str(mounts),
        "--beam-width",
        "25",
        "-q",
    ]
    res = CliRunner().invoke(main, args)
    assert res.exit_code == 0, res.output
    log = read_log(out)
    assert np.isinf(log.ranges[0, 1]) and log.sensor.beam_width == pytest.approx(math.radians(25))
    assert_allclose(
        log.sensor.mount, [[0.1, 0, 0], [0, 0.1, HALF_PI], [-0.1, 0, -math.pi], [0, -0.1, -HALF_PI]], atol=1e-12
    )
    bad = tmp_path / "bad.txt"
    bad.write_text("0 0 0 1\n0 0 0 x\n")
    out2 = tmp_path / "bad.h5"
    res = CliRunner().invoke(main, ["import", "text", "--ranges", str(bad), "-o", str(out2)])
    assert res.exit_code == 2 and "bad.txt: column 4: line 2: expected a number, got 'x'" in res.output
    assert not out2.exists()
    res = CliRunner().invoke(main, ["import", "text", "--ranges", str(data), "-o", str(out2), "--bearings", "1,2"])
    assert res.exit_code == 2 and "--bearings: 2 bearings for 4 range columns" in res.output


@pytest.mark.parametrize("option", [
    ["--max-range", "nan"], ["--max-range", "inf"], ["--max-range", "0"], ["--min-range", "6", "--max-range", "5"],
    ["--bearings", "nan,0,10,20"], ["--beam-width", "180"], ["--beam-width", "0"], ["--noise-sigma", "nan"],
    ["--noise-sigma", "-1"], ["--range-unit", "furlong"], ["--no-echo", "nan"], ["--sensor-radius", "nan"],
])
def test_bad_text_options_are_refused_naming_the_option(tmp_path, option):
    f = tmp_path / "lab.txt"
    f.write_text("0 0 0 1 2 3 4\n1 0 0 1 2 3 4\n")
    r = CliRunner().invoke(main, ["import", "text", "--ranges", str(f), "-o", str(tmp_path / "x.h5"), *option])
    assert r.exit_code == 2, r.output
    assert option[0] in r.output and "Traceback" not in r.output


def test_a_byte_order_mark_before_a_text_table_is_not_a_cell(tmp_path):
    f = tmp_path / "lab.csv"
    f.write_bytes(b"\xef\xbb\xbf" + b"x,y,theta,s1\n0,0,0,1\n1,0,0,2\n")
    r = CliRunner().invoke(main, ["import", "text", "--ranges", str(f), "-o", str(tmp_path / "x.h5")])
    assert r.exit_code == 0, r.output
    assert read_log(tmp_path / "x.h5").n_scans == 2
