"""The surfaces a sonar's readings meet: each wall cell's normal, from the directions it echoed in
(``surface_normals``), the angle of incidence beyond which they stop echoing (``incidence_counts``),
and where a reading's beam met one at a grazing angle and was deflected (``reading_shadows``)."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numba
import numpy as np

from aogm_cli.core.errors import InputError
from aogm_cli.sensor_models.cone import cone_flat_cells, flat_offsets
from aogm_cli.sensor_models.readings import reading_parts, summed_in_parts

# What makes a cell a surface with a direction (``surface_normals``): heard by at least MIN_ECHOES
# readings whose directions (as axes) have a doubled-angle mean resultant length of at least
# MIN_COHERENCE (directions spread evenly over +-30 deg give 0.83, +-45 deg 0.64, +-60 deg 0.41; a
# corner heard from all around 0), and passed by at most MAX_PASS_SHARE of the readings that meet it
# head-on (within HEAD_ON_DEG of its normal), which a surface there would have echoed: a doorway,
# which the echoes of the wall beside it smear over, is passed head-on; a wall is not.
MIN_ECHOES = 2
MIN_COHERENCE = 0.5
MAX_PASS_SHARE = 0.5
HEAD_ON_DEG = 20.0


@dataclass(frozen=True)
class SurfaceConfig:
    """Whether the angle of incidence plays a part (sonar logs only): which cells are surfaces with
    a direction, from the directions they echoed in. A smooth surface echoes only near its normal,
    so the directions from which a cell was heard (each echo's arc, within one cell of its range)
    gather around its normal (``MIN_ECHOES``, ``MIN_COHERENCE``, ``MAX_PASS_SHARE``). Corners,
    pillars and clutter, heard from every side, keep Thrun's model (visible at any angle). A beam
    is deflected where the ``core`` of its cone (this share of its opening about the axis) meets a
    surface at a grazing angle: a cone whose edge clips a door frame mostly passes the door
    (docs/algorithms.md, "The angle of incidence", measures the share)."""

    enabled: bool = True
    core: float = 0.1

    def validate(self) -> SurfaceConfig:
        """Return self, or raise ``InputError(key=<field>)`` for an impossible value (the fields'
        types are checked where the parameters are read: ``mapping.params.check_field_types``)."""
        if not 0 <= self.core <= 1:
            raise InputError(f"expected a number in [0, 1], got {self.core!r}", key="core")
        return self

    def as_dict(self) -> dict:
        return asdict(self)


def surface_normals(tpl, flat, shape: tuple[int, int], cones: tuple, z_max: float, resolution: float,
                    config: SurfaceConfig, believed: np.ndarray | None = None) -> np.ndarray:
    """(2, H * W) float32: the unit normal (d row, d col) of each surface the readings ``cones`` =
    (sensor rows, cols, heading bins, template ranges; NaN invalid, >= z_max no echo) echoed from,
    NaN elsewhere, on a grid of ``shape``: ``tpl`` and ``flat`` are the cone templates' kernel
    arrays and flat offsets. With ``believed`` (bool, the grid's shape), only the cells it marks
    (a map's occupied cells) can be surfaces."""
    rows, cols, bins, z = (np.ascontiguousarray(a).reshape(-1) for a in cones)
    readings = (rows.astype(np.int64), cols.astype(np.int64), bins.astype(np.int64), z.astype(np.float64))
    # float32 sums and normals (12 + 8 bytes a cell at their largest; sums of whole counts and of
    # unit doubled-angle terms, exact enough for a threshold on their ratio)
    sums = np.zeros((3, shape[0] * shape[1]), dtype=np.float32)
    echo_direction_sums(tpl, flat, shape, readings, float(resolution), float(z_max), sums)
    count = sums[2]
    surface = count >= MIN_ECHOES
    if believed is not None:
        surface &= np.asarray(believed, dtype=bool).reshape(-1)
    cells = np.flatnonzero(surface)
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
    """The cells of heading bin k's cone from (row0, col0) up to template range ``end`` (``right``:
    ranges <= end, else < end) into ``ib`` (``cone.cone_flat_cells``): (their count, the bin's
    ranges); none when the cone cannot touch the grid or ``end`` <= 0."""
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
    """out[c] += 1 for every reading span[0] <= t < span[1] of ``readings`` = (rows, cols, bins, z)
    whose cone holds the surface cell c (``normal`` not NaN) more than ``margin`` before its range
    (every cell of a reading without echo), met within the angle whose cos^2 is ``cos2`` of its
    normal."""
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
    """Add, for every echo (z < z_max) of ``readings`` = (rows, cols, bins, z) and every cell of
    its cone within ``half_band`` of its range, the doubled angle of the direction from the sensor
    to the cell, (cos 2 phi, sin 2 phi) in (row, col) axes, into out[0], out[1] and 1 into out[2]
    (``out`` (3, H * W))."""
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


def cos2_of(specular_deg: float) -> float:
    """cos^2 of the largest incidence angle that still echoes (0 at 90 deg: nothing hidden)."""
    if specular_deg >= 90.0:
        return 0.0
    return math.cos(math.radians(specular_deg)) ** 2


@numba.njit(cache=True, inline="always")
def hidden(normal, cos2, cell, row0, col0, width):
    """True when the flat ``cell`` is a surface cell that a reading from sensor cell (row0, col0)
    meets at more than the specular angle from its normal (cos^2 of that angle: ``cos2``): a
    grazing pass, which returns no echo; the beam is deflected there (``shadow_ranges``)."""
    n_r = normal[0, cell]
    if not n_r == n_r:  # NaN: no surface there
        return False
    d_r, d_c = _offset(cell, row0, col0, width)
    dot = d_r * n_r + d_c * normal[1, cell]
    return dot * dot < cos2 * (d_r * d_r + d_c * d_c)


INCIDENCE_BINS = 9  # of 10 degrees, 0-90: ``incidence_counts``


@numba.njit(cache=True, nogil=True)
def incidence_kernel(tpl, flat, shape, readings, occupied, normal, model, out, span):
    """``incidence_counts`` of the readings span[0] <= t < span[1]."""
    sigma, window, z_max, margin = model
    rows, cols, bins, z_all = readings
    n_cells = shape[0] * shape[1]
    ib = np.empty(int(np.max(np.diff(tpl.offsets))), dtype=np.int32)
    passed = np.zeros(INCIDENCE_BINS, dtype=np.bool_)
    for t in range(span[0], span[1]):
        z = z_all[t]
        if not z == z:  # NaN
            continue
        at_max = not z < z_max
        m, r = cone_walk(tpl, flat, shape, rows[t], cols[t], bins[t], z_max if at_max else min(z + window * sigma, z_max),
                         True, ib)
        passed[:] = False
        for j in range(m):
            c = np.int64(ib[j])
            if c >= n_cells or not occupied[c]:
                continue
            in_window = not at_max and abs(r[j] - z) <= window * sigma
            d_r, d_c = _offset(c, rows[t], cols[t], shape[1])
            d2 = d_r * d_r + d_c * d_c
            if normal[0, c] == normal[0, c] and d2 > 0.0:
                cos_i = min(abs(d_r * normal[0, c] + d_c * normal[1, c]) / math.sqrt(d2), 1.0)
                a = min(int(math.degrees(math.acos(cos_i)) / 10.0), INCIDENCE_BINS - 1)
                if in_window:
                    out[0, a] += 1.0
                elif not passed[a] and (at_max or r[j] < z - margin):
                    passed[a] = True
                    out[1, a] += 1.0
            if in_window:
                break


def incidence_counts(tpl, flat, shape, readings, occupied, normal, model, out):
    """How often the readings echoed from, and passed, the occupied surface cells of the flat map
    ``occupied`` (normals ``normal``), by angle of incidence: ``out`` (2, INCIDENCE_BINS) gets, per
    10-degree bin, in row 0 the readings whose first occupied cell inside the Gaussian window (the
    echo) is a surface met at that angle, and in row 1 the readings that passed an occupied surface
    cell met at that angle at least ``margin`` before its range (once per reading and bin; a
    reading without echo passes every one in its cone).

    ``readings`` = (rows, cols, bins, z) (template ranges; >= z_max: no echo), ``model`` =
    (sigma, window, z_max, margin)."""
    summed_in_parts(readings[3].shape[0], out,
                    lambda _, part, span: incidence_kernel(tpl, flat, shape, readings, occupied, normal, model, part, span))


def specular_angle(counts: np.ndarray, fraction: float = 0.5, min_readings: int = 30) -> float:
    """The incidence angle (degrees) beyond which surfaces stop echoing, from ``incidence_counts``:
    where the echo rate echoes / (echoes + passes) first falls below ``fraction`` of its largest
    value within 30 degrees of the normal (linear between the bins' centres), 90 when it never
    does. Bins with fewer than ``min_readings`` readings are skipped; without any within 30
    degrees, 90."""
    total = counts[0] + counts[1]
    ok = total >= min_readings
    with np.errstate(invalid="ignore", divide="ignore"):
        rate = np.where(ok, counts[0] / total, np.nan)
    if not ok[:3].any():
        return 90.0
    half = fraction * np.nanmax(rate[:3])
    centres = 10.0 * np.arange(INCIDENCE_BINS) + 5.0
    prev = None
    for a in np.flatnonzero(ok):
        if rate[a] < half:
            if prev is None:
                return float(centres[a])
            x0, y0, x1, y1 = centres[prev], rate[prev], centres[a], rate[a]
            return float(x0 + (y0 - half) * (x1 - x0) / (y0 - y1))
        prev = a
    return 90.0


@numba.njit(cache=True, nogil=True)
def shadow_ranges(tpl, flat, shape, readings, normal, cos2, model, out, span):
    """out[t], span[0] <= t < span[1], = the template range of the first cell of the core of reading
    t's cone (within the angle whose cosine is ``core_cos`` of its axis), before its Gaussian window, that is a surface
    met beyond the specular angle (``hidden``; out[t] untouched when there is none). ``readings``
    = (rows, cols, bins, z) (template ranges; >= z_max: no echo), ``model`` = (sigma, window,
    z_max, core_cos)."""
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


def reading_shadows(run, normals: np.ndarray, forward, core: float = 1.0) -> np.ndarray | None:
    """Per reading of ``run`` (a ``readings.LaidOutReadings``), the template range where the core
    of its beam (the share ``core`` of its opening about the axis) met one of the surfaces
    ``normals`` (``surface_normals``) beyond ``forward.specular_deg`` before its window (+inf:
    none): the beam was deflected there (``forward_model.deflect``). None when the angle is 90
    degrees."""
    if forward.specular_deg >= 90.0:
        return None
    out = np.full(run.z.shape[0], np.inf)
    grid = run.grid
    args = (run.templates.kernel_arrays, flat_offsets(run.templates, grid.width), grid.shape,
            (run.rows.astype(np.int64), run.cols.astype(np.int64), run.bins.astype(np.int64), run.z.astype(np.float64)),
            normals, cos2_of(forward.specular_deg),
            (float(forward.sigma), float(forward.window), float(run.sensor.max_range),
             math.cos(0.5 * core * run.sensor.beam_width)), out)
    reading_parts(out.size, lambda _, span: shadow_ranges(*args, span))  # each reading's own: any thread count
    return out
