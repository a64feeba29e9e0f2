"""EM with forward models on hand-computable cases: obstacles where readings say, openings kept."""

import math

import numpy as np
import pytest

from aogm_cli.core.grid import GridSpec
from aogm_cli.mapping.em import run_em
from aogm_cli.mapping.params import EMConfig
from aogm_cli.mapping.sensor_models.cone import build_cone_templates
from aogm_cli.mapping.sensor_models.forward_model import ForwardModelConfig, build_forward_index, log_likelihoods

GRID = GridSpec(0.0, 0.0, 0.1, 21, 41)
FORWARD = ForwardModelConfig(sigma=0.05, p_rand=0.05, p_hit=0.4, p_max=0.0)
CONFIG = EMConfig(forward=FORWARD, start="empty")


def index_for(ranges, beam_deg=10.0, yaw=0.0, row=10, col=5):
    """Readings all taken from cell (row, col) facing ``yaw``."""
    tpl = build_cone_templates(GRID.resolution, math.radians(beam_deg), 4.0)
    n = len(ranges)
    rows, cols = np.full(n, row), np.full(n, col)
    bins = tpl.heading_bin(np.full(n, yaw))
    return build_forward_index(rows, cols, bins, np.asarray(ranges, float), GRID, tpl, 4.0, FORWARD), tpl


def cell_range(flat, row=10, col=5):
    r, c = np.divmod(flat, GRID.width)
    return GRID.resolution * np.hypot(r - row, c - col)


def test_readings_square_to_a_wall_put_the_obstacle_at_their_range():
    index, _ = index_for([1.0] * 5)
    occupied = np.zeros(GRID.height * GRID.width, dtype=bool)
    result = run_em(index, occupied, np.unique(index.cell), CONFIG)
    cells = np.flatnonzero(occupied)
    assert cells.size >= 1
    # every obstacle lies at the readings' range (within one cell), none before it
    assert np.all(np.abs(cell_range(cells) - 1.0) <= 0.1 + 1e-9)
    # the cell on the beam axis at 1.0 m is occupied; the axis cells before it are free
    assert occupied[10 * GRID.width + 15]
    assert not occupied[10 * GRID.width + 6 : 10 * GRID.width + 14].any()
    assert result.flips[-1] == 0


def test_empty_start_creates_obstacles_and_the_objective_never_decreases():
    index, _ = index_for([1.0] * 5 + [1.5] * 3 + [np.inf])
    occupied = np.zeros(GRID.height * GRID.width, dtype=bool)
    result = run_em(index, occupied, np.unique(index.cell), CONFIG)
    assert occupied.any()
    assert all(b >= a - 1e-9 for a, b in zip(result.objective, result.objective[1:], strict=False))
    # the tracked objective is the true one: data log-likelihood plus the prior term
    data = log_likelihoods(index, occupied).sum()
    prior = CONFIG.l_prior * occupied[result.candidates].sum()
    assert result.objective[-1] == pytest.approx(data + prior, rel=1e-9)


def test_a_random_reading_does_not_create_an_obstacle():
    index, _ = index_for([2.0] * 20 + [1.0])
    occupied = np.zeros(GRID.height * GRID.width, dtype=bool)
    run_em(index, occupied, np.unique(index.cell), CONFIG)
    ranges = cell_range(np.flatnonzero(occupied))
    assert ranges.size and np.all(ranges > 1.8)


def test_cells_outside_the_candidates_are_held_fixed():
    index, _ = index_for([1.0] * 5)
    occupied = np.zeros(GRID.height * GRID.width, dtype=bool)
    fixed = 10 * GRID.width + 15  # the cell EM would occupy
    candidates = np.setdiff1d(np.unique(index.cell), [fixed])
    occupied[12 * GRID.width + 20] = True  # not in any cone: untouched
    run_em(index, occupied, candidates, CONFIG)
    assert not occupied[fixed]
    assert occupied[12 * GRID.width + 20]


def test_residual_probability_is_high_on_the_obstacle_and_low_before_it():
    index, _ = index_for([1.0] * 5)
    occupied = np.zeros(GRID.height * GRID.width, dtype=bool)
    result = run_em(index, occupied, np.unique(index.cell), CONFIG)
    p = dict(zip(result.candidates.tolist(), result.residual.tolist(), strict=True))
    assert p[10 * GRID.width + 15] > 0.9
    assert p[10 * GRID.width + 10] < 0.1


def test_em_is_deterministic():
    index, _ = index_for([1.0, 1.02, 0.98, 1.5, np.inf])
    runs = []
    for _ in range(2):
        occupied = np.zeros(GRID.height * GRID.width, dtype=bool)
        result = run_em(index, occupied, np.unique(index.cell), CONFIG)
        runs.append((occupied.copy(), result.residual.copy(), result.objective))
    assert np.array_equal(runs[0][0], runs[1][0])
    assert np.array_equal(runs[0][1], runs[1][1])
    assert runs[0][2] == runs[1][2]


def test_forward_model_likelihood_by_hand():
    # one reading, one obstacle at exactly its range: p = p_rand/zmax + w * (p_hit g + q G0)
    index, _ = index_for([1.0], beam_deg=1.0)
    occupied = np.zeros(GRID.height * GRID.width, dtype=bool)
    occupied[10 * GRID.width + 15] = True
    g = 1.0 / (math.sqrt(2 * math.pi) * 0.05)
    g0 = g * math.exp(-0.5 * (3.0 / 0.05) ** 2)
    expected = 0.05 / 4.0 + 0.95 * (0.4 * g + 0.6 * g0)
    assert log_likelihoods(index, occupied)[0] == pytest.approx(math.log(expected))
    occupied[:] = False
    assert log_likelihoods(index, occupied)[0] == pytest.approx(math.log(0.05 / 4.0 + 0.95 * g0))


def test_residual_from_the_last_sweep_equals_a_fresh_pass():
    from aogm_cli.mapping import em as E

    index, _ = index_for([1.0, 1.0, 1.02, 1.5, 0.6, np.inf, 2.0])
    occupied = np.zeros(GRID.height * GRID.width, dtype=bool)
    result = run_em(index, occupied, np.unique(index.cell), CONFIG)
    assert result.flips[-1] == 0
    pairs = E.pair_index(index, result.candidates)
    qpow = (1 - FORWARD.p_hit) ** np.arange(np.max(np.diff(index.ptr)) + 1)
    model = E.EMModel(FORWARD.p_hit, CONFIG.l_prior, qpow)
    state = E._init_state(index.kernel_arrays, model, occupied)
    fresh = E._residual(pairs, index.kernel_arrays, model, occupied, state)
    assert np.allclose(result.residual, fresh, rtol=1e-9, atol=1e-12)


def test_a_mask_keeps_only_the_readings_that_touch_it():
    tpl = build_cone_templates(GRID.resolution, math.radians(10.0), 4.0)
    rows, cols = np.array([10, 10]), np.array([5, 5])
    bins = tpl.heading_bin(np.array([0.0, math.pi / 2]))  # one reading along +x, one along +y
    mask = np.zeros(GRID.height * GRID.width, dtype=bool)
    mask[10 * GRID.width + 12] = True  # on the +x beam
    index = build_forward_index(rows, cols, bins, np.array([1.0, 1.0]), GRID, tpl, 4.0, FORWARD, mask=mask)
    assert np.diff(index.ptr).tolist()[1] == 0 and np.diff(index.ptr)[0] > 0


def test_leaving_out_cells_held_free_changes_no_likelihood_and_no_flip():
    # readings at two ranges, so that cones hold obstacles before and inside the windows
    tpl = build_cone_templates(GRID.resolution, math.radians(20.0), 4.0)
    ranges = np.array([1.0, 1.0, 1.5, 1.5, 0.8, np.inf])
    rows, cols = np.full(6, 10), np.full(6, 5)
    bins = tpl.heading_bin(np.array([0.0, 0.1, 0.0, -0.1, 0.05, 0.0]))
    full = build_forward_index(rows, cols, bins, ranges, GRID, tpl, 4.0, FORWARD)
    n = GRID.height * GRID.width
    candidates = np.zeros(n, dtype=bool)
    candidates[np.unique(full.cell)[::3]] = True  # a third of the cone cells may flip
    fixed_occupied = np.zeros(n, dtype=bool)
    fixed_occupied[10 * GRID.width + 12] = True  # an obstacle before the 1.0 m readings' windows
    fixed_occupied[10 * GRID.width + 15] = True  # and one inside them
    fixed_occupied &= ~candidates
    held_free = ~(candidates | fixed_occupied)
    small = build_forward_index(rows, cols, bins, ranges, GRID, tpl, 4.0, FORWARD, held_free=held_free)
    assert small.cell.size < full.cell.size and not held_free[small.cell].any()
    rng = np.random.default_rng(3)
    for _ in range(5):  # any map that keeps the held-free cells free: the same likelihoods
        m = fixed_occupied | (candidates & (rng.random(n) < 0.3))
        assert np.array_equal(log_likelihoods(full, m), log_likelihoods(small, m))
    a, b = fixed_occupied.copy(), fixed_occupied.copy()
    ra = run_em(full, a, np.flatnonzero(candidates), EMConfig(forward=FORWARD))
    rb = run_em(small, b, np.flatnonzero(candidates), EMConfig(forward=FORWARD))
    assert np.array_equal(a, b) and ra.flips == rb.flips
    assert np.array_equal(ra.residual, rb.residual)
