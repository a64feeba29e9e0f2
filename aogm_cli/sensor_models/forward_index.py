"""The forward model as an index (Thrun 2003): every reading's cone, in range order, as CSR arrays
(``build_forward_index``), and each reading's log-likelihood under a binary map (``log_likelihoods``): the
reference that EM's tests and the held-out scores (``evaluation.holdout``) compute with."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numba
import numpy as np

from aogm_cli.sensor_models.cone import flat_offsets, unheard
from aogm_cli.sensor_models.forward_model import (
    ExpectationReadings,
    ForwardModelConfig,
    cone_limits,
    gaussian_at,
    reading_cone_cells,
    reading_constants,
)


class ForwardArrays(NamedTuple):
    """A ``ForwardIndex`` as compiled kernels take it (``ForwardIndex.kernel_arrays``)."""

    ptr: np.ndarray  # (R+1,) int64: reading t's entries are ptr[t]:ptr[t+1]
    cell: np.ndarray  # (E,) int64 flat grid index of each entry
    g: np.ndarray  # (E,) float64 N(z_t; d, sigma^2) of each entry (0 beyond the window)
    g0: np.ndarray  # (R,) float64 G0_t
    const: np.ndarray  # (R,) float64 C_t
    w: float  # 1 - p_rand - p_max


@dataclass(frozen=True)
class ForwardIndex:
    """Readings and the cells of their (truncated) cones, in range order, as CSR arrays."""

    ptr: np.ndarray
    cell: np.ndarray
    g: np.ndarray
    g0: np.ndarray
    const: np.ndarray
    w: float
    p_hit: float

    @property
    def n_readings(self) -> int:
        return int(self.ptr.shape[0] - 1)

    @property
    def kernel_arrays(self) -> ForwardArrays:
        """The index as compiled kernels take it (``p_hit`` apart)."""
        return ForwardArrays(self.ptr, self.cell, self.g, self.g0, self.const, float(self.w))


class IndexGrid(NamedTuple):
    """``_fill_index``'s grid: its shape and the flat bool cells left out of every cone (empty: none)."""

    height: int
    width: int
    held_free: np.ndarray


class IndexBuffers(NamedTuple):
    """``_fill_index``'s outputs."""

    cell: np.ndarray  # (upper bound of the entries,) int64
    g: np.ndarray  # (same,) float64
    counts: np.ndarray  # (readings,) int64: entries of each reading
    scratch: np.ndarray  # (entries of the largest template,) int32: one cone's flat cells


@numba.njit(cache=True)
def reading_log_likelihoods(index, p_hit, occupied):
    """log p(z_t | m) for every reading of ``index`` (``ForwardArrays``): S_t under the binary map ``occupied``."""
    n = index.ptr.shape[0] - 1
    out = np.empty(n)
    q = 1.0 - p_hit
    for t in range(n):
        qk = 1.0
        s = 0.0
        for e in range(index.ptr[t], index.ptr[t + 1]):
            if occupied[index.cell[e]]:
                s += qk * p_hit * index.g[e]
                qk *= q
        out[t] = math.log(index.const[t] + index.w * (s + qk * index.g0[t]))
    return out


def log_likelihoods(index: ForwardIndex, occupied_flat: np.ndarray) -> np.ndarray:
    """log p(z_t | m) per reading of ``index`` for the flat binary map ``occupied_flat``."""
    return reading_log_likelihoods(index.kernel_arrays, index.p_hit, np.ascontiguousarray(occupied_flat, dtype=np.bool_))


@numba.njit(cache=True, _nrt=False)  # allocates nothing: as ``standard._standard_kernel``
def _fill_index(tpl, flat, grid, readings, sigma, window, out):
    """Cone cells (flat ids) and Gaussians of every reading, packed; returns the number of entries."""
    n_cells = grid.height * grid.width
    drop = grid.held_free.shape[0] > 0
    ib = out.scratch
    pos = 0
    for t in range(readings.z.shape[0]):
        z = readings.z[t]
        m, r, s0 = reading_cone_cells(tpl, flat, (grid.height, grid.width), readings, t, (z, readings.limit[t]),
                                      (sigma, window), ib)
        n = 0
        for j in range(m):
            c = np.int64(ib[j])
            if c >= n_cells or unheard(tpl, s0 + j):  # unheard cells: not in the reading's cone
                continue
            if drop and grid.held_free[c]:
                continue
            out.cell[pos + n] = c
            out.g[pos + n] = gaussian_at(z, r[j], sigma, window)
            n += 1
        out.counts[t] = n
        pos += n
    return pos


def build_forward_index(cones: tuple, grid, templates, z_max: float, config: ForwardModelConfig,
                        held_free: np.ndarray | None = None, shadow: np.ndarray | None = None) -> ForwardIndex:
    """The forward model's index for ``cones`` = (rows, cols, bins, z); NaN readings are dropped.
    ``held_free`` (flat bool) cells stay free while the index is used: a free cell adds nothing to any S_t,
    so leaving it out changes no likelihood and keeps a small cluster's index small. ``shadow`` cuts
    readings short (``cone_limits``)."""
    rows, cols, bins, z = cones
    z = np.asarray(z, dtype=np.float64).reshape(-1)
    keep = ~np.isnan(z)
    rows, cols, bins = (np.asarray(a, dtype=np.int64).reshape(-1)[keep] for a in (rows, cols, bins))
    z = z[keep]
    z, limits = cone_limits(z, z_max, config, None if shadow is None else np.asarray(shadow).reshape(-1)[keep])
    z_eff = np.where(np.isfinite(z), np.minimum(z, z_max), z_max)
    # an upper bound of each reading's entry count: template entries within its limit
    base = templates.base_bin[bins]
    upper = 0
    for b in np.unique(base):
        sel = base == b
        s, e = templates.offsets[b], templates.offsets[b + 1]
        upper += int(np.searchsorted(templates.ranges[s:e], limits[sel], side="right").sum())
    out_cell = np.empty(upper, dtype=np.int64)
    out_g = np.empty(upper, dtype=np.float64)
    counts = np.zeros(len(z), dtype=np.int64)
    scratch = np.empty(int(np.diff(templates.offsets).max()), dtype=np.int32)
    held_free = np.zeros(0, dtype=np.bool_) if held_free is None else np.ascontiguousarray(held_free, dtype=np.bool_).reshape(-1)
    n = _fill_index(templates.kernel_arrays, flat_offsets(templates, grid.width),
                    IndexGrid(grid.height, grid.width, held_free), ExpectationReadings(rows, cols, bins, z_eff, limits),
                    float(config.sigma), float(config.window), IndexBuffers(out_cell, out_g, counts, scratch))
    ptr = np.zeros(len(z) + 1, dtype=np.int64)
    np.cumsum(counts, out=ptr[1:])
    g0, const, w = reading_constants(z, z_max, config)
    return ForwardIndex(ptr, out_cell[:n], out_g[:n], g0, const, w, config.p_hit)  # views: no copy
