"""Scoring a map without ground truth by the field's held-out protocol (ALGORITHMS.md section 7): which
scans are held out (``HoldoutSplit``, ``split_log``), and how well a map made from the others predicts
their readings (``holdout_scores``: ROC AUCs and the log-likelihood under a fixed reference model)."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numba
import numpy as np

from aogm_cli.core.errors import InputError
from aogm_cli.core.frames import sensor_poses
from aogm_cli.core.grid import GridSpec
from aogm_cli.core.log import Log, SensorSpec
from aogm_cli.core.scores import SCORE_KEYS as SCORE_KEYS  # ``holdout_scores``'s
from aogm_cli.evaluation.consistency import reading_endpoints
from aogm_cli.sensor_models.cone import (
    NO_CUT,
    SPARE_MASK,
    ConeReadings,
    cone_flat_cells,
    flat_offsets,
    range_search,
    reading_geometry,
)
from aogm_cli.sensor_models.forward_index import build_forward_index, log_likelihoods
from aogm_cli.sensor_models.forward_model import ForwardModelConfig
from aogm_cli.sensor_models.inverse_model import occupied_arc
from aogm_cli.sensor_models.ray import AXIS_SHORT, axis_counts, is_narrow_beam, ray_cells
from aogm_cli.sensor_models.readings import cone_templates, echo_ranges, lay_out_readings

OPTION = "--holdout"
MAX_FRACTION = 0.5  # at most every second scan held out: the map keeps at least half
# The reference model, chosen to be tolerant rather than fitted to any one sensor: sigma 0.1 m (two
# cells of the default grid: a real sonar's noise plus pose error, not our simulator's 0.02 m), p_rand
# 0.1 and p_max 0.1 (one reading in ten random, one in ten a specular dropout, so that a few surprising
# readings do not dominate the mean), p_hit 0.5 (an obstacle as likely missed as seen, between EM's
# trade-off values). EM's own defaults are fitted to our simulator; scoring with them would favour the
# EM maps that maximise them. The same model for every mode and every run, independent of the modes'
# own parameters and of any calibration, so that modes compare fairly.
REFERENCE_MODEL = ForwardModelConfig(sigma=0.1, p_rand=0.1, p_hit=0.5, p_max=0.1).validate()
REFERENCE_ALPHA = 2 * REFERENCE_MODEL.sigma  # m: the arc band z -/+ sigma of the reference model
READING_CHUNK = 8192  # held-out readings per forward-model index: bounds the index's memory
SCAN_CHUNK = 4096  # scans read from the log at a time


@dataclass(frozen=True)
class HoldoutSplit:
    """Which scans are held out: those with index % period == offset, period = round(1 / fraction),
    offset drawn from ``seed``. ``validate`` checks 0 < fraction <= 0.5."""

    fraction: float
    seed: int = 0

    def validate(self) -> HoldoutSplit:
        f = self.fraction
        if isinstance(f, bool) or not isinstance(f, (int, float)) or not 0 < f <= MAX_FRACTION:
            raise InputError(f"expected a fraction of scans in (0, {MAX_FRACTION:g}], got {f!r}", key=OPTION)
        return self

    @property
    def period(self) -> int:
        return max(2, round(1.0 / self.fraction))

    @property
    def offset(self) -> int:
        return int(np.random.default_rng(self.seed).integers(self.period))

    def held_out(self, n_scans: int) -> np.ndarray:
        """Indices (int64, increasing) of the held-out scans of a log of ``n_scans`` scans."""
        return np.arange(self.offset, n_scans, self.period, dtype=np.int64)

    def as_dict(self) -> dict:
        """What a map made from the kept scans records (its ``params["holdout"]``)."""
        return {"fraction": float(self.fraction), "seed": int(self.seed), "period": self.period, "offset": self.offset}


# How ``holdout_auc`` labels cells (``axis_labels``), as the JSON of a comparison records it: a results
# file whose reference lacks it scored ``holdout_auc`` as ``holdout_auc_band`` does now
AUC_PROTOCOL = {"positive": "the echo's cell on the sensor's axis",
                "negatives": f"the cells on that axis from the sensor to {AXIS_SHORT} cells short of it"}


def reference_json() -> dict:
    """The fixed scoring model and the AUC's protocol, for the JSON of a comparison."""
    return {"forward_model": REFERENCE_MODEL.as_dict(), "alpha": REFERENCE_ALPHA, "map": "probability > 0.5",
            "auc": AUC_PROTOCOL}


def split_log(log, split: HoldoutSplit) -> tuple[Log, np.ndarray]:
    """(the kept scans as an in-memory ``Log``, the held-out scan indices) of a log source; the
    kept log keeps the truth (its per-reading arrays cut to the kept scans). InputError when
    no scan would be kept."""
    whole = log.read()
    held = split.held_out(whole.n_scans)
    keep = np.ones(whole.n_scans, dtype=bool)
    keep[held] = False
    if not keep.any():
        raise InputError(f"{whole.n_scans} scan(s): --holdout {split.fraction:g} would keep none to map",
                         file=log.path or None, key=OPTION)
    truth = whole.truth
    if truth is not None:
        truth = dataclasses.replace(truth, cause=truth.cause[keep], ideal_range=truth.ideal_range[keep])
    kept = Log(whole.time[keep], whole.pose[keep], whole.ranges[keep], whole.sensor, whole.source, truth, whole.seed)
    return kept, held


def held_out_scans(log, split: HoldoutSplit, chunk: int = SCAN_CHUNK) -> tuple[np.ndarray, np.ndarray]:
    """(pose (T, 3), ranges (T, S)) of the held-out scans of a log source, read ``chunk`` scans
    at a time (only the held-out share is kept in memory)."""
    poses, ranges = [np.zeros((0, 3))], [np.zeros((0, log.sensor.count), dtype=np.float32)]
    for start, _time, pose, rng in log.chunks(chunk):
        sel = np.arange(start, start + pose.shape[0]) % split.period == split.offset
        poses.append(pose[sel])
        ranges.append(rng[sel])
    return np.concatenate(poses), np.concatenate(ranges)


def auc_from_counts(scores, positives, negatives) -> float:
    """ROC AUC of ``scores`` where item i counts ``positives[i]`` times as a positive and
    ``negatives[i]`` times as a negative: the Mann-Whitney U with average ranks for ties,
    P(score of a positive > score of a negative) + P(equal) / 2. NaN without positives or
    without negatives."""
    scores = np.asarray(scores, dtype=np.float64).reshape(-1)
    pos = np.asarray(positives, dtype=np.float64).reshape(-1)
    neg = np.asarray(negatives, dtype=np.float64).reshape(-1)
    n_pos, n_neg = pos.sum(), neg.sum()
    if not (n_pos > 0 and n_neg > 0):
        return math.nan
    values, inverse = np.unique(scores, return_inverse=True)
    p = np.bincount(inverse, weights=pos, minlength=values.size)
    n = np.bincount(inverse, weights=neg, minlength=values.size)
    below = np.cumsum(n) - n  # negatives scored lower than each value
    return float(np.sum(p * (below + 0.5 * n)) / (n_pos * n_neg))


def roc_auc(positive_scores, negative_scores) -> float:
    """ROC AUC of two samples of scores (``auc_from_counts`` with each score counted once)."""
    pos = np.asarray(positive_scores, dtype=np.float64).reshape(-1)
    neg = np.asarray(negative_scores, dtype=np.float64).reshape(-1)
    return auc_from_counts(np.concatenate([pos, neg]), np.repeat([1.0, 0.0], [pos.size, neg.size]),
                           np.repeat([0.0, 1.0], [pos.size, neg.size]))


@numba.njit(cache=True)
def _cone_labels(readings, tpl, flat, limits, height, width, counts, scratch, probability, arc_max):
    """Count, per cell, the readings whose occupied arc holds it (``counts[0]``) and those whose
    free region holds it (``counts[1]``); ``limits`` = (alpha / 2, min_range, max_range). With a
    non-empty flat ``probability`` (H * W), also each reading's largest probability over its
    arc's cells inside the grid into ``arc_max`` (NaN: no echo, or no arc cell in the grid).

    ``readings`` are ``cone.ConeReadings`` with ranges shifted by ``readings.echo_ranges``,
    ``tpl`` ``ConeTemplates.kernel_arrays``, ``flat`` its ``cone.FlatOffsets`` for ``width``.
    ``counts`` (2, H * W + SPARE_MASK + 1) int32: cells outside the grid land in the spare
    cells after it; ``scratch`` holds one template bin's entries. The regions are the standard
    mapper's (``mapping.standard._standard_kernel``).
    """
    half_alpha, min_range, max_range = limits
    pos = counts[0]
    neg = counts[1]
    z = readings.z
    ext = tpl.extent
    n_cells = height * width
    scoring = probability.size > 0
    for t in range(z.size):
        if scoring:
            arc_max[t] = np.nan
        zt = z[t]
        row0 = readings.rows[t]
        col0 = readings.cols[t]
        if not zt >= 0.0 or row0 + ext < 0 or row0 - ext >= height or col0 + ext < 0 or col0 - ext >= width:
            continue  # no information, or a cone that cannot touch the grid
        k = readings.bins[t]
        b = tpl.base_bin[k]
        r = tpl.ranges[tpl.offsets[b] : tpl.offsets[b + 1]]
        ri = tpl.range_index[b]
        shift = readings.offset[t]
        if zt >= max_range:  # no echo: free up to max_range (inclusive), nothing occupied
            f1 = range_search(r, ri, tpl.resolution, max_range + shift, True)
            m = f1
        else:
            free_end, arc_end = occupied_arc(zt, half_alpha, max_range)
            f1 = range_search(r, ri, tpl.resolution, free_end + shift, False)
            m = range_search(r, ri, tpl.resolution, arc_end + shift, True)
        f0 = min(range_search(r, ri, tpl.resolution, min_range + shift, False), f1)
        cone_flat_cells(scratch, tpl, flat, k, m, row0, col0, height, width)
        for j in range(f0, f1):
            neg[scratch[j]] += 1
        for j in range(f1, m):
            c = scratch[j]
            pos[c] += 1
            if scoring and c < n_cells and not probability[c] <= arc_max[t]:
                arc_max[t] = probability[c]


def arc_alpha(grid: GridSpec) -> float:
    """The arc thickness of the AUC on ``grid``: ``REFERENCE_ALPHA``, or one cell if larger."""
    return max(REFERENCE_ALPHA, float(grid.resolution))


def cone_labels(pose: np.ndarray, ranges: np.ndarray, sensor: SensorSpec, grid: GridSpec,
                probability: np.ndarray | None = None):
    """(positives, negatives), each int32 (H, W): how many of the readings (pose (T, 3),
    ranges (T, S)) hold each cell in their occupied arc, and in their free region; with
    ``probability`` (H, W), also each reading's largest probability over its arc (flat, NaN
    where it has none) as a third value."""
    templates = cone_templates(grid, sensor)
    rows, cols, bins, valid, offset = reading_geometry(pose, sensor, grid, templates)
    z = np.where(valid, echo_ranges(ranges, grid), np.nan)
    readings = ConeReadings(rows.reshape(-1), cols.reshape(-1), bins.reshape(-1), z.reshape(-1), offset.reshape(-1),
                            NO_CUT)
    n = grid.height * grid.width
    counts = np.zeros((2, n + SPARE_MASK + 1), dtype=np.int32)
    scratch = np.empty(int(np.diff(templates.offsets).max()), dtype=np.int32)
    limits = (0.5 * arc_alpha(grid), float(sensor.min_range), float(sensor.max_range))
    prob = np.zeros(0) if probability is None else np.ascontiguousarray(probability, dtype=np.float64).reshape(-1)
    arc_max = np.empty(readings.z.size if probability is not None else 0)
    _cone_labels(readings, templates.kernel_arrays, flat_offsets(templates, grid.width), limits, grid.height,
                 grid.width, counts, scratch, prob, arc_max)
    labels = counts[0, :n].reshape(grid.shape), counts[1, :n].reshape(grid.shape)
    return labels if probability is None else (*labels, arc_max)


def ray_labels(pose: np.ndarray, ranges: np.ndarray, sensor: SensorSpec, grid: GridSpec,
               probability: np.ndarray | None = None):
    """``cone_labels`` for narrow beams: each in-range reading's endpoint cell is a positive;
    the cells its ray crosses before z - alpha/2 (up to max_range for no echo) and past
    min_range are negatives. With ``probability`` (H, W), also each reading's largest
    probability over the cells its ray crosses within alpha/2 of z (NaN for no echo), third."""
    n = grid.height * grid.width
    rows, cols, counted = reading_endpoints(pose, ranges, sensor, grid)
    inside = counted & (rows >= 0) & (rows < grid.height) & (cols >= 0) & (cols < grid.width)
    positives = np.bincount(rows[inside] * grid.width + cols[inside], minlength=n).astype(np.int32)
    sp = sensor_poses(np.asarray(pose, dtype=np.float64).reshape(-1, 3), sensor.mount).reshape(-1, 3)
    z = np.asarray(ranges, dtype=np.float64).reshape(-1)
    half = 0.5 * arc_alpha(grid)
    band_max = np.full(z.size, np.nan)
    cells = []
    for t in np.flatnonzero((z >= 0) & np.isfinite(sp).all(axis=1)):  # one call per reading, not per cell
        echo = z[t] < sensor.max_range
        reach = min(z[t] + half, sensor.max_range) if echo else sensor.max_range
        r, c, _enter, t_exit = ray_cells(grid, sp[t, 0], sp[t, 1], sp[t, 2], reach)
        free = (t_exit > sensor.min_range) & (t_exit <= z[t] - half if echo else True)
        cells.append(r[free] * grid.width + c[free])
        if echo and probability is not None:
            band = t_exit > z[t] - half
            if band.any():
                band_max[t] = np.max(probability[r[band], c[band]])
    negatives = np.bincount(np.concatenate(cells or [np.zeros(0, dtype=np.int64)]), minlength=n).astype(np.int32)
    labels = positives.reshape(grid.shape), negatives.reshape(grid.shape)
    return labels if probability is None else (*labels, band_max)


def reading_scores(pose: np.ndarray, ranges: np.ndarray, sensor: SensorSpec, grid: GridSpec,
                   probability: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(one positive score per reading that has one, negatives (H, W) int32): the map's
    ``probability`` (H, W) where each held-out reading says an obstacle is, the largest over
    the cells within alpha/2 of its range (a sonar: its occupied arc, since one cell of the arc
    echoed, not every one; a narrow beam: the cells its ray crosses there), and per cell how
    many readings pass through it as free."""
    labels = ray_labels if is_narrow_beam(sensor, grid.resolution) else cone_labels
    _positives, negatives, band_max = labels(pose, ranges, sensor, grid, np.asarray(probability, dtype=np.float64))
    return band_max[np.isfinite(band_max)], negatives


def cell_labels(pose: np.ndarray, ranges: np.ndarray, sensor: SensorSpec, grid: GridSpec) -> tuple[np.ndarray, np.ndarray]:
    """(positives, negatives) per cell of the readings: ``ray_labels`` for narrow beams, else
    ``cone_labels``."""
    labels = ray_labels if is_narrow_beam(sensor, grid.resolution) else cone_labels
    return labels(pose, ranges, sensor, grid)


def axis_labels(pose: np.ndarray, ranges: np.ndarray, sensor: SensorSpec, grid: GridSpec) -> tuple[np.ndarray, np.ndarray]:
    """(positives, negatives), each int32 (H, W), of the held-out protocol after Hilbert maps that
    ``holdout_auc`` scores (``ray.axis_counts``): each echo (a finite range below max_range, of a
    finite pose) makes the cell at its range on the sensor's axis a positive (when inside the
    grid), and every cell that axis crosses from the sensor out to ``AXIS_SHORT`` cells short of
    the range (z - 2 resolution) a negative, one count per reading. A no-echo or NaN reading
    labels nothing; sonar and laser alike (the axis, not the cone)."""
    return axis_counts(pose, ranges, sensor, grid, AXIS_SHORT)


def reference_log_likelihoods(pose: np.ndarray, ranges: np.ndarray, sensor: SensorSpec, grid: GridSpec,
                              occupied: np.ndarray, chunk: int = READING_CHUNK) -> np.ndarray:
    """log p(z | m) under ``REFERENCE_MODEL`` of every reading of (pose (T, 3), ranges (T, S))
    but the NaN ones (and those of a pose that is not finite), for the binary map ``occupied``
    (bool (H, W)). A range at or beyond max_range counts as no echo (+inf). The readings are
    indexed ``chunk`` at a time, each index holding only their occupied cone cells (a free cell
    adds nothing to a reading's likelihood)."""
    r = np.asarray(ranges, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        r = np.where(r >= sensor.max_range, np.inf, r)
    laid = lay_out_readings(np.asarray(pose, dtype=np.float64).reshape(-1, 3), r, sensor, grid)
    keep = ~np.isnan(laid.z)
    rows, cols, bins, z = laid.rows[keep], laid.cols[keep], laid.bins[keep], laid.z[keep]
    occupied_flat = np.ascontiguousarray(occupied, dtype=np.bool_).reshape(-1)
    free = ~occupied_flat
    out = np.empty(z.size)
    for start in range(0, z.size, chunk):
        part = slice(start, start + chunk)
        index = build_forward_index((rows[part], cols[part], bins[part], z[part]), grid, laid.templates,
                                    float(sensor.max_range), REFERENCE_MODEL, held_free=free)
        out[part] = log_likelihoods(index, occupied_flat)
    return out


# What is measured. Every ``period``-th scan is held out, period = round(1 / fraction), starting at an
# offset drawn from the seed: whole scans on a fixed pattern, so that neighbouring readings of one scan
# do not leak into the map that scores them. The map is made from the other scans; then:
# * ``holdout_auc``: the protocol after Hilbert maps (``axis_labels``): the ROC AUC of the map's
#   occupancy probability at the cell of each held-out echo on its sensor's axis (a positive) against
#   the cells that axis crosses from the sensor to two cells short of the echo (negatives), each
#   (reading, cell) pair counted once, ties by average ranks (Mann-Whitney); no-echo readings label
#   nothing. Every cell is scored by what the map says of that very cell: a map that puts a wall one
#   cell off where held-out readings end, or holds the cell confidently free, is penalised.
# * ``holdout_auc_band``: the earlier definition, kept under its own name: a reading's
#   positive is the largest probability over a band of cells around its range, the negatives the cells
#   before the band. Sonar cones: the band is its occupied arc (one cell of the arc echoed), the
#   negatives the cells of its free region, both drawn as the standard mapper's inverse model draws
#   them (``mapping.standard``: arc z -/+ alpha/2, free from min_range up to the arc); a no-echo
#   (max-range) reading gives negatives only, its cone from min_range up to max_range. Narrow beams
#   (lasers, ``ray.is_narrow_beam``): the band is the cells the ray crosses within alpha/2 of z, the
#   negatives the cells it crosses before it and past min_range (as ``beam.BeamMapper`` marks them
#   free), up to max_range for no echo. The band's thickness is fixed, ``REFERENCE_ALPHA`` = z -/+ the
#   reference model's sigma (0.1 m), or one cell if larger. The largest over the band forgives a
#   sharp map a wall one cell off, and the band's cells are never negatives: it ranks a thin (EM)
#   wall above a thick (standard) one where the map's probability at the echo's own cell does not.
#   Both: unobserved cells score 0.5, cells outside the grid are left out, NaN when no reading gives
#   a positive or none a negative.
# * ``holdout_loglik``: the mean of log p(z | m) over the held-out readings (NaN ones left out; no
#   echo, or a range at or beyond max_range, is a max-range reading) under Thrun's forward model
#   (``sensor_models.forward_model``, the formula EM maximises) with the fixed ``REFERENCE_MODEL``,
#   for the binary map p > 0.5. It is a density (per metre): higher is better, and it can be positive.
def holdout_scores(log, m, split: HoldoutSplit) -> dict:
    """The held-out scores of map ``m`` (an ``OccupancyMap`` made from the kept scans of ``split``)
    against the held-out scans of the log source ``log``: ``holdout_auc``, ``holdout_auc_band``,
    ``holdout_loglik`` (NaN when nothing scores), ``holdout_readings`` (readings in the
    log-likelihood) and ``holdout_scans``."""
    pose, ranges = held_out_scans(log, split)
    ll = reference_log_likelihoods(pose, ranges, log.sensor, m.grid, np.asarray(m.probability) > 0.5)
    probability = np.asarray(m.probability, dtype=np.float64)
    band, negatives = reading_scores(pose, ranges, log.sensor, m.grid, probability)
    free = negatives > 0
    n_band = band.size
    return {
        "holdout_auc": auc_from_counts(probability, *axis_labels(pose, ranges, log.sensor, m.grid)),
        "holdout_auc_band": auc_from_counts(np.concatenate([band, probability[free]]),
                                            np.concatenate([np.ones(n_band), np.zeros(int(free.sum()))]),
                                            np.concatenate([np.zeros(n_band), negatives[free]])),
        "holdout_loglik": float(ll.mean()) if ll.size else math.nan,
        "holdout_readings": int(ll.size),
        "holdout_scans": int(pose.shape[0]),
    }
