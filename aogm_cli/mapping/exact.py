"""The exact inverse model on a log (``inverse_model.model: exact``, or ``exact.thin``): readings in log order, cells
independent as in Elfes' map, each update from the forward model given the map so far; and the thinned map."""

from __future__ import annotations

import math

import numpy as np

from aogm_cli.core.grid import GridSpec
from aogm_cli.core.log import SensorSpec
from aogm_cli.sensor_models.cone import SPARE_MASK, ConeTemplates, flat_offsets, reading_geometry
from aogm_cli.sensor_models.exact_inverse import (
    BOUND,
    L0,
    MARGIN,
    PRIOR,
    cone_scratch,
    exact_inverse_updates,
    map_evidence_sums,
)
from aogm_cli.sensor_models.forward_model import ExpectationReadings, ForwardModelConfig, deflect
from aogm_cli.sensor_models.readings import (
    READING_PARTS,
    LaidOutReadings,
    forward_templates,
    reading_spans,
    summed_in_parts,
)


class ExactMapper:
    """``update`` with chunks of scans, then ``result``, as ``standard.StandardMapper``, on EM's cones."""

    def __init__(self, sensor: SensorSpec, grid: GridSpec, forward: ForwardModelConfig,
                 templates: ConeTemplates | None = None, prior: float = PRIOR):
        forward.validate()
        self.sensor, self.grid, self.prior = sensor, grid, prior
        self.templates = forward_templates(grid, sensor) if templates is None else templates
        self.flat = flat_offsets(self.templates, grid.width)
        self.model = forward.kernel_model(sensor.max_range)
        self.bounds = (_sigmoid(-BOUND), _sigmoid(BOUND), float(prior))
        self.scratch = cone_scratch(self.templates)
        n = grid.height * grid.width
        self._flat = np.zeros(n + SPARE_MASK + 1, dtype=np.float32)
        self.state = self._flat[:n]  # the grid's cells
        self.state[:] = -1.0

    def update(self, pose: np.ndarray, ranges: np.ndarray, cut: np.ndarray | None = None) -> None:
        """Apply scans (pose (T, 3), ranges (T, S)) in order; a finite ``cut`` is a deflected beam."""
        rows, cols, bins, valid, offset = reading_geometry(pose, self.sensor, self.grid, self.templates)
        z = np.where(valid, np.asarray(ranges, dtype=np.float64), np.nan) + offset
        z, limit = deflect(z.reshape(-1), None if cut is None else np.asarray(cut, dtype=np.float64).reshape(-1),
                           self.sensor.max_range)
        readings = ExpectationReadings(rows.reshape(-1).astype(np.int64), cols.reshape(-1).astype(np.int64),
                                       bins.reshape(-1).astype(np.int64), z, limit)
        for span in reading_spans(z.size):  # back in Python between spans, where a signal's handler runs
            exact_inverse_updates(self.templates.kernel_arrays, self.flat, self.grid.shape, readings, self._flat,
                                  self.model, self.bounds, self.scratch, span)

    def result(self) -> tuple[np.ndarray, np.ndarray]:
        """(log_odds float32 (H, W), observed bool (H, W)); unobserved cells hold the prior's log-odds."""
        p = self.state.reshape(self.grid.shape).astype(np.float64)
        observed = p >= 0.0
        p[~observed] = self.prior
        return np.log(p / (1.0 - p)).astype(np.float32), observed


def map_evidence(run: LaidOutReadings, forward: ForwardModelConfig, occupied: np.ndarray) -> np.ndarray:
    """(H, W): each cell's evidence log p(Z | occupied) - log p(Z | free) at ``occupied``, as EM scores candidates."""
    grid, templates = run.grid, run.templates
    n = grid.height * grid.width
    occupancy = np.zeros(n + SPARE_MASK + 1, dtype=np.float32)
    occupancy[:n] = np.asarray(occupied, dtype=bool).reshape(-1)
    z, limit = deflect(run.z, run.shadow, run.sensor.max_range)
    readings = ExpectationReadings(run.rows, run.cols, run.bins, z, limit)
    model, flat = forward.kernel_model(run.sensor.max_range), flat_offsets(templates, grid.width)
    scratch = [cone_scratch(templates) for _ in range(READING_PARTS)]
    total = np.zeros(n)
    summed_in_parts(z.size, total, lambda k, part, span: map_evidence_sums(
        templates.kernel_arrays, flat, grid.shape, readings, occupancy, model, scratch[k], span, part))
    return total.reshape(grid.shape)


def _sigmoid(x: float) -> float:
    return 1.0 / (1.0 + math.exp(-x))


def thinned(log_odds: np.ndarray, observed: np.ndarray, exact: tuple[np.ndarray, np.ndarray], free: float,
            margin: float = MARGIN) -> np.ndarray:
    """``log_odds`` with the cells the exact map ``exact`` holds free (``margin`` below its prior) set to ``free``."""
    exact_log_odds, exact_observed = exact
    out = log_odds.copy()
    out[observed & exact_observed & (exact_log_odds < L0 - margin)] = np.float32(free)
    return out
