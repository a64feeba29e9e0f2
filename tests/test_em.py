"""EM with forward models on hand-computable cases: obstacles where readings say, openings kept."""

import math

import numpy as np
import pytest

from aogm_cli.core.grid import GridSpec
from aogm_cli.mapping.em import em_problem, em_readings, run_em
from aogm_cli.mapping.params import EMConfig
from aogm_cli.sensor_models.cone_build import build_cone_templates
from aogm_cli.sensor_models.forward_index import build_forward_index, log_likelihoods
from aogm_cli.sensor_models.forward_model import ForwardModelConfig

GRID = GridSpec(0.0, 0.0, 0.1, 21, 41)
FORWARD = ForwardModelConfig(sigma=0.05, p_rand=0.05, p_hit=0.4, p_max=0.0)
CONFIG = EMConfig(forward=FORWARD)
N_CELLS = GRID.height * GRID.width


def readings_for(ranges, beam_deg=10.0, yaw=0.0, row=10, col=5):
    """(templates, rows, cols, bins, z) of readings all taken from cell (row, col) facing ``yaw``."""
    tpl = build_cone_templates(GRID.resolution, math.radians(beam_deg), 4.0)
    n = len(ranges)
    rows, cols = np.full(n, row), np.full(n, col)
    bins = tpl.heading_bin(np.full(n, yaw))
    return tpl, rows, cols, bins, np.asarray(ranges, float)


def problem_for(ranges, occupied=None, config=CONFIG, **kw):
    """(problem, occupied, reference index): EM's problem of ``readings_for`` under ``occupied``
    (empty by default; the same array is to be passed to run_em) and the forward model's index."""
    tpl, rows, cols, bins, z = readings_for(ranges, **kw)
    occupied = np.zeros(N_CELLS, dtype=bool) if occupied is None else occupied
    rd = em_readings((rows, cols, bins, z), tpl, GRID, 4.0, config.forward)
    problem = em_problem(rd, tpl, GRID.shape, occupied, config)
    return problem, occupied, build_forward_index((rows, cols, bins, z), GRID, tpl, 4.0, config.forward)


def cone_cells(problem):
    return np.flatnonzero(problem.seen)


def cell_range(flat, row=10, col=5):
    r, c = np.divmod(flat, GRID.width)
    return GRID.resolution * np.hypot(r - row, c - col)


def test_readings_square_to_a_wall_put_the_obstacle_at_their_range():
    problem, occupied, _ = problem_for([1.0] * 5)
    result = run_em(problem, occupied, cone_cells(problem), CONFIG)
    cells = np.flatnonzero(occupied)
    assert cells.size >= 1
    # every obstacle lies at the readings' range (within one cell), none before it
    assert np.all(np.abs(cell_range(cells) - 1.0) <= 0.1 + 1e-9)
    # the cell on the beam axis at 1.0 m is occupied; the axis cells before it are free
    assert occupied[10 * GRID.width + 15]
    assert not occupied[10 * GRID.width + 6 : 10 * GRID.width + 14].any()
    assert result.flips[-1] == 0


def test_the_cells_the_cones_hold_are_the_reference_index_cells():
    problem, _, index = problem_for([1.0] * 5 + [1.5] * 3 + [np.inf], beam_deg=30.0)
    assert np.array_equal(cone_cells(problem), np.unique(index.cell))


def test_empty_start_creates_obstacles_and_the_objective_never_decreases():
    problem, occupied, index = problem_for([1.0] * 5 + [1.5] * 3 + [np.inf])
    result = run_em(problem, occupied, cone_cells(problem), CONFIG)
    assert occupied.any()
    assert all(b >= a - 1e-9 for a, b in zip(result.objective, result.objective[1:], strict=False))
    # the tracked objective is the true one: data log-likelihood plus the prior term
    data = log_likelihoods(index, occupied).sum()
    prior = CONFIG.l_prior * occupied[result.candidates].sum()
    assert result.objective[-1] == pytest.approx(data + prior, rel=1e-9)


def test_a_random_reading_does_not_create_an_obstacle():
    problem, occupied, _ = problem_for([2.0] * 20 + [1.0])
    run_em(problem, occupied, cone_cells(problem), CONFIG)
    ranges = cell_range(np.flatnonzero(occupied))
    assert ranges.size and np.all(ranges > 1.8)


def test_cells_outside_the_candidates_are_held_fixed():
    occupied = np.zeros(N_CELLS, dtype=bool)
    occupied[12 * GRID.width + 20] = True  # not in any cone: untouched
    problem, occupied, _ = problem_for([1.0] * 5, occupied)
    fixed = 10 * GRID.width + 15  # the cell EM would occupy
    candidates = np.setdiff1d(cone_cells(problem), [fixed])
    run_em(problem, occupied, candidates, CONFIG)
    assert not occupied[fixed]
    assert occupied[12 * GRID.width + 20]


def test_residual_probability_is_high_on_the_obstacle_and_low_before_it():
    problem, occupied, _ = problem_for([1.0] * 5)
    result = run_em(problem, occupied, cone_cells(problem), CONFIG)
    p = dict(zip(result.candidates.tolist(), result.residual.tolist(), strict=True))
    assert p[10 * GRID.width + 15] > 0.9
    assert p[10 * GRID.width + 10] < 0.1


def test_em_is_deterministic():
    runs = []
    for _ in range(2):
        problem, occupied, _ = problem_for([1.0, 1.02, 0.98, 1.5, np.inf])
        result = run_em(problem, occupied, cone_cells(problem), CONFIG)
        runs.append((occupied.copy(), result.residual.copy(), result.objective))
    assert np.array_equal(runs[0][0], runs[1][0])
    assert np.array_equal(runs[0][1], runs[1][1])
    assert runs[0][2] == runs[1][2]


def test_forward_model_likelihood_by_hand():
    # one reading, one obstacle at exactly its range: p = p_rand/zmax + w * (p_hit g + q G0)
    occupied = np.zeros(N_CELLS, dtype=bool)
    occupied[10 * GRID.width + 15] = True
    problem, occupied, index = problem_for([1.0], occupied, beam_deg=1.0)
    g = 1.0 / (math.sqrt(2 * math.pi) * 0.05)
    g0 = g * math.exp(-0.5 * (3.0 / 0.05) ** 2)
    expected = 0.05 / 4.0 + 0.95 * (0.4 * g + 0.6 * g0)
    assert log_likelihoods(index, occupied)[0] == pytest.approx(math.log(expected))
    # EM's state of the reading says the same (no candidates: the objective is the data term)
    result = run_em(problem, occupied, np.zeros(0, dtype=np.int64), CONFIG)
    assert result.objective[0] == pytest.approx(math.log(expected), rel=1e-12)
    occupied[:] = False
    assert log_likelihoods(index, occupied)[0] == pytest.approx(math.log(0.05 / 4.0 + 0.95 * g0))
    problem, occupied, _ = problem_for([1.0], occupied, beam_deg=1.0)
    result = run_em(problem, occupied, np.zeros(0, dtype=np.int64), CONFIG)
    assert result.objective[0] == pytest.approx(math.log(0.05 / 4.0 + 0.95 * g0), rel=1e-12)


def test_residual_from_the_last_sweep_equals_a_fresh_pass():
    ranges = [1.0, 1.0, 1.02, 1.5, 0.6, np.inf, 2.0]
    problem, occupied, _ = problem_for(ranges)
    result = run_em(problem, occupied, cone_cells(problem), CONFIG)
    assert result.flips[-1] == 0
    # a new problem set up under EM's map: its one sweep scores every candidate afresh, flips none
    fresh_problem, fresh_map, _ = problem_for(ranges, occupied.copy())
    fresh = run_em(fresh_problem, fresh_map, result.candidates, EMConfig(forward=FORWARD, max_sweeps=1))
    assert fresh.flips == [0] and np.array_equal(fresh_map, occupied)
    assert np.allclose(result.residual, fresh.residual, rtol=1e-9, atol=1e-12)


def test_leaving_out_cells_held_free_changes_no_likelihood():
    # readings at two ranges, so that cones hold obstacles before and inside the windows
    tpl = build_cone_templates(GRID.resolution, math.radians(20.0), 4.0)
    ranges = np.array([1.0, 1.0, 1.5, 1.5, 0.8, np.inf])
    rows, cols = np.full(6, 10), np.full(6, 5)
    bins = tpl.heading_bin(np.array([0.0, 0.1, 0.0, -0.1, 0.05, 0.0]))
    full = build_forward_index((rows, cols, bins, ranges), GRID, tpl, 4.0, FORWARD)
    candidates = np.zeros(N_CELLS, dtype=bool)
    candidates[np.unique(full.cell)[::3]] = True  # a third of the cone cells may flip
    fixed_occupied = np.zeros(N_CELLS, dtype=bool)
    fixed_occupied[10 * GRID.width + 12] = True  # an obstacle before the 1.0 m readings' windows
    fixed_occupied[10 * GRID.width + 15] = True  # and one inside them
    fixed_occupied &= ~candidates
    held_free = ~(candidates | fixed_occupied)
    small = build_forward_index((rows, cols, bins, ranges), GRID, tpl, 4.0, FORWARD, held_free=held_free)
    assert small.cell.size < full.cell.size and not held_free[small.cell].any()
    rng = np.random.default_rng(3)
    for _ in range(5):  # any map that keeps the held-free cells free: the same likelihoods
        m = fixed_occupied | (candidates & (rng.random(N_CELLS) < 0.3))
        assert np.array_equal(log_likelihoods(full, m), log_likelihoods(small, m))


def test_hidden_cells_are_reported_unobserved_unless_the_standard_map_holds_them():
    """EM's residual at the candidates the data decides (occupied, or occupancy lowering the likelihood by over
    ``view.HIDDEN_GAIN``); a cell EM leaves free though occupancy costs the data nothing (evidence 0, residual =
    the prior 0.3) or next to nothing (0.01) keeps a standard estimate above 0.5 and is returned to be reported
    unobserved otherwise; one the data objects to (evidence -3) is never hidden."""
    from aogm_cli.mapping.em import EMResult
    from aogm_cli.mapping.view import decided, residual_into

    prior = CONFIG.prior_occupied
    logistic = lambda x: 1 / (1 + math.exp(-x))  # noqa: E731
    residual = np.array([prior, logistic(CONFIG.l_prior - 3.0), 0.9, logistic(CONFIG.l_prior - 0.01)])
    result = EMResult(1, [0], [0.0, 0.0], np.array([0, 1, 2, 3]), residual, [4], [0], 0, 0)
    assert decided(result, CONFIG).tolist() == [False, True, True, False]
    probability = np.array([0.8, 0.8, 0.8, 0.4, 0.8])  # cell 3: hidden, the standard map has it free
    unseen = residual_into(probability, result, CONFIG)
    assert unseen.tolist() == [3]
    np.testing.assert_allclose(probability, [0.8, residual[1], 0.9, 0.4, 0.8])


def test_planner_view_reports_unseen_cells_unobserved_and_clears_the_footprint():
    """On a 3 x 4 grid: the unseen cells become unobserved, the footprint's cells observed and
    at most the free probability, whatever EM or the standard map held there."""
    from aogm_cli.core.log import SensorSpec
    from aogm_cli.mapping.view import footprint, planner_view

    grid = GridSpec(0.0, 0.0, 1.0, 3, 4)
    sensor = SensorSpec(mount=np.array([[1.0, 0.0, 0.0], [0.0, 1.5, 1.6]]))
    body = footprint(grid, np.array([[0.5, 0.5, 0.0]]), sensor)  # ring radius 1: cell (0, 0) and its 4-neighbours
    assert body.astype(int).tolist() == [[1, 1, 0, 0], [1, 0, 0, 0], [0, 0, 0, 0]]
    probability = np.array([0.9, 0.3, 0.6, 0.5, 0.2, 0.5, 0.4, 0.8, 0.3, 0.3, 0.3, 0.3])
    observed = np.ones((3, 4), dtype=bool)
    observed[0, 1] = False
    out = planner_view(probability, observed, np.array([2, 4, 6]), body, 0.12)
    assert out.astype(int).tolist() == [[1, 1, 0, 1], [1, 1, 0, 1], [1, 1, 1, 1]]
    np.testing.assert_allclose(probability, [0.12, 0.12, 0.6, 0.5, 0.12, 0.5, 0.4, 0.8, 0.3, 0.3, 0.3, 0.3])


@pytest.mark.parametrize("col, where", [(15, "inside the window"), (8, "far before it")])
def test_a_flips_gain_is_the_change_of_the_readings_log_likelihood_by_hand(col, where):
    """One reading (z = 1.0 m) along a row with an obstacle held at 0.8 m; the candidate cell is
    at 1.0 m (inside the Gaussian window: a second detection term) or at 0.3 m (before the
    window: every term behind it scaled by q). EM's score of the flip, read back from its
    residual and objective, is log p(z | m with the cell) - log p(z | m) plus the prior."""
    fixed, cell = 10 * GRID.width + 13, 10 * GRID.width + col
    occupied = np.zeros(N_CELLS, dtype=bool)
    occupied[fixed] = True
    problem, occupied, _ = problem_for([1.0], occupied, beam_deg=1.0)
    p_hit, q, w, sigma = 0.4, 0.6, 0.95, 0.05

    def n(r):
        return math.exp(-0.5 * ((1.0 - r) / sigma) ** 2) / (math.sqrt(2 * math.pi) * sigma)

    const, g0 = 0.05 / 4.0, n(4.0)
    before = p_hit * n(0.8) + q * g0
    after = p_hit * n(0.8) + q * p_hit * n(1.0) + q * q * g0 if col == 15 else q * before
    gain = math.log(const + w * after) - math.log(const + w * before)
    result = run_em(problem, occupied, np.array([cell]), CONFIG)
    assert result.residual[0] == pytest.approx(1.0 / (1.0 + math.exp(-(gain + CONFIG.l_prior))), rel=1e-9)
    assert occupied[cell] == (gain + CONFIG.l_prior > 0)
    if occupied[cell]:
        assert result.objective[-1] - result.objective[0] == pytest.approx(gain + CONFIG.l_prior, rel=1e-9)


def test_the_decided_pass_scores_a_far_cell_by_hand():
    """``exact.map_evidence`` (adaptive's ``decided`` pass) scores the cell of the flip test above (0.3 m, before
    the window of the reading at 1.0 m, an obstacle held at 0.8 m) by hand: every term behind it scaled by q."""
    from aogm_cli.core.log import SensorSpec
    from aogm_cli.mapping.exact import map_evidence
    from aogm_cli.sensor_models.readings import LaidOutReadings

    fixed, cell = 10 * GRID.width + 13, 10 * GRID.width + 8
    occupied = np.zeros(N_CELLS, dtype=bool)
    occupied[fixed] = True
    tpl, rows, cols, bins, z = readings_for([1.0], beam_deg=1.0)
    sensor = SensorSpec(mount=np.zeros((1, 3)), beam_width=math.radians(1.0), max_range=4.0)
    run = LaidOutReadings(GRID, sensor, tpl, z.reshape(1, 1), rows, cols, bins, z)
    evidence = map_evidence(run, FORWARD, occupied).reshape(-1)

    def n(r):
        return math.exp(-0.5 * ((1.0 - r) / 0.05) ** 2) / (math.sqrt(2 * math.pi) * 0.05)

    const, w, before = 0.05 / 4.0, 0.95, 0.4 * n(0.8) + 0.6 * n(4.0)
    expected = math.log(const + w * 0.6 * before) - math.log(const + w * before)
    assert evidence[cell] == pytest.approx(expected, rel=1e-6, abs=1e-12)
