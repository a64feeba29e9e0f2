"""Consistency of a map with its log (logs without truth): endpoints and sonar arcs on hand-made
maps, the shares, the log loop, and ``aogm compare`` on a log without truth."""

import json
import math

import numpy as np
import pytest
from click.testing import CliRunner
from numpy.testing import assert_array_equal

from aogm_cli.cli import main
from aogm_cli.core.grid import GridSpec
from aogm_cli.core.log import Log, SensorSpec
from aogm_cli.evaluation.consistency import (
    AGREES,
    CONTRADICTS,
    NOT_COUNTED,
    UNKNOWN,
    arc_status,
    believed_free,
    believed_occupied,
    endpoint_status,
    log_consistency,
    reading_endpoints,
    summarize,
    with_neighbours,
)
from aogm_cli.io.logfile import LogReader, write_log
from aogm_cli.mapping.standard import standard_map
from aogm_cli.sensor_models.readings import cone_templates as standard_templates

LASER = SensorSpec(np.array([[0.1, 0.0, 0.0]]), "laser", math.radians(0.5), 0.0, 4.0, 0.01)
GRID = GridSpec(0.0, 0.0, 0.1, 6, 8)


def test_believed_cells_and_neighbours():
    p = np.array([[0.9, 0.5, 0.1], [0.6, 0.4, 0.5]])
    obs = np.array([[True, True, True], [False, True, True]])
    assert_array_equal(believed_occupied(p, obs), [[1, 0, 0], [0, 0, 0]])
    assert_array_equal(believed_free(p, obs), [[0, 0, 1], [0, 1, 0]])
    grown = with_neighbours(np.pad([[True]], 2))
    assert grown.sum() == 9 and grown[1:4, 1:4].all()


def test_endpoints_from_the_sensor_pose():
    # robot at (0.25, 0.15) facing +y; the laser 0.1 m ahead, at (0.25, 0.25)
    pose = np.array([[0.25, 0.15, math.pi / 2]])
    rows, cols, counted = reading_endpoints(pose, np.array([[0.3]]), LASER, GRID)
    assert (rows[0, 0], cols[0, 0], counted[0, 0]) == (5, 2, True)  # (0.25, 0.55)
    for z in (np.inf, np.nan, 4.0, -1.0):  # no echo, invalid, at max range, negative
        assert not reading_endpoints(pose, np.array([[z]]), LASER, GRID)[2][0, 0]
    assert not reading_endpoints(np.array([[np.nan, 0.1, 0.0]]), np.array([[0.3]]), LASER, GRID)[2][0, 0]


def test_endpoint_status_on_a_hand_made_map():
    occupied = np.zeros((3, 3), bool)
    free = np.zeros((3, 3), bool)
    occupied[0, 0] = True
    free[0, 1] = True  # (0, 2) and the others: unobserved
    rows = np.array([0, 0, 0, 5, 0])
    cols = np.array([0, 1, 2, 0, 0])
    counted = np.array([True, True, True, True, False])
    status = endpoint_status(occupied, free, rows, cols, counted)
    assert_array_equal(status, [AGREES, CONTRADICTS, UNKNOWN, UNKNOWN, NOT_COUNTED])
    status_8 = endpoint_status(with_neighbours(occupied), free, rows, cols, counted)
    assert_array_equal(status_8, [AGREES, AGREES, UNKNOWN, UNKNOWN, NOT_COUNTED])
    contradicted = np.zeros((3, 3), bool)
    contradicted[0, 1] = True
    c = summarize(status, status_8, contradicted, free, "endpoint")
    assert c == {"method": "endpoint", "readings": 4, "endpoint_occupied": 0.25, "endpoint_occupied_8": 0.5,
                 "endpoint_free": 0.25, "free_cells": 1, "free_contradicted": 1.0}


def test_nothing_counted_gives_null_shares():
    empty = np.zeros(0, np.int8)
    c = summarize(empty, empty, np.zeros((2, 2), bool), np.zeros((2, 2), bool), "endpoint")
    assert c["readings"] == 0 and c["endpoint_occupied"] is None and c["free_contradicted"] is None


# the sonar case of test_standard: a 30 deg cone from the centre of cell (5, 2) of an 11 x 11
# grid at 0.1 m, pointing +x; a logged 0.45 m (0.5 m after the half-cell shift of
# readings.echo_ranges, which standard_map and the re-cast both apply) with alpha 0.1 marks
# cells (5, 7), (4, 7), (6, 7) occupied.
SONAR = SensorSpec(np.zeros((1, 3)), "sonar", math.radians(30.0), 0.05, 5.0)
SONAR_GRID = GridSpec(0.0, 0.0, 0.1, 11, 11)
ARC = [(5, 7), (4, 7), (6, 7)]


def sonar_status(occupied, free, z=0.45):
    templates = standard_templates(SONAR_GRID, SONAR)
    contradicted = np.zeros(SONAR_GRID.shape, bool)
    status = arc_status(occupied, free, (np.array([[0.25, 0.55, 0.0]]), np.array([[z]])), SONAR, SONAR_GRID,
                        templates, 0.1, contradicted)
    return int(status[0, 0]), {(int(r), int(c)) for r, c in zip(*np.nonzero(contradicted), strict=True)}


def test_sonar_arc_is_the_standard_mappers_occupied_arc():
    from aogm_cli.sensor_models.inverse_model import InverseModelConfig

    log_odds, _ = standard_map([(0, None, np.array([[0.25, 0.55, 0.0]]), np.array([[0.45]], np.float32))],
                               SONAR, SONAR_GRID, InverseModelConfig(alpha=0.1, model="constant"))
    assert {(int(r), int(c)) for r, c in zip(*np.nonzero(log_odds > 0), strict=True)} == set(ARC)


def test_sonar_arc_status_on_hand_made_maps():
    free = np.ones(SONAR_GRID.shape, bool)
    occupied = np.zeros(SONAR_GRID.shape, bool)
    # every arc cell believed free: the reading contradicts the map on all three
    assert sonar_status(occupied, free) == (CONTRADICTS, set(ARC))
    # one arc cell occupied: it agrees, nothing is contradicted
    occupied[4, 7], free[4, 7] = True, False
    assert sonar_status(occupied, free) == (AGREES, set())
    # no arc cell occupied, one unobserved: neither; the believed-free ones are contradicted
    occupied[4, 7] = False
    assert sonar_status(occupied, free) == (UNKNOWN, {(5, 7), (6, 7)})
    # a max-range reading is not counted
    assert sonar_status(occupied, free, z=np.inf) == (NOT_COUNTED, set())


def laser_log(tmp_path, truth=None):
    """Four readings of one scan from (0.25, 0.15) facing +y (laser at (0.25, 0.25)), beams at
    -90, 0, +90 deg and 0 deg again: see ``test_log_consistency_of_a_hand_made_map``."""
    mount = np.array([[0.1, 0.0, -math.pi / 2], [0.1, 0.0, 0.0], [0.1, 0.0, math.pi / 2], [0.1, 0.0, 0.0]])
    sensor = SensorSpec(mount, "laser", math.radians(0.5), 0.0, 4.0, 0.01)
    pose = np.array([[0.25, 0.15, math.pi / 2]])
    ranges = np.array([[0.2, 0.3, 0.2, np.inf]], dtype=np.float32)
    path = tmp_path / "bare.h5"
    write_log(path, Log(np.zeros(1), pose, ranges, sensor, source="test", truth=truth))
    return path


def test_log_consistency_of_a_hand_made_map(tmp_path):
    # endpoints: -90 deg (facing +x) -> (0.45, 0.25) = cell (2, 4); 0 deg -> (0.25, 0.55) = (5, 2);
    # +90 deg -> (0.05, 0.25) = (2, 0); the fourth reading has no echo
    path = laser_log(tmp_path)
    probability = np.full(GRID.shape, 0.2, np.float32)
    observed = np.ones(GRID.shape, bool)
    probability[2, 4] = 0.9  # agrees
    probability[5, 3] = 0.9  # (5, 2) is free but next to an occupied cell
    observed[2, 0] = False  # unknown
    with LogReader(path) as reader:
        c = log_consistency(reader, GRID, probability, observed)
    n_free = GRID.height * GRID.width - 3
    assert c == {"method": "endpoint", "readings": 3, "endpoint_occupied": pytest.approx(1 / 3),
                 "endpoint_occupied_8": pytest.approx(2 / 3), "endpoint_free": pytest.approx(1 / 3),
                 "free_cells": n_free, "free_contradicted": pytest.approx(1 / n_free)}


def test_compare_reports_consistency_for_a_log_without_truth(tmp_path):
    path = laser_log(tmp_path)
    out = tmp_path / "r.json"
    result = CliRunner().invoke(main, ["compare", str(path), "--modes", "standard", "--json", str(out), "-q"])
    assert result.exit_code == 0, result.output
    assert "Ends on occ." in result.output and "Free contra." in result.output
    (r,) = json.loads(out.read_text())["results"]
    # no truth: no accuracy, only what a planner sees against the standard map (itself)
    assert r["metrics"] == {"walls_kept": 1.0, "leak_vs_standard": 0.0, "far_leak": 0.0}
    c = r["consistency"]
    assert c["method"] == "endpoint" and c["readings"] == 3
    # the standard map of its own three rays puts every endpoint on an occupied cell
    assert c["endpoint_occupied"] == 1.0 and c["endpoint_occupied_8"] == 1.0 and c["free_contradicted"] == 0.0
