"""The compiled kernels of EM mapping (``mapping.em``): per-reading likelihood state, the
incremental E-step after a flip, one sweep of single-cell flips, the objective and residuals.

Pure functions on arrays; ``mapping.em`` lays out their inputs and drives the sweeps.
"""

from __future__ import annotations

import math

import numba
import numpy as np

# ---------------------------------------------------------------------------------------
# compiled state, per reading t:
#   nfar[t]  obstacles before the reading's window (g = 0; they only scale S_t by q each);
#   obs_pos  the obstacles inside the window (entry positions, in range order), nobs[t] many,
#            from nptr[t] (room for the reading's window entries);
#   pre      prefix sums of their terms without the q^nfar factor, from nptr[t] + t;
# The kernels below that only touch this state take nptr in the place of ptr.
#   s[t]     S_t = q^nfar (pre[nobs] + q^nobs G0);  far_ratio (ratios): see _set_sum.
# Far obstacles all come before the window's (entries are in range order), so the window's
# obstacle of rank r is the (nfar + r)-th obstacle of the reading.
# ---------------------------------------------------------------------------------------


@numba.njit(cache=True, inline="always")
def _set_sum(t, ptr, g0, p_hit, qpow, pre, nobs, nfar, const, w, s, far_ratio):
    """Recompute S_t from the state, and the likelihood ratios of adding / removing a far obstacle.

    A far cell has g = 0 and so have all obstacles before it (they are nearer), so adding
    it makes S_t -> q S_t and removing it S_t -> S_t / q, whatever its rank: one value per
    reading instead of a search per (cell, reading) pair.
    """
    q = 1.0 - p_hit
    n = nobs[t]
    value = qpow[nfar[t]] * (pre[ptr[t] + t + n] + qpow[n] * g0[t])
    s[t] = value
    base = const[t] + w * value
    far_ratio[2 * t] = (const[t] + w * q * value) / base  # likelihood ratio of adding one
    far_ratio[2 * t + 1] = (const[t] + w * value / q) / base  # ... and of removing one


@numba.njit(cache=True)
def _rebuild_reading(t, ptr, nptr, cell, g, g0, p_hit, qpow, occupied, obs_pos, pre, nobs, nfar, s, const, w,
                     far_ratio):
    base = nptr[t]
    pbase = nptr[t] + t
    k = 0
    far = 0
    acc = 0.0
    pre[pbase] = 0.0
    for e in range(ptr[t], ptr[t + 1]):
        if occupied[cell[e]]:
            if g[e] == 0.0:
                far += 1
                continue
            obs_pos[base + k] = e
            acc += qpow[k] * p_hit * g[e]
            k += 1
            pre[pbase + k] = acc
    nobs[t] = k
    nfar[t] = far
    _set_sum(t, nptr, g0, p_hit, qpow, pre, nobs, nfar, const, w, s, far_ratio)


@numba.njit(cache=True, inline="always")
def _rank(obs_pos, lo, hi, e):
    """How many of the sorted entry positions obs_pos[lo:hi] lie before entry ``e``."""
    k = lo
    while k < hi and obs_pos[k] < e:  # a window holds few obstacles: a linear scan
        k += 1
    return k - lo


@numba.njit(cache=True, inline="always")
def _update_reading(t, e, adding, ptr, g, g0, p_hit, qpow, obs_pos, pre, nobs, nfar, s, const, w, far_ratio):
    """Add (or remove) the obstacle at entry ``e`` of reading t: O(1) before the window,
    else an insertion into the window's list and its prefix sums from that rank on."""
    if g[e] == 0.0:
        nfar[t] += 1 if adding else -1
        _set_sum(t, ptr, g0, p_hit, qpow, pre, nobs, nfar, const, w, s, far_ratio)
        return
    base = ptr[t]
    pbase = ptr[t] + t
    n = nobs[t]
    r = _rank(obs_pos, base, base + n, e)
    acc = pre[pbase + r]
    if adding:
        for k in range(n, r, -1):
            obs_pos[base + k] = obs_pos[base + k - 1]
        obs_pos[base + r] = e
        n += 1
        for k in range(r, n):
            acc += qpow[k] * p_hit * g[obs_pos[base + k]]
            pre[pbase + k + 1] = acc
    else:  # shift down and redo the prefix sums in one pass
        n -= 1
        for k in range(r, n):
            moved = obs_pos[base + k + 1]
            obs_pos[base + k] = moved
            acc += qpow[k] * p_hit * g[moved]
            pre[pbase + k + 1] = acc
    nobs[t] = n
    _set_sum(t, ptr, g0, p_hit, qpow, pre, nobs, nfar, const, w, s, far_ratio)


@numba.njit(cache=True)
def _init_state(ptr, cell, g, g0, const, w, p_hit, qpow, occupied):
    """The state of every reading; ``nptr`` delimits each reading's room for window obstacles
    (its entries with g > 0), so that the arrays the sweeps touch stay small."""
    n = ptr.shape[0] - 1
    nptr = np.zeros(n + 1, dtype=np.int64)
    for t in range(n):
        room = 0
        for e in range(ptr[t], ptr[t + 1]):
            if g[e] != 0.0:
                room += 1
        nptr[t + 1] = nptr[t] + room
    obs_pos = np.empty(nptr[n], dtype=np.int64)
    pre = np.empty(nptr[n] + n, dtype=np.float64)
    nobs = np.zeros(n, dtype=np.int64)
    nfar = np.zeros(n, dtype=np.int64)
    s = np.empty(n, dtype=np.float64)
    far_ratio = np.empty(2 * n, dtype=np.float64)
    for t in range(n):
        _rebuild_reading(t, ptr, nptr, cell, g, g0, p_hit, qpow, occupied, obs_pos, pre, nobs, nfar, s, const, w,
                         far_ratio)
    return nptr, obs_pos, pre, nobs, nfar, s, far_ratio


@numba.njit(cache=True, inline="always")
def _flip_gain(c, cand_cell, cand_ptr, pair_t, pair_e, ptr, pair_g, const, w, p_hit, qpow, occupied, obs_pos, pre,
               nobs, nfar, s, far_ratio):
    """Exact change of sum_t log p(z_t | m) when candidate c flips (data part only).

    ``pair_g`` holds each pair's Gaussian (index.g of its entry), stored along the pairs so
    that the hot loop reads it sequentially."""
    q = 1.0 - p_hit
    adding = not occupied[cand_cell[c]]
    far = 0 if adding else 1
    delta = 0.0
    ratio = 1.0
    for p in range(cand_ptr[c], cand_ptr[c + 1]):
        t = pair_t[p]
        if pair_g[p] == 0.0:  # before the reading's window: see _set_sum
            ratio *= far_ratio[2 * t + far]
            if ratio > 1e100 or ratio < 1e-100:
                delta += math.log(ratio)
                ratio = 1.0
            continue
        # r = window obstacles of reading t before entry e (binary search in their positions)
        r = _rank(obs_pos, ptr[t], ptr[t] + nobs[t], pair_e[p])
        qf = qpow[nfar[t]]
        a = qf * pre[ptr[t] + t + r]
        term = qf * qpow[r] * p_hit * pair_g[p]
        st = s[t]
        if adding:
            s_new = a + term + q * (st - a)
        else:
            rest = st - a - term
            if rest < 0.0:
                rest = 0.0
            s_new = a + rest / q
        # one log per candidate instead of one per pair: multiply the ratios, taking the log
        # only when the product leaves a safe range
        ratio *= (const[t] + w * s_new) / (const[t] + w * st)
        if ratio > 1e100 or ratio < 1e-100:
            delta += math.log(ratio)
            ratio = 1.0
    return delta + math.log(ratio)


# _nrt=False: the sweep allocates nothing, and without numba's reference-counting runtime
# the arrays it hands to the inlined helpers cost nothing per call (as in simulation.raycast;
# _nrt is a private numba option)
@numba.njit(cache=True, _nrt=False)
def _sweep(cand_cell, cand_ptr, pair_t, pair_e, ptr, cell, g, g0, const, w, p_hit, l_prior, qpow,
           occupied, obs_pos, pre, nobs, nfar, s, far_ratio, reading_stamp, cand_stamp, clock, last_gain, pair_g):
    """One pass over the candidates in order; a flip is kept when it raises the objective.

    A candidate none of whose readings changed since it was last scored keeps its (non-
    improving) gain, so it is skipped: the result equals a full sweep's, at a fraction of
    the cost once the map settles. ``clock[0]`` counts accepted flips; ``reading_stamp`` and
    ``cand_stamp`` record when a reading last changed and when a candidate was last scored;
    ``last_gain`` keeps each candidate's last data gain (after a sweep without flips, every
    one is current, which gives the residual probabilities without another pass).
    """
    flips = 0
    evaluated = 0
    for c in range(cand_cell.shape[0]):
        if cand_stamp[c] >= 0:
            dirty = False
            for p in range(cand_ptr[c], cand_ptr[c + 1]):
                if reading_stamp[pair_t[p]] > cand_stamp[c]:
                    dirty = True
                    break
            if not dirty:
                continue
        evaluated += 1
        d = _flip_gain(c, cand_cell, cand_ptr, pair_t, pair_e, ptr, pair_g, const, w, p_hit, qpow,
                       occupied, obs_pos, pre, nobs, nfar, s, far_ratio)
        last_gain[c] = d
        x = cand_cell[c]
        d += -l_prior if occupied[x] else l_prior
        if d > 1e-9:
            occupied[x] = not occupied[x]
            last_gain[c] = -last_gain[c]  # flipping back undoes exactly this gain
            flips += 1
            clock[0] += 1
            adding = occupied[x]
            for p in range(cand_ptr[c], cand_ptr[c + 1]):
                _update_reading(pair_t[p], pair_e[p], adding, ptr, g, g0, p_hit, qpow, obs_pos, pre, nobs, nfar,
                                s, const, w, far_ratio)
                reading_stamp[pair_t[p]] = clock[0]
        cand_stamp[c] = clock[0]
    return flips, evaluated


@numba.njit(cache=True)
def _objective(const, w, s, occupied, cand_cell, l_prior):
    total = 0.0
    for t in range(s.shape[0]):
        total += math.log(const[t] + w * s[t])
    for c in range(cand_cell.shape[0]):
        if occupied[cand_cell[c]]:
            total += l_prior
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


@numba.njit(cache=True)
def _residual(cand_cell, cand_ptr, pair_t, pair_e, ptr, pair_g, const, w, p_hit, l_prior, qpow,
              occupied, obs_pos, pre, nobs, nfar, s, far_ratio):
    """p(m_x = 1 | Z, m*) of each candidate with every other cell held at m*."""
    out = np.empty(cand_cell.shape[0])
    for c in range(cand_cell.shape[0]):
        d = _flip_gain(c, cand_cell, cand_ptr, pair_t, pair_e, ptr, pair_g, const, w, p_hit, qpow,
                       occupied, obs_pos, pre, nobs, nfar, s, far_ratio)
        out[c] = _logistic((-d if occupied[cand_cell[c]] else d) + l_prior)
    return out


@numba.njit(cache=True)
def _pair_index(ptr, cell, g, lookup, lo, n_cand):
    n_read = ptr.shape[0] - 1
    counts = np.zeros(n_cand + 1, dtype=np.int64)
    for e in range(cell.shape[0]):
        k = cell[e] - lo
        if 0 <= k < lookup.shape[0] and lookup[k] >= 0:
            counts[lookup[k] + 1] += 1
    cand_ptr = np.cumsum(counts)
    fill = cand_ptr[:-1].copy()
    pair_t = np.empty(cand_ptr[-1], dtype=np.int64)
    pair_e = np.empty(cand_ptr[-1], dtype=np.int64)
    pair_g = np.empty(cand_ptr[-1], dtype=np.float64)
    for t in range(n_read):
        for e in range(ptr[t], ptr[t + 1]):
            k = cell[e] - lo
            if 0 <= k < lookup.shape[0] and lookup[k] >= 0:
                j = fill[lookup[k]]
                pair_t[j] = t
                pair_e[j] = e
                pair_g[j] = g[e]
                fill[lookup[k]] += 1
    return cand_ptr, pair_t, pair_e, pair_g
