"""The surfaces a sonar's readings meet: each wall cell's normal, from the directions it echoed in
(``surface_normals``), and the angle-of-incidence test of the forward model (``hidden``): a reading
that passes a surface at a grazing angle is no evidence against it (no echo comes back)."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import NamedTuple

import numba
import numpy as np

from aogm_cli.core.errors import InputError
from aogm_cli.sensor_models.cone import cone_flat_cells

SEGMENT_BITS = 32  # columns per word of ``Surfaces.bits`` (EM's tiles are this wide)


@dataclass(frozen=True)
class SurfaceConfig:
    """Which cells are surfaces with a direction, from the directions they echoed in (sonar logs only).

    A smooth surface echoes only near its normal, so the directions from which a cell was heard
    (each echo's arc, within one cell of its range) gather around its normal: a cell heard by at
    least ``min_echoes`` readings whose directions (as axes: the two sides of a wall alike) have a
    mean resultant length of at least ``min_coherence`` is a surface with that mean direction as
    its normal. Corners, pillars and clutter, heard from every side, keep Thrun's model (visible
    at any angle)."""

    enabled: bool = True
    min_echoes: int = 2
    # the doubled-angle resultant length: directions spread evenly over +-30 deg give 0.83, +-45
    # deg 0.64, +-60 deg 0.41; a corner heard from all around 0
    min_coherence: float = 0.5

    def validate(self) -> SurfaceConfig:
        if not isinstance(self.enabled, bool):
            raise InputError(f"expected true or false, got {self.enabled!r}", key="enabled")
        if isinstance(self.min_echoes, bool) or not isinstance(self.min_echoes, int) or self.min_echoes < 1:
            raise InputError(f"expected a whole number >= 1, got {self.min_echoes!r}", key="min_echoes")
        v = self.min_coherence
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not 0 <= v <= 1:
            raise InputError(f"expected a number in [0, 1], got {v!r}", key="min_coherence")
        return self

    def as_dict(self) -> dict:
        return asdict(self)


class Surfaces(NamedTuple):
    """Each grid cell's surface normal, as kernels take it."""

    normal: np.ndarray  # (2, H * W) float64 unit normal (d row, d col) of each surface cell; NaN elsewhere
    bits: np.ndarray  # (H, ceil(W / SEGMENT_BITS)) int64: bit k of word s set when column s * 32 + k is a surface cell


def no_surfaces(shape: tuple[int, int]) -> Surfaces:
    """No surface anywhere: every cell visible at any angle (lasers, or the model turned off)."""
    return Surfaces(np.zeros((2, 0)), np.zeros((shape[0], -(-shape[1] // SEGMENT_BITS)), dtype=np.int64))


def surface_normals(tpl, flat, shape: tuple[int, int], cones: tuple, z_max: float, resolution: float,
                    config: SurfaceConfig) -> Surfaces:
    """The ``Surfaces`` that the readings ``cones`` = (sensor rows, cols, heading bins, template
    ranges; NaN invalid, >= z_max no echo) echoed from, on a grid of ``shape``: ``tpl`` and
    ``flat`` are the cone templates' kernel arrays and flat offsets."""
    if not config.enabled:
        return no_surfaces(shape)
    rows, cols, bins, z = (np.ascontiguousarray(a).reshape(-1) for a in cones)
    sums = np.zeros((3, shape[0] * shape[1]))
    echo_direction_sums(tpl, flat, shape, (rows.astype(np.int64), cols.astype(np.int64), bins.astype(np.int64),
                                           z.astype(np.float64)), float(resolution), float(z_max), sums)
    count = sums[2]
    with np.errstate(invalid="ignore", divide="ignore"):
        coherence = np.hypot(sums[0], sums[1]) / count
    surface = (count >= config.min_echoes) & (coherence >= config.min_coherence)
    angle = 0.5 * np.arctan2(sums[1, surface], sums[0, surface])  # the mean axis, from the doubled angles
    normal = np.full((2, count.size), np.nan)
    normal[0, surface] = np.cos(angle)
    normal[1, surface] = np.sin(angle)
    return Surfaces(normal, surface_bits(surface.reshape(shape)))


@numba.njit(cache=True)
def echo_direction_sums(tpl, flat, shape, readings, half_band, z_max, out):
    """Add, for every echo (z < z_max) of ``readings`` = (rows, cols, bins, z) and every cell of
    its cone within ``half_band`` of its range, the doubled angle of the direction from the sensor
    to the cell, (cos 2 phi, sin 2 phi) in (row, col) axes, into out[0], out[1] and 1 into out[2]
    (``out`` (3, H * W))."""
    height, width = shape
    rows, cols, bins, z = readings
    n_cells = height * width
    ext = tpl.extent
    ib = np.empty(int(np.max(np.diff(tpl.offsets))), dtype=np.int32)
    for t in range(z.shape[0]):
        if not z[t] < z_max:  # no echo (or NaN)
            continue
        row0, col0 = rows[t], cols[t]
        if row0 + ext < 0 or row0 - ext >= height or col0 + ext < 0 or col0 - ext >= width:
            continue
        k = bins[t]
        b = tpl.base_bin[k]
        r = tpl.ranges[tpl.offsets[b] : tpl.offsets[b + 1]]
        lo = np.searchsorted(r, z[t] - half_band, side="left")
        m = np.searchsorted(r, z[t] + half_band, side="right")
        cone_flat_cells(ib, tpl, flat, k, m, row0, col0, height, width)
        for j in range(lo, m):
            c = np.int64(ib[j])
            if c >= n_cells:
                continue
            row = c // width
            d_r = float(row - row0)
            d_c = float(c - row * width - col0)
            d2 = d_r * d_r + d_c * d_c
            if d2 == 0.0:
                continue
            out[0, c] += (d_r * d_r - d_c * d_c) / d2
            out[1, c] += 2.0 * d_r * d_c / d2
            out[2, c] += 1.0


def surface_bits(surface: np.ndarray) -> np.ndarray:
    """(H, ceil(W / 32)) int64 words: bit k of word s is column s * 32 + k of ``surface`` (H, W)."""
    height, width = surface.shape
    n_seg = -(-width // SEGMENT_BITS)
    padded = np.zeros((height, n_seg * SEGMENT_BITS), dtype=np.int64)
    padded[:, :width] = surface
    weights = np.int64(1) << np.arange(SEGMENT_BITS, dtype=np.int64)
    return (padded.reshape(height, n_seg, SEGMENT_BITS) * weights).sum(axis=2).astype(np.int64)


def cos2_of(specular_deg: float) -> float:
    """cos^2 of the largest incidence angle that still echoes (0 at 90 deg: nothing hidden)."""
    if specular_deg >= 90.0:
        return 0.0
    return math.cos(math.radians(specular_deg)) ** 2


@numba.njit(cache=True, inline="always")
def hidden(normal, cos2, cell, row0, col0, width):
    """True when the flat ``cell`` is a surface cell that a reading from sensor cell (row0, col0)
    meets at more than the specular angle from its normal (cos^2 of that angle: ``cos2``): a
    grazing pass, which returns no echo, so the reading says nothing of the cell before its echo."""
    if normal.shape[1] == 0:
        return False
    n_r = normal[0, cell]
    if not n_r == n_r:  # NaN: no surface there
        return False
    row = cell // width
    d_r = float(row - row0)
    d_c = float(cell - row * width - col0)
    dot = d_r * n_r + d_c * normal[1, cell]
    return dot * dot < cos2 * (d_r * d_r + d_c * d_c)
