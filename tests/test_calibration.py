"""The forward model learned from the log: the E-step's sums against a hand-written reference,
the closed-form M-step and its bounds, recovery of a simulator's noise and random-reading rate,
and `aogm calibrate` / `--calibrate` as users run them."""

import json
import math
from pathlib import Path

import h5py
import numpy as np
import pytest
from click.testing import CliRunner

from aogm_cli.cli import main
from aogm_cli.core.grid import GridSpec
from aogm_cli.io.mapfile import read_map_file
from aogm_cli.mapping import calibration as C
from aogm_cli.mapping.params import CalibrationConfig
from aogm_cli.sensor_models import forward_model as F
from aogm_cli.sensor_models.cone import build_cone_templates, flat_offsets

WORLDS = Path(__file__).resolve().parents[1] / "worlds"
GRID = GridSpec(0.0, 0.0, 0.05, 60, 80)
Z_MAX = 3.0


def run(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def reference_sums(tpl, rows, cols, bins, z, occupied, model):
    """The E-step's sums written out reading by reading from the templates' own cell lists."""
    p_rand, p_max, p_hit, sigma, window, z_max = model
    q, w = 1.0 - p_hit, 1.0 - p_rand - p_max
    out = np.zeros(F.E_SIZE)
    for row, col, k, zt in zip(rows, cols, bins, z, strict=True):
        at_max = not zt < z_max
        zt = min(zt, z_max)
        limit = z_max if at_max else min(zt + window * sigma, z_max)
        cells, ranges = tpl.reading_cells(GRID, row, col, k, limit)
        g = np.array([F.gaussian(zt, r, sigma) if abs(zt - r) <= window * sigma else 0.0 for r in ranges])
        while len(ranges) and ranges[-1] > zt and g[-1] == 0.0:  # the cone ends where the Gaussian does
            cells, ranges, g = cells[:-1], ranges[:-1], g[:-1]
        obstacles = occupied[cells]
        d, gk = ranges[obstacles], g[obstacles]
        g0 = F.gaussian(zt, z_max, sigma)
        terms = np.array([w * q**i * p_hit * gk[i] for i in range(len(d))])
        miss = w * q ** len(d) * g0
        p = p_rand / z_max + p_max * g0 + terms.sum() + miss
        out += [1, math.log(p), p_rand / z_max / p, p_max * g0 / p, terms.sum() / p,
                (np.arange(1, len(d) + 1) * terms).sum() / p + len(d) * miss / p, (terms * (zt - d) ** 2).sum() / p,
                miss / p]
    return out


def wall_map():
    """A wall across the grid at x = 2.0 .. 2.1 m and a pillar nearer the sensor, flat bool."""
    occ = np.zeros(GRID.shape, dtype=bool)
    occ[:, 40:42] = True
    occ[28:31, 25:27] = True
    return occ.reshape(-1)


def test_expectation_sums_match_the_reference_reading_by_reading():
    tpl = build_cone_templates(GRID.resolution, math.radians(25), Z_MAX)
    rng = np.random.default_rng(3)
    n = 40
    rows, cols = rng.integers(20, 40, n), rng.integers(2, 20, n)
    bins = tpl.heading_bin(rng.uniform(-0.6, 0.6, n))
    z = rng.uniform(0.3, 2.6, n)
    z[::7] = np.inf  # max-range readings: their cones reach z_max
    occupied = wall_map()
    model = (0.07, 0.05, 0.6, 0.04, 4.0, Z_MAX)
    out = np.zeros(F.E_SIZE)
    F.expectation_sums(tpl.kernel_arrays, flat_offsets(tpl, GRID.width), GRID.shape,
                       F.ExpectationReadings(rows, cols, bins, z, np.full(n, np.inf)), occupied, model, out)
    expected = reference_sums(tpl, rows, cols, bins, z, occupied, model)
    np.testing.assert_allclose(out, expected, rtol=1e-10)
    # every reading's causes add up to one: random + dropout + detections + no detection
    assert out[F.E_RANDOM] + out[F.E_DROPOUT] + out[F.E_DETECTED] + out[F.E_MISSED] == pytest.approx(n)


def test_obstacles_found_at_a_broader_sigma_give_the_same_sums():
    # a fit keeps the cones' obstacles while sigma changes: found at 0.12, summed at 0.04 and 0.09,
    # they must give what a fresh walk of every cone gives, bit for bit
    tpl = build_cone_templates(GRID.resolution, math.radians(25), Z_MAX)
    rng = np.random.default_rng(5)
    n = 60
    rows, cols = rng.integers(20, 40, n), rng.integers(2, 20, n)
    bins = tpl.heading_bin(rng.uniform(-0.6, 0.6, n))
    z = rng.uniform(0.3, 2.6, n)
    z[::9] = np.inf
    readings = F.ExpectationReadings(rows, cols, bins, z, np.where(np.arange(n) % 5 == 0, 1.5, np.inf))
    flat, occupied = flat_offsets(tpl, GRID.width), wall_map()
    broad = F.find_obstacles(tpl.kernel_arrays, flat, GRID.shape, readings, occupied, 0.12, 4.0, Z_MAX)
    for sigma in (0.04, 0.09):
        model = (0.07, 0.05, 0.6, sigma, 4.0, Z_MAX)
        fresh, kept = np.zeros(F.E_SIZE), np.zeros(F.E_SIZE)
        F.expectation_sums(tpl.kernel_arrays, flat, GRID.shape, readings, occupied, model, fresh)
        used = F.expectation_sums(tpl.kernel_arrays, flat, GRID.shape, readings, occupied, model, kept, broad)
        assert used is broad and (fresh == kept).all() and fresh[F.E_DETECTED] > 0
    # a sigma beyond the obstacles' finds them again
    model = (0.07, 0.05, 0.6, 0.2, 4.0, Z_MAX)
    assert F.expectation_sums(tpl.kernel_arrays, flat, GRID.shape, readings, occupied, model, np.zeros(F.E_SIZE),
                              broad).sigma == 0.2


def test_one_reading_one_obstacle_by_hand():
    """A reading at 1.0 m, the only obstacle of its cone at the axis cell 1.0 m away."""
    grid = GridSpec(0.0, 0.0, 0.1, 21, 41)
    tpl = build_cone_templates(grid.resolution, math.radians(2), 4.0)
    occupied = np.zeros(grid.height * grid.width, dtype=bool)
    occupied[10 * grid.width + 15] = True
    model = (0.1, 0.0, 0.5, 0.05, 4.0, 4.0)
    out = np.zeros(F.E_SIZE)
    F.expectation_sums(tpl.kernel_arrays, flat_offsets(tpl, grid.width), grid.shape,
                       F.ExpectationReadings(np.array([10]), np.array([5]), tpl.heading_bin(np.zeros(1)),
                                             np.array([1.02]), np.array([np.inf])), occupied, model, out)
    g = math.exp(-0.5 * (0.02 / 0.05) ** 2) / (math.sqrt(2 * math.pi) * 0.05)  # N(1.02; 1.0, 0.05^2)
    g0 = math.exp(-0.5 * (2.98 / 0.05) ** 2) / (math.sqrt(2 * math.pi) * 0.05)  # N(1.02; 4.0): 0
    hit = 0.9 * 0.5 * g
    p = 0.1 / 4.0 + hit + 0.9 * 0.5 * g0
    assert out[F.E_LOGLIK] == pytest.approx(math.log(p))
    assert out[F.E_RANDOM] == pytest.approx(0.025 / p)
    assert out[F.E_DETECTED] == pytest.approx(hit / p)
    assert out[F.E_SQUARED] == pytest.approx(hit / p * 0.02**2)
    assert out[F.E_EXAMINED] == pytest.approx(1.0 - 0.025 / p)  # one obstacle examined, detected or not


def test_m_step_is_the_closed_form_clipped_to_its_bounds():
    sums = np.zeros(F.E_SIZE)
    sums[[F.E_READINGS, F.E_RANDOM, F.E_DROPOUT, F.E_DETECTED, F.E_EXAMINED, F.E_SQUARED]] = [100, 8, 12, 60, 80, 60 * 0.07**2]
    start = F.ForwardModelConfig()
    new = C.m_step(sums, start, CalibrationConfig())
    assert (new.p_rand, new.p_max, new.p_hit) == pytest.approx((0.08, 0.12, 0.75))
    assert new.sigma == pytest.approx(0.07)
    assert new.window == start.window
    clipped = C.m_step(sums, start, CalibrationConfig(sigma_max=0.05, p_hit_max=0.7, p_rand_max=0.05))
    assert (clipped.sigma, clipped.p_hit, clipped.p_rand) == (0.05, 0.7, 0.05)
    only_sigma = C.m_step(sums, start, CalibrationConfig(learn="sigma"))
    assert only_sigma == F.ForwardModelConfig(sigma=pytest.approx(0.07))
    # a dropout mass switched off stays off
    assert C.m_step(sums, F.ForwardModelConfig(p_max=0.0), CalibrationConfig()).p_max == 0.0


@pytest.mark.parametrize("noise, rate", [(0.06, 0.10), (0.10, 0.03)])
def test_the_fit_at_the_true_map_recovers_the_simulators_noise_and_random_rate(tmp_path, noise, rate):
    text = (WORLDS / "corridor_door.yaml").read_text()
    text = text.replace("noise_sigma: 0.02", f"noise_sigma: {noise}").replace("random_rate: 0.02", f"random_rate: {rate}")
    world = tmp_path / "w.yaml"
    world.write_text(text)
    assert run("simulate", world, "-o", tmp_path / "w.h5", "--seed", 2, "-q").exit_code == 0
    from aogm_cli.io.logfile import read_log
    from aogm_cli.sensor_models.readings import lay_out_readings

    log = read_log(tmp_path / "w.h5")
    grid = log.truth.grid
    laid = lay_out_readings(log.pose, log.ranges, log.sensor, grid)
    occupied = np.ascontiguousarray(log.truth.occupancy.reshape(-1).astype(bool))
    fit = C.fit_at_map(laid, C.sample_readings(laid, 10**6), occupied, F.ForwardModelConfig(), CalibrationConfig())
    assert fit.forward.sigma == pytest.approx(noise, rel=0.2)
    assert fit.forward.p_rand == pytest.approx(rate, abs=0.03)


def test_calibrated_map_records_the_learned_model_and_its_rounds(corridor_door_log, tmp_path):
    out = tmp_path / "em.h5"
    result = run("map", corridor_door_log, "--mode", "em", "-o", out, "-q")
    assert result.exit_code == 0, result.output
    m = read_map_file(out)
    record = m.stats["calibration"]
    # the specular angle is learned before the rounds; the beam's opening is not learned by default
    # (0: the log's cone)
    assert record["initial"] == {"sigma": 0.03, "p_rand": 0.05, "p_hit": 0.7, "p_max": 0.1, "specular_deg": 90.0,
                                 "opening_deg": 0.0}
    assert record["rounds"][0]["sigma"] == 0.1  # round 0 maps with the broad start
    assert {k: m.params["em"][k] for k in record["final"]} == record["final"]
    assert m.params["calibration"]["enabled"] is True
    # corridor_door's walls are rough: they echo at every angle, so nothing is deflected
    assert record["incidence"]["specular_deg"] == 90.0
    # the learned noise is the simulator's 0.02 m and the grid's quantisation (0.05 / sqrt 12)
    assert 0.015 < record["final"]["sigma"] < 0.04
    fits = [r["loglik_per_reading"] for r in record["rounds"][1:]]
    assert all(b >= a - 1e-3 for a, b in zip(fits, fits[1:], strict=False))

    off = tmp_path / "off.h5"
    assert run("map", corridor_door_log, "--mode", "em", "-o", off, "--no-calibrate", "-q").exit_code == 0
    m = read_map_file(off)
    assert "calibration" not in m.stats and m.params["em"]["sigma"] == 0.03


def test_calibrate_prints_the_model_and_writes_params_that_map_takes(corridor_door_log, tmp_path):
    model = tmp_path / "model.yaml"
    result = run("calibrate", corridor_door_log, "-o", model, "-q")
    assert result.exit_code == 0, result.output
    assert "sigma" in result.output and "learned from" in result.output
    assert not list(tmp_path.glob("*.h5"))  # no map written
    out = tmp_path / "m.h5"
    assert run("map", corridor_door_log, "--mode", "em", "--params", model, "-o", out, "-q").exit_code == 0
    with h5py.File(out) as f:
        params = json.loads(f.attrs["params"])
        assert "calibration" not in f["stats"].attrs
    learned = dict(line.strip().split(": ") for line in model.read_text().splitlines() if line.startswith("  ") and "enabled" not in line)
    assert params["em"]["sigma"] == float(learned["sigma"]) and params["calibration"]["enabled"] is False


@pytest.mark.parametrize("text, key", [
    ("calibration: {rounds: 0}\n", "calibration.rounds"),
    ("calibration: {learn: 'sigma,p_foo'}\n", "calibration.learn"),
    ("calibration: {enabled: 3}\n", "calibration.enabled"),
    ("calibration: {sigma_min: 0.2, sigma_max: 0.1}\n", "calibration.sigma_min"),
    ("calibration: {speed: 1}\n", "calibration.speed"),
])
def test_bad_calibration_params_exit_2_naming_the_key(corridor_door_log, tmp_path, text, key):
    params = tmp_path / "p.yaml"
    params.write_text(text)
    result = run("map", corridor_door_log, "--mode", "em", "--params", params, "-o", tmp_path / "m.h5", "-q")
    assert result.exit_code == 2 and key in result.output and "Traceback" not in result.output
    assert not (tmp_path / "m.h5").exists()


def test_calibration_maps_the_whole_log_once_and_part_of_it_before(corridor_door_log):
    """The fits are made at maps of every 4th, then every 2nd scan; only the final EM run maps
    every scan (issue 22: calibration at the cost of at most one extra EM over part of the log)."""
    from aogm_cli.io.logfile import LogReader
    from aogm_cli.mapping.params import EMConfig
    from aogm_cli.mapping.pipeline import log_grid
    from aogm_cli.sensor_models.readings import lay_out_readings

    with LogReader(corridor_door_log) as reader:
        log, grid = reader.read(), log_grid(reader, 0.05)
    run_ = lay_out_readings(log.pose, log.ranges, log.sensor, grid)
    calls = []

    def em_step(config, occupied, subset):
        calls.append((config.forward.sigma, config.max_sweeps, None if subset is None else subset.copy()))
        occupied[:] = truth  # the map EM would find
        return 1.0, 1, "result"

    truth = log.truth.occupancy.reshape(-1).astype(bool)
    occupied = np.zeros(grid.height * grid.width, dtype=bool)
    config = CalibrationConfig(rounds=3)
    used, result, record = C.calibrated_em(run_, occupied, EMConfig(), config, em_step)
    assert result == "result" and record["final"] == C.model_values(used.forward)
    assert len(calls) == 3  # the broad map, a map for the second fit (at which the model settles), the final
    assert [c[2] is None for c in calls] == [False] * (len(calls) - 1) + [True]  # one run over every scan, the last
    scans = log.ranges.shape[0]
    first = calls[0][2].reshape(scans, -1)[:, 0]
    assert np.array_equal(np.flatnonzero(first), np.arange(0, scans, 4))  # the broad map: every 4th scan
    assert calls[0][0] == config.start_sigma and calls[0][1] == config.start_sweeps
    for _sigma, sweeps, subset in calls[1:-1]:  # maps made for a fit: every 2nd scan, few sweeps
        assert np.array_equal(np.flatnonzero(subset.reshape(scans, -1)[:, 0]), np.arange(0, scans, 2))
        assert sweeps == config.fit_sweeps
    assert calls[-1][1] == EMConfig().max_sweeps and record["final_em"]["em_sweeps"] == 1


def test_a_long_log_calibrates_on_runs_of_consecutive_scans(corridor_door_log):
    """Beyond calibration.max_scans, the rounds map (and the fits take) CAL_BLOCKS runs of
    consecutive scans spread over the log, every n-th scan of them; the final EM maps every scan."""
    from aogm_cli.io.logfile import LogReader
    from aogm_cli.mapping.params import EMConfig
    from aogm_cli.mapping.pipeline import log_grid
    from aogm_cli.sensor_models.readings import lay_out_readings

    with LogReader(corridor_door_log) as reader:
        log, grid = reader.read(), log_grid(reader, 0.05)
    run_ = lay_out_readings(log.pose, log.ranges, log.sensor, grid)
    scans, width = log.ranges.shape
    calls = []

    def em_step(config, occupied, subset):
        calls.append(None if subset is None else subset.reshape(scans, width)[:, 0].copy())
        return 1.0, 1, "result"

    config = CalibrationConfig(rounds=2, max_scans=40, subsample=1)
    _, _, record = C.calibrated_em(run_, np.zeros(grid.height * grid.width, dtype=bool), EMConfig(), config, em_step)
    blocks = calls[1]  # the second round: every scan of the runs (subsample 1)
    starts = np.flatnonzero(np.diff(np.concatenate([[0], blocks.astype(int)])) == 1)
    assert blocks.sum() == 40 and len(starts) == C.CAL_BLOCKS and starts[0] == 0 and starts[-1] == scans - 10
    assert np.array_equal(calls[0], blocks & (np.arange(scans) % config.start_subsample == 0))  # the broad map
    assert calls[-1] is None and "4 runs of 10 consecutive scans" in record["fitted_at"]
    assert record["readings_used"] <= 40 * width
    # a log within max_scans is left whole
    assert C._scan_blocks(run_, scans) is None
