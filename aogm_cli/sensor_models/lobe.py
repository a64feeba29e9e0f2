"""The sonar's beam as it detects: Kuc & Siegel's detection lobe, theta0 and R0, learned from the echoes
(``learn_lobe``) as the lobe that explains most of them at the map's walls."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numba
import numpy as np

from aogm_cli.core.grid import GridSpec
from aogm_cli.sensor_models.cone import flat_offsets
from aogm_cli.sensor_models.readings import reading_parts
from aogm_cli.sensor_models.surface import cone_walk

LOBE_BIN_DEG = 1.0  # the width of a bin of the angle off the axis (degrees)


def lobe_bins(beam_width: float) -> int:
    """How many ``LOBE_BIN_DEG`` bins of |angle off the axis| a cone ``beam_width`` (rad) wide has."""
    return max(1, int(math.ceil(math.degrees(0.5 * beam_width) / LOBE_BIN_DEG - 1e-9)))


# --- the detection lobe (docs/algorithms.md, "The beam that detects is narrower than the cone we draw") ---
# Kuc & Siegel: a cone cell at range r and angle phi off the axis is heard when exp(-2 phi^2 / theta0^2) / r^2
# >= 1 / R0^2, i.e. phi^2 <= theta0^2 ln(R0 / r); R0 is the on-axis range at which a surface met head-on is
# no longer heard (its reflectivity and the threshold in one number). Incidence is left out: R0 is the reach
# averaged over the angles the log meets its walls at, shorter than the head-on one (docs/algorithms.md, "The
# detection lobe": cos^n of incidence at the map's normals, or cells met obliquely left out, did not help).
THETA0_GRID_DEG = np.arange(1.0, 45.01, 0.5)  # the fit's candidates of theta0 (degrees)
R0_GRID_M = np.geomspace(1.0, 100.0, 21)  # and of R0 (metres, log-spaced: 26% apart)
LOBE_RANGE_BIN = 0.5  # m: the range bins of the record's hits and chances
LOBE_ECHOES = 6000  # the echoes the lobe is fitted on, spread evenly over the log: its cost stays bounded
# candidates explaining within this share as many echoes as the best explain the log as well (the intervals)
LOBE_TIE = 0.01
# the cone as drawn stays unless the best lobe explains this share more echoes than it: the bundled worlds'
# cones gain at most 2.9% from a lobe (glass_corridor; cluttered_lab_real 2.6%), their theta0 8 and 12 variants (seed 1)
# 3.4% or more but furnished_room theta0 12 (2.3%) (docs/algorithms.md)
LOBE_CONE_TOLERANCE = 0.03
# and unless it explains this share of all the log's echoes more: where the walls explain few echoes (the pillars
# of pillar_hall, 15% of them) a few more make no lobe (there 0.75% more; a narrow beam's 2.4-12.8%)
LOBE_MIN_GAIN = 0.015
# a lobe a sonar may have hears at least this share of the half-cone at 1 m: the simulator's cone of separate
# sub-rays misses thin pillars between them, which a lobe of 1 degree "explains" (pillar_hall; docs/algorithms.md)
LOBE_MIN_HEARD_AT_1M = 1.0 / 3.0


@numba.njit(cache=True, nogil=True)
def nearest_surfaces(tpl, flat, bearings, shape, readings, occupied, model, near, angle, span):
    """For every echo span[0] <= t < span[1] (z < z_max) and bin a of the angle off the axis, the nearest cell
    of ``occupied`` its cone holds up to z + band: near[t, a] its range (inf: none), angle[t, a] its |angle off
    the axis| (rad; NaN: none). ``readings`` = (rows, cols, bins, z) of echoes; ``model`` = (band, z_max, bin width)."""
    band, z_max, width = model
    rows, cols, bins, z_all = readings
    n_bins = near.shape[1]
    n_cells = shape[0] * shape[1]
    ib = np.empty(int(np.max(np.diff(tpl.offsets))), dtype=np.int32)
    for t in range(span[0], span[1]):
        near[t, :] = np.inf
        angle[t, :] = np.nan
        z = z_all[t]
        if not z < z_max:  # no echo (or NaN)
            continue
        m, r = cone_walk(tpl, flat, shape, rows[t], cols[t], bins[t], min(z + band, z_max), True, ib)
        s = tpl.offsets[tpl.base_bin[bins[t]]]
        for j in range(m):
            c = np.int64(ib[j])
            if c >= n_cells or not occupied[c]:
                continue
            phi = abs(bearings[s + j])
            a = min(int(phi / width), n_bins - 1)
            if r[j] < near[t, a]:
                near[t, a] = r[j]
                angle[t, a] = phi


@numba.njit(cache=True, inline="always")
def _below(grid, v, g0, per_step):
    """``np.searchsorted(grid, v)`` (the candidates below v) of an evenly spaced ascending ``grid`` (first value
    ``g0``, ``per_step`` steps a unit): a guess from the spacing, set right by comparing."""
    n = grid.shape[0]
    if not v < np.inf:
        return n
    i = min(max(int(math.ceil((v - g0) * per_step)), 0), n)
    while i > 0 and grid[i - 1] >= v:
        i -= 1
    while i < n and grid[i] < v:
        i += 1
    return i


@numba.njit(cache=True)
def explained_by_lobe(near, angle, z, band, theta0, log_r0, out):
    """out[i, j] += 1 for every echo t whose range the lobe (theta0[i] (rad, ascending), R0 = exp(log_r0[j]))
    explains: the nearest of its ``nearest_surfaces`` (near[t], angle[t]) that the lobe hears lies within
    ``band`` of z[t]. A bin is heard once theta0 >= phi / sqrt(ln(R0 / r)), never when r >= R0; so the echo is
    explained from the theta0 that hears the first bin within ``band`` of z up to the one that hears the first
    bin nearer (bins beyond decide nothing): one interval per echo and R0, added as +1 and -1 at its ends and
    summed over theta0 at last."""
    n_bins = near.shape[1]
    n_theta = theta0.shape[0]
    t0 = theta0[0]
    per_step = (n_theta - 1) / (theta0[-1] - theta0[0]) if n_theta > 1 else 0.0
    steps = np.zeros((n_theta + 1, log_r0.shape[0]))
    log_near = np.empty(n_bins)  # the echo's bins that hold a cell up to z + band: ln r, phi^2, on the echo
    phi2 = np.empty(n_bins)
    on_echo = np.empty(n_bins, dtype=np.bool_)
    for t in range(near.shape[0]):
        n = 0
        any_on = False
        for a in range(n_bins):
            r = near[t, a]
            if r <= z[t] + band:
                log_near[n] = math.log(r)
                phi2[n] = angle[t, a] * angle[t, a]
                on_echo[n] = r >= z[t] - band
                any_on = any_on or on_echo[n]
                n += 1
        if not any_on:  # no cell on the echo: no lobe explains it
            continue
        for j in range(log_r0.shape[0]):
            on = np.inf  # (theta0)^2 from which a bin on the echo is heard
            short = np.inf  # and from which a bin nearer than the echo is
            for k in range(n):
                headroom = log_r0[j] - log_near[k]
                if not headroom > 0.0:
                    continue
                v = phi2[k] / headroom
                if on_echo[k]:
                    on = min(on, v)
                else:
                    short = min(short, v)
            if on < short:
                steps[_below(theta0, math.sqrt(on), t0, per_step), j] += 1.0
                steps[_below(theta0, math.sqrt(short), t0, per_step), j] -= 1.0
    for j in range(log_r0.shape[0]):
        running = 0.0
        for i in range(n_theta):
            running += steps[i, j]
            out[i, j] += running


class SurfaceTable(NamedTuple):
    """``nearest_surfaces`` of a log's echoes: (echoes, angle bins) ranges and angles; z the echoes'."""

    near: np.ndarray
    angle: np.ndarray
    z: np.ndarray


@dataclass(frozen=True)
class Lobe:
    """The detection lobe learned from a log (``learn_lobe``): theta0 (degrees) and R0 (metres) of the rule
    above, each with the interval of values explaining the log as well (``LOBE_TIE``), or ``full_cone``: the
    cone as drawn explains the echoes within ``LOBE_CONE_TOLERANCE`` as well as the best lobe (then theta0_deg and
    r0_m are inf). ``counts`` (2, angle bins,
    range bins): per echo, the nearest wall cell of each angle bin up to it (chances, counts[0]) and those
    on it (hits, counts[1]), by the cell's range: the hit rate traces the lobe."""

    theta0_deg: float
    r0_m: float
    full_cone: bool
    theta0_interval_deg: tuple[float, float]
    r0_interval_m: tuple[float, float]
    echoes: int
    explained_best: int  # echoes the learned lobe explains
    explained_cone: int  # and those the whole cone does
    angle_edges_deg: np.ndarray  # (A + 1,) the bins of |angle off the axis|
    range_edges_m: np.ndarray  # (R + 1,)
    counts: np.ndarray  # (2, A, R) chances and hits

    def as_dict(self) -> dict:
        """The record as JSON takes it (inf as None)."""
        def finite(v: float) -> float | None:
            return float(v) if math.isfinite(v) else None
        return {"theta0_deg": finite(self.theta0_deg), "r0_m": finite(self.r0_m), "full_cone": self.full_cone,
                "theta0_interval_deg": list(self.theta0_interval_deg), "r0_interval_m": list(self.r0_interval_m),
                "echoes": self.echoes, "explained_best": self.explained_best, "explained_cone": self.explained_cone,
                "angle_edges_deg": self.angle_edges_deg.tolist(), "range_edges_m": self.range_edges_m.tolist(),
                "chances": self.counts[0].astype(int).tolist(), "hits": self.counts[1].astype(int).tolist()}


def surface_table(templates, grid: GridSpec, cones: tuple, occupied: np.ndarray, z_max: float,
                  band: float) -> SurfaceTable:
    """``nearest_surfaces`` of the echoes of ``cones`` = (rows, cols, bins, z) at ``occupied`` (H * W bool), at most
    ``LOBE_ECHOES`` of them."""
    rows, cols, bins, z = (np.ascontiguousarray(a).reshape(-1) for a in cones)
    echo = np.flatnonzero(z < z_max)
    if echo.size > LOBE_ECHOES:
        echo = echo[np.unique(np.linspace(0, echo.size - 1, LOBE_ECHOES).round().astype(np.int64))]
    readings = (rows[echo].astype(np.int64), cols[echo].astype(np.int64), bins[echo].astype(np.int64),
                z[echo].astype(np.float64))
    table = SurfaceTable(*(np.empty((echo.size, lobe_bins(templates.beam_width))) for _ in range(2)), readings[3])
    tpl, flat = templates.kernel_arrays, flat_offsets(templates, grid.width)
    occupied = np.ascontiguousarray(occupied, dtype=np.bool_).reshape(-1)
    model = (float(band), float(z_max), math.radians(LOBE_BIN_DEG))  # each reading's own rows: any thread count alike
    reading_parts(echo.size, lambda _, span: nearest_surfaces(tpl, flat, templates.bearings, grid.shape, readings,
                                                              occupied, model, table.near, table.angle, span))
    return table


def hits_and_chances(table: SurfaceTable, band: float, z_max: float) -> tuple[np.ndarray, np.ndarray]:
    """(range edges, counts (2, angle bins, range bins)): each angle bin's nearest wall cell up to the echo
    (a chance) and on it, within ``band`` of z (a hit), by that cell's range."""
    edges = np.arange(0.0, z_max + LOBE_RANGE_BIN, LOBE_RANGE_BIN)
    counts = np.zeros((2, table.near.shape[1], edges.size - 1))
    _count_hits(table.near, table.z, float(band), LOBE_RANGE_BIN, counts)
    return edges, counts


@numba.njit(cache=True)
def _count_hits(near, z, band, bin_width, counts):
    """``hits_and_chances``' counts: range bin k holds the cells at [k, k + 1) ``bin_width`` (the last one beyond)."""
    last = counts.shape[2] - 1
    for t in range(near.shape[0]):
        for a in range(near.shape[1]):
            r = near[t, a]
            if not r < np.inf:
                continue
            k = min(int(r / bin_width), last)
            counts[0, a, k] += 1.0
            if abs(r - z[t]) <= band:
                counts[1, a, k] += 1.0


def _interval(profile: np.ndarray, grid: np.ndarray, best: float) -> tuple[float, float]:
    """The span of ``grid`` whose ``profile`` lies within ``LOBE_TIE`` of ``best``."""
    near_best = np.flatnonzero(profile >= (1.0 - LOBE_TIE) * best)
    return float(grid[near_best[0]]), float(grid[near_best[-1]])


def learn_lobe(templates, grid: GridSpec, cones: tuple, occupied: np.ndarray, z_max: float, band: float) -> Lobe:
    """The detection lobe that explains most echoes of ``cones`` = (rows, cols, bins, z) at the walls
    ``occupied`` (H * W bool; ``beam_model.lobe_walls``): of the candidates ``THETA0_GRID_DEG`` x
    ``R0_GRID_M``, the one under which most echoes lie within ``band`` of the nearest wall cell it hears
    (``explained_by_lobe``: the likelihood of a hard threshold with random readings). The cone as drawn
    stays (``full_cone``) unless the best lobe explains ``LOBE_CONE_TOLERANCE`` more echoes than it, and
    ``LOBE_MIN_GAIN`` of all the echoes more. Only lobes that hear ``LOBE_MIN_HEARD_AT_1M`` of the half-cone
    at 1 m, and a surface on the axis met head-on out to ``z_max`` (the sensor's rated range), are candidates
    (the others explain 0 in ``explained``: the R0 below z_max are not counted at all)."""
    table = surface_table(templates, grid, cones, occupied, z_max, band)
    explained = np.zeros((THETA0_GRID_DEG.size, R0_GRID_M.size))
    reach = np.flatnonzero(R0_GRID_M >= z_max * (1.0 - 1e-9))  # a surface met head-on is heard out to the max range
    if reach.size:
        counted = np.zeros((THETA0_GRID_DEG.size, reach.size))
        explained_by_lobe(table.near, table.angle, table.z, float(band), np.radians(THETA0_GRID_DEG),
                          np.log(R0_GRID_M[reach]), counted)
        explained[:, reach] = counted
    cone = int(np.sum(np.abs(table.near.min(axis=1, initial=np.inf) - table.z) <= band))
    heard_at_1m = THETA0_GRID_DEG[:, None] * np.sqrt(np.maximum(np.log(R0_GRID_M), 0.0))[None, :]
    explained[heard_at_1m < LOBE_MIN_HEARD_AT_1M * math.degrees(0.5 * templates.beam_width)] = 0.0
    i, j = np.unravel_index(int(np.argmax(explained)), explained.shape)
    best = float(explained[i, j])
    full = best == 0 or cone >= (1.0 - LOBE_CONE_TOLERANCE) * best or best - cone < LOBE_MIN_GAIN * table.z.size
    edges, counts = hits_and_chances(table, band, z_max)
    theta0, r0 = (math.inf, math.inf) if full else (float(THETA0_GRID_DEG[i]), float(R0_GRID_M[j]))
    return Lobe(theta0, r0, full, _interval(explained.max(axis=1), THETA0_GRID_DEG, best),
                _interval(explained.max(axis=0), R0_GRID_M, best), int(table.z.size), int(best), cone,
                LOBE_BIN_DEG * np.arange(table.near.shape[1] + 1), edges, counts)
