"""The surfaces a sonar's readings meet: each wall cell's normal, from the directions it echoed in
(``surface_normals``), and where a reading's beam met one beyond the specular angle and was deflected
(``reading_shadows``)."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numba
import numpy as np

from aogm_cli.core.errors import InputError
from aogm_cli.sensor_models.cone import cone_flat_cells, flat_offsets
from aogm_cli.sensor_models.readings import reading_parts, summed_in_parts

# A cell is a surface with a direction (``surface_normals``) when heard by at least MIN_ECHOES readings
# whose directions' doubled-angle mean resultant length is at least MIN_COHERENCE (even spread over
# +-45 deg: 0.64; a corner: 0), and passed by at most MAX_PASS_SHARE of the readings that meet it within
# HEAD_ON_DEG of its normal: a doorway smeared by the wall's echoes is passed head-on; a wall is not.
MIN_ECHOES = 2
MIN_COHERENCE = 0.5
MAX_PASS_SHARE = 0.5
HEAD_ON_DEG = 20.0


@dataclass(frozen=True)
class SurfaceConfig:
    """The angle of incidence (sonar logs, ``em.specular_deg`` below 90): a smooth surface echoes only near its
    normal; corners and clutter keep Thrun's model. A beam is deflected where the ``core`` of its cone meets a
    surface at a grazing angle (an edge clipping a door frame passes it; docs/algorithms.md)."""

    core: float = 0.1

    def validate(self) -> SurfaceConfig:
        """Return self, or raise ``InputError(key=<field>)`` for an impossible value."""
        if not 0 <= self.core <= 1:
            raise InputError(f"expected a number in [0, 1], got {self.core!r}", key="core")
        return self

    def as_dict(self) -> dict:
        return asdict(self)


def surface_normals(tpl, flat, shape: tuple[int, int], cones: tuple, z_max: float, resolution: float,
                    believed: np.ndarray) -> np.ndarray:
    """(2, H * W) float32: the unit normal (d row, d col) of each surface the readings ``cones`` echoed
    from, NaN elsewhere; only the cells ``believed`` marks can be surfaces."""
    rows, cols, bins, z = (np.ascontiguousarray(a).reshape(-1) for a in cones)
    readings = (rows.astype(np.int64), cols.astype(np.int64), bins.astype(np.int64), z.astype(np.float64))
    # float32: sums of counts and unit terms, exact enough for a threshold on their ratio
    sums = np.zeros((3, shape[0] * shape[1]), dtype=np.float32)
    echo_direction_sums(tpl, flat, shape, readings, float(resolution), float(z_max), sums)
    count = sums[2]
    cells = np.flatnonzero((count >= MIN_ECHOES) & np.asarray(believed, dtype=bool).reshape(-1))
    coherent = np.hypot(sums[0, cells], sums[1, cells]) >= MIN_COHERENCE * count[cells]
    cells = cells[coherent]
    angle = 0.5 * np.arctan2(sums[1, cells], sums[0, cells])  # the mean axis, from the doubled angles
    echoes = count[cells]
    del sums, count
    normal = np.full((2, shape[0] * shape[1]), np.nan, dtype=np.float32)
    normal[0, cells] = np.cos(angle)
    normal[1, cells] = np.sin(angle)
    passes = np.zeros(normal.shape[1], dtype=np.float32)
    cos2 = math.cos(math.radians(HEAD_ON_DEG)) ** 2
    summed_in_parts(z.size, passes, lambda _, out, span: head_on_passes(tpl, flat, shape, readings, normal, cos2,
                                                                       float(resolution), float(z_max), out, span))
    passed = cells[passes[cells] > MAX_PASS_SHARE * (passes[cells] + echoes)]
    normal[:, passed] = np.nan
    return normal


@numba.njit(cache=True, inline="always")
def _offset(cell, row0, col0, width):
    """(d row, d col) of the flat ``cell`` from the sensor cell (row0, col0)."""
    row = cell // width
    return float(row - row0), float(cell - row * width - col0)


@numba.njit(cache=True, inline="always")
def cone_walk(tpl, flat, shape, row0, col0, k, end, right, ib):
    """The cells of heading bin k's cone up to range ``end`` into ``ib``: (count, the bin's ranges)."""
    height, width = shape
    ext = tpl.extent
    b = tpl.base_bin[k]
    r = tpl.ranges[tpl.offsets[b] : tpl.offsets[b + 1]]
    if not end > 0.0 or row0 + ext < 0 or row0 - ext >= height or col0 + ext < 0 or col0 - ext >= width:
        return 0, r
    m = np.searchsorted(r, end, side="right") if right else np.searchsorted(r, end, side="left")
    cone_flat_cells(ib, tpl, flat, k, m, row0, col0, height, width)
    return m, r


@numba.njit(cache=True, nogil=True)
def head_on_passes(tpl, flat, shape, readings, normal, cos2, margin, z_max, out, span):
    """out[c] += 1 for every reading meeting surface cell c head-on (``cos2``), ``margin`` before its range."""
    rows, cols, bins, z = readings
    n_cells = shape[0] * shape[1]
    ib = np.empty(int(np.max(np.diff(tpl.offsets))), dtype=np.int32)
    for t in range(span[0], span[1]):
        if not z[t] == z[t]:
            continue
        m, _ = cone_walk(tpl, flat, shape, rows[t], cols[t], bins[t], z_max if not z[t] < z_max else z[t] - margin,
                     False, ib)
        for j in range(m):
            c = np.int64(ib[j])
            if c < n_cells and normal[0, c] == normal[0, c] and not hidden(normal, cos2, c, rows[t], cols[t], shape[1]):
                out[c] += 1.0


@numba.njit(cache=True)
def echo_direction_sums(tpl, flat, shape, readings, half_band, z_max, out):
    """Add, for every echo and every cell of its cone within ``half_band`` of its range, the doubled
    angle of the direction to the cell, (cos 2 phi, sin 2 phi), into out[0], out[1] and 1 into out[2]."""
    rows, cols, bins, z = readings
    n_cells = shape[0] * shape[1]
    ib = np.empty(int(np.max(np.diff(tpl.offsets))), dtype=np.int32)
    for t in range(z.shape[0]):
        if not z[t] < z_max:  # no echo (or NaN)
            continue
        m, r = cone_walk(tpl, flat, shape, rows[t], cols[t], bins[t], z[t] + half_band, True, ib)
        for j in range(np.searchsorted(r[:m], z[t] - half_band, side="left"), m):
            c = np.int64(ib[j])
            if c >= n_cells:
                continue
            d_r, d_c = _offset(c, rows[t], cols[t], shape[1])
            d2 = d_r * d_r + d_c * d_c
            if d2 == 0.0:
                continue
            out[0, c] += (d_r * d_r - d_c * d_c) / d2
            out[1, c] += 2.0 * d_r * d_c / d2
            out[2, c] += 1.0


@numba.njit(cache=True, inline="always")
def hidden(normal, cos2, cell, row0, col0, width):
    """True when a reading from (row0, col0) meets the surface ``cell`` beyond the specular angle."""
    n_r = normal[0, cell]
    if not n_r == n_r:  # NaN: no surface there
        return False
    d_r, d_c = _offset(cell, row0, col0, width)
    dot = d_r * n_r + d_c * normal[1, cell]
    return dot * dot < cos2 * (d_r * d_r + d_c * d_c)


@numba.njit(cache=True, nogil=True)
def shadow_ranges(tpl, flat, shape, readings, normal, cos2, model, out, span):
    """out[t] = the range of the first cell of the core of reading t's cone, before its window, that
    is ``hidden`` (out[t] untouched when none). ``model`` = (sigma, window, z_max, core_cos)."""
    sigma, window, z_max, core_cos = model
    n_bins = tpl.base_bin.shape[0]
    rows, cols, bins, z_all = readings
    n_cells = shape[0] * shape[1]
    ib = np.empty(int(np.max(np.diff(tpl.offsets))), dtype=np.int32)
    for t in range(span[0], span[1]):
        z = z_all[t]
        if not z == z:
            continue
        k = bins[t]
        m, r = cone_walk(tpl, flat, shape, rows[t], cols[t], k, z_max if not z < z_max else z - window * sigma, False, ib)
        a_c = math.cos(2.0 * math.pi * k / n_bins)
        a_r = math.sin(2.0 * math.pi * k / n_bins)
        for j in range(m):
            c = np.int64(ib[j])
            if c >= n_cells or not hidden(normal, cos2, c, rows[t], cols[t], shape[1]):
                continue
            d_r, d_c = _offset(c, rows[t], cols[t], shape[1])
            if d_c * a_c + d_r * a_r >= core_cos * math.sqrt(d_r * d_r + d_c * d_c):
                out[t] = r[j]
                break


def reading_shadows(run, normals: np.ndarray, forward, core: float) -> np.ndarray:
    """Per reading of ``run``, the range where the core of its beam met a surface beyond
    ``forward.specular_deg`` (below 90: ``plan.incidence``) before its window (+inf: none)."""
    out = np.full(run.z.shape[0], np.inf)
    grid = run.grid
    args = (run.templates.kernel_arrays, flat_offsets(run.templates, grid.width), grid.shape,
            (run.rows.astype(np.int64), run.cols.astype(np.int64), run.bins.astype(np.int64), run.z.astype(np.float64)),
            normals, math.cos(math.radians(forward.specular_deg)) ** 2,  # cos^2 of the widest angle that echoes
            (float(forward.sigma), float(forward.window), float(run.sensor.max_range),
             math.cos(0.5 * core * run.sensor.beam_width)), out)
    reading_parts(out.size, lambda _, span: shadow_ranges(*args, span))  # each reading's own: any thread count
    return out
