"""What a map of EM shows a planner: EM's residuals where the data decide, hidden cells unobserved, the robot's
footprint clear (``em_view``); an adaptive map's outside put on the scale of its clusters (``joined_view``)."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from aogm_cli.core.log import Log
from aogm_cli.mapping.em import EMOutcome, EMResult
from aogm_cli.mapping.params import EMConfig, MapParams
from aogm_cli.mapping.standard import probability_from_log_odds
from aogm_cli.sensor_models.ray import axis_counts

HIDDEN_GAIN = 0.05  # log-odds: the evidence that decides a cell free (``decided``, ``stages.adaptive_view``)


def decided_free(evidence: np.ndarray) -> np.ndarray:
    """Where ``evidence`` decides a cell free: occupancy would lower the likelihood by over ``HIDDEN_GAIN``."""
    return evidence < -HIDDEN_GAIN


def decided(result: EMResult, config: EMConfig) -> np.ndarray:
    """``result``'s candidates the data decides: occupied or ``decided_free`` (the others are hidden)."""
    with np.errstate(divide="ignore"):
        evidence = np.log(result.residual) - np.log1p(-result.residual) - config.l_prior  # log p(Z|occ) - log p(Z|free)
    return (result.residual > 0.5) | decided_free(evidence)


def residual_into(probability: np.ndarray, result: EMResult, config: EMConfig) -> np.ndarray:
    """Write EM's residuals into ``probability`` at the ``decided`` candidates; returns the hidden cells to report
    unobserved, those whose standard estimate is at most 0.5 (a planner must not drive where no reading says free;
    Thrun's residual there reads as free, and the standard map's estimate erases walls)."""
    keep = decided(result, config)
    probability[result.candidates[keep]] = result.residual[keep]
    hidden = result.candidates[~keep]
    return hidden[probability[hidden] <= 0.5]


def footprint(grid, poses: np.ndarray, sensor) -> np.ndarray:
    """Bool (H, W): cells inside the sensor ring (smallest mount radius) at some pose: the robot's body."""
    radius = np.hypot(sensor.mount[:, 0], sensor.mount[:, 1])
    return grid.cells_near(poses[:, 0], poses[:, 1], float(np.min(radius[np.isfinite(radius)])))


def planner_view(probability: np.ndarray, observed: np.ndarray, unseen: np.ndarray, body: np.ndarray,
                 free: float) -> np.ndarray:
    """EM's map for a planner: ``unseen`` unobserved, the robot's ``body`` observed and at most ``free``, as a
    costmap clears its footprint (no cone covers it well; a short random reading can leave an obstacle)."""
    out = observed.copy()
    flat = out.reshape(-1)
    flat[unseen] = False
    cells = np.flatnonzero(body)
    flat[cells] = True
    probability[cells] = np.minimum(probability[cells], free)
    return out

def em_view(log_odds: np.ndarray, observed: np.ndarray, outcome: EMOutcome | None, grid, poses: np.ndarray, sensor,
            params: MapParams, body: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(probability, observed) (H, W) of an em or adaptive map as a planner sees it, 0.5 where unobserved."""
    probability = probability_from_log_odds(log_odds, observed).reshape(-1)
    if outcome is not None:
        free = probability_from_log_odds(np.float64(params.inverse_model.clamp_min))
        observed = planner_view(probability, observed, residual_into(probability, outcome.result, outcome.config),
                                footprint(grid, poses, sensor) if body is None else body, free)
    probability = probability.reshape(grid.shape)
    probability[~observed] = 0.5
    return probability, observed


# --- one scale --------------------------------------------------------------------------------------
# EM's residuals inside the clusters and the standard map outside rank cells unlike each other (docs/algorithms.md,
# "Where the defaults come from"), so each outside cell takes the EM probability of the cluster cells with its hit
# rate (``ray.axis_counts``): one increasing map per log, from its readings, each cell on its side of 0.5.

RATE_BINS = (-15, 15)  # log-odds: the hit-rate curves' bins are one log-odds wide over this range
SIDE = 1e-3  # a cell the scale would move across 0.5 stops this far short of it


def joined_view(log_odds: np.ndarray, observed: np.ndarray, outcome: EMOutcome | None, clusters: np.ndarray,
                whole: Log, grid, params: MapParams, evidence: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """``em_view`` of an adaptive map, the cells outside the clusters on EM's scale: by final ``evidence`` if
    given (``residual_scale``), else by hit rates (``one_scale``)."""
    robot = footprint(grid, whole.pose, whole.sensor) if outcome is not None or evidence is not None else None
    probability, observed = em_view(log_odds, observed, outcome, grid, whole.pose, whole.sensor, params, robot)
    if outcome is None and evidence is None:
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
    """``probability`` with ``cells`` at EM's residual logistic(evidence + l_prior), each on its side of 0.5."""
    residual = 1.0 / (1.0 + np.exp(-(np.asarray(evidence, dtype=np.float64) + l_prior)))
    p = probability[cells]
    side = np.where(p > 0.5, np.maximum(residual[cells], 0.5 + SIDE), np.minimum(residual[cells], 0.5 - SIDE))
    out = probability.copy()
    out[cells] = np.where(p == 0.5, 0.5, side)
    return out


def pool_adjacent_violators(y: np.ndarray, weights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Increasing weighted least-squares fit of ``y`` (PAV): (pooled values, the index where each pool starts)."""
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
    """``hit_rate_curve``'s pools (bins one log-odds wide, pooled until the rate rises), in increasing order."""

    rate: np.ndarray  # (ends + 1/2) / (reaches + 1) of its cells' echoes, pooled
    mean: np.ndarray  # its cells' probability, the mean weighted by reaches
    low: np.ndarray  # its cells' lowest probability
    high: np.ndarray  # and highest


def hit_rate_curve(probability: np.ndarray, ends: np.ndarray, passes: np.ndarray, region: np.ndarray) -> HitRates:
    """How often the echoes end in ``region``'s reached cells by probability: per log-odds bin the hit rate
    (ends + 1/2) / (reaches + 1) (Jeffreys: never 0 or 1), pooled until it rises (empty if none reached)."""
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
    """``probability`` (H, W), a copy, with the observed cells outside ``inside`` put on the inside's scale: an
    outside cell's hit rate h is placed among the inside pools' rates (linear between pool k's highest and
    k + 1's lowest probability, proportional beyond), each kept on its side of 0.5 (``SIDE``)."""
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
