"""World files: the bundled worlds load; bad input names the file and the key path."""

import math
from pathlib import Path

import numpy as np
import pytest
import yaml
from click.testing import CliRunner

from aogm_cli.cli import main
from aogm_cli.core.errors import InputError
from aogm_cli.core.log import SensorSpec
from aogm_cli.evaluation.metrics import run_checks
from aogm_cli.world.config import BlockedCheck
from aogm_cli.world.loader import load_world, parse_world
from aogm_cli.world.truth import truth_occupancy

WORLDS = sorted((Path(__file__).resolve().parents[1] / "worlds").glob("*.yaml"))


def minimal(**over):
    raw = {
        "bounds": [0, 0, 10, 5],
        "walls": [{"points": [[0, 0], [10, 0]], "thickness": 0.1}],
        "trajectory": {"waypoints": [[1, 1], [9, 1]]},
    }
    raw.update(over)
    return raw


def error_of(raw) -> str:
    with pytest.raises(InputError) as info:
        parse_world(raw, file="w.yaml")
    return str(info.value)


def test_at_least_eight_bundled_worlds_load():
    assert len(WORLDS) >= 8
    for path in WORLDS:
        world = load_world(path)
        assert world.checks, f"{path.name} has no checks"
        assert world.sonar is not None


def test_seed_worlds_are_the_papers():
    door = load_world(WORLDS[0].parent / "corridor_door.yaml")
    assert door.robot.radius == 0.25
    (wall,) = [w for w in door.walls if w.openings]
    assert wall.openings[0].width == pytest.approx(2 * 2 * door.robot.radius)
    assert [c.name for c in door.checks] == ["door_passable", "behind_wall_west", "behind_wall_east"]
    spec = load_world(WORLDS[0].parent / "corridor_specular.yaml")
    assert min(s.specular_threshold for s in spec.surfaces.values()) < math.radians(25)
    assert [c.name for c in spec.checks] == ["corridor_passable", "behind_upper_wall", "behind_lower_wall"]


def test_defaults_give_a_24_sonar_ring():
    w = parse_world(minimal(), file="w.yaml")
    assert len(w.sonar.mounts) == 24
    yaws = [m[2] for m in w.sonar.mounts]
    assert yaws[1] - yaws[0] == pytest.approx(2 * math.pi / 24)
    assert w.sonar.beam_width == pytest.approx(math.radians(30))
    assert w.surfaces["rough"].specular_threshold == pytest.approx(math.pi / 2)


def test_a_world_without_sonar_has_the_sonar_defaults_of_every_log():
    """The beam's defaults are written once, as ``SensorSpec``'s field defaults."""
    w = parse_world(minimal(), file="w.yaml")
    for key in ("beam_width", "min_range", "max_range", "noise_sigma"):
        assert getattr(w.sonar, key) == getattr(SensorSpec, key), key
    assert SensorSpec.beam_width == math.radians(30.0)


def test_negative_thickness_names_the_key_path():
    raw = minimal(walls=[{"points": [[0, 0], [1, 0]]}, {"points": [[0, 1], [1, 1]], "thickness": -0.1}])
    assert error_of(raw) == "w.yaml: walls[1].thickness: expected a positive number, got -0.1"


def test_misspelled_key_is_named_with_a_suggestion():
    raw = minimal(sonar={"beam_widht_deg": 30})
    msg = error_of(raw)
    assert msg.startswith("w.yaml: sonar.beam_widht_deg: unknown key")
    assert "beam_width_deg" in msg


def test_zero_sensors_and_trajectory_outside_world():
    assert "sonar.count" in error_of(minimal(sonar={"count": 0}))
    msg = error_of(minimal(trajectory={"waypoints": [[1, 1], [12, 1]]}))
    assert "trajectory.waypoints[1]" in msg and "inside bounds" in msg


def test_unknown_surface_and_missing_required_keys():
    assert "walls[0].surface: unknown surface 'glass'" in error_of(
        minimal(walls=[{"points": [[0, 0], [1, 0]], "surface": "glass"}])
    )
    raw = minimal()
    del raw["bounds"]
    assert "bounds: missing" in error_of(raw)


def test_opening_beyond_wall_length_and_bad_check():
    msg = error_of(minimal(walls=[{"points": [[0, 0], [4, 0]], "openings": [{"at": 5, "width": 1}]}]))
    assert "walls[0].openings[0].at" in msg
    msg = error_of(minimal(checks=[{"name": "a", "passable": {"from": [1, 1], "to": [20, 1]}}]))
    assert "checks[0].passable.to" in msg


def test_explicit_poses_and_mounts_in_degrees():
    w = parse_world(
        minimal(trajectory={"poses": [[1, 1, 90]]}, sonar={"mounts": [[0.1, 0, 0], [0, 0.1, 90]]}), file="w.yaml"
    )
    assert w.trajectory.poses[0][2] == pytest.approx(math.pi / 2)
    assert w.sonar.mounts[1][2] == pytest.approx(math.pi / 2)


def test_malformed_yaml_names_the_file_and_line(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("bounds: [0, 0, 1\nwalls: x\n")
    with pytest.raises(InputError) as info:
        load_world(bad)
    assert str(bad) in str(info.value) and "line" in str(info.value)


def test_missing_file():
    with pytest.raises(InputError, match="no such file"):
        load_world("does/not/exist.yaml")


def test_every_bundled_world_has_a_blocked_check_and_its_truth_passes_every_check():
    """Each bundled world says where a map must hold a wall (``blocked``), and the truth raster
    itself, as a map (observed everywhere), passes every passable and blocked check."""
    for path in WORLDS:
        world = load_world(path)
        assert any(isinstance(c, BlockedCheck) for c in world.checks), f"{path.name} has no blocked check"
        grid, occupancy = truth_occupancy(world)
        checks = [c.as_json() for c in world.checks]
        failed = [c["name"] for c in run_checks(grid, occupancy, np.ones(grid.shape, bool), checks) if not c["passed"]]
        assert not failed, f"{path.name}: {failed} fail on the truth"


def test_a_blocked_check_reads_and_bad_ones_name_the_key_path(tmp_path):
    check = {"name": "wall", "blocked": {"from": [1, 1], "to": [1, 4]}}
    (parsed,) = parse_world(minimal(checks=[check]), file="w.yaml").checks
    assert isinstance(parsed, BlockedCheck) and parsed.robot_radius == 0.25  # the robot's, as for passable
    assert parsed.as_json() == {"name": "wall", "blocked": {"from": [1.0, 1.0], "to": [1.0, 4.0], "robot_radius": 0.25}}
    assert "checks[0].blocked.to: expected a point inside bounds" in error_of(
        minimal(checks=[{"name": "a", "blocked": {"from": [1, 1], "to": [20, 1]}}]))
    both = {"name": "a", "blocked": check["blocked"], "passable": check["blocked"]}
    assert "checks[0]: expected exactly one of 'passable' or 'blocked'" in error_of(minimal(checks=[both]))
    assert "checks[0]: expected exactly one" in error_of(minimal(checks=[{"name": "a"}]))
    world = minimal(checks=[{"name": "a", "blocked": {"from": [1, 1], "to": [1, 4], "robot_radius": -0.2}}])
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(world))
    result = CliRunner().invoke(main, ["simulate", str(path), "-o", str(tmp_path / "log.h5")])
    assert result.exit_code == 2 and "Traceback" not in result.output
    assert f"{path}: checks[0].blocked.robot_radius: " in result.output and not (tmp_path / "log.h5").exists()
