"""Standard occupancy-grid mapping (Elfes 1989, Moravec 1988), each cell on its own in log-odds: ``standard_map``
streams a log through one compiled kernel, ``inverse_model - l0`` per cone cell, clamped; narrow beams: ``beam``."""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Iterable
from typing import NamedTuple

import numba
import numpy as np

from aogm_cli.core.grid import GridSpec
from aogm_cli.core.log import Log, SensorSpec
from aogm_cli.mapping.beam import BeamMapper
from aogm_cli.mapping.exact import ExactMapper, thinned
from aogm_cli.mapping.params import MapParams
from aogm_cli.sensor_models.cone import (
    NO_CUT,
    SPARE_MASK,
    ConeReadings,
    ConeTemplates,
    cone_flat_cells,
    flat_offsets,
    range_search,
    reading_geometry,
)
from aogm_cli.sensor_models.exact_inverse import L0, MARGIN
from aogm_cli.sensor_models.forward_model import ForwardModelConfig
from aogm_cli.sensor_models.heard import heard_templates
from aogm_cli.sensor_models.inverse_model import (
    UNOBSERVED,
    InverseModelConfig,
    angular_profile,
    float32_update,
    inverse_update,
    observed_log_odds,
    occupied_arc,
)
from aogm_cli.sensor_models.ray import is_narrow_beam
from aogm_cli.sensor_models.readings import cone_templates, echo_ranges, reading_spans


def probability_from_log_odds(log_odds, observed=None) -> np.ndarray:
    """Occupancy probability p = 1 - 1 / (1 + exp(l)) as float32; 0.5 where not ``observed``."""
    lo = np.asarray(log_odds, dtype=np.float64)
    with np.errstate(over="ignore"):
        p = 1.0 - 1.0 / (1.0 + np.exp(lo))
    if observed is not None:
        p = np.where(np.asarray(observed, dtype=bool), p, 0.5)
    return p.astype(np.float32)


class EntryTables(NamedTuple):
    """Per template entry, read-only float32: what the standard kernel reads besides the cell."""

    weights: np.ndarray  # Elfes' E_a(bearing) (clipped at 0), or 1 for the constant model
    ranges32: np.ndarray  # the entry's range (m)


class PaddedGrid(NamedTuple):
    """The standard kernel's grid: the flat padded state and the scratch of one reading."""

    state: np.ndarray  # (height * width + SPARE_MASK + 1,) float32 log-odds, -inf = unobserved
    height: int  # of the padded grid
    width: int
    idx_buf: np.ndarray  # (max entries of a template,) int32: one reading's flat cell indices
    inc_buf: np.ndarray  # (max entries of a template,) float32: ... and their increments


@functools.lru_cache(maxsize=8)
def _entry_tables(templates: ConeTemplates, model: str, beam_width: float) -> EntryTables:
    """Angular weights and ranges per template entry as read-only float32 arrays; cached."""
    if model == "elfes":
        weights = np.maximum(angular_profile(templates.bearings, beam_width), 0.0).astype(np.float32)
    else:
        weights = np.ones(templates.ranges.shape, dtype=np.float32)
    ranges32 = templates.ranges.astype(np.float32)
    weights.setflags(write=False)
    ranges32.setflags(write=False)
    return EntryTables(weights, ranges32)


# Choices: clamping after every update (OctoMap's), so that a long run of identical evidence cannot make a
# cell too confident to change back; the order is the log's, so maps are reproducible. A reading visits each
# cone cell once. Cones come from ``cone`` templates (sensor snapped to its cell's centre); the snap along the
# beam axis is corrected per reading (``cone.reading_geometry``) so that the occupied arc does not jitter
# (templates reach one cell beyond max_range). ``observed``: every cell a cone covered, blind zone included.
# Float32 in a fixed order: a map made chunk by chunk equals the one-pass map bit for bit. Narrow beams are
# rays (``beam.BeamMapper``): cone templates of an 80 m laser would be enormous, and a ray is its own model.
class StandardMapper:
    """Incremental standard mapping on one grid: ``update`` with chunks of scans, then ``result``. One float32
    state, ``UNOBSERVED`` (-inf) until a cone covers a cell (no second scattered write for "observed"),
    padded by the templates' extent so that a sensor inside the grid needs no bounds checks."""

    def __init__(self, sensor: SensorSpec, grid: GridSpec, config: InverseModelConfig, *,
                 templates: ConeTemplates | None = None):
        config.validate()
        if templates is None:
            templates = cone_templates(grid, sensor)
        if templates.resolution != grid.resolution or templates.beam_width != sensor.beam_width:
            raise ValueError("cone templates do not match the grid resolution and the sensor's beam width")
        if templates.reach < sensor.max_range:
            raise ValueError("cone templates do not reach the sensor's max_range")
        self.sensor = sensor
        self.grid = grid
        self.config = config
        self.templates = templates
        self.entries = _entry_tables(templates, config.model, float(sensor.beam_width))
        self.update_constants = inverse_update(config, sensor, templates.resolution)
        self.pad = int(templates.extent)
        self.padded_shape = (grid.height + 2 * self.pad, grid.width + 2 * self.pad)
        if self.padded_shape[0] * self.padded_shape[1] + SPARE_MASK + 1 >= 2**31:
            raise ValueError(f"grid of {grid.height} x {grid.width} cells is too large (limit 2**31 cells)")
        self.flat_offsets = flat_offsets(templates, self.padded_shape[1])
        size = int(np.diff(templates.offsets).max())
        # spare cells after the grid absorb the updates of cone cells outside it
        hp, wp = self.padded_shape
        flat = np.full(hp * wp + SPARE_MASK + 1, UNOBSERVED, dtype=np.float32)
        self._grid = PaddedGrid(flat, hp, wp, np.empty(size, dtype=np.int32), np.empty(size, dtype=np.float32))
        padded = flat[: hp * wp].reshape(hp, wp)
        self.state = padded[self.pad : self.pad + grid.height, self.pad : self.pad + grid.width]

    def update(self, pose: np.ndarray, ranges: np.ndarray, cut: np.ndarray | None = None) -> None:
        """Apply scans in order; a finite ``cut`` is a deflected beam: free space up to the cut, nothing beyond."""
        rows, cols, bins, valid, offset = reading_geometry(pose, self.sensor, self.grid, self.templates)
        z = np.where(valid, np.asarray(ranges, dtype=np.float32), np.float32(np.nan)).astype(np.float32)
        readings = ConeReadings(rows.reshape(-1) + self.pad, cols.reshape(-1) + self.pad, bins.reshape(-1),
                                z.reshape(-1), offset.reshape(-1),
                                NO_CUT if cut is None else np.asarray(cut, dtype=np.float32).reshape(-1))
        for span in reading_spans(z.size):  # back in Python between spans, where a signal's handler runs
            _standard_kernel(self._grid, readings, self.templates.kernel_arrays, self.flat_offsets, self.entries,
                             self.update_constants, span)

    def result(self) -> tuple[np.ndarray, np.ndarray]:
        """(log_odds float32 (H, W), observed bool (H, W)); unobserved cells hold the prior l0."""
        return observed_log_odds(self.state, self.config.l0)


def _mapper_for(sensor: SensorSpec, grid: GridSpec, config: InverseModelConfig, templates: ConeTemplates | None,
                narrow: bool, forward: ForwardModelConfig | None = None):
    """The mapper: ``ExactMapper`` for the exact model, else ``BeamMapper`` if ``narrow``, else ``StandardMapper``."""
    if config.model == "exact":
        return ExactMapper(sensor, grid, forward or ForwardModelConfig(), templates)
    if narrow:
        return BeamMapper(sensor, grid, config)
    return StandardMapper(sensor, grid, config, templates=templates)


def standard_map(chunks: Iterable[tuple[int, np.ndarray, np.ndarray, np.ndarray]], sensor: SensorSpec, grid: GridSpec,
                 config: InverseModelConfig, *, templates: ConeTemplates | None = None, narrow: bool | None = None,
                 cuts: np.ndarray | None = None, forward: ForwardModelConfig | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Standard log-odds map of logged scans: (log_odds float32 (H, W), observed bool (H, W)).
    ``chunks`` yields (start, time, pose (T, 3), ranges (T, S)) as logged (``LogReader.chunks()``). Cones
    take ``readings.echo_ranges``; rays the logged range, the hit being the endpoint's cell (OctoMap's
    convention: docs/algorithms.md, "Where the defaults come from"). Memory: grid, templates, one chunk.
    ``cuts`` stop deflected beams; ``forward``: the exact inverse model's forward model."""
    if narrow is None:
        narrow = is_narrow_beam(sensor, grid.resolution)
    mapper = _mapper_for(sensor, grid, config, templates, narrow, forward)
    exact = isinstance(mapper, ExactMapper)
    for start, _time, pose, ranges in chunks:
        z = np.asarray(ranges, dtype=np.float32) if narrow and not exact else echo_ranges(ranges, grid).astype(np.float32)
        if cuts is None:
            mapper.update(pose, z)
        else:
            mapper.update(pose, z, cuts[start : start + len(pose)])
    return mapper.result()


def set_up(sensor: SensorSpec, grid: GridSpec, params: MapParams) -> None:
    """One-time set-up of ``standard_log_odds`` before any clock starts: the templates (none for a narrow beam)."""
    narrow = is_narrow_beam(sensor, grid.resolution)
    templates = None if narrow else cone_templates(grid, sensor)
    standard_map([], sensor, grid, params.inverse_model, templates=templates, narrow=narrow,
                 forward=params.em.forward)


def standard_log_odds(log, grid: GridSpec, params: MapParams, cuts=None, chunk: int = 4096):
    """(log_odds, observed) of a whole log source, streamed in chunks; ``cuts`` stop deflected beams."""
    narrow = is_narrow_beam(log.sensor, grid.resolution)  # decided once, for the templates and the map
    templates = None if narrow else cone_templates(grid, log.sensor)
    if templates is not None and params.inverse_model.model == "exact":  # it hears what EM hears
        templates = heard_templates(templates, params.em.forward.lobe_deg, params.em.forward.lobe_range)
    return standard_map(log.chunks(chunk), log.sensor, grid, params.inverse_model, templates=templates,
                        narrow=narrow, cuts=cuts, forward=params.em.forward)


# log-odds of occupied evidence alone that make a cell a wall (``echo_walls``): the standard map loses walls that
# passing beams clear, grazing or unheard (docs/algorithms.md: the p_max of ``rates``, the lobe's walls)
ECHO_EVIDENCE = 2.0


def echo_walls(log, grid: GridSpec, params: MapParams, log_odds: np.ndarray, cuts=None) -> np.ndarray:
    """``log_odds`` with the cells occupied evidence alone makes walls (``ECHO_EVIDENCE``) occupied (at least 1)."""
    evidence = occupied_evidence(log, grid, params, cuts)
    return np.where(evidence >= ECHO_EVIDENCE, np.maximum(log_odds, np.float32(1.0)), log_odds)


def occupied_evidence(log, grid: GridSpec, params: MapParams, cuts=None) -> np.ndarray:
    """(H, W): the log-odds Elfes' occupied arcs alone give each cell: where echoes end, though beams cleared it."""
    inverse = dataclasses.replace(params.inverse_model, l_free=params.inverse_model.l0,
                                  model="elfes" if params.inverse_model.model == "exact" else params.inverse_model.model)
    hits, _ = standard_log_odds(log, grid, dataclasses.replace(params, inverse_model=inverse), cuts=cuts)
    return hits - np.float32(params.inverse_model.l0)


class Thinned(NamedTuple):
    """``thin_pass``: the thinned log-odds and the exact model's evidence (less its prior; 0 unreached)."""

    log_odds: np.ndarray
    evidence: np.ndarray


class ExactPass(NamedTuple):
    """The exact inverse model's map of a log (``exact_pass``), the models it was made with and the scans and
    cuts it was made of: the lobe's walls and the thinned map share one pass when all three are the same."""

    log_odds: np.ndarray
    observed: np.ndarray
    models: tuple
    source: tuple  # (the log object, its cuts)

    def made_with(self, params: MapParams, log=None, cuts=None) -> bool:
        """Made with ``params``' models (and, given, of the very ``log`` object, with equal ``cuts``)."""
        made, made_cuts = self.source
        same_cuts = made_cuts is cuts or (made_cuts is not None and cuts is not None and np.array_equal(made_cuts, cuts))
        same_scans = log is None or (made is log and same_cuts)
        return same_scans and self.models == _exact_models(params)


def _exact_models(params: MapParams) -> tuple:
    """What an exact pass depends on besides the log: the inverse model's settings and the forward model."""
    return params.inverse_model, params.em.forward


def exact_pass(log, grid: GridSpec, params: MapParams, cuts=None) -> ExactPass:
    """The exact inverse model's (log_odds, observed) of a whole log source (``standard_log_odds``)."""
    exact_params = dataclasses.replace(params, inverse_model=dataclasses.replace(params.inverse_model, model="exact"))
    return ExactPass(*standard_log_odds(log, grid, exact_params, cuts=cuts), _exact_models(params), (log, cuts))


def thin_pass(log, grid: GridSpec, params: MapParams, log_odds: np.ndarray, observed: np.ndarray,
              cuts=None, margin: float = MARGIN, exact: ExactPass | None = None) -> Thinned:
    """``log_odds`` thinned by one more pass with the exact inverse model (``exact.thinned``, at ``margin``);
    ``exact``: that pass made already (taken when made with ``params``' models, of the same scans and ``cuts``)."""
    if exact is None or not exact.made_with(params, log, cuts):
        exact = exact_pass(log, grid, params, cuts)
    evidence = np.where(exact.observed, exact.log_odds - np.float32(L0), np.float32(0.0))
    return Thinned(thinned(log_odds, observed, exact[:2], params.inverse_model.clamp_min, margin),
                   evidence)


def truth_grid_map(log: Log) -> tuple[np.ndarray, np.ndarray]:
    """(probability, observed) (H, W): the default standard map of a simulated ``log`` on its truth grid."""
    grid = log.truth.grid
    ranges = np.asarray(log.ranges, dtype=np.float32)
    log_odds, observed = standard_map([(0, log.time, log.pose, ranges)], log.sensor, grid, InverseModelConfig())
    return probability_from_log_odds(log_odds, observed), observed


# Speed (``bench/bench_standard.py`` compares with a plain compiled scatter-add): no transcendental function
# per cell (per template entry a precomputed angular weight a, range d and flat offset; the free increment is
# a (c_free - B u^2), u = d - Rmin, B = c_free / span^2 per reading; the occupied one c_occ a); region bounds
# by table-assisted binary searches (``cone.range_search``); ``_nrt=False`` (a private numba option, for
# kernels that allocate nothing): no reference counting of the named tuples' arrays per reading.
@numba.njit(cache=True, _nrt=False)
def _standard_kernel(grid, readings, tpl, flat, entries, update, span):
    """Compiled log-odds update of readings span[0] <= t < span[1] in order on ``grid.state`` (the padded
    grid plus SPARE_MASK + 1 spare cells absorbing cone cells outside it). Per reading, template entries
    [0, f0) are the blind zone (observed only), [f0, f1) free, [f1, m) occupied, each update clamped.
    Vectorised passes fill ``inc_buf`` and ``idx_buf``, then a scalar pass as lean as a scatter-add does
    the read-modify-write. Loops run over slices from 0 so that numba drops negative-index checks."""
    state = grid.state
    height = grid.height
    width = grid.width
    resolution = tpl.resolution
    ext = tpl.extent
    weights = entries.weights
    min_range = update.min_range
    max_range = update.max_range
    c_free = update.l_free_minus_l0
    c_occ, lo, hi, l0 = float32_update(update)
    zero = np.float32(0.0)
    for t in range(span[0], span[1]):
        zt = np.float64(readings.z[t])
        if not zt >= 0.0:  # NaN or negative: no information
            continue
        row0 = readings.rows[t]
        col0 = readings.cols[t]
        if row0 + ext < 0 or row0 - ext >= height or col0 + ext < 0 or col0 - ext >= width:
            continue  # the cone cannot touch the grid
        k = readings.bins[t]
        b = tpl.base_bin[k]
        s = tpl.offsets[b]
        r = tpl.ranges[s : tpl.offsets[b + 1]]
        ri = tpl.range_index[b]
        # region boundaries, in template ranges (= real ranges + the sensor's axis offset)
        shift = readings.offset[t]
        blind_end = range_search(r, ri, resolution, min_range + shift, False)
        ct = np.float64(readings.cut[t]) if readings.cut.shape[0] > 0 else np.inf
        if ct < max_range + shift:  # a deflected beam: free space only, up to where it was deflected
            f1 = range_search(r, ri, resolution, ct, False)
            m = f1
            span = ct - shift - min_range
        elif zt >= max_range:  # max-range reading: free space only, up to max_range
            f1 = range_search(r, ri, resolution, max_range + shift, True)
            m = f1
            span = max_range - min_range
        else:
            z_free, arc_end = occupied_arc(zt, update.half_alpha, max_range)
            f1 = range_search(r, ri, resolution, z_free + shift, False)
            m = range_search(r, ri, resolution, arc_end + shift, True)
            span = z_free - min_range
        f0 = min(blind_end, f1)
        # increments: free (<= 0 exactly: rounding must not make it positive), occupied (>= 0)
        fa = np.float32(c_free)
        fb = np.float32(0.0)
        if update.elfes and span > 0.0:
            fb = np.float32(max(c_free / (span * span), -1e30))
        r_min = np.float32(min_range + shift)
        w1 = weights[s + f0 : s + f1]
        r1 = entries.ranges32[s + f0 : s + f1]
        c1 = grid.inc_buf[f0:f1]
        for j in range(f1 - f0):
            u = r1[j] - r_min
            c1[j] = min(w1[j] * (fa - fb * (u * u)), zero)
        w2 = weights[s + f1 : s + m]
        c2 = grid.inc_buf[f1:m]
        for j in range(m - f1):
            c2[j] = c_occ * w2[j]
        ib = grid.idx_buf[:m]
        cone_flat_cells(ib, tpl, flat, k, m, row0, col0, height, width)
        # read-modify-write: the only loops that touch the grid
        i0 = ib[:f0]
        for j in range(f0):
            i = np.uint64(np.uint32(i0[j]))
            x = state[i]
            state[i] = l0 if x < lo else x
        i1 = ib[f0:f1]
        for j in range(f1 - f0):
            i = np.uint64(np.uint32(i1[j]))
            x = state[i]
            state[i] = max((l0 if x < lo else x) + c1[j], lo)
        i2 = ib[f1:m]
        for j in range(m - f1):
            i = np.uint64(np.uint32(i2[j]))
            x = state[i]
            state[i] = min((l0 if x < lo else x) + c2[j], hi)
