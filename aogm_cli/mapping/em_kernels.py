"""The compiled kernels of EM mapping (``mapping.em``): per-reading likelihood state, the
incremental E-step after a flip, one sweep of single-cell flips, the objective and residuals.

Pure functions on arrays, grouped into named tuples by meaning: the forward index
(``forward_model.ForwardArrays``), the model's constants (``EMModel``), the readings' state
(``EMState``), the cell -> readings index (``PairIndex``) and the sweeps' bookkeeping
(``SweepStamps``). ``mapping.em`` lays out their inputs and drives the sweeps.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np


class EMModel(NamedTuple):
    """The constants of the objective."""

    p_hit: float  # detection probability of each obstacle in a cone (q = 1 - p_hit)
    l_prior: float  # log-odds of the occupancy prior, added per occupied candidate
    qpow: np.ndarray  # float64 q^k for k = 0 .. the most entries of a reading


class EMState(NamedTuple):
    """The likelihood state of every reading t under the current map (``_init_state``).

    Far obstacles all come before the window's (entries are in range order), so the window's
    obstacle of rank r is the (nfar + r)-th obstacle of the reading.
    """

    nptr: np.ndarray  # (R+1,) int64: reading t's room in obs_pos is nptr[t]:nptr[t+1] (its entries with g > 0)
    obs_pos: np.ndarray  # entry positions of the obstacles inside the window, in range order, nobs[t] many
    pre: np.ndarray  # prefix sums of their terms without the q^nfar factor, from nptr[t] + t (nobs[t] + 1 of them)
    nobs: np.ndarray  # (R,) int64
    nfar: np.ndarray  # (R,) int64: obstacles before the window (g = 0; they only scale S_t by q each)
    s: np.ndarray  # (R,) float64: S_t = q^nfar (pre[nobs] + q^nobs G0)
    far_ratio: np.ndarray  # (2R,) float64: likelihood ratios of adding / removing a far obstacle (_set_sum)


class PairIndex(NamedTuple):
    """Cell -> readings index of EM's candidates (``em.pair_index``)."""

    cand_cell: np.ndarray  # (C,) int64 sorted flat ids of the candidates
    cand_ptr: np.ndarray  # (C+1,) int64: candidate c's pairs are cand_ptr[c]:cand_ptr[c+1], in reading order
    pair_t: np.ndarray  # (P,) int64 reading of each pair
    pair_e: np.ndarray  # (P,) int64 entry of the forward index of each pair
    pair_g: np.ndarray  # (P,) float64 the entry's Gaussian (index.g[pair_e]), stored along the pairs


class SweepStamps(NamedTuple):
    """What the sweeps remember between them (see ``_sweep``)."""

    reading_stamp: np.ndarray  # (R,) int64: the clock when each reading last changed
    cand_stamp: np.ndarray  # (C,) int64: the clock when each candidate was last scored (-1: never)
    clock: np.ndarray  # (1,) int64: accepted flips so far
    last_gain: np.ndarray  # (C,) float64: each candidate's last data gain of flipping


@numba.njit(cache=True, inline="always")
def _set_sum(t, index, model, state):
    """Recompute S_t from the state, and the likelihood ratios of adding / removing a far obstacle.

    A far cell has g = 0 and so have all obstacles before it (they are nearer), so adding
    it makes S_t -> q S_t and removing it S_t -> S_t / q, whatever its rank: one value per
    reading instead of a search per (cell, reading) pair.
    """
    qpow = model.qpow
    const = index.const
    w = index.w
    far_ratio = state.far_ratio
    q = 1.0 - model.p_hit
    n = state.nobs[t]
    value = qpow[state.nfar[t]] * (state.pre[state.nptr[t] + t + n] + qpow[n] * index.g0[t])
    state.s[t] = value
    base = const[t] + w * value
    far_ratio[2 * t] = (const[t] + w * q * value) / base  # likelihood ratio of adding one
    far_ratio[2 * t + 1] = (const[t] + w * value / q) / base  # ... and of removing one


@numba.njit(cache=True, inline="always")
def _rebuild_reading(t, index, model, occupied, state):
    """Reading t's state from scratch under the map ``occupied``."""
    cell = index.cell
    g = index.g
    qpow = model.qpow
    p_hit = model.p_hit
    obs_pos = state.obs_pos
    pre = state.pre
    base = state.nptr[t]
    pbase = state.nptr[t] + t
    k = 0
    far = 0
    acc = 0.0
    pre[pbase] = 0.0
    for e in range(index.ptr[t], index.ptr[t + 1]):
        if occupied[cell[e]]:
            if g[e] == 0.0:
                far += 1
                continue
            obs_pos[base + k] = e
            acc += qpow[k] * p_hit * g[e]
            k += 1
            pre[pbase + k] = acc
    state.nobs[t] = k
    state.nfar[t] = far
    _set_sum(t, index, model, state)


@numba.njit(cache=True, inline="always")
def _rank(obs_pos, lo, hi, e):
    """How many of the sorted entry positions obs_pos[lo:hi] lie before entry ``e``."""
    k = lo
    while k < hi and obs_pos[k] < e:  # a window holds few obstacles: a linear scan
        k += 1
    return k - lo


@numba.njit(cache=True, inline="always")
def _update_reading(t, e, adding, index, model, state):
    """Add (or remove) the obstacle at entry ``e`` of reading t: O(1) before the window,
    else an insertion into the window's list and its prefix sums from that rank on."""
    g = index.g
    if g[e] == 0.0:
        state.nfar[t] += 1 if adding else -1
        _set_sum(t, index, model, state)
        return
    qpow = model.qpow
    p_hit = model.p_hit
    obs_pos = state.obs_pos
    pre = state.pre
    base = state.nptr[t]
    pbase = state.nptr[t] + t
    n = state.nobs[t]
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
    state.nobs[t] = n
    _set_sum(t, index, model, state)


@numba.njit(cache=True)
def _init_state(index, model, occupied):
    """The ``EMState`` of every reading of ``index`` (``ForwardArrays``) under ``occupied``;
    ``nptr`` delimits each reading's room for window obstacles (its entries with g > 0), so
    that the arrays the sweeps touch stay small."""
    ptr = index.ptr
    g = index.g
    n = ptr.shape[0] - 1
    nptr = np.zeros(n + 1, dtype=np.int64)
    for t in range(n):
        room = 0
        for e in range(ptr[t], ptr[t + 1]):
            if g[e] != 0.0:
                room += 1
        nptr[t + 1] = nptr[t] + room
    state = EMState(
        nptr,
        np.empty(nptr[n], dtype=np.int64),
        np.empty(nptr[n] + n, dtype=np.float64),
        np.zeros(n, dtype=np.int64),
        np.zeros(n, dtype=np.int64),
        np.empty(n, dtype=np.float64),
        np.empty(2 * n, dtype=np.float64),
    )
    _rebuild_all(index, model, occupied, state)
    return state


# _nrt=False (as _sweep): no reference counting of the tuples' arrays per reading
@numba.njit(cache=True, _nrt=False)
def _rebuild_all(index, model, occupied, state):
    """Every reading's state from scratch (``_rebuild_reading``)."""
    for t in range(state.nobs.shape[0]):
        _rebuild_reading(t, index, model, occupied, state)


@numba.njit(cache=True, inline="always")
def _flip_gain(c, pairs, index, model, occupied, state):
    """Exact change of sum_t log p(z_t | m) when candidate c flips (data part only).

    ``pairs.pair_g`` holds each pair's Gaussian (index.g of its entry), stored along the pairs
    so that the hot loop reads it sequentially."""
    pair_t = pairs.pair_t
    pair_e = pairs.pair_e
    pair_g = pairs.pair_g
    const = index.const
    w = index.w
    p_hit = model.p_hit
    qpow = model.qpow
    nptr = state.nptr
    obs_pos = state.obs_pos
    pre = state.pre
    nobs = state.nobs
    nfar = state.nfar
    s = state.s
    far_ratio = state.far_ratio
    q = 1.0 - p_hit
    adding = not occupied[pairs.cand_cell[c]]
    far = 0 if adding else 1
    delta = 0.0
    ratio = 1.0
    for p in range(pairs.cand_ptr[c], pairs.cand_ptr[c + 1]):
        t = pair_t[p]
        if pair_g[p] == 0.0:  # before the reading's window: see _set_sum
            ratio *= far_ratio[2 * t + far]
            if ratio > 1e100 or ratio < 1e-100:
                delta += math.log(ratio)
                ratio = 1.0
            continue
        # r = window obstacles of reading t before entry e (binary search in their positions)
        r = _rank(obs_pos, nptr[t], nptr[t] + nobs[t], pair_e[p])
        qf = qpow[nfar[t]]
        a = qf * pre[nptr[t] + t + r]
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
def _sweep(pairs, index, model, occupied, state, stamps):
    """One pass over the candidates in order; a flip is kept when it raises the objective.

    A candidate none of whose readings changed since it was last scored keeps its (non-
    improving) gain, so it is skipped: the result equals a full sweep's, at a fraction of
    the cost once the map settles. ``stamps.clock[0]`` counts accepted flips;
    ``reading_stamp`` and ``cand_stamp`` record when a reading last changed and when a
    candidate was last scored; ``last_gain`` keeps each candidate's last data gain (after a
    sweep without flips, every one is current, which gives the residual probabilities
    without another pass). Returns (flips, candidates scored).
    """
    cand_cell = pairs.cand_cell
    cand_ptr = pairs.cand_ptr
    pair_t = pairs.pair_t
    pair_e = pairs.pair_e
    l_prior = model.l_prior
    reading_stamp = stamps.reading_stamp
    cand_stamp = stamps.cand_stamp
    clock = stamps.clock
    last_gain = stamps.last_gain
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
        d = _flip_gain(c, pairs, index, model, occupied, state)
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
                _update_reading(pair_t[p], pair_e[p], adding, index, model, state)
                reading_stamp[pair_t[p]] = clock[0]
        cand_stamp[c] = clock[0]
    return flips, evaluated


@numba.njit(cache=True)
def _objective(index, model, state, occupied, cand_cell):
    """sum_t log p(z_t | m) plus l_prior per occupied candidate."""
    const = index.const
    w = index.w
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


@numba.njit(cache=True)
def _residual(pairs, index, model, occupied, state):
    """p(m_x = 1 | Z, m*) of each candidate with every other cell held at m*."""
    cand_cell = pairs.cand_cell
    out = np.empty(cand_cell.shape[0])
    for c in range(cand_cell.shape[0]):
        d = _flip_gain(c, pairs, index, model, occupied, state)
        out[c] = _logistic((-d if occupied[cand_cell[c]] else d) + model.l_prior)
    return out


@numba.njit(cache=True)
def _pair_index(index, candidates, lookup, lo):
    """The ``PairIndex`` of ``candidates`` (sorted flat ids); ``lookup[x - lo]`` is the
    position of cell x among them, or -1."""
    ptr = index.ptr
    cell = index.cell
    g = index.g
    n_read = ptr.shape[0] - 1
    counts = np.zeros(candidates.shape[0] + 1, dtype=np.int64)
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
    return PairIndex(candidates, cand_ptr, pair_t, pair_e, pair_g)
