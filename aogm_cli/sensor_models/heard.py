"""Which cells of a sonar's cone it hears (ALGORITHMS.md section 10): an echo's strength is Kuc and Siegel's lobe
exp(-2 phi^2 / theta0^2) over r^2, heard above the weakest echo, so a cell at range r and angle phi off the axis
is heard when r <= lobe_range * exp(-(phi / theta0)^2). ``heard_templates`` marks those template entries."""

from __future__ import annotations

import dataclasses
import functools
import math

import numpy as np

from aogm_cli.sensor_models.cone import ConeTemplates


def heard_cells(ranges: np.ndarray, bearings: np.ndarray, lobe_deg: float, lobe_range: float) -> np.ndarray:
    """Bool: the cells at ``ranges`` (m) and ``bearings`` (rad off the axis) a lobe ``lobe_deg`` wide (theta0)
    hears out to ``lobe_range`` (m) on its axis; the sensor's own cell always."""
    theta0 = math.radians(lobe_deg)
    reach = lobe_range * np.exp(-((np.asarray(bearings) / theta0) ** 2))
    return (np.asarray(ranges) <= reach) | (np.asarray(ranges) == 0.0)


def _rows_closed(heard: np.ndarray, templates: ConeTemplates) -> np.ndarray:
    """``heard`` with every template row (grid rows and grid columns alike) filled between its first and last
    heard cell: EM lists a reading's cells row by row as one run (``em_kernels.listing``)."""
    ext = templates.extent
    out = heard.copy()
    for b in range(templates.offsets.shape[0] - 1):
        s, e = int(templates.offsets[b]), int(templates.offsets[b + 1])
        dr, dc = templates.drow[s:e].astype(np.int64), templates.dcol[s:e].astype(np.int64)
        h = out[s:e]
        changed = True
        while changed:
            before = h.copy()
            for key, other in ((dr + ext, dc), (dc + ext, dr)):
                lo = np.full(2 * ext + 1, np.iinfo(np.int64).max)
                hi = np.full(2 * ext + 1, np.iinfo(np.int64).min)
                np.minimum.at(lo, key[h], other[h])
                np.maximum.at(hi, key[h], other[h])
                h |= (other >= lo[key]) & (other <= hi[key])
            changed = bool(np.any(h != before))
        out[s:e] = h
    return out


@functools.lru_cache(maxsize=8)
def heard_templates(templates: ConeTemplates, lobe_deg: float, lobe_range: float) -> ConeTemplates:
    """``templates`` with ``heard`` set for the lobe (``heard_cells``, each row one run), or ``templates`` itself
    when ``lobe_deg`` is 0 (every cell heard)."""
    if lobe_deg <= 0.0:
        return templates
    heard = _rows_closed(heard_cells(templates.ranges, templates.bearings, lobe_deg, lobe_range), templates)
    if heard.all():
        return templates
    mask = heard.astype(np.uint8)  # writable, as ``cone.NO_CELLS``: the kernels compile one type for both
    return dataclasses.replace(templates, heard=mask, lobe=(float(lobe_deg), float(lobe_range)))
