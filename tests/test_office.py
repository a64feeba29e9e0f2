"""The generated office floor (aogm_cli/world/office.py): a valid world file with exactly the scans
asked for, the same floor for a seed at any length, and a path the robot fits along."""

import numpy as np
import pytest
import yaml
from scipy import ndimage

from aogm_cli.evaluation.metrics import run_checks
from aogm_cli.world.loader import parse_world
from aogm_cli.world.office import DOOR_WIDTHS, ROBOT_RADIUS, office_spec, office_yaml
from aogm_cli.world.trajectory import trajectory_poses
from aogm_cli.world.truth import truth_occupancy


def world_of(scans: int, seed: int = 1):
    text = office_yaml(office_spec(scans, seed), "a comment")
    return parse_world(yaml.safe_load(text), file="office.yaml", text=text)


@pytest.mark.parametrize("scans", [2, 3, 137, 2000, 10000])
def test_the_trajectory_makes_exactly_the_scans_asked_for(scans):
    assert len(trajectory_poses(world_of(scans))[0]) == scans


def test_the_yaml_reads_back_as_the_spec():
    spec = office_spec(500)
    assert yaml.safe_load(office_yaml(spec)) == spec


def test_the_floor_is_the_papers_office_at_any_length():
    world = world_of(2000)
    grid, _ = truth_occupancy(world)
    assert grid.shape == (820, 1220)
    assert len(world.sonar.mounts) == 24
    doors = [o.width for w in world.walls for o in w.openings]
    assert len(doors) == 40
    assert min(doors) >= DOOR_WIDTHS[0] and max(doors) <= DOOR_WIDTHS[1]
    assert sum(w.surface == "glass" for w in world.walls) >= 5
    assert len(world.boxes) > 100 and len(world.circles) > 100
    short, long = office_spec(2000), office_spec(10000)
    for key in ("walls", "boxes", "circles"):
        assert short[key] == long[key]
    assert short["trajectory"]["waypoints"][:-1] == long["trajectory"]["waypoints"][: len(short["trajectory"]["waypoints"]) - 1]
    assert office_spec(2000, seed=2)["walls"] != short["walls"]
    assert office_yaml(office_spec(2000)) == office_yaml(short)


def test_the_robot_fits_along_its_path_and_the_checks_pass_on_the_truth():
    world = world_of(10000)
    grid, occ = truth_occupancy(world)
    _, pose = trajectory_poses(world)
    clearance = ndimage.distance_transform_edt(occ == 0) * grid.resolution
    rows, cols = (np.asarray(v, dtype=int) for v in grid.world_to_cell(pose[:, 0], pose[:, 1]))
    assert clearance[rows, cols].min() > ROBOT_RADIUS
    checks = [c.as_json() for c in world.checks]
    results = run_checks(grid, occ.astype(float), np.ones(occ.shape, dtype=bool), checks)
    assert all(r["passed"] for r in results), results
