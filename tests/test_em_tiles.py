"""EM's tiled kernels (``em_kernels``) against a plain reference hill-climber.

The reference scores each flip with the forward model's reference evaluation
(``build_forward_index`` + ``log_likelihoods``) over every reading, sweeping the candidates in
increasing flat id. On small random problems (grids wider than one 32-column tile segment,
readings near all four borders and outside the grid, cones that leave it, max-range readings,
wide and narrow beams, candidate subsets, fixed obstacles) ``run_em`` must make the same flips,
track the true objective and give each candidate the residual of its exact flip gain.
"""

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
import pytest

from aogm_cli.core.budget import Limits, using
from aogm_cli.core.grid import GridSpec
from aogm_cli.mapping import em as E
from aogm_cli.mapping import sweeps as S
from aogm_cli.mapping.em import em_problem, em_readings, run_em
from aogm_cli.mapping.em_kernels import extents as kernel_readings
from aogm_cli.mapping.em_kernels import layout as L
from aogm_cli.mapping.em_kernels import likelihood, tiles
from aogm_cli.mapping.params import EMConfig
from aogm_cli.sensor_models import readings as laid_out
from aogm_cli.sensor_models.cone_build import build_cone_templates
from aogm_cli.sensor_models.forward_index import build_forward_index, log_likelihoods
from aogm_cli.sensor_models.forward_model import ForwardModelConfig
from aogm_cli.sensor_models.heard import heard_templates


@dataclass(frozen=True)
class Windowed(ForwardModelConfig):
    """The forward model with its Gaussian cut at ``window`` sigmas (the model's own is 4): the kernels take any."""

    window: float = 4.0


GRID = GridSpec(0.0, 0.0, 0.1, 30, 70)
Z_MAX = 2.5


def climb(index, occupied, candidates, l_prior, max_sweeps, order=None):
    """The reference: (map, flips per sweep, objective after each sweep, the start's first),
    visiting the candidates in ``order`` (default: increasing flat id)."""
    m = occupied.copy()
    candidates = np.unique(candidates)
    order = candidates if order is None else order
    data = log_likelihoods(index, m).sum()
    objective = [data + l_prior * m[candidates].sum()]
    flips = []
    for _ in range(max_sweeps):
        n = 0
        for c in order:
            m[c] = not m[c]
            flipped = log_likelihoods(index, m).sum()
            if flipped - data + (l_prior if m[c] else -l_prior) > 1e-9:
                data = flipped
                n += 1
            else:
                m[c] = not m[c]
        flips.append(n)
        objective.append(data + l_prior * m[candidates].sum())
        if n == 0:
            break
    return m, flips, objective


def residual(index, occupied, candidates, l_prior):
    """p(m_x = 1 | Z, m*) of each candidate: the logistic of its exact data gain of being
    occupied rather than free (the other cells as in ``occupied``) plus l_prior."""
    m = occupied.copy()
    data = log_likelihoods(index, m).sum()
    out = np.empty(len(candidates))
    for i, c in enumerate(candidates):
        m[c] = not m[c]
        gain = log_likelihoods(index, m).sum() - data
        m[c] = not m[c]
        out[i] = 1.0 / (1.0 + math.exp(-((-gain if m[c] else gain) + l_prior)))
    return out


@dataclass
class Case:
    grid: GridSpec
    templates: object
    rows: np.ndarray
    cols: np.ndarray
    bins: np.ndarray
    z: np.ndarray
    config: EMConfig
    candidates: np.ndarray
    start: np.ndarray
    shadow: np.ndarray | None = None

    def index(self):
        return build_forward_index((self.rows, self.cols, self.bins, self.z), self.grid, self.templates, Z_MAX,
                                   self.config.forward, shadow=self.shadow)

    def problem(self, occupied):
        rd = em_readings((self.rows, self.cols, self.bins, self.z), self.templates, self.grid, Z_MAX, self.config.forward,
                         shadow=self.shadow)
        return em_problem(rd, self.templates, self.grid.shape, occupied, self.config)


def border_distance(grid, row, col, yaw):
    """Metres from the centre of cell (row, col) along ``yaw`` to where the ray leaves the grid."""
    x, y = (col + 0.5) * grid.resolution, (row + 0.5) * grid.resolution
    width, height = grid.width * grid.resolution, grid.height * grid.resolution
    dx, dy = math.cos(yaw), math.sin(yaw)
    t = math.inf
    for p, d, size in ((x, dx, width), (y, dy, height)):
        if abs(d) > 1e-12:
            t = min(t, ((size if d > 0 else 0.0) - p) / d)
    return max(t, 0.0)


def random_case(seed, grid=GRID, n_readings=(4, 41), max_sweeps=20, beams=(2.0, 8.0, 30.0, 60.0, 120.0)):
    rng = np.random.default_rng(seed)
    height, width = grid.shape
    forward = Windowed(sigma=float(rng.choice([0.03, 0.05, 0.1])), p_rand=float(rng.choice([0.05, 0.2])),
                       p_hit=float(rng.choice([0.3, 0.7, 0.9])), p_max=float(rng.choice([0.0, 0.1])),
                       window=float(rng.choice([2.0, 4.0])))
    config = EMConfig(forward=forward, prior_occupied=float(rng.choice([0.3, 0.5])), max_sweeps=max_sweeps)
    templates = build_cone_templates(grid.resolution, math.radians(float(rng.choice(beams))), Z_MAX)
    n = int(rng.integers(*n_readings))
    rows = rng.integers(-3, height + 3, n)  # a few sensors outside the grid
    cols = rng.integers(-3, width + 3, n)
    # the first four near the bottom, top, left and right borders
    side = np.arange(n) % 4
    near = np.arange(n) < 4
    rows = np.where(near & (side == 0), rng.integers(0, 3, n), rows)
    rows = np.where(near & (side == 1), rng.integers(height - 3, height, n), rows)
    cols = np.where(near & (side == 2), rng.integers(0, 3, n), cols)
    cols = np.where(near & (side == 3), rng.integers(width - 3, width, n), cols)
    yaw = rng.uniform(-math.pi, math.pi, n)
    axis = rng.random(n) < 0.3  # headings on the octants' edges (the templates' symmetries)
    yaw[axis] = rng.integers(0, 8, axis.sum()) * (math.pi / 4)
    z = rng.uniform(0.0, 1.05 * Z_MAX, n)
    for t in np.flatnonzero(rng.random(n) < 0.3):  # walls near where the beam leaves the grid
        z[t] = max(border_distance(grid, rows[t], cols[t], yaw[t]) + rng.uniform(-0.15, 0.15), 0.0)
    z[rng.random(n) < 0.15] = np.inf  # no echo
    case = Case(grid, templates, rows, cols, templates.heading_bin(yaw), z, config, np.zeros(0, dtype=np.int64),
                np.zeros(height * width, dtype=bool))
    seen = np.unique(case.index().cell)
    kind = seed % 3
    if kind == 0:
        case.candidates = seen
    elif kind == 1:  # a subset: the other cone cells are held fixed, some of them occupied
        case.candidates = np.sort(rng.choice(seen, max(1, seen.size // 3), replace=False))
    else:  # cells no cone holds too: only the prior decides those
        case.candidates = np.union1d(seen, rng.choice(height * width, height * width // 20))
    if rng.random() < 0.5:
        case.start = rng.random(height * width) < 0.2
    return case


def check_against_reference(case, result, occupied, problem, order=None):
    index = case.index()
    l_prior = case.config.l_prior
    assert np.array_equal(np.flatnonzero(problem.seen), np.unique(index.cell))  # the cells the cones hold
    m, flips, objective = climb(index, case.start, case.candidates, l_prior, case.config.max_sweeps, order)
    assert np.array_equal(result.candidates, np.unique(case.candidates))
    assert result.flips == flips and result.sweeps == len(flips)
    assert np.array_equal(occupied, m)
    assert result.objective == pytest.approx(objective, rel=1e-9, abs=1e-9)
    truth = log_likelihoods(index, occupied).sum() + l_prior * occupied[result.candidates].sum()
    assert result.objective[-1] == pytest.approx(truth, rel=1e-9, abs=1e-9)
    assert np.allclose(result.residual, residual(index, occupied, result.candidates, l_prior), rtol=0, atol=1e-9)


def run_case(case):
    """(result, map, problem) of EM on ``case``."""
    occupied = case.start.copy()
    problem = case.problem(occupied)
    return run_em(problem, occupied, case.candidates, case.config), occupied, problem


# a few grids beside 30 x 70: exactly two segments, one more column, one segment and a bit
SHAPES = [(30, 70)] * 5 + [(12, 64), (20, 33), (9, 97)]


@pytest.mark.parametrize("seed", range(16))
def test_run_em_makes_the_reference_climbs_flips(seed):
    height, width = SHAPES[seed % len(SHAPES)]
    case = random_case(seed, GridSpec(0.0, 0.0, 0.1, height, width))
    result, occupied, problem = run_case(case)
    assert result.flips[-1] == 0  # converged: the residual comes from the last sweep's scores
    check_against_reference(case, result, occupied, problem)


@pytest.mark.parametrize("seed", range(200, 208))
def test_shadowed_readings_climb_as_the_reference(seed):
    # readings whose beams a grazing surface deflected (a finite shadow): max-range readings whose
    # cones end just before the shadow, in EM's readings and the reference index alike
    height, width = SHAPES[seed % len(SHAPES)]
    case = random_case(seed, GridSpec(0.0, 0.0, 0.1, height, width), n_readings=(10, 60))
    rng = np.random.default_rng(seed)
    shadow = np.full(case.z.shape, np.inf)
    cut = rng.random(case.z.size) < 0.4
    shadow[cut] = rng.uniform(0.0, 1.0, cut.sum()) * np.minimum(case.z[cut], Z_MAX)
    case.shadow = shadow
    result, occupied, problem = run_case(case)
    check_against_reference(case, result, occupied, problem)
    index = case.index()
    plain = dataclasses.replace(case, shadow=None).index()
    assert index.cell.size < plain.cell.size  # the cones were cut
    t = np.flatnonzero(cut & np.isfinite(case.z))[0]
    assert index.g0[t] == pytest.approx(index.g0.max())  # a cut reading is a max-range one


@pytest.mark.parametrize("seed", range(100, 106))
def test_residual_is_exact_when_stopped_by_max_sweeps(seed):
    case = random_case(seed, max_sweeps=1)
    result, occupied, problem = run_case(case)
    assert result.sweeps == 1
    check_against_reference(case, result, occupied, problem)


def band_order(case, phases):
    """The candidates as banded sweeps visit them: colour by colour, band by band, each band's
    by flat id (rows, then columns within the band)."""
    cells = np.unique(case.candidates)
    cols = cells % case.grid.width
    return np.concatenate([cells[(cols >= band.seg_lo * L.SEGMENT) & (cols < band.seg_hi * L.SEGMENT)]
                           for bands in phases for band in bands])


WIDE = GridSpec(0.0, 0.0, 0.1, 16, 230)  # 8 segments; cones of 2.5 m: bands of 1 or 2 segments


@pytest.mark.parametrize("seed", [30, 31, 32, 34])
def test_banded_sweeps_climb_as_the_reference_in_band_order(seed, monkeypatch):
    monkeypatch.setattr(S, "BAND_READINGS", 1)
    case = random_case(seed, WIDE, n_readings=(60, 90), beams=(8.0, 30.0))
    occupied = case.start.copy()
    problem = case.problem(occupied)
    phases, order = S.sweep_bands(problem.readings, WIDE.width)
    assert len(phases) >= 2 and sum(len(bands) for bands in phases) > len(phases) and order is not None
    fixed = [name for name in L.READING_INTS.names if name not in L.EMState._fields]  # all but the state
    readings_before = problem.readings.ints[fixed].copy()
    result = run_em(problem, occupied, case.candidates, case.config)
    assert sum(result.flips) > 0
    check_against_reference(case, result, occupied, problem, band_order(case, phases))
    # the readings are back in their order, their state that of the final map (as a fresh problem's)
    assert np.array_equal(problem.readings.ints[fixed], readings_before)
    fresh = case.problem(occupied.copy())
    for name in ("nobs", "nfar"):
        assert np.array_equal(problem.readings.ints[name], fresh.readings.ints[name])
    assert np.allclose(problem.readings.floats["s"], fresh.readings.floats["s"], rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("seed", [30, 33])
def test_the_same_run_on_any_number_of_threads(seed, monkeypatch):
    monkeypatch.setattr(S, "BAND_READINGS", 1)
    runs = []
    for threads in (1, 2, 3):
        case = random_case(seed, WIDE, n_readings=(60, 90), beams=(8.0, 30.0), max_sweeps=3)
        with using(Limits(threads=threads)):
            result, occupied, _ = run_case(case)
        runs.append((result, occupied))
    (one, map_one), *others = runs
    for result, occupied in others:
        assert np.array_equal(occupied, map_one)
        assert result.flips == one.flips and result.objective == one.objective and result.scored == one.scored
        assert np.array_equal(result.residual, one.residual)


@pytest.mark.parametrize("seed", range(300, 312))
def test_cells_no_window_holds_are_held_free_as_the_reference(seed, monkeypatch):
    """With the prior below one half, the candidates that start free and lie in no reading's
    Gaussian window are left out of the sweeps (``em.HELD_FREE_SHARE`` 0: whatever their share)
    and their residuals come from the readings' far runs: the same flips, objective and
    residuals as the reference climb, which sweeps them all."""
    monkeypatch.setattr(E, "HELD_FREE_SHARE", 0.0)
    height, width = SHAPES[seed % len(SHAPES)]
    case = random_case(seed, GridSpec(0.0, 0.0, 0.1, height, width), beams=(2.0, 8.0, 30.0))
    case.config = dataclasses.replace(case.config, prior_occupied=0.3)
    swept, held = E._flippable(case.problem(case.start.copy()), case.start, np.unique(case.candidates))
    assert held.size > 0 and not case.start[held].any()
    assert np.array_equal(np.union1d(swept, held), np.unique(case.candidates))
    result, occupied, problem = run_case(case)
    check_against_reference(case, result, occupied, problem)
    assert not occupied[held].any()
    # with a prior of one half none is held free: occupancy costs nothing, a flip may be a tie
    even = dataclasses.replace(case.config, prior_occupied=0.5)
    start = case.start.copy()
    assert E._flippable(dataclasses.replace(case, config=even).problem(start), start, swept)[1].size == 0


def test_more_readings_than_one_word_of_the_active_set():
    case = random_case(7, n_readings=(150, 151), beams=(8.0,))
    result, occupied, problem = run_case(case)
    check_against_reference(case, result, occupied, problem)


def test_cones_that_just_reach_or_just_miss_the_border():
    # a cone lies inside the grid when its template's extent does: sensors one cell either side
    # of that limit at each border (and inside it from the other three), facing the border, with
    # readings at max range and just before it (each side's away from the others' cones, so that
    # a cell wrapped across a border would show)
    grid = GridSpec(0.0, 0.0, 0.1, 62, 72)
    templates = build_cone_templates(grid.resolution, math.radians(8.0), Z_MAX)
    ext = templates.extent
    assert 2 * ext + 10 < grid.height and 2 * ext + 10 < grid.width
    rows, cols, yaw = [], [], []
    for d in (-1, 0, 1):
        for row, col, heading in ((ext + 1, grid.width - 1 - ext + d, 0.0), (ext + 8, ext - d, math.pi),
                                  (grid.height - 1 - ext + d, ext + 2, math.pi / 2),
                                  (ext - d, grid.width - ext - 3, -math.pi / 2)):
            rows.append(row)
            cols.append(col)
            yaw.append(heading)
    n = len(rows)
    z = np.concatenate([np.full(n, np.inf), np.full(n, Z_MAX - 0.05)])
    forward = ForwardModelConfig(sigma=0.05, p_rand=0.05, p_hit=0.7, p_max=0.1)
    start = np.random.default_rng(1).random(grid.shape) < 0.2
    start[[0, -1], :] = start[:, [0, -1]] = True  # where a cone's cell wrapped across a border would land
    start = start.reshape(-1)
    case = Case(grid, templates, np.array(rows * 2), np.array(cols * 2), templates.heading_bin(np.array(yaw * 2)), z,
                EMConfig(forward=forward), np.zeros(0, dtype=np.int64), start)
    case.candidates = np.unique(case.index().cell)
    result, occupied, problem = run_case(case)
    check_against_reference(case, result, occupied, problem)


def random_clusters(rng, shape, n):
    """Flat cluster ids (0 outside) of n random rectangles (a later one keeps only its free cells)."""
    height, width = shape
    labels = np.zeros(shape, dtype=np.int64)
    for k in range(1, n + 1):
        r0, c0 = rng.integers(0, height), rng.integers(0, width)
        block = labels[r0 : r0 + rng.integers(1, 6), c0 : c0 + rng.integers(1, 12)]
        block[block == 0] = k
    return labels.reshape(-1)


def coupled_reference(index, labels, n):
    """Root (the least id) of each cluster 1..n: clusters whose cells one cone holds are joined."""
    root = list(range(n + 1))

    def find(x):
        while root[x] != x:
            x = root[x]
        return x

    for t in range(index.n_readings):
        ids = np.unique(labels[index.cell[index.ptr[t] : index.ptr[t + 1]]])
        for a in ids[ids > 0]:
            ra, rb = find(int(a)), find(int(ids[ids > 0][0]))
            root[max(ra, rb)] = min(ra, rb)
    return [find(k) for k in range(1, n + 1)]


@pytest.mark.parametrize("seed", [3, 5, 8, 9, 13, 17])
def test_a_cluster_problem_climbs_as_the_reference_over_the_cluster_cells(seed):
    # with labels, the readings are active only where their cones hold cluster cells
    case = random_case(seed)
    rng = np.random.default_rng(seed)
    n_clusters = int(rng.integers(2, 7))
    labels = random_clusters(rng, case.grid.shape, n_clusters)
    n_clusters = int(labels.max())
    case.candidates = np.flatnonzero(labels > 0)
    occupied = case.start.copy()
    rd = em_readings((case.rows, case.cols, case.bins, case.z), case.templates, case.grid, Z_MAX, case.config.forward)
    problem = em_problem(rd, case.templates, case.grid.shape, occupied, case.config, labels=labels)
    groups = [likelihood._find(problem.parent, k) for k in range(1, n_clusters + 1)]
    reference = coupled_reference(case.index(), labels, n_clusters)
    assert all((groups[a] == groups[b]) == (reference[a] == reference[b])
               for a in range(n_clusters) for b in range(n_clusters))
    result = run_em(problem, occupied, case.candidates, case.config)
    check_against_reference(case, result, occupied, problem)


def test_run_em_continues_on_its_problem():
    # sweeps one at a time on one problem: its state carries over, as one run of four sweeps
    case = random_case(1, max_sweeps=4)  # the reference climbs for three sweeps
    occupied = case.start.copy()
    problem = case.problem(occupied)
    one = EMConfig(forward=case.config.forward, prior_occupied=case.config.prior_occupied, max_sweeps=1)
    flips = []
    for _ in range(4):
        result = run_em(problem, occupied, case.candidates, one)
        flips += result.flips
    index = case.index()
    m, ref_flips, objective = climb(index, case.start, case.candidates, case.config.l_prior, 4)
    assert sum(ref_flips) > 0
    assert flips == ref_flips + [0] * (4 - len(ref_flips))
    assert np.array_equal(occupied, m)
    assert result.objective[-1] == pytest.approx(objective[-1], rel=1e-9, abs=1e-9)
    assert np.allclose(result.residual, residual(index, occupied, result.candidates, case.config.l_prior),
                       rtol=0, atol=1e-9)


def tiny_work(rd, n_seg):
    """EM's tile scratch with every growable buffer one element long: every tile asks for more."""
    work = ORIGINAL_WORK(rd, n_seg)
    one = {name: np.empty(1, dtype=getattr(work, name).dtype)
           for name in ("seg_list", "far_lo", "far_hi", "pair_pos", "pair_j", "pair_g", "obs_j", "obs_g", "pre", "spans")}
    return work._replace(**one)


ORIGINAL_WORK, ORIGINAL_GROWN = S._work, S._grown


@pytest.mark.parametrize("seed", [3, 11, 12, 20])
def test_scratch_grown_mid_sweep_gives_the_same_run(seed, monkeypatch):
    # the sweeps stop for larger buffers (and compact the window arena) and resume where they stopped
    case = random_case(seed, n_readings=(30, 80))
    expected, expected_map, _ = run_case(case)
    grown = []
    monkeypatch.setattr(S, "_work", tiny_work)
    monkeypatch.setattr(S, "_grown", lambda work: grown.append(1) or ORIGINAL_GROWN(work))
    result, occupied, problem = run_case(case)
    assert len(grown) >= 3
    assert np.array_equal(occupied, expected_map) and result.flips == expected.flips
    assert result.objective == expected.objective
    assert np.array_equal(result.residual, expected.residual)
    check_against_reference(case, result, occupied, problem)


@pytest.mark.parametrize("seed, tiny", [(3, False), (11, True), (12, False), (20, True)])
def test_sweeps_paused_before_every_tile_give_the_same_run(seed, tiny, monkeypatch):
    # with a budget of one pair the kernel returns (PAUSED) before every row and tile but the first
    # of each call, and resumes there; the cone walks run a few readings per call; with ``tiny``
    # the scratch grows mid-sweep too
    case = random_case(seed, n_readings=(30, 80))
    expected, expected_map, _ = run_case(case)
    statuses, sweep = [], tiles._sweep_tiles
    monkeypatch.setattr(L, "PAUSE_WORK", 1)
    monkeypatch.setattr(laid_out, "READINGS_PER_CALL", 3)
    monkeypatch.setattr(tiles, "_sweep_tiles", lambda *args: statuses.append(sweep(*args)) or statuses[-1])
    if tiny:
        monkeypatch.setattr(S, "_work", tiny_work)
    result, occupied, problem = run_case(case)
    assert statuses.count(L.PAUSED) >= 10 * (result.sweeps + 1)
    assert (L.NEED_BUFFERS in statuses) == tiny
    assert np.array_equal(occupied, expected_map) and result.flips == expected.flips
    assert result.objective == expected.objective
    assert np.array_equal(result.residual, expected.residual)
    check_against_reference(case, result, occupied, problem)


def test_unsorted_candidates_with_repeats_are_the_same_candidates():
    case = random_case(5)
    expected, expected_map, _ = run_case(case)
    rng = np.random.default_rng(0)
    case.candidates = rng.permutation(np.concatenate([case.candidates, case.candidates[::7]]))
    result, occupied, _ = run_case(case)
    assert np.array_equal(result.candidates, expected.candidates)
    assert np.array_equal(occupied, expected_map) and result.flips == expected.flips
    assert np.array_equal(result.residual, expected.residual)


def one_reading_case(z, forward, occupied_cols=(), beam_deg=1.0):
    """One reading from cell (10, 5) along +x on GRID; cells (10, c) for c in occupied_cols occupied."""
    templates = build_cone_templates(GRID.resolution, math.radians(beam_deg), Z_MAX)
    start = np.zeros(GRID.height * GRID.width, dtype=bool)
    start[[10 * GRID.width + c for c in occupied_cols]] = True
    return Case(GRID, templates, np.array([10]), np.array([5]), templates.heading_bin(np.array([0.0])), np.array([z]),
                EMConfig(forward=forward), np.zeros(0, dtype=np.int64), start)


def test_a_cone_ends_before_a_cell_of_zero_weight_beyond_its_range():
    # z = 0.1, 4 sigmas of 0.05 m: the cell at 0.3 m has (z - r) / sigma = -4.000000000000001 by rounding,
    # g = 0; were it in the cone, it would scale the terms of the window's obstacles by q as if it came
    # before them. It is left out (the cone beyond z ends where g does), by EM and by the reference alike.
    forward = ForwardModelConfig(sigma=0.05, p_rand=0.05, p_hit=0.4, p_max=0.0)
    case = one_reading_case(0.1, forward, occupied_cols=(6, 8))
    index = case.index()
    assert index.cell[-1] == 10 * GRID.width + 7 and index.g[-1] > 0.0
    result, _, _ = run_case(case)
    assert result.objective[0] == pytest.approx(log_likelihoods(index, case.start).sum(), rel=1e-9)



def test_a_window_wide_enough_for_the_gaussian_to_underflow():
    # window = 40 sigmas: beyond about 38.6 sigmas g underflows to 0
    forward = Windowed(sigma=0.01, p_rand=0.05, p_hit=0.4, p_max=0.0, window=40.0)
    case = one_reading_case(0.11, forward, occupied_cols=(6, 10))  # at 0.1 m (near g's peak) and 0.5 m (39 sigmas)
    index = case.index()
    assert index.cell.max() < 10 * GRID.width + 10 and (index.g[index.cell > 10 * GRID.width + 6] > 0.0).all()
    result, _, _ = run_case(case)
    assert result.objective[0] == pytest.approx(log_likelihoods(index, case.start).sum(), rel=1e-9)


def test_one_reading_takes_the_kernels_compiled_for_many():
    # numpy calls a column of a one-row table contiguous (a strided one for many rows): the kernels
    # take the tables and their columns themselves, so that a problem of one reading (a cluster that
    # one reading reaches) runs the kernels compiled for many (modes.warm_up compiles no other)
    kernels = (kernel_readings._reading_extent, kernel_readings._window_rows, likelihood._init_state, likelihood._objective,
               tiles._sweep_tiles)
    run_case(random_case(3))
    compiled = [list(kernel.signatures) for kernel in kernels]
    forward = ForwardModelConfig(sigma=0.05, p_rand=0.05, p_hit=0.4, p_max=0.0)
    case = one_reading_case(0.5, forward, occupied_cols=(8,))
    case.candidates = np.arange(10 * GRID.width, 11 * GRID.width)
    result, _, _ = run_case(case)
    assert result.sweeps >= 1 and result.candidates.size > 0
    assert [list(kernel.signatures) for kernel in kernels] == compiled


@pytest.mark.parametrize("seed", range(300, 312))
def test_a_lobe_climbs_as_the_reference(seed):
    # cones whose cells the sonar hears only near the axis and, farther off it, only near the sensor
    # (``heard.heard_templates``): EM's tiles, state and windows leave the unheard cells out of a
    # reading as the reference index does; every cone cell still counts as seen
    height, width = SHAPES[seed % len(SHAPES)]
    case = random_case(seed, GridSpec(0.0, 0.0, 0.1, height, width), n_readings=(10, 60), beams=(30.0, 60.0))
    rng = np.random.default_rng(seed)
    whole = case.templates
    case.templates = heard_templates(whole, float(rng.choice([3.0, 8.0, 12.0])), float(rng.choice([0.7, 1.5, 3.0])))
    assert 0 < int(case.templates.heard.sum()) < case.templates.heard.size
    result, occupied, problem = run_case(case)
    everything = dataclasses.replace(case, templates=whole).index()
    heard = case.index()
    assert heard.cell.size < everything.cell.size
    assert np.array_equal(np.flatnonzero(problem.seen), np.unique(everything.cell))
    check_against_reference(case, result, occupied, dataclasses.replace(problem, seen=np.isin(
        np.arange(problem.seen.size), heard.cell)))
