"""The exact inverse sensor model: the linear-time posterior against brute force over every binary
map of a cone, a hand-computed two-cell cone, and one reading on a tiny grid (free before the echo,
occupied at it, untouched behind an obstacle the map believes in)."""

import itertools
import math

import numpy as np
import pytest

from aogm_cli.core.grid import GridSpec
from aogm_cli.core.log import SensorSpec
from aogm_cli.mapping.exact import ExactMapper
from aogm_cli.mapping.standard import standard_map
from aogm_cli.sensor_models.exact_inverse import L0 as PRIOR_L0
from aogm_cli.sensor_models.exact_inverse import PRIOR, cone_terms
from aogm_cli.sensor_models.forward_model import ForwardModelConfig
from aogm_cli.sensor_models.inverse_model import InverseModelConfig


def cone_ratios(p, g, j0, g0, p_hit, const, w, n, a, u, r, na, out):
    """``cone_terms``' ratios in ``out`` (False, ``out`` unset, when every ratio is exactly 1)."""
    if not cone_terms(p, g, j0, g0, p_hit, const, w, n, a, u, r, na, out):
        return False
    out[:n] /= na[:n]
    return True


def ratios(p, g, g0, p_hit, const, w):
    n = len(p)
    g = np.asarray(g, float)
    j0 = int(np.argmax(g != 0)) if g.any() else n  # the cells before the window: g = 0
    out = np.empty(n)
    assert cone_ratios(np.asarray(p, float), g, j0, g0, p_hit, const, w, n,
                       np.empty(n), np.empty(n), np.empty(n), np.empty(n), out)
    return np.log(out)


def brute_force(p, g, g0, p_hit, const, w):
    """log p(z | m_j = 1) - log p(z | m_j = 0) by summing the forward model over every binary map."""
    n = len(p)
    mass = np.zeros((n, 2))
    for m in itertools.product((0, 1), repeat=n):
        s, qk = 0.0, 1.0
        for i in range(n):
            if m[i]:
                s += qk * p_hit * g[i]
                qk *= 1.0 - p_hit
        likelihood = const + w * (s + qk * g0)
        for j in range(n):
            others = np.prod([p[i] if m[i] else 1.0 - p[i] for i in range(n) if i != j])
            mass[j, m[j]] += others * likelihood
    return np.log(mass[:, 1]) - np.log(mass[:, 0])


def test_linear_pass_matches_brute_force_on_random_cones():
    rng = np.random.default_rng(7)
    for _ in range(100):
        n = int(rng.integers(1, 8))
        p = rng.uniform(0.01, 0.99, n)
        g = rng.uniform(0.0, 12.0, n) * (rng.random(n) < 0.6)  # cells before the window have g = 0
        args = (p, g, rng.uniform(0.0, 5.0), rng.uniform(0.1, 0.99), rng.uniform(1e-3, 0.1), rng.uniform(0.5, 0.95))
        np.testing.assert_allclose(ratios(*args), brute_force(*args), rtol=0, atol=1e-9)


def three_passes(p, g, g0, p_hit, const, w):
    """The ratios as the comment above ``cone_terms`` writes them: forward, backward, then per cell."""
    n, q = len(p), 1.0 - p_hit
    a, u, r, out = [0.0] * n, [0.0] * n, [0.0] * n, [0.0] * n
    prod, acc = 1.0, 0.0
    for j in range(n):
        u[j], a[j] = acc, prod
        acc += p[j] * p_hit * g[j] * prod
        prod *= 1.0 - p_hit * p[j]
    tail = g0
    for j in range(n - 1, -1, -1):
        r[j] = tail
        tail = p[j] * p_hit * g[j] + (1.0 - p_hit * p[j]) * tail
    for j in range(n):
        out[j] = (const + w * (u[j] + a[j] * (p_hit * g[j] + q * r[j]))) / (const + w * (u[j] + a[j] * r[j]))
    return out


def test_split_passes_equal_the_three_passes():
    # long cones (to a sonar's 2,600 cells) of cells before the window, then a window of echoes;
    # dense priors make the beam's return through them negligible: cone_ratios then says so
    # (False), and only when every ratio is exactly 1. Before the window the kernel takes one
    # product of the cells' a_i where the three passes take A_j and R_j apart: the same ratios,
    # rounded otherwise (a relative 3e-15 at most here)
    rng = np.random.default_rng(11)
    skipped = 0
    worst = 0.0
    for trial in range(300):
        j0, n_window = int(rng.integers(0, 2600)), int(rng.integers(0, 12))
        n = j0 + n_window
        if n == 0:
            continue
        p = rng.choice([0.1, 0.01, 0.5, 0.99, 1e-3], n) * rng.uniform(0.5, 1.0, n)
        if trial % 3 == 0:
            p[:] = 1e-3  # a cone across free cells: its far cells still see the echo
        g = np.zeros(n)
        g[j0:] = rng.uniform(0.0, 13.3, n_window) * (rng.random(n_window) < 0.9)
        g0 = (0.0, 13.3, 1e-300)[trial % 3]
        p_hit, const, w = 0.7, 0.05 / 5.0 + 0.1 * g0, 0.85
        out = np.empty(n)
        scratch = [np.empty(n) for _ in range(4)]
        expected = np.array(three_passes(list(p), list(g), g0, p_hit, const, w))
        if cone_ratios(p, g, j0, g0, p_hit, const, w, n, *scratch, out):
            worst = max(worst, float(np.max(np.abs(out / expected - 1.0))))
        else:
            skipped += 1
            assert (expected == 1.0).all()
    assert 10 < skipped < 290  # both paths taken
    assert worst < 1e-13, worst


def test_two_cells_by_hand():
    # cell 1 before the window (g = 0), cell 2 at the echo (g = 10); G0 = 0, C = 0.01, w = 0.85
    p_hit, const, w = 0.5, 0.01, 0.85
    out = ratios([0.5, 0.5], [0.0, 10.0], 0.0, p_hit, const, w)
    # cell 1: occupied, it is detected first (no echo there) or missed (q = 0.5) before cell 2,
    # whose expected term is 0.5 * 0.5 * 10 = 2.5: S(1) = 0.5 * 2.5, S(0) = 2.5
    assert out[0] == pytest.approx(math.log(const + w * 1.25) - math.log(const + w * 2.5))
    # cell 2: A = 1 - 0.25 = 0.75 of the beams reach it; S(1) = 0.75 * 0.5 * 10, S(0) = 0
    assert out[1] == pytest.approx(math.log(const + w * 3.75) - math.log(const))


SONAR = SensorSpec(mount=np.zeros((1, 3)), beam_width=math.radians(30.0), min_range=0.05, max_range=2.0)
GRID = GridSpec(0.0, 0.0, 0.1, 11, 21)
FORWARD = ForwardModelConfig(sigma=0.05, p_rand=0.05, p_hit=0.7, p_max=0.1)
L0 = -2.0  # the log-odds of the prior the tests below give the mapper (the maps': exact_inverse.PRIOR)


def one_reading(z, prior=None):
    mapper = ExactMapper(SONAR, GRID, FORWARD, prior=1.0 / (1.0 + math.exp(-L0)))
    if prior is not None:  # log-odds, -inf unobserved
        mapper.state[:] = np.where(np.isfinite(prior), 1.0 / (1.0 + np.exp(-prior)), -1.0).reshape(-1)
    # the sensor at the centre of cell (row 5, col 1), pointing +x
    mapper.update(np.array([[0.15, 0.55, 0.0]]), np.array([[z]], dtype=np.float32))
    return mapper.result()


def test_one_reading_frees_before_the_echo_and_marks_it():
    log_odds, observed = one_reading(1.0)  # a template range: the echo at col 11
    axis = log_odds[5]
    assert observed[5, 1:13].all() and not observed[5, 15:].any()  # the cone ends 4 sigma beyond z
    assert (axis[2:9] < L0).all()  # free before the echo
    # occupied at it; the echo's credit shared by the arc's five cells at that range
    assert axis[11] > L0 + 0.5
    assert axis[11] == log_odds.max() and (log_odds[3:8, 11] > L0 + 0.5).all()


def test_nothing_learned_behind_a_believed_obstacle():
    prior = np.full(GRID.shape, -np.inf, dtype=np.float32)
    prior[:, 6] = 4.0  # a wall the map is sure of, at col 6
    log_odds, _ = one_reading(1.0, prior)
    # the reading most likely echoed off the wall... or is random: cells behind it barely move
    assert abs(log_odds[5, 8] - L0) < abs(one_reading(1.0)[0][5, 8] - L0)


def test_the_standard_mode_takes_the_exact_model():
    ranges = np.full((1, 1), 1.0, dtype=np.float32)
    chunks = [(0, np.zeros(1), np.array([[0.15, 0.55, 0.0]]), ranges)]
    log_odds, observed = standard_map(chunks, SONAR, GRID, InverseModelConfig(model="exact"), forward=FORWARD)
    assert observed[5, 5] and log_odds[5, 5] < PRIOR_L0
    # every map's prior (exact_inverse.PRIOR, 0.1) where no reading reached
    assert PRIOR == 0.1 and (~observed).any() and np.all(log_odds[~observed] == np.float32(math.log(0.1 / 0.9)))


def test_thinning_frees_what_the_exact_model_holds_free(corridor_door_log, tmp_path):
    # the map file records the section; the thinned map frees cells of the Elfes map's walls'
    # thickness and keeps its walls (a cell the exact model is unsure of keeps Elfes' value)
    from aogm_cli.map_files import map_file, resolve_params

    params = tmp_path / "p.yaml"
    params.write_text("exact: {thin: true}\n")
    plain = map_file(corridor_door_log, "standard", resolve_params())
    thin = map_file(corridor_door_log, "standard", resolve_params(str(params)))
    assert thin.params["exact"]["thin"] is True and plain.params["exact"]["thin"] is False
    assert (thin.observed == plain.observed).all()
    changed = thin.probability != plain.probability
    assert changed.any() and (thin.probability[changed] < plain.probability[changed]).all()
    walls = plain.probability > 0.5
    assert 0.2 < (thin.probability[walls] > 0.5).mean() < 0.95


def test_map_takes_the_exact_model_by_option(corridor_door_log, tmp_path):
    from click.testing import CliRunner

    from aogm_cli.cli import main
    from aogm_cli.io.mapfile import read_map_file

    out = tmp_path / "m.h5"
    result = CliRunner().invoke(main, ["map", str(corridor_door_log), "--mode", "standard", "--model", "exact",
                                       "-o", str(out), "-q"])
    assert result.exit_code == 0, result.output
    m = read_map_file(out)
    assert m.params["inverse_model"]["model"] == "exact" and m.observed.any()
