"""The exact inverse sensor model of Thrun's forward model (Kaufman et al. 2016, for cones): each
cell's posterior given one reading and the map so far, cells independent, in time linear in the
cone's cells (``cone_terms``), and the sequential log-odds update of a log's readings with it."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numba
import numpy as np

from aogm_cli.sensor_models.cone import range_search
from aogm_cli.sensor_models.forward_model import cone_reach, gaussian_at, reading_cone_cells

BOUND = 7.0  # the exact model's log-odds stay within +-BOUND (the standard map's clamps starve it)
MARGIN = 0.5  # log-odds below the prior at which the thinning frees a cell
# ``map_evidence_sums`` skips a reading whose ratios lie within this of 1 (a million such readings
# add < 0.001 to a cell's evidence, against HIDDEN_GAIN's 0.05)
NEGLIGIBLE = 1e-9
# the occupancy each cell starts at: from a prior of 0.5 the exact map learns nothing (a beam's chance to reach a
# cell is the product of 1 - p_hit P before it), hence 0.1 (docs/algorithms.md, "The exact inverse model")
PRIOR = 0.1
L0 = math.log(PRIOR / (1.0 - PRIOR))  # the prior as log-odds


@dataclass(frozen=True)
class ExactModelConfig:
    """The exact inverse model's own setting (section ``exact:``; its prior is ``PRIOR``)."""

    # thin: the standard map's cells that the exact model holds MARGIN below its prior are set free
    # (clamp_min): wall thickness towards the robot and arcs across doorways go
    thin: bool = False

    def validate(self) -> ExactModelConfig:
        """Return self (``thin``'s type is checked with every section's)."""
        return self

    def as_dict(self) -> dict:
        return asdict(self)


# Under the forward model, a cone of cells 1..n (range order) each occupied with probability P_i has
#     p(z | m_j = x) = C + w S_j(x),   a_i = 1 - p_hit P_i (the expectation of q^[m_i]),
#     S_j(1) = U_j + A_j (p_hit g_j + q R_j),   S_j(0) = U_j + A_j R_j,
#     A_j = prod_{i<j} a_i,   U_j = sum_{i<j} P_i p_hit g_i A_i,
#     R_j = sum_{i>j} P_i p_hit g_i prod_{j<l<i} a_l + G0 prod_{l>j} a_l,
# one pass forward (A, U), one backward (R); cell j's odds are multiplied by p(z | m_j = 1) / p(z | m_j = 0).
# No division by a_j; the map is kept as probabilities (no exp or log per cell).
# Speed (measures and rounding tests: docs/algorithms.md, "The exact inverse model"):
# * before the Gaussian window (g = 0) U_j = 0 and A_j R_j = P R_w / a_j (P the product of the a_i
#   there, R_w the backward sum at the window): the ratio is (C a_j + w q P R_w) / (C a_j + w P R_w);
# * ratios leave ``cone_terms`` as numerator and denominator: one division per cell, vectorised (no
#   denominator is 0: C > 0, a_j >= q > 0);
# * a reading whose every w S_j is below half an ulp of C has every ratio exactly 1 and is passed over
#   (``cone_terms``' ``floor``), bounding S_j <= P R / q before the window and P (n_window + 2) g_max
#   within it (g_max the largest of G0 and the window's g).


@numba.njit(cache=True, error_model="numpy", inline="always")
def cone_terms(p, g, j0, g0, p_hit, const, w, n, a, u, r, na, out):
    """The ratios p(z | m_j = 1) / p(z | m_j = 0) of the first ``n`` cells of one cone, numerators
    in out[j], denominators in na[j] (``g``'s first ``j0``, before the window, not read; ``a``, ``u``,
    ``r`` scratch). Returns False, ``out`` unset, when every ratio is exactly 1."""
    q = 1.0 - p_hit
    for j in range(n):
        na[j] = 1.0 - p_hit * p[j]
    # backward through the window, and the bound of every S_j per unit of the forward product
    tail = g0
    top = g0
    for k in range(n - j0):  # j unsigned, here and in the window's loops below: no test for a
        j = np.uint64(n - 1 - k)  # negative index per cell, and the loops vectorise where they can
        r[j] = tail
        tail = p[j] * p_hit * g[j] + na[j] * tail
        top = max(top, g[j])
    floor = const * 2.0**-56 / (w * top * (n - j0 + 2) / q)
    # P before the window (the comment above), in four independent chains
    p0 = p1 = p2 = p3 = 1.0
    i = 0
    while i + 4 <= j0:
        p0 *= na[i]
        p1 *= na[i + 1]
        p2 *= na[i + 2]
        p3 *= na[i + 3]
        i += 4
    while i < j0:
        p0 *= na[i]
        i += 1
    prod = (p0 * p1) * (p2 * p3)
    if j0 > 0 and prod < floor:
        return False
    before = w * (prod * tail)
    acc = 0.0
    for k in range(n - j0):
        j = np.uint64(j0 + k)
        u[j] = acc
        a[j] = prod  # A_j
        acc += p[j] * p_hit * g[j] * prod
        prod *= na[j]
    for j in range(j0):
        c = const * na[j]
        out[j] = c + q * before
        na[j] = c + before
    for k in range(n - j0):
        j = np.uint64(j0 + k)
        out[j] = const + w * (u[j] + a[j] * (p_hit * g[j] + q * r[j]))
        na[j] = const + w * (u[j] + a[j] * r[j])
    return True


@numba.njit(cache=True, _nrt=False, error_model="numpy")
def _reading_cone(tpl, flat, shape, readings, t, state, prior, model, ib, fl):
    """Reading t's cone under ``state`` (negative: ``prior``): flat ids in ``ib``, occupancy in
    ``fl[0]``, Gaussians in ``fl[1]``. Returns (m, j0, g0, C); m = 0 for no reading or a cone off the grid."""
    p_rand, p_max, p_hit, sigma, window, z_max = model
    z = readings.z[t]
    if not z == z:  # NaN: no reading
        return 0, 0, 0.0, 0.0
    z, limit = cone_reach(z, readings.limit[t], z_max, sigma, window)
    m, rk, s0 = reading_cone_cells(tpl, flat, shape, readings, t, (z, limit), (sigma, window), ib)
    b = tpl.base_bin[readings.bins[t]]
    # the slack keeps in the window any cell whose g might not round to 0
    j0 = min(range_search(rk, tpl.range_index[b], tpl.resolution, z - window * sigma - 1e-9, False), m)
    p = fl[0]
    g = fl[1]
    if tpl.heard.shape[0] > 0:  # the cone's heard cells only, in order (``ConeTemplates.heard``)
        heard, ranges = tpl.heard[s0:], fl[2]
        n = n0 = 0
        for j in range(m):
            if heard[j] != 0:
                ib[n] = ib[j]
                ranges[n] = rk[j]
                n += 1
                if j < j0:
                    n0 += 1
        m, j0, rk = n, n0, ranges
    for j in range(m):
        v = state[np.uint64(np.uint32(ib[j]))]
        p[j] = prior if v < 0.0 else v
    last = -1.0
    gj = 0.0
    for j in range(j0, m):
        if rk[j] != last:
            last = rk[j]
            gj = gaussian_at(z, last, sigma, window)
        g[j] = gj
    u0 = (z - z_max) / sigma
    g0 = math.exp(-0.5 * u0 * u0) / (math.sqrt(2.0 * math.pi) * sigma)
    return m, j0, g0, p_rand / z_max + p_max * g0


# _nrt=False (as the standard kernel): nothing is allocated per reading; the scratch comes in
@numba.njit(cache=True, _nrt=False, error_model="numpy")
def exact_inverse_updates(tpl, flat, shape, readings, state, model, bounds, scratch, span):
    """Apply readings in ``span`` in order to the occupancy ``state`` (negative: the prior ``bounds[2]``):
    each cone cell's odds times its ratio, clamped. The spare cells (occupancy 0) after the grid leave
    every product and sum unchanged to the last bit, so they need no test until the write."""
    p_min, p_max_clamp, prior = bounds
    p_hit, w = model[2], 1.0 - model[0] - model[1]
    n_cells = np.uint64(shape[0] * shape[1])  # unsigned as the cell ids: compared as integers
    # what a reading whose ratios are all 1 leaves in an unobserved cell
    kept_prior = np.float32(min(max(prior / (prior + 1.0 - prior), p_min), p_max_clamp))
    ib = scratch[0]
    fl = scratch[1]
    for t in range(span[0], span[1]):  # in order: each reading sees the map the earlier ones left
        m, j0, g0, const = _reading_cone(tpl, flat, shape, readings, t, state, prior, model, ib, fl)
        if m == 0:  # no reading, or a cone off the grid
            continue
        # numerators in fl[6], denominators in fl[5]; False: every ratio exactly 1
        if not cone_terms(fl[0], fl[1], j0, g0, p_hit, const, w, m, fl[2], fl[3], fl[4], fl[5], fl[6]):
            for j in range(m):  # every ratio 1: the cone's unobserved cells become observed
                c = np.uint64(np.uint32(ib[j]))
                if c < n_cells and state[c] < 0.0:
                    state[c] = kept_prior
            continue
        pm = fl[0][:m]
        den = fl[5][:m]
        om = fl[6][:m]
        for j in range(m):  # p N / (p N + (1 - p) D)
            pn = pm[j] * om[j]
            om[j] = min(max(pn / (pn + (1.0 - pm[j]) * den[j]), p_min), p_max_clamp)
        for j in range(m):
            c = np.uint64(np.uint32(ib[j]))
            if c < n_cells:
                state[c] = om[j]


@numba.njit(cache=True, _nrt=False, error_model="numpy", nogil=True)
def map_evidence_sums(tpl, flat, shape, readings, occupancy, model, scratch, span, evidence):
    """Add to ``evidence`` each reading's log ratio log p(z | m_j = 1) - log p(z | m_j = 0) for its
    cone's cells under the fixed binary map ``occupancy``: EM's evidence at that map.

    Before the window, with K occupied cells and R the backward sum at it, A_j R_j is q^K R (free
    cell) or q^(K - 1) R (occupied): two ratios; the window's cells are ``cone_terms``' ratios with w q^K."""
    p_rand, p_max, p_hit = model[0], model[1], model[2]
    w = 1.0 - p_rand - p_max
    q = 1.0 - p_hit
    n_cells = np.uint64(shape[0] * shape[1])  # unsigned as the cell ids: compared as integers
    ib = scratch[0]
    fl = scratch[1]
    p = fl[0]
    g = fl[1]
    out = fl[6]
    for t in range(span[0], span[1]):
        m, j0, g0, const = _reading_cone(tpl, flat, shape, readings, t, occupancy, 0.0, model, ib, fl)
        if m == 0:
            continue
        occupied = 0
        for j in range(j0):
            if p[j] > 0.0:
                occupied += 1
        wk = w * q**occupied
        tail = g0  # R at the window's start
        for j in range(m - 1, j0 - 1, -1):
            tail = p[j] * p_hit * g[j] + (1.0 - p_hit * p[j]) * tail
        n = m - j0
        if n > 0:
            # from j0 = 0 never all 1 (``cone_terms``): numerators in ``out``, denominators in fl[5]
            cone_terms(p[j0:m], g[j0:m], 0, g0, p_hit, const, wk, n, fl[2], fl[3], fl[4], fl[5], out)
            den = fl[5]
            for j in range(n):
                c = np.uint64(np.uint32(ib[j0 + j]))
                if c < n_cells:
                    evidence[c] += math.log(out[j] / den[j])
        free = (const + wk * (q * tail)) / (const + wk * tail)
        held = (const + wk * tail) / (const + wk * tail / q)
        if abs(free - 1.0) < NEGLIGIBLE and (occupied == 0 or abs(held - 1.0) < NEGLIGIBLE):
            continue
        log_free = math.log(free)
        log_held = math.log(held) if occupied > 0 else 0.0
        for j in range(j0):
            c = np.uint64(np.uint32(ib[j]))
            if c < n_cells:
                evidence[c] += log_held if p[j] > 0.0 else log_free


def cone_scratch(templates) -> tuple[np.ndarray, np.ndarray]:
    """``exact_inverse_updates``' scratch for ``templates`` (their longest cone)."""
    size = int(np.diff(templates.offsets).max())
    return np.empty(size, dtype=np.int32), np.empty((7, size))
