"""Every bundled world drives as a robot does: aogm check's pose and time limits hold along
each trajectory (issue 23: the check reports nothing on the clean bundled logs)."""

from pathlib import Path

import pytest

from aogm_cli.report.log_check import CheckLimits, _poses, _time
from aogm_cli.world.loader import load_world
from aogm_cli.world.trajectory import trajectory_poses

WORLDS = sorted((Path(__file__).resolve().parent.parent / "worlds").glob("*.yaml"))


@pytest.mark.parametrize("path", WORLDS, ids=[p.stem for p in WORLDS])
def test_a_bundled_world_turns_and_drives_within_the_checks_limits(path):
    time, pose = trajectory_poses(load_world(path))
    limits = CheckLimits()
    motion, clock = _poses(time, pose, limits), _time(time, limits)
    assert motion["turns"] == 0, f"turns at {motion['fastest_turn']:.2f} rad/s (limit {limits.max_turn})"
    assert motion["jumps"] == 0 and clock["gaps"] == 0 and clock["backwards"] == 0


def test_the_limits_catch_a_waypoint_turned_between_two_scans():
    import numpy as np

    time = np.arange(3) * 0.5
    pose = np.array([[0.0, 0.0, 0.0], [0.15, 0.0, 0.0], [0.15, 0.0, np.pi / 2]])  # 90 deg in 0.5 s
    assert _poses(time, pose, CheckLimits())["turns"] == 1
