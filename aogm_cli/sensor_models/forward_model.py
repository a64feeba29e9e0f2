"""Thrun's (2003) forward sensor model: its parameters (``ForwardModelConfig``), the pieces every user
of it shares (its Gaussian ``gaussian_at``, a cone's end ``cone_entries``, the per-reading constants) and
the E-step's sums at a binary map (``expectation_sums``); ``forward_index`` holds the reference index."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import NamedTuple

import numba
import numpy as np

from aogm_cli.core.errors import InputError
from aogm_cli.sensor_models.cone import cone_flat_cells, unheard

# A reading has one cause: random, a max-range dropout, no obstacle detected, or the k-th obstacle of its
# cone (d_1 <= ... <= d_K), each detected with p_hit; q = 1 - p_hit, g(d) = N(z; d, sigma^2), G0 = g(z_max):
#     p(z | m) = C + w * S,   C = p_rand / z_max + p_max * G0,   w = 1 - p_rand - p_max,
#     S = sum_k q^(k-1) p_hit g(d_k) + q^K G0.
# g is truncated at WINDOW sigmas, and so is a cone beyond z (a max-range reading's reaches z_max):
# cells before the window change p only through the factor q, which EM scores in O(1) per reading.
WINDOW = 4.0


@dataclass(frozen=True)
class ForwardModelConfig:
    """Parameters of the forward model (the comment above; defaults: docs/algorithms.md)."""

    sigma: float = 0.03  # m: sonar noise 0.02 m and the grid's quantisation (0.05 / sqrt 12)
    p_rand: float = 0.05  # prior of a random reading
    p_hit: float = 0.7  # probability that each obstacle in the cone, nearest first, is detected
    p_max: float = 0.1  # point mass of a max-range dropout (specular reflection)
    # the largest angle off a surface's normal (``surface.py``) at which it still echoes: a beam whose core
    # meets a surface more obliquely before its window is deflected there (a grazing pass is no evidence
    # against the surface). 90: Thrun's model, no beam deflected (the angle of incidence off). 15: a 40 kHz sonar
    # on glass or gloss paint; fixed, not learned (docs/algorithms.md, "Why 15 degrees, and not learned": the
    # rate a log would learn it from does not fall on rough walls, where 90 lets random and grazing beams erase them)
    specular_deg: float = 15.0
    # the lobe that hears (``heard``): a cell at range r, phi off the axis, is heard when
    # r <= lobe_range * exp(-(phi / lobe_deg)^2); EM, the exact inverse model and calibration leave the others
    # out of its reading. 0: every cell of the cone
    lobe_deg: float = 0.0
    lobe_range: float = 10.0  # m: how far a surface met head-on on the axis is heard
    window = WINDOW  # sigmas beyond z up to which a cone's cells count: the model's own, no setting

    def validate(self) -> ForwardModelConfig:
        if not self.sigma > 0:
            raise InputError(f"expected a positive number, got {self.sigma:g}", key="sigma")
        if not 0 < self.p_rand < 1:  # > 0: every reading keeps a finite likelihood
            raise InputError(f"expected a probability in (0, 1), got {self.p_rand:g}", key="p_rand")
        if not 0 < self.p_hit <= 1:
            raise InputError(f"expected a probability in (0, 1], got {self.p_hit:g}", key="p_hit")
        if not 0 <= self.p_max < 1 or self.p_rand + self.p_max >= 1:
            raise InputError(f"expected p_max in [0, 1) with p_rand + p_max < 1, got {self.p_max:g}", key="p_max")
        if not 0 < self.specular_deg <= 90:
            raise InputError(f"expected an angle in (0, 90] degrees, got {self.specular_deg:g}", key="specular_deg")
        if not 0 <= self.lobe_deg <= 90:
            raise InputError(f"expected an angle in [0, 90] degrees (0: every cell of the cone heard), "
                             f"got {self.lobe_deg:g}", key="lobe_deg")
        if not self.lobe_range > 0:
            raise InputError(f"expected a positive range (m), got {self.lobe_range:g}", key="lobe_range")
        return self

    def as_dict(self) -> dict:
        return asdict(self)

    def kernel_model(self, z_max: float) -> tuple:
        """The compiled kernels' ``model``: (p_rand, p_max, p_hit, sigma, window, z_max)."""
        return (float(self.p_rand), float(self.p_max), float(self.p_hit), float(self.sigma), float(self.window),
                float(z_max))


class ExpectationReadings(NamedTuple):
    """Readings as the forward model's kernels take them: flat arrays, NaN readings left out."""

    rows: np.ndarray  # the sensor's cell (int64; may lie outside the grid)
    cols: np.ndarray
    bins: np.ndarray  # heading bin (int64)
    z: np.ndarray  # float64 range in template ranges; +inf (or >= z_max): a max-range reading
    limit: np.ndarray  # float64 template range beyond which the cone holds no cell (``cone_limits``; +inf: none)


def gaussian(z, d, sigma):
    """N(z; d, sigma^2) as numpy."""
    return np.exp(-0.5 * ((z - d) / sigma) ** 2) / (math.sqrt(2.0 * math.pi) * sigma)


def reading_constants(z: np.ndarray, z_max: float, config: ForwardModelConfig):
    """Per-reading (g0, const, w): G0 = N(z; z_max), C = p_rand/z_max + p_max*G0, w."""
    z_eff = np.where(np.isfinite(z), z, z_max)
    g0 = gaussian(z_eff, z_max, config.sigma)
    const = config.p_rand / z_max + config.p_max * g0
    return g0, const, 1.0 - config.p_rand - config.p_max


@numba.njit(cache=True, inline="always")
def gaussian_at(z, r, sigma, window):
    """Compiled N(z; r, sigma^2), 0 beyond ``window`` sigmas: the one formula of every kernel."""
    u = (z - r) / sigma
    if abs(u) <= window:
        return 1.0 / (math.sqrt(2.0 * math.pi) * sigma) * math.exp(-0.5 * u * u)
    return 0.0


@numba.njit(cache=True, inline="always")
def cone_reach(z, cut, z_max, sigma, window):
    """Compiled (z, limit) of a reading: z at most z_max, and the range its cone counts up to."""
    if not z < z_max:
        return z_max, min(z_max, cut)
    return z, min(min(z + window * sigma, z_max), cut)


@numba.njit(cache=True)
def cone_entries(r, z, limit, sigma, window):
    """How many of a template bin's entries a reading's cone holds: up to ``limit``, and beyond z only
    while the Gaussian is not 0 (a zero-weight cell after the window would scale its terms by q)."""
    if not limit >= 0.0:
        return 0
    m = np.searchsorted(r, limit, side="right")
    while m > 0 and r[m - 1] > z and gaussian_at(z, r[m - 1], sigma, window) == 0.0:
        m -= 1
    return m


@numba.njit(cache=True, inline="always")
def reading_cone_cells(tpl, flat, shape, readings, t, reach, gauss, ib):
    """Reading t's cone (``reach`` its (z, limit), ``gauss`` (sigma, window)) into ``ib`` (``cone_flat_cells``):
    (m, its bin's ranges, its bin's first entry); m = 0 for a cone off the grid (``cone_entries``)."""
    height, width = shape
    ext = tpl.extent
    row0 = readings.rows[t]
    col0 = readings.cols[t]
    k = readings.bins[t]
    s0 = tpl.offsets[tpl.base_bin[k]]
    r = tpl.ranges[s0 : tpl.offsets[tpl.base_bin[k] + 1]]
    if row0 + ext < 0 or row0 - ext >= height or col0 + ext < 0 or col0 - ext >= width:
        return 0, r, s0
    m = cone_entries(r, reach[0], reach[1], gauss[0], gauss[1])
    cone_flat_cells(ib, tpl, flat, k, m, row0, col0, height, width)
    return m, r, s0


def deflect(z: np.ndarray, shadow: np.ndarray | None, z_max: float) -> tuple[np.ndarray, np.ndarray]:
    """(z, limit) of readings: a deflected one becomes a max-range reading ending before the surface."""
    z = np.asarray(z, dtype=np.float64)
    if shadow is None:
        return z, np.full(z.shape, np.inf)
    cut = np.isfinite(shadow) & ~np.isnan(z)
    return np.where(cut, np.inf, z), np.where(cut, np.nextafter(np.minimum(shadow, z_max), 0.0), np.inf)


def cone_limits(z: np.ndarray, z_max: float, config: ForwardModelConfig,
                shadow: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(z, limit) of each reading as the forward model takes it (``cone_reach``, ``deflect``)."""
    z, cut = deflect(z, shadow, z_max)
    limits = np.where(np.isfinite(z), np.minimum(z + config.window * config.sigma, z_max), z_max)
    return z, np.minimum(limits, cut)


# The E-step's sufficient statistics (``expectation_sums``), slots of its output array
E_READINGS, E_LOGLIK, E_RANDOM, E_DROPOUT, E_DETECTED, E_EXAMINED, E_SQUARED, E_MISSED, E_SIZE = range(9)


@numba.njit(cache=True)
def cone_obstacles(tpl, flat, shape, readings, occupied, sigma, window, z_max, ptr, d):
    """The ranges of the occupied cells of each reading's cone at ``sigma``, reading t's at
    ``d[ptr[t]:ptr[t + 1]]``. Returns how many there are (when ``d`` holds fewer, only ``ptr`` is right)."""
    n_cells = shape[0] * shape[1]
    room = d.shape[0]
    ib = np.empty(int(np.max(np.diff(tpl.offsets))), dtype=np.int32)
    ptr[0] = 0
    for t in range(readings.z.shape[0]):
        z, limit = cone_reach(readings.z[t], readings.limit[t], z_max, sigma, window)
        n = ptr[t]
        m, r, s0 = reading_cone_cells(tpl, flat, shape, readings, t, (z, limit), (sigma, window), ib)
        for j in range(m):
            c = ib[j]
            if c < n_cells and occupied[c] and not unheard(tpl, s0 + j):  # unheard: no obstacle of the reading
                if n < room:
                    d[n] = r[j]
                n += 1
        ptr[t + 1] = n
    return ptr[readings.z.shape[0]]


@numba.njit(cache=True)
def obstacle_sums(ptr, d, readings, model, out):
    """``expectation_sums`` from the obstacles found at a sigma at least ``model``'s."""
    p_rand, p_max, p_hit, sigma, window, z_max = model
    q = 1.0 - p_hit
    w = 1.0 - p_rand - p_max
    for t in range(readings.z.shape[0]):
        z, limit = cone_reach(readings.z[t], readings.limit[t], z_max, sigma, window)
        lo = ptr[t]
        n_obs = 0
        for i in range(lo, ptr[t + 1]):
            if d[i] > limit or (d[i] > z and gaussian_at(z, d[i], sigma, window) == 0.0):
                break
            n_obs += 1
        u0 = (z - z_max) / sigma
        g0 = math.exp(-0.5 * u0 * u0) / (math.sqrt(2.0 * math.pi) * sigma)
        s = 0.0
        qk = 1.0
        for i in range(n_obs):
            s += qk * p_hit * gaussian_at(z, d[lo + i], sigma, window)
            qk *= q
        s_miss = qk * g0
        p = p_rand / z_max + p_max * g0 + w * (s + s_miss)
        out[E_READINGS] += 1.0
        out[E_LOGLIK] += math.log(p)
        out[E_RANDOM] += p_rand / z_max / p
        out[E_DROPOUT] += p_max * g0 / p
        e_miss = w * s_miss / p
        out[E_MISSED] += e_miss
        out[E_EXAMINED] += n_obs * e_miss
        qk = 1.0
        for i in range(n_obs):
            e = w * qk * p_hit * gaussian_at(z, d[lo + i], sigma, window) / p
            qk *= q
            out[E_DETECTED] += e
            out[E_EXAMINED] += (i + 1) * e
            out[E_SQUARED] += e * (z - d[lo + i]) ** 2


class Obstacles(NamedTuple):
    """``cone_obstacles``' result: per reading, its cone's obstacles, found at ``sigma``."""

    ptr: np.ndarray
    d: np.ndarray
    sigma: float


def find_obstacles(tpl, flat, shape, readings, occupied, sigma: float, window: float, z_max: float) -> Obstacles:
    """``cone_obstacles`` of ``readings`` at ``sigma`` (two walks when d's first size is short)."""
    ptr = np.zeros(readings.z.shape[0] + 1, dtype=np.int64)
    d = np.empty(16 * readings.z.shape[0] + 1)
    n = cone_obstacles(tpl, flat, shape, readings, occupied, sigma, window, z_max, ptr, d)
    if n > d.shape[0]:
        d = np.empty(n)
        cone_obstacles(tpl, flat, shape, readings, occupied, sigma, window, z_max, ptr, d)
    return Obstacles(ptr, d, float(sigma))


def expectation_sums(tpl, flat, shape, readings, occupied, model, out, obstacles: Obstacles | None = None) -> Obstacles:
    """The expectations of every reading's cause under the flat binary map ``occupied``, summed:
    the causes' posteriors are e_rand = (p_rand / z_max) / p, e_dropout = p_max G0 / p, e_k = w
    q^(k-1) p_hit g(d_k) / p and e_0 = w q^K G0 / p; ``out`` gets their sums (the E_* slots).
    ``obstacles`` found at a sigma at least ``model``'s are reused; returns those used."""
    sigma, window, z_max = model[3], model[4], model[5]
    if obstacles is None or obstacles.sigma < sigma:
        obstacles = find_obstacles(tpl, flat, shape, readings, occupied, sigma, window, z_max)
    obstacle_sums(obstacles.ptr, obstacles.d, readings, model, out)
    return obstacles
