"""The sonar's beam as it detects: how many readings a map explains when the beam detects out to each
angle off its axis (``opening_matches``), and the effective opening learned from that curve
(``learned_opening``)."""

from __future__ import annotations

import math

import numba
import numpy as np

from aogm_cli.sensor_models.surface import cone_walk

LOBE_BIN_DEG = 1.0  # the width of a bin of the angle off the axis (degrees)
# A log keeps its cone unless it explains this share fewer echoes than the best opening: the thinned
# map's smear leaves the cone a little short, and a too narrow cone costs EM accuracy (docs/algorithms.md)
CONE_TOLERANCE = 0.04
# then the opening is the widest that explains at least this share fewer than the best one does
OPENING_TOLERANCE = 0.01
MIN_ECHOES = 100  # a log with fewer echoes keeps its cone


def lobe_bins(beam_width: float) -> int:
    """How many ``LOBE_BIN_DEG`` bins of |angle off the axis| a cone ``beam_width`` (rad) wide has."""
    return max(1, int(math.ceil(math.degrees(0.5 * beam_width) / LOBE_BIN_DEG - 1e-9)))


@numba.njit(cache=True)
def opening_matches(tpl, flat, bearings, shape, readings, occupied, model, out):
    """out[a] += 1 for every echo that the map ``occupied`` explains when the beam detects up to
    (a + 1) bins off its axis: the nearest occupied cell within that angle lies within ``band`` of z.

    A narrower opening puts the nearest surface too far, a wider one too near: the curve peaks at
    the beam's. ``readings`` = (rows, cols, bins, z); ``model`` = (band, z_max, bin)."""
    band, z_max, width = model
    rows, cols, bins, z_all = readings
    n_bins = out.shape[0]
    n_cells = shape[0] * shape[1]
    ib = np.empty(int(np.max(np.diff(tpl.offsets))), dtype=np.int32)
    first = np.empty(n_bins)
    for t in range(z_all.shape[0]):
        z = z_all[t]
        if not z < z_max:  # no echo (or NaN)
            continue
        m, r = cone_walk(tpl, flat, shape, rows[t], cols[t], bins[t], min(z + band, z_max), True, ib)
        s = tpl.offsets[tpl.base_bin[bins[t]]]
        first[:] = np.inf
        for j in range(m):
            c = np.int64(ib[j])
            if c >= n_cells or not occupied[c]:
                continue
            b = min(int(abs(bearings[s + j]) / width), n_bins - 1)
            if r[j] < first[b]:
                first[b] = r[j]
        nearest = np.inf
        for a in range(n_bins):
            nearest = min(nearest, first[a])
            if abs(nearest - z) <= band:
                out[a] += 1.0


def cone_deg(beam_width: float) -> float:
    """A cone's opening ``beam_width`` (rad) in degrees, rounded to 1e-9 (30, not 29.999999999999996)."""
    return round(math.degrees(beam_width), 9)


def learned_opening(matches: np.ndarray, echoes: int, beam_width: float) -> float:
    """The effective opening (degrees) from ``opening_matches``' curve (the constants above)."""
    if echoes < MIN_ECHOES or matches.size == 0 or matches[-1] >= (1.0 - CONE_TOLERANCE) * matches.max():
        return cone_deg(beam_width)
    a = int(np.flatnonzero(matches >= (1.0 - OPENING_TOLERANCE) * matches.max())[-1])
    return 2.0 * LOBE_BIN_DEG * (a + 1)
