"""A Pioneer 3-DX under RosAria (issue 23): /RosAria/sonar clouds of 16 points whose 8 rear sonars
are disabled (RosAria puts their points at the robot's origin), poses as nav_msgs/Odometry
/RosAria/pose. The rear readings are stored as invalid and named in the summary, the standard map
has no phantom wall along the path, ``--mounts p3dx`` is ARIA's table, docs/your-robot.md's example runs as
written, and long imports show a progress bar on a terminal only."""

from __future__ import annotations

import dataclasses
import math
import re
import shlex
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import yaml
from bag_writer import T0, Bag
from click.testing import CliRunner
from numpy.testing import assert_allclose, assert_array_equal

from aogm_cli.cli import main
from aogm_cli.io.importers.mounts import load_mounts, presets
from aogm_cli.io.importers.rosbag import RosbagOptions, read_bag
from aogm_cli.io.importers.rosbag_messages import CONE_TOLERANCE, not_echoes
from aogm_cli.io.logfile import read_log
from aogm_cli.mapping.modes import map_in_mode
from aogm_cli.mapping.params import MapParams
from aogm_cli.simulation.sonar import simulate
from aogm_cli.world.loader import parse_world

ROOT = Path(__file__).resolve().parents[1]
# ARIA's params/p3dx.p, its SonarUnit lines (x mm, y mm, heading deg), written out by hand
P3DX_SONAR_UNITS = [
    (69, 136, 90), (114, 119, 50), (148, 78, 30), (166, 27, 10), (166, -27, -10), (148, -78, -30),
    (114, -119, -50), (69, -136, -90), (-157, -136, -90), (-203, -119, -130), (-237, -78, -150),
    (-255, -27, -170), (-255, 27, 170), (-237, 78, 150), (-203, 119, 130), (-157, 136, 90),
]
REAR = range(8, 16)


@pytest.fixture(scope="module")
def pioneer():
    """corridor_door (seed 1) driven by a P3-DX with all 16 sonars. No random readings: a short
    random reading is a real reading, and this test is about readings that are not."""
    raw = yaml.safe_load((ROOT / "worlds" / "corridor_door.yaml").read_text())
    raw["sonar"] = {"mounts": [[x / 1000, y / 1000, h] for x, y, h in P3DX_SONAR_UNITS], "beam_width_deg": 30,
                    "max_range": 5.0, "noise_sigma": 0.02, "random_rate": 0.0}
    return simulate(parse_world(raw, file="p3dx_corridor.yaml", text=yaml.safe_dump(raw)), seed=1)


def write_rosaria_bag(path: Path, log, disabled=REAR, kind: str = "ros1") -> None:
    """What RosAria records: per scan a nav_msgs/Odometry /RosAria/pose and a sensor_msgs/PointCloud
    /RosAria/sonar of each sonar's echo point in base_link (at max range without an echo); a
    disabled sonar's point at the robot's origin (0, 0, 0)."""
    s = log.sensor
    with Bag(path, kind) as bag:
        for t, pose, row in zip(log.time, log.pose, log.ranges, strict=True):
            stamp = T0 + t
            bag.write("/RosAria/pose", "nav_msgs/msg/Odometry", stamp, bag.odometry(stamp, pose))
            reach = np.where(np.isfinite(row), row, s.max_range).astype(np.float64)
            px = s.mount[:, 0] + reach * np.cos(s.mount[:, 2])
            py = s.mount[:, 1] + reach * np.sin(s.mount[:, 2])
            px[list(disabled)] = py[list(disabled)] = 0.0
            points = [bag.msg("geometry_msgs/msg/Point32", x=float(x), y=float(y), z=0.0)
                      for x, y in zip(px, py, strict=True)]
            bag.write("/RosAria/sonar", "sensor_msgs/msg/PointCloud", stamp,
                      bag.msg("sensor_msgs/msg/PointCloud", header=bag.header(stamp, "base_link"), points=points,
                              channels=[]))


def run(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def occupied_near_poses(log, distance: float = 0.3) -> int:
    """Cells of the standard map above 0.5 within ``distance`` of some pose."""
    m = map_in_mode(log, "standard", MapParams())
    near = m.grid.cells_near(log.pose[:, 0], log.pose[:, 1], distance)
    return int((near & m.observed & (m.probability > 0.5)).sum())


@pytest.fixture(scope="module")
def bag(tmp_path_factory, pioneer):
    path = tmp_path_factory.mktemp("rosaria") / "p3dx.bag"
    write_rosaria_bag(path, pioneer)
    return path


def test_disabled_rear_sonars_are_invalid_named_and_leave_no_phantom_wall(bag, pioneer, tmp_path):
    out = tmp_path / "p3dx.h5"
    result = run("import", "rosbag", bag, "--ranges", "/RosAria/sonar", "--pose", "/RosAria/pose", "--mounts", "p3dx",
                 "-o", out)
    assert result.exit_code == 0, result.output
    log = read_log(out)
    n = pioneer.n_scans
    assert np.isnan(log.ranges[:, 8:]).all()  # the rear points were no echoes
    front = np.where(np.isnan(pioneer.ranges[:, :8]), np.inf, pioneer.ranges[:, :8])
    assert_array_equal(np.isposinf(log.ranges[:, :8]), np.isposinf(front))
    assert_allclose(log.ranges[:, :8], front, rtol=0, atol=1e-5)  # float32 echo points
    assert f"{8 * n} at the robot's origin (sensors 8-15: {n} each)" in result.output
    assert f"warning: sensors 8-15: no valid echo in {n} scans: disabled?" in result.output
    assert "mounts from --mounts p3dx" in log.source
    assert occupied_near_poses(log) == 0
    # what aogm did before: each rear point read as an echo at its distance from the mount
    distance = np.hypot(log.sensor.mount[8:, 0], log.sensor.mount[8:, 1])
    phantom = dataclasses.replace(log, ranges=np.hstack([log.ranges[:, :8], np.tile(distance, (n, 1))]).astype(np.float32))
    assert occupied_near_poses(phantom) > 0


def test_quiet_import_still_warns_of_the_disabled_sonars(bag, tmp_path):
    result = run("import", "rosbag", bag, "--ranges", "/RosAria/sonar", "--pose", "/RosAria/pose", "--mounts", "p3dx",
                 "-o", tmp_path / "q.h5", "-q")
    assert result.exit_code == 0, result.output
    assert result.output.startswith("aogm: warning: ") and "sensors 8-15: no valid echo" in result.output
    assert "REP-117" not in result.output  # the summary itself is quiet


def test_points_outside_their_sonars_cone_are_not_echoes():
    beam = math.radians(30)
    off = np.array([0.0, math.radians(15), 0.5 * beam + CONE_TOLERANCE + 1e-6, math.radians(100), 0.0])
    origin = np.array([False, False, False, False, True])
    assert not_echoes(off, origin, beam).tolist() == [0, 0, 2, 2, 1]


def test_mounts_p3dx_is_the_aria_table_written_out_by_hand(bag, tmp_path):
    table = tmp_path / "p3dx_sonars.txt"
    table.write_text("".join(f"{x / 1000} {y / 1000} {h}\n" for x, y, h in P3DX_SONAR_UNITS))
    logs = []
    for mounts in ("p3dx", table):
        out = tmp_path / f"{Path(str(mounts)).stem}.h5"
        result = run("import", "rosbag", bag, "--ranges", "/RosAria/sonar", "--pose", "/RosAria/pose",
                     "--mounts", mounts, "-o", out, "-q")
        assert result.exit_code == 0, result.output
        logs.append(read_log(out))
    preset, by_hand = logs
    for field in ("time", "pose", "ranges"):
        assert_array_equal(getattr(preset, field), getattr(by_hand, field))
    assert_array_equal(preset.sensor.mount, by_hand.sensor.mount)
    assert preset.sensor.as_dict() == by_hand.sensor.as_dict()
    assert preset.source.replace("--mounts p3dx (aogm's p3dx preset)", "--mounts") == by_hand.source


@pytest.mark.parametrize("preset,count", [("p3dx", 16), ("p3at", 16), ("peoplebot", 32), ("nomad200", 16)])
def test_every_preset_reads_and_names_its_source_in_the_readme(preset, count):
    assert preset in presets()
    mounts, _ = load_mounts(preset)
    assert mounts.shape == (count, 3)
    assert np.all(np.hypot(mounts[:, 0], mounts[:, 1]) < 0.35)  # metres, not millimetres
    readme = (ROOT / "docs" / "your-robot.md").read_text()
    assert re.search(rf"`{preset}`[^\n]*\n?[^\n]*(ARIA|Player)", readme), preset


def test_an_unknown_preset_or_missing_file_names_the_option(bag, tmp_path):
    out = tmp_path / "x.h5"
    result = run("import", "rosbag", bag, "--ranges", "/RosAria/sonar", "--pose", "/RosAria/pose", "--mounts", "p3xd",
                 "-o", out)
    assert result.exit_code == 2 and "p3xd: --mounts: no such file, and not a robot preset" in result.output
    assert "p3dx" in result.output and not out.exists()


def test_the_readmes_p3dx_example_runs_as_written(pioneer, tmp_path, monkeypatch):
    line = next(line.strip() for line in (ROOT / "docs" / "your-robot.md").read_text().splitlines()
                if line.strip().startswith("aogm import rosbag p3dx.bag"))
    args = shlex.split(line)
    assert args[args.index("--mounts") + 1] == "p3dx"
    write_rosaria_bag(tmp_path / "p3dx.bag", pioneer)
    monkeypatch.chdir(tmp_path)
    result = CliRunner().invoke(main, args[1:])
    assert result.exit_code == 0, result.output
    assert read_log(tmp_path / args[args.index("-o") + 1]).n_scans == pioneer.n_scans


class Terminal:
    """A stderr that says it is a terminal and keeps what is written to it."""

    def __init__(self):
        self.text = ""

    def isatty(self):
        return True

    def write(self, s):
        self.text += s

    def flush(self):
        pass


def test_a_bag_import_shows_progress_on_a_terminal_only(bag, pioneer, tmp_path, monkeypatch):
    calls = []
    read_bag(bag, RosbagOptions(ranges=("/RosAria/sonar",), pose="/RosAria/pose"), load_mounts("p3dx")[0],
             progress=lambda n, total: calls.append((n, total)))
    assert sum(n for n, _ in calls) == 2 * pioneer.n_scans and {t for _, t in calls} == {2 * pioneer.n_scans}
    import aogm_cli.cli.options as options

    args = ["import", "rosbag", bag, "--ranges", "/RosAria/sonar", "--pose", "/RosAria/pose", "--mounts", "p3dx"]
    assert "msg/s" not in run(*args, "-o", tmp_path / "a.h5").output  # not a terminal (CliRunner's stderr)
    for quiet, shown in ((False, True), (True, False)):
        terminal = Terminal()
        monkeypatch.setattr(options, "sys", SimpleNamespace(stderr=terminal))
        result = run(*args, "-o", tmp_path / f"{quiet}.h5", *(["-q"] if quiet else []))
        assert result.exit_code == 0, result.output
        assert ("import:" in terminal.text and "msg" in terminal.text) == shown, terminal.text
