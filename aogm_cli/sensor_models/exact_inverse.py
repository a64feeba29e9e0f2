"""The exact inverse sensor model of Thrun's forward model (Kaufman et al. 2016, for cones): each
cell's posterior given one reading and the map so far, cells independent, in time linear in the
cone's cells (``cone_log_ratios``), and the sequential log-odds update of a log's readings with it.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numba
import numpy as np

from aogm_cli.core.errors import InputError
from aogm_cli.sensor_models.cone import cone_flat_cells
from aogm_cli.sensor_models.forward_model import cone_entries, cone_reach, gaussian_at

BOUND = 7.0  # the exact model's log-odds stay within +-BOUND (the standard map's clamps starve it)
MARGIN = 0.5  # log-odds below the prior at which the thinning frees a cell


@dataclass(frozen=True)
class ExactModelConfig:
    """The exact inverse model's own settings (section ``exact:``): where it starts, how far it
    may go, and whether it thins the standard map.

    Measured on the 13 bundled worlds without a Pioneer (seed 1, standard mode; the exact map
    alone, and the Elfes map thinned by it): from a prior of 0.5 the exact map learns nothing
    (a beam's chance to reach a cell is the product of 1 - p_hit P over the cone's cells before
    it: 0.65 per cell at 0.5, so the far cells of a cone stay unknown; Brier 0.25, block 1.0);
    a prior of 0.1 (log-odds -2.2) and bounds of +-7 let it work. Alone it has thin walls with
    holes (accuracy 0.84-0.96 against Elfes' 0.76-0.89, block 0.002-0.06 against 0.13-0.42,
    but leak 0.06-0.48): each reading that passes a wall cell counts against it, and a wall
    already believed explains the next echo, which then adds little (explaining away).
    """

    prior: float = 0.1  # the occupancy each cell starts at
    # thin: the standard map's cells that the exact model holds free, more than MARGIN (log-odds)
    # below its prior, are set free (to inverse_model.clamp_min): the thickness of walls towards the
    # robot, the arcs that smear a doorway, go; walls stay where Elfes' model keeps them
    thin: bool = False

    def validate(self) -> ExactModelConfig:
        """Return self, or raise ``InputError(key=<field>)`` for an impossible value (the fields'
        types are checked where the parameters are read: ``mapping.params.check_field_types``)."""
        if not 0 < self.prior < 1:
            raise InputError(f"expected a probability in (0, 1), got {self.prior:g}", key="prior")
        if not BOUND > abs(self.l0):
            raise InputError(f"expected a prior whose log-odds lie within +-{BOUND:g}, got {self.prior:g}", key="prior")
        return self

    @property
    def l0(self) -> float:
        """The prior as log-odds."""
        return math.log(self.prior / (1.0 - self.prior))

    def as_dict(self) -> dict:
        return asdict(self)


# Under the forward model (the comment above ``forward_model.ForwardModelConfig``) a reading z whose
# cone holds cells 1..n in range order, each occupied with probability P_i independently, has
#
#     p(z | m_j = x) = C + w S_j(x),   a_i = 1 - p_hit P_i (the expectation of q^[m_i]),
#     S_j(1) = U_j + A_j (p_hit g_j + q R_j),   S_j(0) = U_j + A_j R_j,
#     A_j = prod_{i<j} a_i,   U_j = sum_{i<j} P_i p_hit g_i A_i,
#     R_j = sum_{i>j} P_i p_hit g_i prod_{j<l<i} a_l + G0 prod_{l>j} a_l,
#
# one pass forward (A, U) and one backward (R). The reading multiplies cell j's odds by
# p(z | m_j = 1) / p(z | m_j = 0): below 1 before the echo (the more so the likelier the beam got
# that far), above at it, near 1 behind a likely obstacle, which the beam did not reach. No division
# by a_j: a cell believed occupied (a_j -> 1 - p_hit) costs nothing extra; and the map is kept as
# probabilities, so that a cell's update is a few multiplications (no exp or log per cell).


@numba.njit(cache=True)
def cone_ratios(p, g, g0, p_hit, const, w, n, a, u, r, out):
    """out[j] = p(z | m_j = 1) / p(z | m_j = 0) for the first ``n`` cells of one cone: ``p``
    their occupancy, ``g`` their Gaussians N(z; d_j, sigma^2), ``g0`` G0 = N(z; z_max), ``const``
    C and ``w`` of the reading (see the comment above). ``a``, ``u``, ``r`` are scratch of at
    least ``n`` entries."""
    q = 1.0 - p_hit
    prod = 1.0
    acc = 0.0
    for j in range(n):
        u[j] = acc
        a[j] = prod  # A_j
        acc += p[j] * p_hit * g[j] * prod
        prod *= 1.0 - p_hit * p[j]
    tail = g0
    for j in range(n - 1, -1, -1):
        r[j] = tail
        tail = p[j] * p_hit * g[j] + (1.0 - p_hit * p[j]) * tail
    for j in range(n):
        s1 = u[j] + a[j] * (p_hit * g[j] + q * r[j])
        s0 = u[j] + a[j] * r[j]
        out[j] = (const + w * s1) / (const + w * s0)


# _nrt=False (as the standard kernel): nothing is allocated per reading; the scratch comes in
@numba.njit(cache=True, _nrt=False)
def exact_inverse_updates(tpl, flat, shape, readings, state, model, bounds, scratch, span):
    """Apply readings t = span[0] .. span[1] - 1 in order to the flat float32 occupancy ``state``
    (negative: not yet observed, taken as ``bounds[2]``, the prior): each cell of the reading's
    cone has its odds multiplied by its ``cone_ratios`` under the map as it stands, its
    probability then clamped to [bounds[0], bounds[1]].

    ``tpl``, ``flat``: the forward templates and their ``cone.FlatOffsets`` for the grid's width;
    ``shape`` (height, width) of the grid ``state`` covers (plus the spare cells ``cone_flat_cells``
    sends outside cells to); ``readings`` is ``forward_model.ExpectationReadings`` (template
    ranges; +inf a max-range reading; ``limit`` cuts a deflected beam); ``model`` (p_rand, p_max,
    p_hit, sigma, window, z_max); ``scratch`` (``cone_scratch``): (int32 (longest template,),
    float64 (7, same): p, g, a, u, r, out and the cells' flat ids)."""
    p_rand, p_max, p_hit, sigma, window, z_max = model
    p_min, p_max_clamp, prior = bounds
    height, width = shape
    n_cells = height * width
    ext = tpl.extent
    ranges = tpl.ranges
    w = 1.0 - p_rand - p_max
    ib = scratch[0]
    fl = scratch[1]
    p = fl[0]
    g = fl[1]
    a = fl[2]
    u = fl[3]
    r = fl[4]
    out = fl[5]
    where = fl[6]
    for t in range(span[0], span[1]):  # in order: each reading sees the map the earlier ones left
        z = readings.z[t]
        if not z == z:  # NaN: no reading
            continue
        row0 = readings.rows[t]
        col0 = readings.cols[t]
        if row0 + ext < 0 or row0 - ext >= height or col0 + ext < 0 or col0 - ext >= width:
            continue
        z, limit = cone_reach(z, readings.limit[t], z_max, sigma, window)
        k = readings.bins[t]
        b = tpl.base_bin[k]
        rk = ranges[tpl.offsets[b] : tpl.offsets[b + 1]]
        m = cone_entries(rk, z, limit, sigma, window)
        cone_flat_cells(ib, tpl, flat, k, m, row0, col0, height, width)
        n = 0
        for j in range(m):
            c = ib[j]
            if c >= n_cells:  # outside the grid: no cell, no term
                continue
            v = state[c]
            p[n] = prior if v < 0.0 else v
            g[n] = gaussian_at(z, rk[j], sigma, window)
            where[n] = c
            n += 1
        u0 = (z - z_max) / sigma
        g0 = math.exp(-0.5 * u0 * u0) / (math.sqrt(2.0 * math.pi) * sigma)
        const = p_rand / z_max + p_max * g0
        cone_ratios(p, g, g0, p_hit, const, w, n, a, u, r, out)
        for j in range(n):
            c = np.int64(where[j])
            odds = p[j] * out[j]
            state[c] = min(max(odds / (odds + 1.0 - p[j]), p_min), p_max_clamp)


def cone_scratch(templates) -> tuple[np.ndarray, np.ndarray]:
    """``exact_inverse_updates``' scratch for ``templates`` (their longest cone)."""
    size = int(np.diff(templates.offsets).max())
    return np.empty(size, dtype=np.int32), np.empty((7, size))
