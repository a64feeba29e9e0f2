"""``aogm check`` (issue 23): each fault injected into a simulated log (corridor_door, seed 1, edited
and written back with the log writer) is named; the clean bundled logs warn only where the warning
is real; table, --json, --strict; the same summary at the end of every import."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from aogm_cli.cli import main
from aogm_cli.core.log import sensor_names
from aogm_cli.io.logfile import read_log, write_log
from aogm_cli.report.log_check import CheckLimits, check_log
from aogm_cli.world.loader import load_world

ROOT = Path(__file__).resolve().parents[1]
WORLDS = sorted((ROOT / "worlds").glob("*.yaml"))


def run(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


@pytest.fixture(scope="module")
def door(corridor_door_log):
    return read_log(corridor_door_log)


def stuck(log):
    r = log.ranges.copy()
    r[:, 5] = np.float32(1.234)
    return dataclasses.replace(log, ranges=r)


def disabled(log):
    r = log.ranges.copy()
    r[:, 7] = np.nan
    return dataclasses.replace(log, ranges=r)


def pose_jump(log):
    pose = log.pose.copy()
    pose[60:, 1] += 3.0  # 3 m sideways in one 0.5 s step
    return dataclasses.replace(log, pose=pose)


def time_backwards(log):
    time = log.time.copy()
    time[[70, 71]] = time[[71, 70]]
    return dataclasses.replace(log, time=time)


def inside_robot(log):
    r = log.ranges.copy()  # sonar 9 at 0.25 m from the centre reads 0.15-0.25 m: inside the robot
    r[:, 9] = np.random.default_rng(1).uniform(0.15, 0.25, r.shape[0]).astype(np.float32)
    return dataclasses.replace(log, ranges=r)


def below_min_range(log):
    r = log.ranges.copy()
    r[::4, 2] = np.float32(0.05)
    return dataclasses.replace(log, ranges=r)


FAULTS = [
    ("stuck", stuck, "stuck", "sensor 5: every valid reading is 1.234 m while the robot moves"),
    ("disabled", disabled, "disabled", "sensor 7: no valid echo in 121 scans: disabled?"),
    ("pose_jump", pose_jump, "pose_jump", "the pose jumps faster than 2 m/s once (first from scan 59 to 60"),
    ("time_backwards", time_backwards, "time_backwards", "time runs backwards once (first from scan 70 to 71)"),
    ("inside_robot", inside_robot, "inside_robot", "sensor 9: 100% of the valid readings inside the robot"),
    ("below_min_range", below_min_range, "below_min_range", "sensor 2: 26% of the valid readings closer than"),
]


@pytest.mark.parametrize("edit,kind,message", [f[1:] for f in FAULTS], ids=[f[0] for f in FAULTS])
def test_each_injected_fault_is_named(door, tmp_path, edit, kind, message):
    path = tmp_path / "bad.h5"
    write_log(path, edit(door))
    result = run("check", path)
    assert result.exit_code == 0, result.output  # warnings are not errors
    assert f"warning: {message}" in result.output, result.output
    kinds = [w["kind"] for w in json.loads(run("check", path, "--json").output)["warnings"]]
    assert kind in kinds
    assert run("check", path, "--strict").exit_code == 3
    assert check_log(door).warnings == []  # the fault, not the log, made the warning


def test_the_clean_log_passes_strict_and_its_table_and_json_agree(door, tmp_path):
    path = tmp_path / "door.h5"
    write_log(path, door)
    table = run("check", path, "--strict")
    assert table.exit_code == 0 and "warnings: none" in table.output, table.output
    assert "grid: 130 x 420 cells at 0.05 m (the truth grid)" in table.output
    data = json.loads(run("check", path, "--json").output)
    assert data["scans"] == 121 and len(data["sensors"]) == 24 and data["warnings"] == []
    assert data["poses"]["fastest_speed"] == pytest.approx(0.3)


def test_thresholds_are_options(door, tmp_path):
    path = tmp_path / "door.h5"
    write_log(path, door)
    slow = run("check", path, "--max-speed", "0.2", "--strict")
    assert slow.exit_code == 3 and "faster than 0.2 m/s 120 times" in slow.output
    assert run("check", path, "--max-speed", "0").exit_code == 2  # must be positive
    assert run("check", path, "--resolution", "1e-300").exit_code == 2


def turns_in_place(world) -> bool:
    """Does the world's trajectory turn at a waypoint without turn_rate_deg (in no time)?"""
    traj = world.trajectory
    if traj.poses or traj.turn_rate > 0:
        return False
    from aogm_cli.world.trajectory import Polyline

    return bool(np.any(np.abs(Polyline(traj.waypoints).turns()) > 1e-9))


@pytest.fixture(scope="module")
def bundled(tmp_path_factory):
    folder = tmp_path_factory.mktemp("bundled")
    result = run("simulate", *WORLDS, "--seeds", "1", "-o", f"{folder}/", "-q")
    assert result.exit_code == 0, result.output
    return folder


@pytest.mark.parametrize("world", WORLDS, ids=[w.stem for w in WORLDS])
def test_the_clean_bundled_logs_warn_only_of_turns_in_place_between_two_scans(bundled, world):
    """The waypoint worlds turn 90 or 180 deg between two scans 0.5 s apart (3.1-6.3 rad/s), which no
    robot does: that warning is real, and it is the only one (worlds turning at turn_rate_deg pass)."""
    result = check_log(read_log(bundled / f"{world.stem}_s1.h5"))
    kinds = {w["kind"] for w in result.warnings}
    assert kinds == ({"turn_jump"} if turns_in_place(load_world(world)) else set()), result.warnings


def test_a_grid_too_large_for_the_log_is_a_warning_naming_the_fix(door):
    pose = door.pose + np.column_stack([np.zeros(door.n_scans), np.linspace(0, 10, door.n_scans), np.zeros(door.n_scans)])
    mm = dataclasses.replace(door, pose=pose * np.array([1000.0, 1000.0, 1.0]), truth=None)  # a 19 x 10 m drive in mm
    warnings = check_log(mm, CheckLimits(max_speed=1e9)).warnings
    assert [w["kind"] for w in warnings] == ["grid_memory"]
    assert "poses or max range in the wrong unit" in warnings[0]["message"]


def test_a_log_without_scans_is_a_warning(door):
    empty = dataclasses.replace(door, time=door.time[:0], pose=door.pose[:0], ranges=door.ranges[:0], truth=None)
    assert [w["kind"] for w in check_log(empty).warnings] == ["no_scans"]


def test_sensor_names():
    assert sensor_names([3]) == "sensor 3"
    assert sensor_names(range(8, 16)) == "sensors 8-15"
    assert sensor_names([0, 2, 8, 9, 10]) == "sensors 0, 2, 8-10"


def test_every_import_ends_with_the_check(tmp_path):
    table = tmp_path / "lab.txt"  # sonar 3 never echoes
    table.write_text("".join(f"{0.1 * k} 0 0 {1 + 0.01 * k} {2 - 0.01 * k} 3.0{k % 2} nan\n" for k in range(20)))
    result = run("import", "text", "--ranges", table, "--sensor-radius", "0.2", "-o", tmp_path / "lab.h5")
    assert result.exit_code == 0, result.output
    assert "warning: sensor 3: no valid echo in 20 scans: disabled?" in result.output
    assert "grid:" in result.output and "poses: fastest 0.1 m/s" in result.output
    quiet = run("import", "text", "--ranges", table, "--sensor-radius", "0.2", "-o", tmp_path / "q.h5", "-q")
    assert quiet.output == f"aogm: warning: {tmp_path / 'q.h5'}: sensor 3: no valid echo in 20 scans: disabled?\n"
    carmen = tmp_path / "c.log"
    carmen.write_text("".join(f"FLASER 3 1.0 2.5 80.0 {k} 2.0 0.5 0.9 1.9 0.4 {10 + k} host {10 + k}\n"
                              for k in range(3)))
    result = run("import", "carmen", carmen, "-o", tmp_path / "c.h5", "--max-range", "30")  # beam 2 reads 80 m
    assert result.exit_code == 0 and "warning: sensor 2: no valid echo in 3 scans" in result.output, result.output


def test_the_json_follows_its_schema_with_and_without_warnings(door, tmp_path, require):
    # docs/schemas/check.schema.json: what scripts may rely on in `aogm check --json`
    jsonschema = require.module("jsonschema")
    schema = json.loads((Path(__file__).resolve().parents[1] / "docs" / "schemas" / "check.schema.json").read_text())
    clean, faulty = tmp_path / "door.h5", tmp_path / "bad.h5"
    write_log(clean, door)
    write_log(faulty, FAULTS[0][1](door))
    for path in (clean, faulty):
        jsonschema.validate(json.loads(run("check", path, "--json").output), schema)
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate({"format": "aogm-check", "scans": -1}, schema)
