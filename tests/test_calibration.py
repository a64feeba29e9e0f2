"""The forward model learned from the log: the E-step's sums against a hand-written reference,
the closed-form M-step and its bounds, recovery of a simulator's noise and random-reading rate,
and `aogm calibrate` / `--calibrate` as users run them."""

import math
from pathlib import Path

import numpy as np
import pytest
import yaml
from click.testing import CliRunner
from cone_views import reading_cells

from aogm_cli.cli import main
from aogm_cli.core.grid import GridSpec
from aogm_cli.io.mapfile import read_map_file
from aogm_cli.mapping import calibration as C
from aogm_cli.mapping.params import CalibrationConfig
from aogm_cli.sensor_models import forward_model as F
from aogm_cli.sensor_models.cone import flat_offsets
from aogm_cli.sensor_models.cone_build import build_cone_templates

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
        cells, ranges = reading_cells(tpl, GRID, row, col, k, limit)
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


def test_a_fit_of_p_max_walks_only_the_readings_a_dropout_may_explain():
    """``dropout_readings`` leaves out the echoes more than 40 sigmas short of z_max: their N(z; z_max) is 0, so the
    sums p_max's update reads (E_READINGS, E_DROPOUT) are those of every reading, bit for bit."""
    from aogm_cli.mapping.calibration import DROPOUT_SIGMAS, dropout_readings

    tpl = build_cone_templates(GRID.resolution, math.radians(25), Z_MAX)
    rng = np.random.default_rng(7)
    n = 80
    rows, cols = rng.integers(20, 40, n), rng.integers(2, 20, n)
    bins = tpl.heading_bin(rng.uniform(-0.6, 0.6, n))
    sigma = 0.04
    z = rng.uniform(0.3, Z_MAX, n)
    z[::6] = np.inf
    z[1::6] = Z_MAX - 0.5 * DROPOUT_SIGMAS * sigma  # near the max range: a dropout explains some of them
    readings = F.ExpectationReadings(rows, cols, bins, z, np.full(n, np.inf))
    kept, left_out = dropout_readings(readings, sigma, Z_MAX)
    near = ~(z < Z_MAX - DROPOUT_SIGMAS * sigma)
    assert left_out == n - near.sum() > 10 and np.array_equal(kept.z, z[near])
    flat, occupied = flat_offsets(tpl, GRID.width), wall_map()
    model = (0.07, 0.05, 0.6, sigma, 4.0, Z_MAX)
    every, part = np.zeros(F.E_SIZE), np.zeros(F.E_SIZE)
    F.expectation_sums(tpl.kernel_arrays, flat, GRID.shape, readings, occupied, model, every)
    part[F.E_READINGS] = left_out
    F.expectation_sums(tpl.kernel_arrays, flat, GRID.shape, kept, occupied, model, part)
    assert part[F.E_READINGS] == every[F.E_READINGS] == n and part[F.E_DROPOUT] == every[F.E_DROPOUT] > 0
    again, none_left_out = dropout_readings(kept, sigma, Z_MAX)  # every one kept: the same readings, not a copy
    assert again is kept and none_left_out == 0


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
    new = C.m_step(sums, start, CalibrationConfig().learned)
    assert (new.p_rand, new.p_max, new.p_hit) == pytest.approx((0.08, 0.12, 0.75))
    assert new.sigma == pytest.approx(0.07)
    assert new.window == start.window
    clipped = C.m_step(sums, start, CalibrationConfig().learned, C.Tuning(sigma_max=0.05, p_hit_max=0.7, p_rand_max=0.05))
    assert (clipped.sigma, clipped.p_hit, clipped.p_rand) == (0.05, 0.7, 0.05)
    only_sigma = C.m_step(sums, start, ("sigma",))
    assert only_sigma == F.ForwardModelConfig(sigma=pytest.approx(0.07))
    # a dropout mass switched off stays off
    assert C.m_step(sums, F.ForwardModelConfig(p_max=0.0), CalibrationConfig().learned).p_max == 0.0


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
    own = tmp_path / "own.yaml"  # calibrated on the log, not the model the detector carries for its sensor
    own.write_text("calibration: {carried: false}\n")
    result = run("map", corridor_door_log, "--mode", "em", "--params", own, "-o", out, "-q")
    assert result.exit_code == 0, result.output
    m = read_map_file(out)
    record = m.stats["calibration"]
    assert record["initial"] == {"sigma": 0.03, "p_rand": 0.05, "p_hit": 0.7, "p_max": 0.1}  # as configured
    assert record["rounds"][0]["sigma"] == 0.1  # round 0 maps with the broad start
    # the map records what it learned apart from its params, which stay as configured
    assert {k: m.learned["sensor"][k] for k in ("sigma", "p_rand", "p_hit", "p_max")} == {
        k: record["final"][k] for k in ("sigma", "p_rand", "p_hit", "p_max")}
    assert m.learned["origin"] == "learned from this log" and "incidence" not in record
    assert m.params["em"]["sigma"] == 0.03 and m.params["calibration"]["enabled"] is True
    # the learned noise is the simulator's 0.02 m and the grid's quantisation (0.05 / sqrt 12)
    assert 0.015 < record["final"]["sigma"] < 0.04
    fits = [r["loglik_per_reading"] for r in record["rounds"][1:]]
    assert all(b >= a - 1e-3 for a, b in zip(fits, fits[1:], strict=False))

    off = tmp_path / "off.h5"
    assert run("map", corridor_door_log, "--mode", "em", "-o", off, "--no-calibrate", "-q").exit_code == 0
    m = read_map_file(off)
    assert "calibration" not in m.stats and m.params["em"]["sigma"] == 0.03
    assert m.learned == {"sensor": None, "origin": "configured", "rates": None, "lobe_deg": None, "lobe_range": None,
                         "lobe": None}


def test_calibrate_writes_the_sensors_model_that_map_and_compare_take(corridor_door_log, tmp_path):
    # aogm calibrate LOG -o MODEL, then another log of the same robot maps with it: no calibration
    # runs (its phases show none), and the map records where its model came from
    model = tmp_path / "model.yaml"
    result = run("calibrate", corridor_door_log, "-o", model, "-q")
    assert result.exit_code == 0, result.output
    assert "sigma" in result.output and "learned from" in result.output
    # and the lobe: the default pattern's echoes are heard across the whole cone
    assert "of 2904 echoes the whole cone explains" in result.output and result.output.rstrip().endswith(
        "-> the whole cone")
    assert not list(tmp_path.glob("*.h5"))  # no map written
    written = yaml.safe_load(model.read_text())
    assert written["format"] == "aogm-sensor-model" and written["format_version"] == 1
    assert written["sensor"]["count"] == 24 and written["sensor"]["beam_width_deg"] == pytest.approx(30)
    # the transducer's lobe goes with the model: here the whole cone (lobe_deg 0)
    assert written["model"]["lobe_deg"] == 0.0 and written["model"]["lobe_range"] > 0
    other = tmp_path / "other.h5"  # another log of the same robot: the same world, another seed
    assert run("simulate", WORLDS / "corridor_door.yaml", "-o", other, "--seed", 5, "-q").exit_code == 0
    out = tmp_path / "m.h5"
    result = run("map", other, "--mode", "em", "--forward-model", model, "-o", out, "-q")
    assert result.exit_code == 0, result.output
    m = read_map_file(out)
    assert "calibration" not in m.stats["phase_seconds"] and "calibration" not in m.stats
    assert m.learned["origin"] == f"file {model}"
    # the sensor's part as the file has it; the building's share of lost readings fitted on this log; the lobe
    # carried, not learned again (no lobe stage)
    sensor_part = {k: v for k, v in written["model"].items() if k not in ("lobe_deg", "lobe_range")}
    assert m.learned["sensor"] == sensor_part | m.learned["rates"] and set(m.learned["rates"]) == {"p_max"}
    assert "lobe" not in m.stats["phase_seconds"] and "lobe_deg" not in m.plan["learns"]
    assert m.learned["lobe_deg"] == 0.0 and m.learned["lobe"] is None
    assert m.params["em"]["sigma"] == 0.03 and m.params["calibration"]["enabled"] is True  # as configured
    # the same model as --params (the old way) makes the same map
    old = tmp_path / "old.yaml"
    assert m.params["em"]["specular_deg"] == 15.0 and "opening_deg" not in written["model"]
    old.write_text("em: {" + ", ".join(f"{k}: {v!r}" for k, v in m.learned["sensor"].items())
                   + "}\ncalibration: {enabled: false}\n")
    result = run("map", other, "--mode", "em", "--params", old, "-o", tmp_path / "old.h5", "-q")
    assert result.exit_code == 0, result.output
    assert np.array_equal(read_map_file(tmp_path / "old.h5").probability, m.probability)
    # compare takes it too, for em and adaptive
    result = run("compare", other, "--modes", "standard,em,adaptive", "--forward-model", model, "--maps-dir",
                 tmp_path / "maps", "-q")
    assert result.exit_code == 0, result.output
    for mode in ("em", "adaptive"):
        compared = read_map_file(tmp_path / "maps" / f"other_{mode}.h5")
        assert compared.learned["origin"] == f"file {model}" and "calibration" not in compared.stats["phase_seconds"]


@pytest.fixture(scope="module")
def model_text(corridor_door_log, tmp_path_factory):
    """A model file of corridor_door's sonar ring (``aogm calibrate -o``), written once."""
    model = tmp_path_factory.mktemp("model") / "model.yaml"
    assert run("calibrate", corridor_door_log, "-o", model, "-q", "--max-sweeps", 2).exit_code == 0
    return model.read_text()


@pytest.mark.parametrize("change, key, word", [
    (lambda d: d["sensor"].update(count=8, mounts=d["sensor"]["mounts"][:8]), "sensor.count", "8 sensors"),
    (lambda d: d["sensor"]["mounts"][0].__setitem__(2, 45.0), "sensor.mounts", "mounts"),
    (lambda d: d["sensor"].update(beam_width_deg=20.0), "sensor.beam_width_deg", "beam of 20 deg"),
    (lambda d: d["sensor"].update(max_range=8.0), "sensor.max_range", "max range 8 m"),
    (lambda d: d.update(format_version=2), "format_version", "newer"),
    (lambda d: d.update(format="aogm-map"), "format", "aogm calibrate -o"),
    (lambda d: d["model"].update(sigma=-1.0), "model.sigma", "expected a number in"),
    (lambda d: d["model"].pop("p_hit"), "model.p_hit", "expected a number"),
    (lambda d: d.update(sensor=[1, 2]), "sensor", "expected a mapping"),
    (lambda d: d["model"].pop("lobe_range"), "model.lobe_range", "expected both lobe_deg and lobe_range"),
    (lambda d: d["model"].update(lobe_deg=95.0), "model.lobe_deg", "expected a number in [0, 90]"),
])
@pytest.mark.parametrize("command", ["map", "compare"])
def test_a_model_file_of_another_sensor_or_damaged_is_refused(corridor_door_log, model_text, tmp_path, change, key, word,
                                                              command):
    model, written = tmp_path / "model.yaml", yaml.safe_load(model_text)
    change(written)
    model.write_text(yaml.safe_dump(written))
    before = model.read_bytes()
    out = tmp_path / "out"
    args = (["map", corridor_door_log, "--mode", "em", "-o", out] if command == "map"
            else ["compare", corridor_door_log, "--modes", "standard,em", "--json", out])
    result = run(*args, "--forward-model", model, "-q")
    assert result.exit_code == 2, result.output
    assert str(model) in result.output and key in result.output and word in result.output, result.output
    assert "Traceback" not in result.output and not out.exists() and model.read_bytes() == before


def test_a_model_files_lobe_is_the_maps_and_one_without_leaves_it_to_the_log(corridor_door_log, model_text, tmp_path):
    """A model file that carries a lobe maps with it, learning none (the same map as the lobe configured and not
    learned); one without (an older file) leaves the lobe to each log, as before."""
    written = yaml.safe_load(model_text)
    written["model"].update(lobe_deg=12.0, lobe_range=6.0)
    narrow = tmp_path / "narrow.yaml"
    narrow.write_text(yaml.safe_dump(written))
    result = run("map", corridor_door_log, "--mode", "em", "--forward-model", narrow, "-o", tmp_path / "n.h5")
    assert result.exit_code == 0, result.output
    assert (f"learned from this log: p_max {read_map_file(tmp_path / 'n.h5').learned['rates']['p_max']:.3g}; the "
            f"sensor's model and its lobe (theta0 12 deg, heard out to 6 m on the axis) file {narrow}") in result.output
    m = read_map_file(tmp_path / "n.h5")
    assert (m.learned["lobe_deg"], m.learned["lobe_range"], m.learned["lobe"]) == (12.0, 6.0, None)
    assert "lobe" not in m.stats["phase_seconds"] and m.plan["learns"] == ["p_max"]
    # the lobe configured instead, the same model without it, the lobe not learned: the same map
    del written["model"]["lobe_deg"], written["model"]["lobe_range"]
    older = tmp_path / "older.yaml"
    older.write_text(yaml.safe_dump(written))
    params = tmp_path / "lobe.yaml"
    params.write_text("em: {lobe_deg: 12.0, lobe_range: 6.0}\ncalibration: {learn: 'sigma,p_rand,p_hit,p_max'}\n")
    result = run("map", corridor_door_log, "--mode", "em", "--forward-model", older, "--params", params, "-o",
                 tmp_path / "c.h5", "-q")
    assert result.exit_code == 0, result.output
    assert np.array_equal(read_map_file(tmp_path / "c.h5").probability, m.probability)
    # a lobe set in --params gives way to the carried one, and the CLI says so
    params.write_text("em: {lobe_deg: 8.0}\n")
    result = run("map", corridor_door_log, "--mode", "em", "--forward-model", narrow, "--params", params, "-o",
                 tmp_path / "w.h5", "-q")
    assert result.exit_code == 0 and result.output.splitlines()[0] == (
        f"warning: em.lobe_deg is the lobe the sensor's model carries (file {narrow}); take lobe_deg out of "
        "calibration.learn to map with 8")
    assert np.array_equal(read_map_file(tmp_path / "w.h5").probability, m.probability)
    # the older file alone: the lobe learned from the log
    result = run("map", corridor_door_log, "--mode", "em", "--forward-model", older, "-o", tmp_path / "o.h5", "-q")
    assert result.exit_code == 0, result.output
    o = read_map_file(tmp_path / "o.h5")
    assert "lobe" in o.stats["phase_seconds"] and "lobe_deg" in o.plan["learns"] and o.learned["lobe"] is not None


def test_a_model_file_that_is_not_yaml_is_refused(corridor_door_log, tmp_path):
    model = tmp_path / "model.yaml"
    model.write_text("format: [unclosed\n")
    result = run("map", corridor_door_log, "--mode", "adaptive", "-o", tmp_path / "m.h5", "--forward-model", model, "-q")
    assert result.exit_code == 2 and str(model) in result.output and "not valid YAML" in result.output
    assert not (tmp_path / "m.h5").exists()


@pytest.mark.parametrize("text, key", [
    ("calibration: {learn: 'sigma,p_foo'}\n", "calibration.learn"),
    ("calibration: {enabled: 3}\n", "calibration.enabled"),
    ("calibration: {sigma_min: 0.2}\n", "calibration.sigma_min"),  # calibration's constants are no settings
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
    tuning = C.TUNING
    used, record = C.calibration_rounds(run_, occupied, EMConfig(), CalibrationConfig(), em_step)
    assert record["final"] == C.model_values(used.forward)
    assert len(calls) == 2  # the broad map, a map for the second fit (at which the model settles)
    assert [c[2] is None for c in calls] == [False] * len(calls)  # the final run over every scan is the caller's
    scans = log.ranges.shape[0]
    first = calls[0][2].reshape(scans, -1)[:, 0]
    assert np.array_equal(np.flatnonzero(first), np.arange(0, scans, 4))  # the broad map: every 4th scan
    assert calls[0][0] == tuning.start_sigma and calls[0][1] == tuning.start_sweeps
    for _sigma, sweeps, subset in calls[1:]:  # maps made for a fit: every 2nd scan, few sweeps
        assert np.array_equal(np.flatnonzero(subset.reshape(scans, -1)[:, 0]), np.arange(0, scans, 2))
        assert sweeps == tuning.fit_sweeps
    assert not occupied.any()  # left as it was: the final map starts where the rounds did


def test_a_sigma_not_learned_stays_as_configured(corridor_door_log):
    """Calibration rounds that learn p_rand, p_hit and p_max only keep the configured sigma: round 0's broad one
    maps, but no fit and no later round takes it."""
    from aogm_cli.io.logfile import LogReader
    from aogm_cli.mapping.params import EMConfig
    from aogm_cli.mapping.pipeline import log_grid
    from aogm_cli.sensor_models.readings import lay_out_readings

    with LogReader(corridor_door_log) as reader:
        log, grid = reader.read(), log_grid(reader, 0.05)
    run_ = lay_out_readings(log.pose, log.ranges, log.sensor, grid)
    truth = log.truth.occupancy.reshape(-1).astype(bool)
    sigmas = []

    def em_step(config, occupied, subset):
        sigmas.append(config.forward.sigma)
        occupied[:] = truth
        return 1.0, 1, "result"

    occupied = np.zeros(grid.height * grid.width, dtype=bool)
    used, record = C.calibration_rounds(run_, occupied, EMConfig(), CalibrationConfig(learn="p_rand,p_hit,p_max"),
                                        em_step)
    assert sigmas[0] == C.TUNING.start_sigma and set(sigmas[1:]) <= {0.03}
    assert used.forward.sigma == 0.03 and record["final"]["sigma"] == 0.03
    assert all(r["sigma"] == 0.03 for r in record["rounds"][1:])


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

    tuning = C.Tuning(max_scans=40, subsample=1, rounds=2)
    _, record = C.calibration_rounds(run_, np.zeros(grid.height * grid.width, dtype=bool), EMConfig(),
                                     CalibrationConfig(), em_step, tuning=tuning)
    blocks = calls[1]  # the second round: every scan of the runs (subsample 1)
    starts = np.flatnonzero(np.diff(np.concatenate([[0], blocks.astype(int)])) == 1)
    assert blocks.sum() == 40 and len(starts) == C.CAL_BLOCKS and starts[0] == 0 and starts[-1] == scans - 10
    assert np.array_equal(calls[0], blocks & (np.arange(scans) % tuning.start_subsample == 0))  # the broad map
    assert "4 runs of 10 consecutive scans" in record["fitted_at"]
    assert record["readings_used"] <= 40 * width
    # a log within max_scans is left whole
    assert C._scan_blocks(run_, scans) is None


def test_a_wide_sensor_calibrates_on_a_bounded_number_of_readings(corridor_door_log):
    """With many beams a scan, the runs hold at most calibration's max_mapped_readings readings:
    fewer scans than max_scans (a laser's 180 beams: 355 scans of 64,000 readings), the same
    runs of consecutive scans."""
    from aogm_cli.io.logfile import LogReader
    from aogm_cli.mapping.params import EMConfig
    from aogm_cli.mapping.pipeline import log_grid
    from aogm_cli.sensor_models.readings import lay_out_readings

    with LogReader(corridor_door_log) as reader:
        log, grid = reader.read(), log_grid(reader, 0.05)
    run_ = lay_out_readings(log.pose, log.ranges, log.sensor, grid)
    scans, width = log.ranges.shape
    assert C.calibration_scans(run_, C.Tuning(max_scans=100, max_mapped_readings=40 * width + width - 1)) == 40
    assert C.calibration_scans(run_, C.Tuning(max_scans=40, max_mapped_readings=10**9)) == 40
    assert C.calibration_scans(run_, C.TUNING) == C.TUNING.max_scans  # 24 sonars: the scans bound the runs
    calls = []

    def em_step(config, occupied, subset):
        calls.append(subset.reshape(scans, width)[:, 0].copy())
        return 1.0, 1, "result"

    tuning = C.Tuning(max_scans=100, max_mapped_readings=40 * width, subsample=1, rounds=2)
    _, record = C.calibration_rounds(run_, np.zeros(grid.height * grid.width, dtype=bool), EMConfig(),
                                     CalibrationConfig(), em_step, tuning=tuning)
    assert calls[1].sum() == 40 and record["readings_used"] <= 40 * width
    assert "4 runs of 10 consecutive scans" in record["fitted_at"]


# --- the sensor model a detector carries (issue 36) --------------------------------------------


def test_carried_model_maps_without_calibrating(corridor_door_log, tmp_path):
    """By default (``calibration.carried``) a simulated log of the packaged detector's ring maps
    with the model it carries: no calibration phase, the building's p_max fitted (``rates``), the
    sensor's sigma, p_hit and p_rand as carried. With ``carried: false`` it calibrates, and aogm
    map says so in one line."""
    from aogm_cli.io.detectorfile import load_detector
    from aogm_cli.map_files import map_file, resolve_params

    carried = map_file(corridor_door_log, "em", resolve_params())
    assert carried.learned["origin"] == "carried by the packaged detector"
    assert "calibration" not in carried.stats["phase_seconds"] and "rates" in carried.stats["phase_seconds"]
    model = load_detector().sensor_models[0]["model"]
    assert {k: carried.learned["sensor"][k] for k in ("sigma", "p_hit", "p_rand")} == {
        k: model[k] for k in ("sigma", "p_hit", "p_rand")}
    assert 0 <= carried.learned["rates"]["p_max"] < 1 and carried.learned["rates"]["p_max"] != model["p_max"]
    own = tmp_path / "own.yaml"
    own.write_text("calibration: {carried: false}\n")
    result = CliRunner().invoke(main, ["map", str(corridor_door_log), "--mode", "em", "--params", str(own), "-o",
                                       str(tmp_path / "m.h5"), "--quiet"])
    assert result.exit_code == 0, result.output
    assert "calibrated the sensor's model on this log (calibration.carried is false)" in result.output


def test_a_detector_carries_the_lobe_only_when_its_training_logs_learned_one_shape():
    """``aogm train --sensor-models``: the median lobe when every log learned the whole cone, or every log a narrower
    lobe; none when they disagree (the packaged detector's training logs: 8 the whole cone, 1 theta0 10), nor when a
    log learned none."""
    from aogm_cli.map_files import one_lobe

    cone, narrow = {"lobe_deg": 0.0, "lobe_range": 10.0}, {"lobe_deg": 9.5, "lobe_range": 6.0}
    assert one_lobe([cone, cone]) and one_lobe([narrow, narrow | {"lobe_deg": 4.0}])
    assert not one_lobe([cone, cone, narrow]) and not one_lobe([cone, {}])
