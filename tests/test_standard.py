"""The standard log-odds mapper: tiny hand-computed maps, clamping, chunking, NaN, borders."""

import math

import numpy as np
import pytest
from cone_views import bin_heading, cells

from aogm_cli.core.grid import GridSpec
from aogm_cli.core.log import SensorSpec
from aogm_cli.mapping.standard import StandardMapper, flat_offsets, probability_from_log_odds, standard_map
from aogm_cli.sensor_models.cone_build import build_cone_templates
from aogm_cli.sensor_models.inverse_model import InverseModelConfig, inverse_model
from aogm_cli.sensor_models.readings import cone_templates as standard_templates

BEAM = math.radians(30.0)
ONE_SONAR = SensorSpec(mount=np.zeros((1, 3)), beam_width=BEAM, min_range=0.05, max_range=5.0)


def kernel_map(chunks, sensor, grid, config, templates=None):
    """The cone kernel on ranges as given (no range convention): what the hand computations assume."""
    mapper = StandardMapper(sensor, grid, config, templates=templates)
    for _start, _time, pose, ranges in chunks:
        mapper.update(pose, ranges)
    return mapper.result()


def run(pose, ranges, sensor=ONE_SONAR, grid=None, config=None, chunk=None):
    grid = grid or GridSpec(0.0, 0.0, 0.1, 11, 11)
    config = config or InverseModelConfig(alpha=0.1)
    pose = np.asarray(pose, dtype=np.float64).reshape(-1, 3)
    ranges = np.asarray(ranges, dtype=np.float32).reshape(pose.shape[0], -1)
    chunk = chunk or max(1, pose.shape[0])
    chunks = [
        (s, np.zeros(min(chunk, len(pose) - s)), pose[s : s + chunk], ranges[s : s + chunk])
        for s in range(0, len(pose), chunk)
    ]
    return kernel_map(chunks, sensor, grid, config)


# the sensor at the centre of cell (row 5, col 2) of an 11 x 11 grid at 0.1 m, pointing +x
POSE = [0.25, 0.55, 0.0]


def test_constant_model_on_a_tiny_grid_by_hand():
    log_odds, observed = run(POSE, 0.5, config=InverseModelConfig(alpha=0.1, model="constant"))
    expected = np.zeros((11, 11), dtype=np.float32)
    # free: cells nearer than z - alpha/2 = 0.45 m in the cone (not the sensor's own cell,
    # nearer than min_range); occupied: cells within alpha/2 of z = 0.5 m
    for r, c in [(5, 3), (5, 4), (5, 5), (5, 6), (4, 6), (6, 6)]:
        expected[r, c] = np.float32(-0.41)
    for r, c in [(5, 7), (4, 7), (6, 7)]:
        expected[r, c] = np.float32(0.85)
    np.testing.assert_array_equal(log_odds, expected)
    seen = {(int(r), int(c)) for r, c in zip(*np.nonzero(observed), strict=True)}
    assert seen == {(5, 2), (5, 3), (5, 4), (5, 5), (5, 6), (4, 6), (6, 6), (5, 7), (4, 7), (6, 7)}


def test_elfes_model_on_a_tiny_grid_by_hand():
    log_odds, observed = run(POSE, 0.5)
    span = 0.4  # z - alpha/2 - min_range
    e_a = {1: 1 - (2 * math.atan2(1, 4) / BEAM) ** 2, 2: 1 - (2 * math.atan2(1, 5) / BEAM) ** 2}
    expected = {
        (5, 3): -0.41 * (1 - (0.05 / span) ** 2),
        (5, 4): -0.41 * (1 - (0.15 / span) ** 2),
        (5, 5): -0.41 * (1 - (0.25 / span) ** 2),
        (5, 6): -0.41 * (1 - (0.35 / span) ** 2),
        (4, 6): -0.41 * e_a[1] * (1 - ((math.hypot(0.1, 0.4) - 0.05) / span) ** 2),
        (5, 7): 0.85,
        (4, 7): 0.85 * e_a[2],
    }
    expected[(6, 6)] = expected[(4, 6)]
    expected[(6, 7)] = expected[(4, 7)]
    want = np.zeros((11, 11))
    for (r, c), v in expected.items():
        want[r, c] = v
    np.testing.assert_allclose(log_odds, want, rtol=1e-6, atol=1e-7)
    assert observed.sum() == 10 and observed[5, 2]


@pytest.mark.parametrize("model", ["elfes", "constant"])
@pytest.mark.parametrize(
    "octant, z", [(0, 1.23), (1, 0.8), (2, 2.0), (3, np.inf), (4, 0.07), (5, 4.99), (6, 0.5), (7, 3.3)]
)
def test_kernel_agrees_with_the_inverse_model_function(model, octant, z):
    grid = GridSpec(0.0, 0.0, 0.1, 110, 110)
    config = InverseModelConfig(alpha=0.1, model=model)
    templates = standard_templates(grid, ONE_SONAR)
    k = int(templates.n_bins * (octant + 0.37) / 8)  # a heading bin in every octant
    yaw = float(bin_heading(templates, k))
    pose = [5.55, 5.45, yaw]  # the centre of cell (54, 55)
    log_odds, observed = kernel_map([(0, None, np.array([pose]), np.array([[z]], np.float32))],
                                      ONE_SONAR, grid, config, templates=templates)
    drow, dcol, rng, bearing = cells(templates, k)
    want = inverse_model(rng, bearing, z, config, beam_width=BEAM, min_range=0.05, max_range=5.0)
    limit = 5.0 if z >= 5.0 else min(z + 0.05, 5.0)
    cover = rng <= limit
    expected = np.zeros((110, 110))
    expected[54 + drow[cover], 55 + dcol[cover]] = want[cover]
    np.testing.assert_allclose(log_odds, expected, rtol=2e-6, atol=2e-7)
    seen = np.zeros((110, 110), dtype=bool)
    seen[54 + drow[cover], 55 + dcol[cover]] = True
    np.testing.assert_array_equal(observed, seen)


def test_flat_offsets_follow_every_heading_bin():
    templates = build_cone_templates(0.1, BEAM, 1.0, n_bins=64)
    flat = flat_offsets(templates, 37)
    for k in range(64):
        drow, dcol, _, _ = cells(templates, k)
        b = templates.base_bin[k]
        x = flat.offsets[flat.sel[k, 0], templates.offsets[b] : templates.offsets[b + 1]]
        np.testing.assert_array_equal(flat.sel[k, 1] * x.astype(np.int64), drow * 37 + dcol)


def test_max_range_reading_only_clears():
    grid = GridSpec(-6.0, -6.0, 0.1, 120, 120)
    # the sensor at a cell centre: ranges to cell centres are exact
    log_odds, observed = run([[0.05, 0.05, 0.3], [0.05, 0.05, 2.0]], [[np.inf], [5.0]], grid=grid)
    assert log_odds.max() <= 0.0
    assert (log_odds < 0).sum() > 1000
    x, y = grid.centres()
    d = np.hypot(x[observed] - 0.05, y[observed] - 0.05)
    assert 4.9 < d.max() <= 5.0 + 1e-9


def test_clamping_after_many_identical_readings():
    poses = np.tile(POSE, (200, 1))
    log_odds, _ = run(poses, np.full(200, 0.5))
    assert log_odds.min() == np.float32(-2.0)
    assert log_odds.max() == np.float32(3.5)
    assert log_odds[5, 7] == np.float32(3.5) and log_odds[5, 3] == np.float32(-2.0)


def test_clamping_applies_after_every_update():
    config = InverseModelConfig(alpha=0.1, model="constant")
    # ten readings put cell (5, 7) on the arc (0.85 each, clamped at 3.5), then one reading
    # at 1.0 m makes it free: 3.5 - 0.41, not 8.5 - 0.41
    ranges = np.r_[np.full(10, 0.5), 1.0]
    log_odds, _ = run(np.tile(POSE, (11, 1)), ranges, config=config)
    assert log_odds[5, 7] == np.float32(np.float32(3.5) + np.float32(-0.41))
    assert log_odds[5, 3] == np.float32(-2.0)  # 11 * -0.41 = -4.51, clamped


def random_log(n_scans, n_sonars=8, seed=0):
    rng = np.random.default_rng(seed)
    pose = np.c_[rng.uniform(-1, 11, n_scans), rng.uniform(-1, 11, n_scans), rng.uniform(-10, 10, n_scans)]
    ranges = rng.uniform(0.0, 6.0, (n_scans, n_sonars)).astype(np.float32)
    ranges[rng.random(ranges.shape) < 0.15] = np.inf
    ranges[rng.random(ranges.shape) < 0.05] = np.nan
    a = np.arange(n_sonars) * 2 * math.pi / n_sonars
    mount = np.c_[0.2 * np.cos(a), 0.2 * np.sin(a), a]
    sensor = SensorSpec(mount=mount, beam_width=BEAM, min_range=0.15, max_range=5.0)
    return pose, ranges, sensor


def test_two_chunks_equal_one_bit_for_bit():
    pose, ranges, sensor = random_log(300)
    grid = GridSpec(0.0, 0.0, 0.05, 200, 200)
    one_l, one_o = run(pose, ranges, sensor, grid)
    for chunk in (150, 7, 1):
        lo, ob = run(pose, ranges, sensor, grid, chunk=chunk)
        np.testing.assert_array_equal(lo.view(np.uint32), one_l.view(np.uint32))
        np.testing.assert_array_equal(ob, one_o)
    assert one_o.mean() > 0.3 and (one_l > 0).any() and (one_l < 0).any()


def test_nan_readings_are_skipped():
    pose, ranges, sensor = random_log(100)
    grid = GridSpec(0.0, 0.0, 0.05, 200, 200)
    # a second sonar on the same mount whose readings are all NaN changes nothing
    mount = np.repeat(sensor.mount, 2, axis=0)
    doubled = SensorSpec(mount=mount, beam_width=BEAM, min_range=0.15, max_range=5.0)
    with_nan = np.full((100, 16), np.nan, dtype=np.float32)
    with_nan[:, ::2] = ranges
    a = run(pose, ranges, sensor, grid)
    b = run(pose, with_nan, doubled, grid)
    np.testing.assert_array_equal(a[0], b[0])
    np.testing.assert_array_equal(a[1], b[1])
    # a NaN pose makes its scan's readings carry no information either
    nan_pose = pose.copy()
    nan_pose[::3] = np.nan
    c = run(nan_pose, ranges, sensor, grid)
    d = run(pose[np.arange(100) % 3 != 0], ranges[np.arange(100) % 3 != 0], sensor, grid)
    np.testing.assert_array_equal(c[0], d[0])


@pytest.mark.parametrize("model", ["elfes", "constant"])
def test_cones_across_the_border_equal_a_crop_of_a_larger_grid(model):
    """Near the border the kernel takes its checked path; it must agree with the unchecked one."""
    pose, ranges, sensor = random_log(200, seed=3)
    pose[:, :2] = pose[:, :2] * 0.3 - 0.5  # sensors within 3 m of a 3 m x 3 m grid
    ranges = np.minimum(ranges, np.float32(1.5))
    sensor = SensorSpec(mount=sensor.mount, beam_width=BEAM, min_range=0.15, max_range=1.5)
    small = GridSpec(0.0, 0.0, 0.05, 60, 60)
    large = GridSpec(-3.0, -3.0, 0.05, 180, 180)
    config = InverseModelConfig(alpha=0.1, model=model)
    ls, os_ = run(pose, ranges, sensor, small, config)
    ll, ol = run(pose, ranges, sensor, large, config)
    np.testing.assert_array_equal(ls.view(np.uint32), ll[60:120, 60:120].view(np.uint32))
    np.testing.assert_array_equal(os_, ol[60:120, 60:120])
    assert os_.any() and ol.sum() > os_.sum()


def test_cone_outside_the_grid_changes_nothing():
    log_odds, observed = run([[-3.0, 0.5, math.pi]], [2.0])
    assert not observed.any() and not log_odds.any()


def test_sensor_off_its_cell_centre_moves_the_arc():
    """The sensor 0.04 m ahead of its cell centre: ranges are corrected along the axis."""
    config = InverseModelConfig(alpha=0.1, model="constant")
    log_odds, _ = run([0.29, 0.55, 0.0], 0.44, config=config)
    # true ranges of the axis cells (cols 3..7) are 0.06, 0.16, ..., 0.46: the arc
    # [0.39, 0.49] holds col 7 only (uncorrected, it would hold col 6 instead)
    np.testing.assert_allclose(log_odds[5, 3:9], [-0.41, -0.41, -0.41, -0.41, 0.85, 0.0], rtol=1e-6)


def test_unobserved_cells_hold_the_prior():
    config = InverseModelConfig(alpha=0.1, model="constant", l0=0.5, l_occ=1.2, l_free=-0.2)
    log_odds, observed = run(POSE, 0.5, config=config)
    assert log_odds[0, 0] == np.float32(0.5) and not observed[0, 0]
    assert log_odds[5, 2] == np.float32(0.5) and observed[5, 2]  # blind zone: observed, prior
    assert log_odds[5, 3] == np.float32(0.5) + np.float32(-0.2 - 0.5)
    assert log_odds[5, 7] == np.float32(0.5) + np.float32(1.2 - 0.5)


def test_probability_from_log_odds():
    lo = np.array([[0.0, math.log(3.0)], [-40.0, 1000.0]], dtype=np.float32)
    p = probability_from_log_odds(lo)
    assert p.dtype == np.float32
    np.testing.assert_allclose(p, [[0.5, 0.75], [0.0, 1.0]], atol=1e-7)
    p = probability_from_log_odds(lo, np.array([[True, False], [True, True]]))
    np.testing.assert_allclose(p, [[0.5, 0.5], [0.0, 1.0]], atol=1e-7)


def test_incremental_mapper_and_template_checks():
    pose, ranges, sensor = random_log(40)
    grid = GridSpec(0.0, 0.0, 0.05, 200, 200)
    mapper = StandardMapper(sensor, grid, InverseModelConfig(alpha=0.1))
    mapper.update(pose[:25], ranges[:25])
    mapper.update(pose[25:], ranges[25:])
    lo, ob = mapper.result()
    l1, o1 = run(pose, ranges, sensor, grid)
    np.testing.assert_array_equal(lo, l1)
    np.testing.assert_array_equal(ob, o1)
    with pytest.raises(ValueError):
        StandardMapper(sensor, grid, InverseModelConfig(alpha=0.1), templates=build_cone_templates(0.1, BEAM, 5.0))
    with pytest.raises(ValueError):
        StandardMapper(sensor, grid, InverseModelConfig(alpha=0.1), templates=build_cone_templates(0.05, BEAM, 2.0))


def test_standard_map_takes_logged_ranges_half_a_cell_long():
    """The public entry point applies the range convention: a cone reading z maps as the kernel's z + res/2."""
    pose, ranges, sensor = random_log(30)
    grid = GridSpec(0.0, 0.0, 0.05, 200, 200)
    config = InverseModelConfig(alpha=0.1)
    logged = standard_map([(0, None, pose, ranges)], sensor, grid, config)
    shifted = kernel_map([(0, None, pose, (ranges.astype(np.float64) + 0.025).astype(np.float32))], sensor, grid, config)
    np.testing.assert_array_equal(logged[0], shifted[0])
    np.testing.assert_array_equal(logged[1], shifted[1])
    unshifted = kernel_map([(0, None, pose, ranges)], sensor, grid, config)
    assert not np.array_equal(logged[0], unshifted[0])


def test_a_deflected_beam_clears_up_to_its_cut_and_nothing_beyond():
    # the constant model's reading at 0.5 m (the first test), its beam deflected at template range
    # 0.35 m: free evidence on the cells before 0.35 m only, no occupied arc, nothing beyond observed
    grid = GridSpec(0.0, 0.0, 0.1, 11, 11)
    config = InverseModelConfig(alpha=0.1, model="constant")
    mapper = StandardMapper(ONE_SONAR, grid, config)
    mapper.update(np.array([POSE]), np.array([[0.5]], dtype=np.float32), cut=np.array([[0.35]]))
    log_odds, observed = mapper.result()
    expected = np.zeros((11, 11), dtype=np.float32)
    for r, c in [(5, 3), (5, 4), (5, 5)]:  # template ranges 0.1, 0.2, 0.3
        expected[r, c] = np.float32(-0.41)
    np.testing.assert_array_equal(log_odds, expected)
    assert {(int(r), int(c)) for r, c in zip(*np.nonzero(observed), strict=True)} == {(5, 2), (5, 3), (5, 4), (5, 5)}
    # a cut at or beyond max range, or none (+inf), changes nothing
    for cut in (np.inf, 9.0):
        again = StandardMapper(ONE_SONAR, grid, config)
        again.update(np.array([POSE]), np.array([[0.5]], dtype=np.float32), cut=np.array([[cut]]))
        plain = StandardMapper(ONE_SONAR, grid, config)
        plain.update(np.array([POSE]), np.array([[0.5]], dtype=np.float32))
        np.testing.assert_array_equal(again.result()[0], plain.result()[0])
