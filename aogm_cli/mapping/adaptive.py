"""The paper's adaptive mode's own parts: standard log-odds everywhere, then EM inside each cluster.

The detector flags readings (``detector.network``), the bands their cones sweep near their
ranges become clusters (``mapping.cluster``), and EM (``mapping.em.run_em``) runs over the
cluster cells with every other cell held at the thresholded standard map; a cluster's cells
get EM's residual probability, and the other cells the same scale (``joined_view``).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from aogm_cli.core.log import Log
from aogm_cli.mapping.cluster import grown, label_clusters, near_occupied, readings_near_clusters
from aogm_cli.mapping.em import EMOutcome, EMProblem, ProblemFor, em_problem, em_readings, em_view, find_root, footprint
from aogm_cli.mapping.params import EMConfig, MapParams
from aogm_cli.mapping.standard import occupied_evidence
from aogm_cli.sensor_models.ray import axis_counts, is_narrow_beam
from aogm_cli.sensor_models.readings import LaidOutReadings, cone_bands

BAND_BELOW = 0.2  # m: a flagged reading's band starts this far before its range
NEAR_OCCUPIED = 0  # cells (8-connected) from a cell the standard map holds occupied that a band may mark


def cluster_problem(run: LaidOutReadings, clusters: np.ndarray, occupied: np.ndarray, config: EMConfig,
                    subset: np.ndarray | None = None) -> EMProblem:
    """EM's problem inside ``clusters`` (ids, 0 outside): the readings whose cones could reach a
    cluster cell (``cluster.readings_near_clusters``; of those ``subset`` marks, if given), under
    the flat map ``occupied``, with which clusters share a reading."""
    near = readings_near_clusters(clusters, run.rows, run.cols, run.z, run.grid, run.sensor.max_range, config.forward)
    if subset is not None:
        near = near[subset[near]]
    rd = em_readings(run.cones, run.templates, run.grid, run.sensor.max_range,
                     config.forward, select=near, shadow=run.shadow)
    return em_problem(rd, run.templates, run.grid.shape, occupied, config, labels=clusters.reshape(-1))


def coupled_groups(problem: EMProblem, n_clusters: int) -> int:
    """How many groups of coupled clusters (clusters joined through a reading whose cone holds
    cells of both): independent problems, which one EM run over every cluster solves at once."""
    parent = problem.parent
    roots = {int(find_root(parent, k)) for k in range(1, n_clusters + 1)}
    return len(roots)


def contested_cells(log: Log, grid, params: MapParams, log_odds: np.ndarray,
                    shadow: np.ndarray | None = None) -> np.ndarray:
    """Cells (H, W) whose occupied evidence alone reaches ``adaptive.contested`` log-odds but
    which the standard map holds free: where the readings disagree and the standard
    map cannot explain them (walls that specular or multipath readings, too long, cleared).
    One more standard pass, with the inverse model's free evidence set to nothing (and the
    deflected beams, ``shadow``, stopped: they hit nothing)."""
    cuts = None if shadow is None else shadow.reshape(np.shape(log.ranges))
    return (occupied_evidence(log, grid, params, cuts) >= params.adaptive.contested) & (log_odds <= 0)


def find_clusters(run: LaidOutReadings, flags: np.ndarray, standard, params: MapParams, outside: str,
                  log: Log | None = None) -> tuple[np.ndarray, int]:
    """(cluster ids (H, W), count): a flagged cone's band near its range, z - BAND_BELOW ..
    z + alpha, where the map ``standard`` (``stages.StandardMap``) holds cells occupied (the
    walls EM may thin or open, a doorway), and as ``outside`` (``stages.outside``) says:

    * "thinned" (the thinned map outside, its free cells no reading holds free unknown): the cells
      the thinned map holds free but the exact inverse model holds occupied by ``adaptive.contested``
      log-odds or more (walls that too-long specular or multipath readings cleared), from the exact
      model's evidence the thinning computed; then every cluster grown by one cell into the wall
      layers the thinning removed (Elfes' map holds them occupied, and EM starts there from it:
      ``stages.start``);
    * "elfes" (Elfes' map outside the clusters): the ``contested`` cells (``contested_cells``,
      one more standard pass over ``log``) and the ``weak`` ones, whose log-odds lie within
      ``adaptive.weak`` of the prior (space behind a wall that one random reading crossed), all
      grown by ``adaptive.grow`` cells (8-connected; sonar cones only: on the intel laser log
      growing cost adaptive's held-out AUC 0.9863 -> 0.9737)."""
    log_odds, observed, config = standard.log_odds, standard.observed, params.adaptive
    region, _ = cone_bands(run.grid, run.templates, tuple(a[flags] for a in run.cones),
                           BAND_BELOW, params.inverse_model.alpha)
    region &= observed & (log_odds > params.inverse_model.clamp_min)
    region &= near_occupied(log_odds, NEAR_OCCUPIED)
    grow = 0
    if outside == "thinned":
        if config.contested > 0 and standard.evidence is not None:
            region |= observed & (log_odds <= 0) & (standard.evidence >= config.contested)
        if standard.elfes is not None:  # the inner layers: EM, not the exact model, thins a wall it works on
            region |= grown(region, 1) & observed & (standard.elfes > 0) & (log_odds <= 0)
    else:
        if config.contested > 0:
            region |= contested_cells(log, run.grid, params, log_odds, run.shadow) & observed
        if config.weak > 0:
            region |= observed & (np.abs(log_odds - params.inverse_model.l0) < config.weak)
        grow = 0 if is_narrow_beam(run.sensor, run.grid.resolution) else config.grow
    return label_clusters(observed & grown(region, grow))


def cluster_problems(run: LaidOutReadings, clusters: np.ndarray) -> ProblemFor:
    """The adaptive mode's problems: EM over every cluster cell at once (``cluster_problem``),
    every other cell held at the map it is given; with ``em.start`` "empty", the cluster cells
    start free. Clusters that share no reading are independent (as the paper has them): one run
    gives each its own result."""
    cells = np.flatnonzero(clusters.reshape(-1) > 0)

    def problem_for(config: EMConfig, occ: np.ndarray, subset: np.ndarray | None):
        if config.start == "empty":
            occ[cells] = False
        return cluster_problem(run, clusters, occ, config, subset), cells

    return problem_for


def near_clusters(run: LaidOutReadings, clusters: np.ndarray, forward) -> np.ndarray:
    """Bool mask of the readings whose cones reach a cluster: those the model is fitted on, the
    ones EM explains (outside the clusters the thresholded standard map stands, and readings
    crossing its thick walls look random)."""
    near = np.zeros(run.z.size, dtype=bool)
    near[readings_near_clusters(clusters, run.rows, run.cols, run.z, run.grid, run.sensor.max_range, forward)] = True
    return near


# --- one scale (issue 28) --------------------------------------------------------------------------
# Inside the clusters a cell's probability is EM's residual, outside the standard map's: two scales
# that rank cells unlike each other (the standard map's free cells sit at its clamp, 0.12, above EM's
# free cells at a wall's edge, where readings end; docs/algorithms.md, "Where the defaults come
# from", has what that cost on the intel log). The log's own readings say what each scale means: of the echoes whose
# axis reaches a cell, the share that end in it (its hit rate, ``ray.axis_counts``). Each observed cell
# outside the clusters takes the EM probability of the cluster cells whose hit rate its probability
# has: one increasing map per log, learned from the readings that made the map (no truth, no
# held-out scan), which keeps every cell on its side of 0.5, so that what the map believes occupied,
# free or unknown (accuracy, checks, what a planner sees) is what it was.

RATE_BINS = (-15, 15)  # log-odds: the hit-rate curves' bins are one log-odds wide over this range
SIDE = 1e-3  # a cell the scale would move across 0.5 stops this far short of it


def joined_view(log_odds: np.ndarray, observed: np.ndarray, outcome: EMOutcome | None, clusters: np.ndarray,
                whole: Log, grid, params: MapParams, evidence: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(probability, observed) (H, W) of an adaptive map: ``em.em_view``'s (EM's residuals in the
    clusters, the standard map's elsewhere, what a planner sees), its observed cells outside the
    clusters put on EM's scale, unless ``adaptive.scale`` is "mixed": with each cell's
    ``evidence`` at the final map (the thinned map outside the clusters: ``stages.decided``), EM's
    residual there (``residual_scale``), else by the hit rates of the log's echoes (``one_scale``)."""
    robot = footprint(grid, whole.pose, whole.sensor) if outcome is not None or evidence is not None else None
    probability, observed = em_view(log_odds, observed, outcome, grid, whole.pose, whole.sensor, params, robot)
    if params.adaptive.scale == "mixed" or (outcome is None and evidence is None):
        return probability, observed
    inside = clusters > 0
    if evidence is not None:
        outside = observed & ~inside
        scaled = residual_scale(probability, outside, evidence, params.em.l_prior)
        body = outside & robot  # cleared: at most the free clamp still
        scaled[body] = np.minimum(scaled[body], probability[body])
        return scaled, observed
    ends, passes = axis_counts(whole.pose, whole.ranges, whole.sensor, grid)
    return one_scale(probability, observed, inside, ends, passes), observed


def residual_scale(probability: np.ndarray, cells: np.ndarray, evidence: np.ndarray, l_prior: float) -> np.ndarray:
    """``probability`` (H, W) with ``cells`` given EM's residual occupancy logistic(evidence +
    l_prior), as EM gives its own candidates (``em.decided``), each kept on its side of 0.5 (``SIDE``
    short of it): what the map believes is unchanged, and the cells outside the clusters rank on
    the scale of those inside. On corridor_door_real and office_doors_real (seed 1, ``aogm compare
    --holdout 0.1 --seed 1``) the held-out band AUC is 0.9942 and 0.9952 (the standard map 0.9933,
    0.9890; EM 0.9941, 0.9955); the hit rates' scale gave the first 0.9907 (docs/algorithms.md)."""
    residual = 1.0 / (1.0 + np.exp(-(np.asarray(evidence, dtype=np.float64) + l_prior)))
    p = probability[cells]
    side = np.where(p > 0.5, np.maximum(residual[cells], 0.5 + SIDE), np.minimum(residual[cells], 0.5 - SIDE))
    out = probability.copy()
    out[cells] = np.where(p == 0.5, 0.5, side)
    return out


def pool_adjacent_violators(y: np.ndarray, weights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The increasing fit of the sequence ``y`` in weighted least squares: adjacent values that
    do not rise are pooled into their weighted mean (weighted pool-adjacent-violators). Returns
    (the pooled values, strictly increasing; the index in ``y`` where each pool starts)."""
    blocks: list[list[float]] = []  # [weight, weight * y, first index]
    for i, (yi, wi) in enumerate(zip(y, weights, strict=True)):
        blocks.append([float(wi), float(wi * yi), i])
        while len(blocks) > 1 and blocks[-2][1] * blocks[-1][0] >= blocks[-1][1] * blocks[-2][0]:
            w, wy, _ = blocks.pop()
            blocks[-1][0] += w
            blocks[-1][1] += wy
    b = np.array(blocks, dtype=np.float64).reshape(-1, 3)
    return b[:, 1] / b[:, 0], b[:, 2].astype(np.int64)


class HitRates(NamedTuple):
    """``hit_rate_curve``: per pool of cells (bins one log-odds wide, pooled until the rate rises),
    in increasing order of probability and of rate."""

    rate: np.ndarray  # (ends + 1/2) / (reaches + 1) of its cells' echoes, pooled
    mean: np.ndarray  # its cells' probability, the mean weighted by reaches
    low: np.ndarray  # its cells' lowest probability
    high: np.ndarray  # and highest


def hit_rate_curve(probability: np.ndarray, ends: np.ndarray, passes: np.ndarray, region: np.ndarray) -> HitRates:
    """How often the log's echoes end in the cells of ``region`` (bool (H, W)) that some echo's
    axis reaches (``ends`` + ``passes`` > 0), against the cells' probability: the cells fall
    into bins one log-odds wide (``RATE_BINS``), and each bin's hit rate, (ends + 1/2) /
    (reaches + 1) (Jeffreys: never 0 or 1), is pooled with its neighbours' until it rises with
    the probability (``pool_adjacent_violators``, weighted by reaches). Empty arrays when no echo
    reaches the region."""
    reach = (ends + passes).astype(np.float64)
    cells = region & (reach > 0)
    p = probability[cells].astype(np.float64)
    w = reach[cells]
    lo_min, lo_max = RATE_BINS
    n = lo_max - lo_min
    with np.errstate(divide="ignore"):
        log_odds = np.log(p) - np.log1p(-p)
    bins = np.clip(np.floor(log_odds - lo_min), 0, n - 1).astype(np.int64)
    weight = np.bincount(bins, weights=w, minlength=n)
    used = np.flatnonzero(weight > 0)
    rate, starts = pool_adjacent_violators((np.bincount(bins, weights=ends[cells], minlength=n)[used] + 0.5)
                                           / (weight[used] + 1.0), weight[used])
    pool = np.full(n, -1, dtype=np.int64)
    pool[used] = np.searchsorted(starts, np.arange(used.size), side="right") - 1
    k = pool[bins]  # each cell's pool
    low = np.full(rate.size, np.inf)
    high = np.full(rate.size, -np.inf)
    np.minimum.at(low, k, p)
    np.maximum.at(high, k, p)
    mean = np.bincount(k, weights=w * p, minlength=rate.size) / np.bincount(k, weights=w, minlength=rate.size)
    return HitRates(rate, mean, low, high)


def one_scale(probability: np.ndarray, observed: np.ndarray, inside: np.ndarray, ends: np.ndarray,
              passes: np.ndarray) -> np.ndarray:
    """``probability`` (H, W) with its observed cells outside ``inside`` (the clusters) put on the
    inside's scale by their hit rates (``hit_rate_curve``). An outside cell's hit rate h is the
    outside cells' curve at its probability (linear between the pools' mean probabilities,
    constant beyond them); it then ranks among the inside cells by h: with h between the rates
    of inside pools k and k + 1 it lies between pool k's highest probability and pool k + 1's
    lowest (linear in h), below the lowest pool's rate under its lowest probability (in
    proportion to h), above the highest pool's rate over its highest (the distance to 1 in
    proportion to 1 - h). Each cell keeps its side of 0.5 (0.5 stays; one that would cross
    stops ``SIDE`` short of it). A copy; unchanged when no echo reaches either side."""
    outside = observed & ~inside
    ins = hit_rate_curve(probability, ends, passes, inside & observed)
    outs = hit_rate_curve(probability, ends, passes, outside)
    out = probability.copy()
    if ins.rate.size == 0 or outs.rate.size == 0:
        return out
    p = probability[outside].astype(np.float64)
    h = np.interp(p, outs.mean, outs.rate)
    rate, low, high = ins.rate, ins.low, ins.high
    k = np.searchsorted(rate, h, side="right") - 1  # rate[k] <= h < rate[k + 1]
    below, above = k < 0, k >= rate.size - 1
    between = ~below & ~above
    kb = k[between]
    q = np.empty_like(h)
    q[between] = high[kb] + (h[between] - rate[kb]) / (rate[kb + 1] - rate[kb]) * (low[kb + 1] - high[kb])
    q[below] = low[0] * h[below] / rate[0]
    q[above] = 1.0 - (1.0 - high[-1]) * (1.0 - h[above]) / (1.0 - rate[-1])
    out[outside] = np.where(p > 0.5, np.maximum(q, 0.5 + SIDE), np.where(p < 0.5, np.minimum(q, 0.5 - SIDE), 0.5))
    return out
