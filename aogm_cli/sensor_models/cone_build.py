"""How cone templates are built (the quantisation below) and kept between processes: ``build_cone_templates``
makes a grid's ``cone.ConeTemplates`` once per process, or finds them in a store (``use_store``: aogm's
keeps them on disk beside this module's numba cache, ``io.template_store``)."""

from __future__ import annotations

import functools
import math
from typing import Protocol

import numpy as np

from aogm_cli.core.errors import InputError
from aogm_cli.sensor_models.cone import TWO_PI, ConeTemplates

# Quantisation:
# * the sensor is snapped to its cell's centre (error <= res / sqrt 2); ``reading_geometry``'s axis
#   offset removes the along-beam part of that error;
# * bin k of ``n_bins`` is centred on yaw k 2 pi / n_bins; a cell is in its cone when its bearing is
#   within beam_width / 2 of the axis and its range <= reach (the sensor's own cell always);
# * ``heading_bins_for``: the worst heading error moves a point at the reach by at most a quarter cell;
# * only the first octant's bins (0..n_bins/8) are stored, 8x smaller (docs/algorithms.md); the others
#   are lattice symmetries of them (``transform``), which keep ranges and so range order.
_TOL = 1e-9  # slack of the inclusion tests, so that cells exactly on the cone's edge are kept

# (a, b, c, d) per octant of the heading: dcol = a*dc + b*dr, drow = c*dc + d*dr
_OCTANT_TRANSFORM = np.array(
    [
        (1, 0, 0, 1),  # [0, 45) deg: identity
        (0, 1, 1, 0),  # [45, 90): mirror in y = x
        (0, -1, 1, 0),  # [90, 135): quarter turn
        (-1, 0, 0, 1),  # [135, 180): mirror in the y axis
        (-1, 0, 0, -1),  # [180, 225): half turn
        (0, -1, -1, 0),  # [225, 270): mirror in y = -x
        (0, 1, -1, 0),  # [270, 315): three quarter turns
        (1, 0, 0, -1),  # [315, 360): mirror in the x axis
    ],
    dtype=np.int64,
)


def heading_bins_for(resolution: float, reach: float) -> int:
    """Number of heading bins whose worst sideways error at ``reach`` is <= resolution / 4."""
    n = math.ceil(4.0 * math.pi * reach / resolution - 1e-9)
    return max(64, 8 * math.ceil(n / 8))


def _wrap(angle: np.ndarray) -> np.ndarray:
    """Angles wrapped to [-pi, pi)."""
    return (angle + math.pi) % TWO_PI - math.pi


def build_cone_templates(
    resolution: float, beam_width: float, max_range: float, *, margin: float = 0.0, n_bins: int | None = None,
    ray: bool = False,
) -> ConeTemplates:
    """Cone templates for ranges up to ``max_range + margin`` (m); with ``ray``, a cone also holds every
    cell its axis crosses (no gap for a beam narrower than a cell). Cached, and kept in the store."""
    if not (math.isfinite(resolution) and resolution > 0):
        raise InputError(f"expected a positive resolution, got {resolution}", key="resolution")
    if not (math.isfinite(beam_width) and 0 < beam_width <= TWO_PI):
        raise InputError(f"expected a beam width in (0, 2 pi] rad, got {beam_width}", key="beam_width")
    reach = float(max_range) + float(margin)
    if not (math.isfinite(reach) and reach > 0):
        raise InputError(f"expected a positive, finite max_range + margin, got {reach}", key="max_range")
    if n_bins is None:
        n_bins = heading_bins_for(resolution, reach)
    if n_bins < 8 or n_bins % 8:
        raise InputError(f"expected a positive multiple of 8, got {n_bins}", key="n_bins")
    return _build(float(resolution), float(beam_width), reach, int(n_bins), bool(ray))


@functools.lru_cache(maxsize=4)
def _build(resolution: float, beam_width: float, reach: float, n_bins: int, ray: bool = False) -> ConeTemplates:
    args = (resolution, beam_width, reach, n_bins, ray)
    store = _STORE
    arrays = None if store is None else store.load(args, _TEMPLATE_ARRAYS)
    if arrays is None:
        arrays = _template_arrays(*args)
        if store is not None:
            store.save(args, arrays)
    for a in arrays.values():
        a.setflags(write=False)
    extent = int(max(np.abs(arrays["dcol"]).max(), np.abs(arrays["drow"]).max()))
    return ConeTemplates(resolution, beam_width, reach, n_bins, extent=extent, **arrays)


_TEMPLATE_ARRAYS = {"offsets": np.int64, "dcol": np.int32, "drow": np.int32, "ranges": np.float64,
                    "bearings": np.float64, "base_bin": np.int64, "transform": np.int64, "range_index": np.int64}


class TemplateStore(Protocol):
    """Where built templates are kept for the next process (``use_store``); this module writes no file."""

    def load(self, args: tuple, dtypes: dict) -> dict | None:
        """The arrays kept for ``_build``'s ``args``, as ``dtypes`` names them, or None."""

    def save(self, args: tuple, arrays: dict) -> None:
        """Keep the arrays built for ``args`` (or not: the store decides)."""


_STORE: TemplateStore | None = None  # None: templates are built anew in each process


def use_store(store: TemplateStore | None) -> None:
    """Keep the templates built from now on in ``store``, and look for them there first (None: none)."""
    global _STORE
    _STORE = store


def _template_arrays(resolution: float, beam_width: float, reach: float, n_bins: int, ray: bool) -> dict:
    """The arrays of ``ConeTemplates`` (``_TEMPLATE_ARRAYS``), built."""
    q = n_bins // 8
    half = 0.5 * beam_width
    ext = int(math.floor(reach / resolution + _TOL))
    # the disc of radius `reach`, with integer squared range (exact ties)
    dr, dc = np.mgrid[-ext : ext + 1, -ext : ext + 1]
    dr = dr.ravel()
    dc = dc.ravel()
    r2 = dc * dc + dr * dr
    rng = resolution * np.sqrt(r2.astype(np.float64))
    keep = rng <= reach + _TOL * resolution
    dr, dc, r2, rng = dr[keep], dc[keep], r2[keep], rng[keep]
    ang = np.arctan2(dr.astype(np.float64), dc.astype(np.float64))
    # pre-select the cells that a stored bin (axis in [0, 45] deg) can see
    lo, hi = -half - 1e-6, math.pi / 4 + half + 1e-6
    # with ``ray``, a cell up to resolution / sqrt 2 off an axis is on its ray: widen by its angle
    slack = np.arcsin(np.minimum(1.0, resolution / np.sqrt(2.0) / np.maximum(rng, 1e-12))) if ray else 0.0
    if beam_width < 1.5 * math.pi:
        near = ((ang - lo + slack) % TWO_PI <= hi - lo + 2 * slack) | (r2 == 0)
        dr, dc, r2, rng, ang = dr[near], dc[near], r2[near], rng[near], ang[near]
    offsets = np.zeros(q + 2, dtype=np.int64)
    parts_dc, parts_dr, parts_r, parts_b = [], [], [], []
    for b in range(q + 1):
        off = _wrap(ang - b * (TWO_PI / n_bins))
        off[r2 == 0] = 0.0
        sel = np.abs(off) <= half + _TOL
        if ray:  # the cells a traversal of the axis crosses
            axis = b * (TWO_PI / n_bins)
            reach_off = 0.5 * resolution * (abs(math.cos(axis)) + abs(math.sin(axis)))
            sel |= (np.abs(off) < math.pi / 2) & (rng * np.abs(np.sin(off)) <= reach_off + _TOL * resolution)
        order = np.lexsort((dc[sel], dr[sel], off[sel], r2[sel]))
        parts_dc.append(dc[sel][order])
        parts_dr.append(dr[sel][order])
        parts_r.append(rng[sel][order])
        parts_b.append(off[sel][order])
        offsets[b + 1] = offsets[b] + order.size
    k = np.arange(n_bins)
    octant = k // q
    base_bin = np.where(octant % 2 == 0, k - octant * q, (octant + 1) * q - k).astype(np.int64)
    transform = _OCTANT_TRANSFORM[octant].copy()
    dcol_all = np.concatenate(parts_dc).astype(np.int32)
    drow_all = np.concatenate(parts_dr).astype(np.int32)
    ranges_all = np.concatenate(parts_r).astype(np.float64)
    shells = np.arange(int(math.ceil(reach / resolution)) + 2) * resolution
    range_index = np.stack(
        [np.searchsorted(ranges_all[offsets[b] : offsets[b + 1]], shells, side="left") for b in range(q + 1)]
    ).astype(np.int64)
    return dict(
        offsets=offsets,
        dcol=dcol_all,
        drow=drow_all,
        ranges=ranges_all,
        bearings=np.concatenate(parts_b).astype(np.float64),
        base_bin=base_bin,
        transform=np.ascontiguousarray(transform),
        range_index=range_index,
    )
