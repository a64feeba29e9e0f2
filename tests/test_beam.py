"""Narrow-beam standard mapping: ray traversal cells by hand, the log-odds along a ray, max-range
readings, hit precedence within a scan, chunking, and the dispatch from the standard mapper."""

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from aogm_cli.core.grid import GridSpec
from aogm_cli.core.log import Log, SensorSpec
from aogm_cli.io.logfile import write_log
from aogm_cli.map_files import map_file
from aogm_cli.mapping.beam import BeamMapper
from aogm_cli.mapping.params import MapParams
from aogm_cli.mapping.standard import StandardMapper, _mapper_for, standard_map
from aogm_cli.sensor_models.inverse_model import InverseModelConfig
from aogm_cli.sensor_models.ray import is_narrow_beam, ray_cells

S5 = math.sqrt(5.0)
LASER = SensorSpec(mount=np.zeros((1, 3)), kind="laser", beam_width=math.radians(0.5), min_range=0.0, max_range=5.0)
CONFIG = InverseModelConfig(alpha=0.05)
FREE, OCC = np.float32(-0.41), np.float32(0.85)


def cells(rows, cols):
    return list(zip(rows.tolist(), cols.tolist(), strict=True))


# --- traversal -------------------------------------------------------------------------------


def test_axis_aligned_ray_from_a_cell_centre():
    grid = GridSpec(0.0, 0.0, 0.1, 5, 10)
    rows, cols, t0, t1 = ray_cells(grid, 0.05, 0.25, 0.0, 0.45)
    assert cells(rows, cols) == [(2, 0), (2, 1), (2, 2), (2, 3), (2, 4)]
    assert_allclose(t0, [0.0, 0.05, 0.15, 0.25, 0.35], atol=1e-12)
    assert_allclose(t1, [0.05, 0.15, 0.25, 0.35, 0.45], atol=1e-12)


def test_axis_aligned_ray_backwards_and_downwards():
    grid = GridSpec(0.0, 0.0, 0.1, 5, 10)
    rows, cols, t0, t1 = ray_cells(grid, 0.45, 0.25, math.pi, 0.3)
    assert cells(rows, cols) == [(2, 4), (2, 3), (2, 2), (2, 1)]
    assert_allclose(t1, [0.05, 0.15, 0.25, 0.3], atol=1e-12)
    rows, cols, _, t1 = ray_cells(grid, 0.32, 0.44, -math.pi / 2, 0.25)  # down to y = 0.19
    assert cells(rows, cols) == [(4, 3), (3, 3), (2, 3), (1, 3)]
    assert_allclose(t1, [0.04, 0.14, 0.24, 0.25], atol=1e-12)


def test_oblique_ray_from_a_non_centre_start():
    # res 1: from (0.5, 0.4) along (2, 1)/sqrt 5, u = t / sqrt 5: x = 0.5 + 2u, y = 0.4 + u.
    # column edges x = 1, 2, 3, 4 at u = 0.25, 0.75, 1.25, 1.75; row edges y = 1, 2 at u = 0.6, 1.6
    grid = GridSpec(0.0, 0.0, 1.0, 4, 6)
    rows, cols, t0, t1 = ray_cells(grid, 0.5, 0.4, math.atan2(1, 2), 2.0 * S5)
    assert cells(rows, cols) == [(0, 0), (0, 1), (1, 1), (1, 2), (1, 3), (2, 3), (2, 4)]
    assert_allclose(t0 / S5, [0.0, 0.25, 0.6, 0.75, 1.25, 1.6, 1.75], atol=1e-12)
    assert_allclose(t1 / S5, [0.25, 0.6, 0.75, 1.25, 1.6, 1.75, 2.0], atol=1e-12)


def test_diagonal_ray_through_corners_steps_diagonally():
    grid = GridSpec(0.0, 0.0, 1.0, 4, 4)
    rows, cols, t0, t1 = ray_cells(grid, 0.5, 0.5, math.pi / 4, 4.5)
    assert cells(rows, cols) == [(0, 0), (1, 1), (2, 2), (3, 3)]
    assert_allclose(t1[:3], np.array([0.5, 1.5, 2.5]) * math.sqrt(2))
    rows, cols, _, _ = ray_cells(grid, 3.0, 1.0, 3 * math.pi / 4, 10.0)  # from a lattice corner
    assert cells(rows, cols) == [(1, 2), (2, 1), (3, 0)]


def test_ray_from_outside_the_grid_and_rays_that_miss_it():
    grid = GridSpec(0.0, 0.0, 1.0, 4, 4)
    rows, cols, t0, t1 = ray_cells(grid, -1.5, 0.5, 0.0, 3.0)
    assert cells(rows, cols) == [(0, 0), (0, 1)]
    assert_allclose(t0, [1.5, 2.5])
    assert_allclose(t1, [2.5, 3.0])
    assert ray_cells(grid, -1.5, 0.5, 0.0, 1.0)[0].size == 0  # ends before the grid
    assert ray_cells(grid, -1.5, 0.5, math.pi, 10.0)[0].size == 0  # points away
    assert ray_cells(grid, 0.5, 5.5, 0.0, 10.0)[0].size == 0  # parallel, above
    rows, cols, _, _ = ray_cells(grid, 2.5, 2.5, 0.0, 100.0)  # leaves the grid
    assert cells(rows, cols) == [(2, 2), (2, 3)]


# --- the log-odds along a ray ----------------------------------------------------------------


def beam_run(pose, ranges, sensor=LASER, grid=None, config=CONFIG, chunk=None):
    grid = grid or GridSpec(0.0, 0.0, 0.1, 3, 10)
    pose = np.asarray(pose, dtype=np.float64).reshape(-1, 3)
    ranges = np.asarray(ranges, dtype=np.float32).reshape(pose.shape[0], -1)
    chunk = chunk or pose.shape[0]
    chunks = [(s, None, pose[s : s + chunk], ranges[s : s + chunk]) for s in range(0, len(pose), chunk)]
    return standard_map(chunks, sensor, grid, config)


POSE = [0.05, 0.15, 0.0]  # centre of cell (1, 0), pointing +x along row 1
# along the ray, cell (1, c) is the stretch [0.1 c - 0.05, 0.1 c + 0.05) (cell (1, 0): [0, 0.05))


def row_of(values):
    out = np.zeros((3, 10), dtype=np.float32)
    out[1, : len(values)] = values
    return out


def test_free_cells_then_the_endpoint_cell():
    log_odds, observed = beam_run(POSE, 0.52)  # hit band [0.495, 0.545]: only cell (1, 5) = [0.45, 0.55)
    assert_array_equal(log_odds, row_of([FREE] * 5 + [OCC]))
    assert_array_equal(observed, row_of([1] * 6) != 0)


def test_the_cell_before_the_endpoint_is_occupied_within_alpha_half():
    log_odds, _ = beam_run(POSE, 0.46)  # band [0.435, 0.485] overlaps (1, 4) = [0.35, 0.45) and (1, 5)
    assert_array_equal(log_odds, row_of([FREE] * 4 + [OCC, OCC]))


def test_blind_zone_is_observed_without_evidence():
    sensor = SensorSpec(np.zeros((1, 3)), "laser", math.radians(0.5), min_range=0.1, max_range=5.0)
    log_odds, observed = beam_run(POSE, 0.52, sensor=sensor)  # cell (1, 0) = [0, 0.05) < min_range
    assert_array_equal(log_odds, row_of([0.0] + [FREE] * 4 + [OCC]))
    assert observed[1, :6].all() and not observed[1, 6:].any()


@pytest.mark.parametrize("z", [np.inf, 0.3, 7.0])
def test_max_range_readings_only_clear_up_to_max_range(z):
    sensor = SensorSpec(np.zeros((1, 3)), "laser", math.radians(0.5), min_range=0.0, max_range=0.3)
    log_odds, observed = beam_run(POSE, z, sensor=sensor)  # (1, 3) = [0.25, 0.35) reaches max_range
    assert_array_equal(log_odds, row_of([FREE] * 4))
    assert_array_equal(observed, row_of([1] * 4) != 0)


def test_a_hit_band_is_cut_at_max_range():
    sensor = SensorSpec(np.zeros((1, 3)), "laser", math.radians(0.5), min_range=0.0, max_range=0.3)
    log_odds, _ = beam_run(POSE, 0.28, sensor=sensor)  # band [0.255, min(0.305, 0.3)]: (1, 3) only
    assert_array_equal(log_odds, row_of([FREE] * 3 + [OCC]))


def test_nan_readings_and_poses_carry_nothing():
    log_odds, observed = beam_run([POSE, [np.nan, 0.15, 0.0]], [np.nan, 0.5])
    assert not observed.any() and not log_odds.any()


def test_clamping_and_order_as_the_cone_mapper():
    log_odds, _ = beam_run([POSE] * 6, [0.52] * 6)
    assert_array_equal(log_odds[1, :6], np.array([-2.0] * 5 + [3.5], dtype=np.float32))
    # cell (1, 5) occupied three times, then free twice (scan by scan): no clamp reached
    log_odds, _ = beam_run([POSE] * 5, [0.52] * 3 + [0.95] * 2)
    expected = np.float32(0.0)
    for inc in (OCC, OCC, OCC, FREE, FREE):
        expected = np.float32(expected + inc)
    assert log_odds[1, 5] == expected


def test_a_hit_wins_over_free_evidence_within_one_scan_only():
    two = SensorSpec(np.zeros((2, 3)), "laser", math.radians(0.5), min_range=0.0, max_range=5.0)
    together, _ = beam_run(POSE, [[0.25, 0.55]], sensor=two)  # one scan: (1, 2) is in beam 0's band
    assert together[1, 2] == OCC and together[1, 5] == OCC
    apart, _ = beam_run([POSE, POSE], [[0.25, np.nan], [np.nan, 0.55]], sensor=two)
    assert apart[1, 2] == np.float32(OCC + FREE)


def test_chunks_give_the_same_map_bit_for_bit():
    rng = np.random.default_rng(3)
    grid = GridSpec(-1.0, -1.0, 0.05, 60, 60)
    sensor = SensorSpec(np.stack([np.zeros(9), np.zeros(9), np.linspace(-2, 2, 9)], axis=1), "laser",
                        math.radians(0.5), 0.0, 1.2)
    pose = np.column_stack([rng.uniform(-0.5, 1.5, 40), rng.uniform(-0.5, 1.5, 40), rng.uniform(-3, 3, 40)])
    ranges = rng.uniform(0.1, 1.5, (40, 9)).astype(np.float32)
    ranges[rng.random((40, 9)) < 0.1] = np.inf
    whole = beam_run(pose, ranges, sensor=sensor, grid=grid)
    parts = beam_run(pose, ranges, sensor=sensor, grid=grid, chunk=7)
    assert_array_equal(whole[0], parts[0])
    assert_array_equal(whole[1], parts[1])
    assert (whole[0] > 0).any() and (whole[0] < 0).any()


# --- dispatch ---------------------------------------------------------------------------------


def test_which_sensors_are_traced_as_rays():
    sonar = SensorSpec(np.zeros((1, 3)), "sonar", math.radians(30.0), 0.15, 5.0)
    assert is_narrow_beam(LASER, 0.05)
    assert not is_narrow_beam(sonar, 0.05)
    thin = SensorSpec(np.zeros((1, 3)), "sonar", math.radians(0.5), 0.0, 5.0)  # 4.4 cm wide at 5 m
    assert is_narrow_beam(thin, 0.05) and not is_narrow_beam(thin, 0.04)
    grid = GridSpec(0.0, 0.0, 0.05, 10, 10)
    assert isinstance(_mapper_for(LASER, grid, CONFIG, None, is_narrow_beam(LASER, grid.resolution)), BeamMapper)
    assert isinstance(_mapper_for(sonar, grid, CONFIG, None, is_narrow_beam(sonar, grid.resolution)), StandardMapper)


def test_map_standard_of_a_laser_log_puts_each_endpoint_on_an_occupied_cell(tmp_path):
    """Through the mapper: no cone templates, readings as logged (no half-cell echo shift)."""
    mount = np.array([[0.0, 0.0, -0.3], [0.0, 0.0, 0.0], [0.0, 0.0, 0.3]])
    sensor = SensorSpec(mount, "laser", math.radians(0.5), 0.0, 4.0, 0.01)
    pose = np.array([[0.0, 0.0, 0.0], [0.3, 0.1, 0.05]])
    # a wall at x = 1.0, seen by every beam
    ranges = np.array([[1.0 / math.cos(a - p[2]) - p[0] / math.cos(a - p[2]) for a in mount[:, 2]] for p in pose])
    path = tmp_path / "laser.h5"
    write_log(path, Log(np.arange(2.0), pose, ranges.astype(np.float32), sensor, source="test"))
    m = map_file(path, "standard", MapParams(resolution=0.05))
    assert m.grid.origin_x == pytest.approx(-4.0) and m.grid.width >= 80  # the poses' bounds plus 4 m
    for p, row in zip(pose, ranges, strict=True):
        for a, z in zip(mount[:, 2], row, strict=True):
            x, y = p[0] + z * math.cos(p[2] + a), p[1] + z * math.sin(p[2] + a)
            r, c = m.grid.world_to_cell(x - 1e-6, y)
            assert m.probability[r, c] > 0.5
    assert m.stats["scans"] == 2 and m.runtime_s > 0
