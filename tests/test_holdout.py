"""Held-out scores of a map (``evaluation.holdout``) and ``aogm compare --holdout``: the split,
the AUC and the reference log-likelihood on hand-computed cases, and the command end to end."""

import dataclasses
import json
import math

import h5py
import numpy as np
import pytest
import yaml
from click.testing import CliRunner
from scipy.stats import rankdata

from aogm_cli.cli import main
from aogm_cli.core.errors import InputError
from aogm_cli.core.grid import GridSpec
from aogm_cli.core.log import Log, SensorSpec, Truth
from aogm_cli.core.scores import STANDARD_KEYS
from aogm_cli.evaluation.holdout import (
    REFERENCE_MODEL,
    SCORE_KEYS,
    HoldoutSplit,
    arc_alpha,
    auc_from_counts,
    axis_labels,
    cell_labels,
    reading_scores,
    reference_log_likelihoods,
    roc_auc,
    split_log,
)
from aogm_cli.io.logfile import read_log, write_log
from aogm_cli.mapping.standard import standard_map
from aogm_cli.sensor_models.inverse_model import InverseModelConfig
from aogm_cli.simulation.sonar import simulate
from aogm_cli.world.loader import parse_world


def run(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


# --- the split -------------------------------------------------------------------------------


def test_every_tenth_scan_is_held_out_from_a_seeded_offset():
    split = HoldoutSplit(0.1, seed=3).validate()
    assert split.period == 10 and 0 <= split.offset < 10
    np.testing.assert_array_equal(split.held_out(35), np.arange(split.offset, 35, 10))
    assert HoldoutSplit(0.1, seed=3).offset == split.offset  # reproducible
    assert len({HoldoutSplit(0.1, seed=s).offset for s in range(20)}) > 1  # the seed moves it
    assert HoldoutSplit(0.5).period == 2 and HoldoutSplit(0.3).period == 3


@pytest.mark.parametrize("fraction", [0.0, -0.1, 0.51, 0.9, math.nan, math.inf, True])
def test_a_fraction_outside_0_to_half_is_refused(fraction):
    with pytest.raises(InputError) as err:
        HoldoutSplit(fraction).validate()
    assert err.value.key == "--holdout"


def test_split_log_keeps_the_other_scans_and_their_truth():
    sensor = SensorSpec(mount=np.zeros((2, 3)))
    n = 23
    truth_like = truth_stub(n)
    log = Log(np.arange(n, dtype=float), np.zeros((n, 3)), np.arange(2 * n, dtype=np.float32).reshape(n, 2), sensor,
              "test", truth=truth_like)
    split = HoldoutSplit(0.1, seed=1)
    kept, held = split_log(log, split)
    np.testing.assert_array_equal(held, np.arange(split.offset, n, 10))
    keep = np.setdiff1d(np.arange(n), held)
    np.testing.assert_array_equal(kept.time, keep)
    np.testing.assert_array_equal(kept.ranges[:, 0], 2 * keep)
    np.testing.assert_array_equal(kept.truth.cause[:, 0], keep)
    assert kept.truth.occupancy is truth_like.occupancy
    one_scan = dataclasses.replace(log, time=log.time[:1], pose=log.pose[:1], ranges=log.ranges[:1], truth=None)
    first_held = next(s for s in range(50) if HoldoutSplit(0.5, seed=s).offset == 0)
    with pytest.raises(InputError, match="keep none"):
        split_log(one_scan, HoldoutSplit(0.5, seed=first_held))


def truth_stub(n):
    grid = GridSpec(0.0, 0.0, 0.1, 2, 2)
    cause = np.repeat(np.arange(n, dtype=np.int8)[:, None], 2, axis=1)
    return Truth(grid, np.zeros((2, 2), dtype=np.uint8), cause, np.zeros((n, 2), dtype=np.float32))


# --- the AUC ---------------------------------------------------------------------------------


def test_auc_of_hand_computed_cases():
    assert roc_auc([0.9, 0.8], [0.1, 0.2]) == 1.0
    assert roc_auc([0.1, 0.2], [0.9, 0.8]) == 0.0
    assert roc_auc([0.5, 0.5, 0.5], [0.5, 0.5]) == 0.5
    # pairs: 0.9 beats both, 0.6 beats both, 0.4 loses to 0.5 and ties 0.4: 4.5 of 6
    assert roc_auc([0.9, 0.6, 0.4], [0.5, 0.4]) == pytest.approx(0.75)
    assert math.isnan(roc_auc([], [0.3])) and math.isnan(roc_auc([0.3], []))


def test_auc_is_mann_whitney_with_average_ranks_and_counts_are_repeats():
    rng = np.random.default_rng(0)
    pos = rng.integers(0, 6, 40) / 5.0  # many ties
    neg = rng.integers(0, 5, 30) / 5.0
    ranks = rankdata(np.concatenate([pos, neg]))
    u = ranks[: pos.size].sum() - pos.size * (pos.size + 1) / 2
    assert roc_auc(pos, neg) == pytest.approx(u / (pos.size * neg.size))
    scores = np.array([0.2, 0.5, 0.7])
    p, n = np.array([0, 3, 2]), np.array([4, 1, 0])
    assert auc_from_counts(scores, p, n) == pytest.approx(roc_auc(np.repeat(scores, p), np.repeat(scores, n)))


# --- which cells a reading labels ------------------------------------------------------------


def test_cone_labels_are_the_standard_mappers_arc_and_free_region():
    """One sonar reading (and one with no echo): positives where the constant inverse model adds
    occupied evidence, negatives where it adds free evidence."""
    grid = GridSpec(0.0, 0.0, 0.05, 60, 80)
    sensor = SensorSpec(mount=np.zeros((1, 3)), max_range=2.5, min_range=0.15)
    config = InverseModelConfig(model="constant", alpha=arc_alpha(grid))
    for z in (1.2137, np.inf):
        pose = np.array([[0.61, 1.52, 0.3]])
        ranges = np.array([[z]], dtype=np.float32)
        log_odds, _ = standard_map([(0, np.zeros(1), pose, ranges)], sensor, grid, config)
        pos, neg = cell_labels(pose, ranges, sensor, grid)
        np.testing.assert_array_equal(pos > 0, log_odds > 0)
        np.testing.assert_array_equal(neg > 0, log_odds < 0)
        assert pos.max() <= 1 and neg.max() <= 1 and not (pos & neg).any()
        assert (pos.sum() > 0) == np.isfinite(z) and neg.sum() > 0


def test_laser_labels_are_the_endpoint_and_the_cells_before_the_hit():
    grid = GridSpec(0.0, 0.0, 0.05, 3, 10)
    sensor = SensorSpec(mount=np.zeros((1, 3)), kind="laser", beam_width=math.radians(0.5), min_range=0.0,
                        max_range=1.0)
    pose = np.array([[0.025, 0.075, 0.0], [0.025, 0.075, 0.0]])
    ranges = np.array([[0.31], [np.inf]], dtype=np.float32)  # endpoint x = 0.335 (col 6); no echo
    pos, neg = cell_labels(pose, ranges, sensor, grid)
    expected_pos = np.zeros(grid.shape, dtype=int)
    expected_pos[1, 6] = 1
    expected_neg = np.zeros(grid.shape, dtype=int)
    expected_neg[1, :] = 1  # the no-echo ray, to the grid's edge
    expected_neg[1, :4] += 1  # cells left before z - alpha/2 = 0.21 (col 3 exits at 0.175, col 4 at 0.225)
    np.testing.assert_array_equal(pos, expected_pos)
    np.testing.assert_array_equal(neg, expected_neg)


def test_a_sonar_readings_positive_is_the_largest_probability_on_its_arc():
    """One cell of a 30-degree arc echoed: a map holding that cell occupied and the rest of the
    arc free scores the reading's positive at that cell's probability."""
    grid = GridSpec(0.0, 0.0, 0.05, 60, 80)
    sensor = SensorSpec(mount=np.zeros((1, 3)), max_range=2.5, min_range=0.15)
    pose = np.array([[0.61, 1.52, 0.3]])
    ranges = np.array([[1.2137]], dtype=np.float32)
    pos, neg = cell_labels(pose, ranges, sensor, grid)
    arc = np.argwhere(pos > 0)
    probability = np.full(grid.shape, 0.2)
    probability[pos > 0] = 0.05
    probability[tuple(arc[len(arc) // 2])] = 0.9
    scores, negatives = reading_scores(pose, ranges, sensor, grid, probability)
    assert scores.tolist() == [0.9]
    np.testing.assert_array_equal(negatives, neg)
    # no echo: no positive, only the free cone
    scores, _ = reading_scores(pose, np.array([[np.inf]], dtype=np.float32), sensor, grid, probability)
    assert scores.size == 0


def test_a_laser_readings_positive_is_the_largest_probability_in_its_hit_band():
    grid = GridSpec(0.0, 0.0, 0.05, 3, 20)
    sensor = SensorSpec(mount=np.zeros((1, 3)), kind="laser", beam_width=math.radians(0.5), min_range=0.0,
                        max_range=1.0)
    pose = np.array([[0.025, 0.075, 0.0]])
    ranges = np.array([[0.31]], dtype=np.float32)  # endpoint x = 0.335 (col 6); band 0.21 .. 0.41 of the ray
    probability = np.full(grid.shape, 0.3)
    probability[1, 8] = 0.8  # x 0.40-0.45: the ray enters it at 0.375, inside the band
    probability[1, 9] = 0.99  # enters at 0.425: beyond the band
    scores, negatives = reading_scores(pose, ranges, sensor, grid, probability)
    assert scores.tolist() == [0.8]
    assert negatives[1, :4].tolist() == [1, 1, 1, 1] and negatives.sum() == 4


# --- the axis protocol (holdout_auc) ----------------------------------------------------------


@pytest.mark.parametrize("kind", ["sonar", "laser"])
def test_axis_labels_and_their_auc_by_hand(kind):
    """A sensor at x = 0.05 facing +x on one row of 0.1 m cells. The echo at 0.6 m ends in col 6
    (x = 0.65), its negatives the cells its axis crosses up to 0.6 - 2 * 0.1 = 0.4 m (x = 0.45:
    cols 0-4); the echo at 0.8 m: col 8, negatives cols 0-6. No echo and NaN label nothing, and
    a sonar is scored on its axis as a laser is."""
    grid = GridSpec(0.0, 0.0, 0.1, 1, 10)
    sensor = SensorSpec(mount=np.zeros((4, 3)), kind=kind, max_range=1.0, min_range=0.0,
                        beam_width=math.radians(0.5 if kind == "laser" else 30))
    pose = np.array([[0.05, 0.05, 0.0]])
    ranges = np.array([[0.6, 0.8, np.inf, np.nan]], dtype=np.float32)
    pos, neg = axis_labels(pose, ranges, sensor, grid)
    assert pos[0].tolist() == [0, 0, 0, 0, 0, 0, 1, 0, 1, 0]
    assert neg[0].tolist() == [2, 2, 2, 2, 2, 1, 1, 0, 0, 0]
    probability = np.array([[0.1, 0.2, 0.3, 0.5, 0.7, 0.5, 0.6, 0.9, 0.4, 0.5]])
    # positive 0.6 beats 9 of the 12 negatives and ties one (col 6 itself, as B's negative): 9.5;
    # positive 0.4 beats the six below 0.4: 6. (9.5 + 6) / (2 * 12)
    assert auc_from_counts(probability, pos, neg) == pytest.approx(15.5 / 24)


def test_axis_labels_follow_the_mount_and_leave_the_grid_out():
    """A sensor mounted facing +y on a robot facing -y looks along +x; an echo beyond the grid
    gives no positive, but its negatives inside the grid count."""
    grid = GridSpec(0.0, 0.0, 0.1, 1, 5)
    sensor = SensorSpec(mount=np.array([[0.0, 0.0, math.pi / 2]]), max_range=2.0, min_range=0.0)
    pose = np.array([[0.05, 0.05, -math.pi / 2], [0.05, 0.05, -math.pi / 2]])
    pos, neg = axis_labels(pose, np.array([[0.3], [0.9]], dtype=np.float32), sensor, grid)
    assert pos[0].tolist() == [0, 0, 0, 1, 0]  # x 0.35; the other ends at x 0.95, outside
    assert neg[0].tolist() == [2, 2, 1, 1, 1]  # to x 0.15 (cols 0-1) and to x 0.75 (every col)


# --- the reference log-likelihood ------------------------------------------------------------


def gaussian(z, d, sigma):
    return math.exp(-0.5 * ((z - d) / sigma) ** 2) / (math.sqrt(2 * math.pi) * sigma)


def test_loglik_of_one_reading_and_one_obstacle_is_the_formula():
    """Sensor at a cell's centre facing +x, one occupied cell 10 cells (0.5 m) ahead. The
    reading 0.48 m is compared at 0.505 m (half a cell further, ``readings.echo_ranges``)."""
    grid = GridSpec(0.0, 0.0, 0.05, 40, 40)
    z_max = 1.5
    sensor = SensorSpec(mount=np.zeros((4, 3)), max_range=z_max)
    occupied = np.zeros(grid.shape, dtype=bool)
    occupied[20, 15] = True
    pose = np.array([[5.5 * 0.05, 20.5 * 0.05, 0.0]])
    ranges = np.array([[0.48, np.inf, np.nan, 1.7]], dtype=np.float32)  # echo, no echo, invalid, beyond z_max
    ll = reference_log_likelihoods(pose, ranges, sensor, grid, occupied)
    m = REFERENCE_MODEL
    w = 1 - m.p_rand - m.p_max
    z = float(np.float32(0.48)) + 0.025
    g0 = gaussian(z, z_max, m.sigma)
    echo = m.p_rand / z_max + m.p_max * g0 + w * (m.p_hit * gaussian(z, 0.5, m.sigma) + (1 - m.p_hit) * g0)
    # no echo: the obstacle, 1 m (10 sigma) short of z_max, lies beyond the Gaussian's window
    g0 = gaussian(z_max, z_max, m.sigma)
    no_echo = m.p_rand / z_max + m.p_max * g0 + w * (1 - m.p_hit) * g0
    np.testing.assert_allclose(ll, [math.log(echo), math.log(no_echo), math.log(no_echo)], rtol=1e-12)
    assert (m.sigma, m.p_rand, m.p_hit, m.p_max) == (0.1, 0.1, 0.5, 0.1)


# --- aogm compare --holdout ------------------------------------------------------------------


@pytest.fixture(scope="module")
def room_log(tmp_path_factory, tiny_room_world):
    world = parse_world(yaml.safe_load(tiny_room_world), file="tiny_room.yaml", text=tiny_room_world)
    log = simulate(world, seed=1)
    assert 20 <= log.n_scans <= 40
    path = tmp_path_factory.mktemp("holdout") / "room.h5"
    write_log(path, log)
    return path


@pytest.fixture(scope="module")
def compared(room_log, tmp_path_factory):
    out = tmp_path_factory.mktemp("cmp")
    result = run("compare", room_log, "--modes", "standard,em", "--holdout", 0.1, "--json", out / "r.json",
                 "--maps-dir", out / "maps", "--require", "em.holdout_auc >= standard.holdout_auc - 1",
                 "--require", "standard.holdout_loglik > -100")
    assert result.exit_code == 0, result.output
    return out, json.loads((out / "r.json").read_text()), result.output


def test_holdout_scores_are_in_the_json_and_the_table(room_log, compared):
    out, doc, output = compared
    split = HoldoutSplit(0.1, seed=0)
    n_scans = read_log(room_log).n_scans
    for r in doc["results"]:
        metrics = r["metrics"]
        assert set(SCORE_KEYS) <= set(metrics) and "accuracy" in metrics  # truth metrics too
        assert 0.5 < metrics["holdout_auc"] <= 1 and math.isfinite(metrics["holdout_loglik"])
        assert metrics["holdout_scans"] == split.held_out(n_scans).size
        assert metrics["holdout_readings"] == 12 * metrics["holdout_scans"]  # no NaN reading in a simulated log
        assert r["params"]["holdout"] == split.as_dict()
    assert doc["holdout"]["period"] == 10 and doc["holdout"]["reference"]["forward_model"]["sigma"] == 0.1
    for column in ("Held-out AUC", "AUC (band)", "Held-out loglik", "Held-out readings", "Held-out scans"):
        assert column in output
    assert "gates: 2 of 2 passed" in output
    with h5py.File(out / "maps" / "room_em.h5") as f:
        assert f.attrs["source_log"] == str(room_log)


def test_holdout_maps_come_back_with_the_same_split_only(room_log, compared, tmp_path):
    out, doc, _ = compared
    maps = [out / "maps" / "room_standard.h5", out / "maps" / "room_em.h5"]
    again = run("compare", *maps, "--holdout", 0.1, "--json", tmp_path / "r.json", "-q")
    assert again.exit_code == 0, again.output
    assert json.loads((tmp_path / "r.json").read_text())["results"] == doc["results"]
    for args in ([], ["--holdout", 0.1, "--seed", 5]):
        refused = run("compare", maps[0], *args, "-q")
        assert refused.exit_code == 2 and "--holdout" in refused.output and "room_standard.h5" in refused.output


def test_a_results_file_of_before_the_axis_auc_reads_back_as_the_band_auc(compared, tmp_path):
    """A --json file written before the axis protocol (its reference records no AUC protocol) scored
    holdout_auc as holdout_auc_band is scored now: read back so, with holdout_auc not available,
    and written again as it now reads."""
    out, doc, _ = compared
    old = json.loads(json.dumps(doc))
    del old["holdout"]["reference"]["auc"]
    for r in old["results"]:
        r["metrics"]["holdout_auc"] = r["metrics"].pop("holdout_auc_band")
    (tmp_path / "old.json").write_text(json.dumps(old))
    result = run("compare", "--from-json", tmp_path / "old.json", "--json", tmp_path / "again.json", "-q",
                 "--require", "em.holdout_auc > 0")
    assert result.exit_code == 1 and "em.holdout_auc > 0  (nan > 0; not a number)" in result.output, result.output
    for before, again in zip(doc["results"], json.loads((tmp_path / "again.json").read_text())["results"], strict=True):
        assert again["metrics"]["holdout_auc"] is None
        assert again["metrics"]["holdout_auc_band"] == before["metrics"]["holdout_auc_band"]
    twice = run("compare", "--from-json", tmp_path / "again.json", "--json", tmp_path / "twice.json", "-q")
    first, second = (json.loads((tmp_path / name).read_text()) for name in ("again.json", "twice.json"))
    assert twice.exit_code == 0 and (first["results"], first["holdout"]) == (second["results"], second["holdout"])


def test_a_failed_holdout_gate_names_its_numbers(room_log):
    result = run("compare", room_log, "--modes", "standard", "--holdout", 0.2, "--seed", 4,
                 "--require", "standard.holdout_auc > 1", "-q")
    assert result.exit_code == 1
    assert "FAILED tiny_room: standard.holdout_auc > 1  (0." in result.output


def test_a_log_without_truth_gets_holdout_scores_only(room_log, tmp_path):
    bare = tmp_path / "bare.h5"
    write_log(bare, dataclasses.replace(read_log(room_log), truth=None))
    result = run("compare", bare, "--modes", "standard", "--holdout", 0.1, "--params", params_file(tmp_path),
                 "--json", tmp_path / "r.json", "--require", "standard.holdout_auc > 0.5", "-q")
    assert result.exit_code == 0, result.output
    (r,) = json.loads((tmp_path / "r.json").read_text())["results"]
    # held-out scores and, against the standard map, what a planner sees; no accuracy
    assert set(r["metrics"]) == set(SCORE_KEYS) | set(STANDARD_KEYS) and r["consistency"] is not None
    assert r["metrics"]["holdout_readings"] > 0 and "Held-out AUC" in result.output


def params_file(folder):
    path = folder / "p.yaml"
    path.write_text("resolution: 0.1\n")
    return path


@pytest.mark.parametrize("value", ["0", "0.9", "nan", "-1"])
def test_an_invalid_holdout_exits_2_naming_the_option(room_log, value):
    result = run("compare", room_log, "--modes", "standard", "--holdout", value, "-q")
    assert result.exit_code == 2 and "--holdout" in result.output


def test_a_holdout_metric_without_holdout_exits_2_naming_it(room_log):
    result = run("compare", room_log, "--modes", "standard", "--require", "standard.holdout_auc > 0.5", "-q")
    assert result.exit_code == 2 and "holdout_auc" in result.output and "--holdout" in result.output
