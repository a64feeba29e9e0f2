"""The arena of window obstacles: each active reading's obstacles inside its Gaussian window,
in range order with prefix sums, rebuilt from the map when a tile needs them."""

from __future__ import annotations

import numba
import numpy as np

from aogm_cli.mapping.em_kernels.extents import _bin_transform, _entry_cell
from aogm_cli.mapping.em_kernels.layout import ARENA_ENTRIES
from aogm_cli.sensor_models.cone import unheard
from aogm_cli.sensor_models.forward_model import gaussian_at


@numba.njit(cache=True, inline="always")
def _room(rd, t):
    """Arena entries of reading t's slot: a header, and room for every window entry plus one."""
    return max(rd.m[t] - rd.jlo[t], 0) + 2


@numba.njit(cache=True, inline="always")
def _build_window(t, tpl, flat, rd, model, cand, state, work):
    """Reading t's window obstacles, their Gaussians and prefix sums into a new arena slot."""
    height = cand.tile_clock.shape[0]
    width = cand.of_cell.shape[0] // height
    qpow = model.qpow
    p_hit = model.p_hit
    k_bin = rd.bin[t]
    s0 = tpl.offsets[tpl.base_bin[k_bin]]
    ctl = work.ctl[0]
    head = ctl.bump
    ctl.bump = head + _room(rd, t)
    work.obs_j[head] = t
    base = head + 1
    state.slot[t] = base
    work.pre[base] = 0.0
    jlo = rd.jlo[t]
    for k in range((rd.m[t] - jlo + 63) >> 6):
        work.obs_j[base + k] = 0
    n = 0
    acc = 0.0
    inside = rd.inside[t] != 0
    x_off = flat.offsets[flat.sel[k_bin, 0]]
    sign = flat.sel[k_bin, 1]
    row0, col0 = np.int64(rd.row0[t]), np.int64(rd.col0[t])
    at = row0 * width + col0
    tr = _bin_transform(tpl, k_bin)
    for j in range(rd.jlo[t], rd.m[t]):
        cell = at + sign * np.int64(x_off[s0 + j]) if inside else _entry_cell(tpl, s0, tr, j, row0, col0, height,
                                                                              width)
        if cell < 0 or not cand.occupied[cell] or unheard(tpl, s0 + j):
            continue
        g = gaussian_at(rd.z[t], tpl.ranges[s0 + j], model.sigma, model.window)
        if g == 0.0:
            continue
        q = j - jlo
        work.obs_j[base + (q >> 6)] |= np.int64(1) << np.int64(q & 63)
        work.obs_g[base + n] = g
        acc += qpow[n] * p_hit * g
        n += 1
        work.pre[base + n] = acc


@numba.njit(cache=True, inline="always")
def _make_room(rd, state, work, need):
    """Compact the arena when fewer than ``need`` entries are free (at the cap drop every slot); False: grow it."""
    ctl = work.ctl[0]
    top = ctl.bump
    if top + need <= work.obs_j.shape[0]:
        return True
    a = 0
    out = 0
    while a < top:
        t = work.obs_j[a]
        size = _room(rd, t)
        if state.slot[t] == a + 1:  # live
            if out != a:
                for k in range(size):
                    work.obs_j[out + k] = work.obs_j[a + k]
                    work.obs_g[out + k] = work.obs_g[a + k]
                    work.pre[out + k] = work.pre[a + k]
                state.slot[t] = out + 1
            out += size
        a += size
    ctl.bump = out
    size = work.obs_j.shape[0]
    if 2 * (out + need) <= size:  # half free at least, or compactions come too often
        return True
    if size < ARENA_ENTRIES:
        ctl.need_room = min(2 * (out + need), ARENA_ENTRIES)
        if ctl.need_room > size:
            return False
    a = 0  # the arena is as large as it gets: drop every slot
    while a < out:
        t = work.obs_j[a]
        state.slot[t] = -1
        a += _room(rd, t)
    ctl.bump = 0
    if need <= size:
        return True
    ctl.need_room = need  # one tile needs more than the cap
    return False


@numba.njit(cache=True, inline="always")
def _popcount(x):
    """Set bits of the int64 x."""
    v = np.uint64(x)
    v = v - ((v >> np.uint64(1)) & np.uint64(0x5555555555555555))
    v = (v & np.uint64(0x3333333333333333)) + ((v >> np.uint64(2)) & np.uint64(0x3333333333333333))
    v = (v + (v >> np.uint64(4))) & np.uint64(0x0F0F0F0F0F0F0F0F)
    return np.int64((v * np.uint64(0x0101010101010101)) >> np.uint64(56))


@numba.njit(cache=True, inline="always")
def _rank(bits, base, q):
    """How many window obstacles lie before window entry q (a thick wall puts tens in one window)."""
    n = 0
    w = q >> 6
    for k in range(w):
        n += _popcount(bits[base + k])
    return n + _popcount(bits[base + w] & ((np.int64(1) << np.int64(q & 63)) - 1))
