"""Each reading's likelihood under the forward model in a few scalars (S_t, its window sum,
its obstacle counts, the far ratios): set up under a map, changed by a flip, scored for a
flip (``_flip_gain``), summed into EM's objective, and turned into residuals."""

from __future__ import annotations

import math

import numba
import numpy as np

from aogm_cli.mapping.em_kernels.extents import _bin_transform, _entry_cell, _extend_box
from aogm_cli.mapping.em_kernels.layout import _columns
from aogm_cli.mapping.em_kernels.windows import _rank
from aogm_cli.sensor_models.cone import unheard
from aogm_cli.sensor_models.forward_model import gaussian_at


@numba.njit(cache=True, inline="always")
def _set_sum(t, rd, model, state):
    """S_t from the state, and the likelihood ratios of adding / removing a far obstacle: S_t -> q S_t
    and S_t / q whatever its rank (every obstacle before it has g = 0 too), one value per reading."""
    qpow = model.qpow
    w = model.w
    q = 1.0 - model.p_hit
    value = qpow[state.nfar[t]] * (state.wsum[t] + qpow[state.nobs[t]] * rd.g0[t])
    state.s[t] = value
    c = rd.const[t]
    base = c + w * value
    state.far_ratio[t, 0] = (c + w * q * value) / base
    state.far_ratio[t, 1] = (c + w * value / q) / base
    state.far_log[t, 0] = math.log(state.far_ratio[t, 0])
    state.far_log[t, 1] = math.log(state.far_ratio[t, 1])


@numba.njit(cache=True, inline="always")
def _find(parent, x):
    """Union-find root of x (path halving)."""
    while parent[x] != x:
        parent[x] = parent[parent[x]]
        x = parent[x]
    return x


@numba.njit(cache=True)
def _join_parents(parent, other):
    """Join into the union-find ``parent`` every set of ``other``, each root its set's least id."""
    for x in range(other.shape[0]):
        a = _find(parent, x)
        c = _find(parent, _find(other, x))
        if a != c:
            parent[max(a, c)] = min(a, c)


# _nrt=False: nothing is allocated, and without reference counting the tuples' arrays cost nothing
# per reading; nogil: parts run on threads
@numba.njit(cache=True, _nrt=False, nogil=True)
def _init_state(tpl, flat, readings, model, occupied, grid_shape, marks, span):
    """The ``EMState`` of each reading in ``span`` under ``occupied`` (one walk of its cone).
    ``marks`` = (seen, window, labels, parent, box), each optional (empty): every cone cell is marked in
    ``seen``, every heard cell of its Gaussian window (entries from jlo) in ``window``; clusters
    (``labels``) that share a reading are joined in ``parent``, and ``box`` gets each reading's
    cluster cells' bounds, the only cells EM may flip."""
    rd, state = _columns(readings)
    seen, window, labels, parent, box = marks
    height, width = grid_shape
    qpow = model.qpow
    p_hit = model.p_hit
    mark = seen.shape[0] > 0
    mark_window = window.shape[0] > 0
    join = labels.shape[0] > 0
    inv_width = 1.0 / width
    for t in range(span[0], span[1]):
        state.stamp[t] = 0
        far = 0
        k = 0
        acc = 0.0
        first = 0
        last = 0  # the cluster of the cone's last cluster cell: the next is mostly in it too
        if join:
            box[t, 0] = height
            box[t, 1] = -1
            box[t, 2] = width
            box[t, 3] = -1
        if rd.box[0, t] <= rd.box[1, t]:
            k_bin = rd.bin[t]
            s0 = tpl.offsets[tpl.base_bin[k_bin]]
            inside = rd.inside[t] != 0
            x_off = flat.offsets[flat.sel[k_bin, 0]]
            sign = flat.sel[k_bin, 1]
            row0, col0 = np.int64(rd.row0[t]), np.int64(rd.col0[t])
            at = row0 * width + col0
            tr = _bin_transform(tpl, k_bin)
            jlo, z = rd.jlo[t], rd.z[t]  # loaded once: the loop's stores (seen, parent) might alias them
            for j in range(rd.m[t]):
                cell = at + sign * np.int64(x_off[s0 + j]) if inside else _entry_cell(tpl, s0, tr, j, row0, col0,
                                                                                      height, width)
                if cell < 0:
                    continue
                if mark:
                    seen[cell] = True
                if unheard(tpl, s0 + j):  # left out but for ``seen``
                    continue
                if mark_window and j >= jlo:
                    window[cell] = True
                if join and labels[cell] > 0:
                    row = np.int64(cell * inv_width)  # cell // width without a division per cell:
                    if row * width > cell:  # the product is off by at most one row either way
                        row -= 1
                    elif (row + 1) * width <= cell:
                        row += 1
                    _extend_box(box, t, row, cell - row * width)
                    if first == 0:
                        first = labels[cell]
                    elif labels[cell] != last:  # the same cluster again joins nothing
                        a = _find(parent, first)
                        c = _find(parent, labels[cell])
                        if a != c:
                            parent[max(a, c)] = min(a, c)
                    last = labels[cell]
                if not occupied[cell]:
                    continue
                g = 0.0 if j < jlo else gaussian_at(z, tpl.ranges[s0 + j], model.sigma, model.window)
                if g == 0.0:
                    far += 1
                    continue
                acc += qpow[k] * p_hit * g
                k += 1
        state.nobs[t] = k
        state.nfar[t] = far
        state.wsum[t] = acc
        _set_sum(t, rd, model, state)


@numba.njit(cache=True, inline="always")
def _flip_gain(c, x, lo_pair, hi_pair, rd, model, cand, state, work):
    """Exact change of sum_t log p(z_t | m) when candidate c flips (data part only)."""
    pair_pos = work.pair_pos
    pair_j = work.pair_j
    pair_g = work.pair_g
    const = rd.const
    w = model.w
    p_hit = model.p_hit
    qpow = model.qpow
    s = state.s
    q = 1.0 - p_hit
    adding = not cand.occupied[cand.cell[c]]
    far = 0 if adding else 1
    delta = 0.0
    for k in range(x + 1):
        delta += work.far_sum[far, k]
    ratio = 1.0
    for p in range(lo_pair, hi_pair):
        t = work.tile_t[pair_pos[p]]
        if pair_g[p] == 0.0:  # a window entry whose Gaussian underflows: as a far one
            ratio *= state.far_ratio[t, far]
            continue
        base = state.slot[t]
        r = _rank(work.obs_j, base, pair_j[p] - rd.jlo[t])
        qf = qpow[state.nfar[t]]
        a = qf * work.pre[base + r]
        term = qf * qpow[r] * p_hit * pair_g[p]
        st = s[t]
        if adding:
            s_new = a + term + q * (st - a)
        else:
            rest = st - a - term
            if rest < 0.0:
                rest = 0.0
            s_new = a + rest / q
        # one log per candidate, not per pair, unless the product leaves a safe range
        ratio *= (const[t] + w * s_new) / (const[t] + w * st)
        if ratio > 1e100 or ratio < 1e-100:
            delta += math.log(ratio)
            ratio = 1.0
    return delta + math.log(ratio)


@numba.njit(cache=True, inline="always")
def _far_changed(li, t, x, old_add, old_rem, state, work):
    """Reading t changed after a flip at column x: move its log far ratios in the tile's sums beyond x."""
    lo = max(work.far_lo[li], x + 1)
    hi = work.far_hi[li]
    if lo > hi:
        return
    d_add = state.far_log[t, 0] - old_add
    d_rem = state.far_log[t, 1] - old_rem
    work.far_sum[0, lo] += d_add
    work.far_sum[0, hi + 1] -= d_add
    work.far_sum[1, lo] += d_rem
    work.far_sum[1, hi + 1] -= d_rem


@numba.njit(cache=True, inline="always")
def _update_reading(t, j, g, adding, model, rd, state, work):
    """Add (or remove) the obstacle at entry j (Gaussian g) of reading t, and redo its sums."""
    if g == 0.0:
        state.nfar[t] += 1 if adding else -1
        _set_sum(t, rd, model, state)
        return
    qpow = model.qpow
    p_hit = model.p_hit
    obs_j = work.obs_j
    obs_g = work.obs_g
    pre = work.pre
    base = state.slot[t]
    n = state.nobs[t]
    q = j - rd.jlo[t]
    r = _rank(obs_j, base, q)
    acc = pre[base + r]
    bit = np.int64(1) << np.int64(q & 63)
    if adding:
        obs_j[base + (q >> 6)] |= bit
        for k in range(n, r, -1):
            obs_g[base + k] = obs_g[base + k - 1]
        obs_g[base + r] = g
        n += 1
        for k in range(r, n):
            acc += qpow[k] * p_hit * obs_g[base + k]
            pre[base + k + 1] = acc
    else:  # shift down and redo the prefix sums in one pass
        obs_j[base + (q >> 6)] &= ~bit
        n -= 1
        for k in range(r, n):
            obs_g[base + k] = obs_g[base + k + 1]
            acc += qpow[k] * p_hit * obs_g[base + k]
            pre[base + k + 1] = acc
    state.nobs[t] = n
    state.wsum[t] = pre[base + n]
    _set_sum(t, rd, model, state)


@numba.njit(cache=True)
def _objective(readings, model, occupied, cand_cell):
    """sum_t log p(z_t | m) plus l_prior per occupied candidate."""
    rd, state = _columns(readings)
    const = rd.const
    w = model.w
    s = state.s
    total = 0.0
    for t in range(s.shape[0]):
        total += math.log(const[t] + w * s[t])
    for c in range(cand_cell.shape[0]):
        if occupied[cand_cell[c]]:
            total += model.l_prior
    return total


@numba.njit(cache=True)
def _logistic(x):
    """1 / (1 + exp(-x)) without overflow."""
    if x >= 0:
        return 1.0 / (1.0 + math.exp(-x))
    ex = math.exp(x)
    return ex / (1.0 + ex)


@numba.njit(cache=True)
def _residual_from_gains(cand_cell, occupied, last_gain, l_prior):
    """p(m_x = 1 | Z, m*) from each candidate's current data gain of flipping."""
    out = np.empty(cand_cell.shape[0])
    for c in range(cand_cell.shape[0]):
        out[c] = _logistic((-last_gain[c] if occupied[cand_cell[c]] else last_gain[c]) + l_prior)
    return out
