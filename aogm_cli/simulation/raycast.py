"""Ray casting against a compiled ``Scene``: the first surface a ray hits, and how it hits it (distance,
surface normal, threshold): ray-segment and ray-circle intersection over the scene's bucket grid, and an
Amanatides-Woo traversal of the floor-plan bitmap; compiled kernels only."""

from __future__ import annotations

import math
from collections import namedtuple

import numba
import numpy as np

from aogm_cli.core.grid import dda_steps
from aogm_cli.world.scene import Scene

# The scene as the kernels take it (one argument). Thresholds are stored as cosines: a hit
# echoes when cos(incidence) >= cos(threshold); a rough surface has cos_threshold = -1.
Geometry = namedtuple(
    "Geometry",
    [
        "bucket_f",  # (3,) float64: x, y of the bucket grid's corner, bucket size
        "bucket_i",  # (2,) int64: nx, ny
        "seg_start",  # (nx*ny + 1,) int64
        "seg",  # (K, 4) float64: x0, y0, ex, ey per bucket entry
        "seg_id",  # (K,) int32
        "seg_cos_threshold",  # (N,) float64
        "circ_start",  # (nx*ny + 1,) int64
        "circ",  # (Kc, 3) float64: cx, cy, r per bucket entry
        "circ_id",  # (Kc,) int32
        "circ_cos_threshold",  # (M,) float64
        "bitmap",  # (H, W) uint8, 1 = occupied
        "bitmap_f",  # (3,) float64: origin x, y, resolution
        "bitmap_cos_threshold",  # float
        "has_bitmap",  # bool
    ],
)

# The kernels are inlined into their one entry point, ``sonar.echo_block`` (through ``trace_sub_ray``);
# none is called from Python, so none is compiled on its own (the tests, too, go through ``echo_block``).
# Performance: the kernels are inlined into their callers at numba IR level and compiled
# without the reference-counting runtime (_nrt=False; they never allocate). Passing the
# Geometry tuple through ordinary calls, and refcounting its arrays, cost more than the
# ray casting itself (see bench/bench_simulate.py).
BOUNCE_OFFSET = 1e-8  # m: a bounced ray starts this far off the surface, on the side it came from


def _cos_threshold(threshold):
    """cos of specular thresholds (rad); -1 for rough surfaces (threshold >= 90 degrees)."""
    thr = np.asarray(threshold, dtype=np.float64)
    return np.where(thr >= math.pi / 2 - 1e-12, -1.0, np.cos(thr))


def geometry(scene: Scene) -> Geometry:
    """The kernel form of ``scene``."""
    ny, nx = scene.bucket_shape
    if scene.bitmap_grid is not None:
        g = scene.bitmap_grid
        bitmap_f = np.array([g.origin_x, g.origin_y, g.resolution], dtype=np.float64)
    else:
        bitmap_f = np.array([0.0, 0.0, 1.0])
    return Geometry(
        np.array([scene.bucket_origin[0], scene.bucket_origin[1], scene.bucket_size], dtype=np.float64),
        np.array([nx, ny], dtype=np.int64),
        np.ascontiguousarray(scene.bucket_segment_start, dtype=np.int64),
        np.ascontiguousarray(scene.bucket_segments, dtype=np.float64),
        np.ascontiguousarray(scene.bucket_segment_ids, dtype=np.int32),
        _cos_threshold(scene.segment_threshold),
        np.ascontiguousarray(scene.bucket_circle_start, dtype=np.int64),
        np.ascontiguousarray(scene.bucket_circles, dtype=np.float64),
        np.ascontiguousarray(scene.bucket_circle_ids, dtype=np.int32),
        _cos_threshold(scene.circle_threshold),
        np.ascontiguousarray(scene.bitmap, dtype=np.uint8),
        bitmap_f,
        float(_cos_threshold(scene.bitmap_threshold)),
        scene.bitmap_grid is not None,
    )


@numba.njit(cache=True, inline="always")
def _interval(o, d, lo, hi):
    """The (t_in, t_out) where lo <= o + t d <= hi; (inf, -inf) when never."""
    if d != 0.0:
        ta = (lo - o) / d
        tb = (hi - o) / d
        if ta > tb:
            return tb, ta
        return ta, tb
    if o < lo or o > hi:
        return np.inf, -np.inf
    return -np.inf, np.inf


@numba.njit(cache=True, inline="always", _nrt=False)
def _dda_start(ox, oy, dx, dy, tmax, gx0, gy0, cell, nx, ny):
    """Amanatides-Woo set-up for the ray o + t d over nx x ny cells of size ``cell`` from
    (gx0, gy0): the span t0..t1 inside the grid (t0 > t1: the ray misses it), whether it enters
    through an x face, the entry cell (ix, iy), the steps, the t of the next x and y faces and
    the t per cell in x and y."""
    tx_in, tx_out = _interval(ox, dx, gx0, gx0 + nx * cell)
    ty_in, ty_out = _interval(oy, dy, gy0, gy0 + ny * cell)
    t0 = max(0.0, tx_in, ty_in)
    t1 = min(tmax, tx_out, ty_out)
    if t0 > t1:
        return t0, t1, False, 0, 0, 1, 1, np.inf, np.inf, np.inf, np.inf
    ix = min(nx - 1, max(0, int(math.floor((ox + t0 * dx - gx0) / cell))))
    iy = min(ny - 1, max(0, int(math.floor((oy + t0 * dy - gy0) / cell))))
    sx, sy, tx, ty, tdx, tdy = dda_steps(ix, iy, ox, oy, dx, dy, gx0, gy0, cell)
    return t0, t1, tx_in >= ty_in, ix, iy, sx, sy, tx, ty, tdx, tdy


@numba.njit(cache=True, inline="always")
def _dda_step(i, step, t_next, t_delta, n):
    """One traversal step along one axis: (the next cell's index, the t of the edge after it,
    whether it lies in [0, n))."""
    i += step
    return i, t_next + t_delta, 0 <= i < n


@numba.njit(cache=True, inline="always", _nrt=False)
def _cast_shapes(ox, oy, dx, dy, tmax, geo):
    """First hit of the ray o + t d (d unit, 0 < t <= tmax) on segments and circles.

    Returns (t, cos_incidence, cos_threshold, nx, ny) with n the unit surface normal (either
    side); t = inf when nothing is hit.
    """
    best = np.inf
    best_cos = 0.0
    best_thr = -1.0
    bnx = 0.0
    bny = 0.0
    gx0 = geo.bucket_f[0]
    gy0 = geo.bucket_f[1]
    size = geo.bucket_f[2]
    nbx = geo.bucket_i[0]
    nby = geo.bucket_i[1]
    t0, t1, _, ix, iy, sx, sy, tx, ty, tdx, tdy = _dda_start(ox, oy, dx, dy, tmax, gx0, gy0, size, nbx, nby)
    if t0 > t1:
        return best, best_cos, best_thr, bnx, bny
    seg = geo.seg
    circ = geo.circ
    best_kind = -1
    best_k = 0
    while True:
        b = iy * nbx + ix
        for k in range(geo.seg_start[b], geo.seg_start[b + 1]):
            ex = seg[k, 2]
            ey = seg[k, 3]
            denom = dx * ey - dy * ex
            if denom == 0.0:
                continue
            wx = seg[k, 0] - ox
            wy = seg[k, 1] - oy
            inv = 1.0 / denom
            t = (wx * ey - wy * ex) * inv
            if t <= 0.0 or t >= best or t > tmax:
                continue
            s = (wx * dy - wy * dx) * inv
            if s < 0.0 or s > 1.0:
                continue
            best = t
            best_kind = 0
            best_k = k
        for k in range(geo.circ_start[b], geo.circ_start[b + 1]):
            cx = ox - circ[k, 0]
            cy = oy - circ[k, 1]
            r = circ[k, 2]
            bb = dx * cx + dy * cy
            cc = cx * cx + cy * cy - r * r
            if cc <= 0.0:
                continue  # the ray starts inside the circle
            disc = bb * bb - cc
            if disc < 0.0:
                continue
            t = -bb - math.sqrt(disc)
            if t <= 0.0 or t >= best or t > tmax:
                continue
            best = t
            best_kind = 1
            best_k = k
        t_next = min(tx, ty)
        if best <= t_next or t_next > t1:
            break
        if tx < ty:
            ix, tx, inside = _dda_step(ix, sx, tx, tdx, nbx)
        else:
            iy, ty, inside = _dda_step(iy, sy, ty, tdy, nby)
        if not inside:
            break
    if best_kind == 0:
        ex = seg[best_k, 2]
        ey = seg[best_k, 3]
        length = math.sqrt(ex * ex + ey * ey)
        bnx = -ey / length
        bny = ex / length
        best_cos = abs(dx * bnx + dy * bny)
        best_thr = geo.seg_cos_threshold[geo.seg_id[best_k]]
    elif best_kind == 1:
        r = circ[best_k, 2]
        bnx = (ox + best * dx - circ[best_k, 0]) / r
        bny = (oy + best * dy - circ[best_k, 1]) / r
        best_cos = abs(dx * bnx + dy * bny)
        best_thr = geo.circ_cos_threshold[geo.circ_id[best_k]]
    return best, best_cos, best_thr, bnx, bny


@numba.njit(cache=True, inline="always", _nrt=False)
def _cast_bitmap(ox, oy, dx, dy, tmax, bitmap, gx0, gy0, res):
    """First occupied pixel the ray o + t d (d unit, t <= tmax) enters (Amanatides-Woo).

    The pixel holding the origin is not tested (a ray starts in free space). Returns
    (t, cos_incidence, nx, ny) with n the normal of the face entered; t = inf for no hit.
    """
    h, w = bitmap.shape
    t0, t1, x_face, ix, iy, sx, sy, tx, ty, tdx, tdy = _dda_start(ox, oy, dx, dy, tmax, gx0, gy0, res, w, h)
    if t0 > t1:
        return np.inf, 0.0, 0.0, 0.0
    # entering from outside the bitmap: the entry pixel is tested, through the face crossed
    test = t0 > 0.0
    t_in = t0
    while True:
        if test and bitmap[iy, ix] != 0:
            if x_face:
                return t_in, abs(dx), -float(sx), 0.0
            return t_in, abs(dy), 0.0, -float(sy)
        test = True
        x_face = tx < ty
        if x_face:
            t_in = tx
            ix, tx, inside = _dda_step(ix, sx, tx, tdx, w)
        else:
            t_in = ty
            iy, ty, inside = _dda_step(iy, sy, ty, tdy, h)
        if not inside or t_in > t1:
            break
    return np.inf, 0.0, 0.0, 0.0


@numba.njit(cache=True, inline="always", _nrt=False)
def first_hit(ox, oy, dx, dy, tmax, geo):
    """First hit of the ray from (ox, oy) along unit (dx, dy) within tmax, on any surface.

    Returns (t, cos_incidence, cos_threshold, nx, ny): distance (inf if none), cosine of the
    incidence angle from the surface normal, cosine of the surface's specular threshold, and
    the unit normal n (either side).
    """
    t, c, thr, nx, ny = _cast_shapes(ox, oy, dx, dy, tmax, geo)
    if geo.has_bitmap:
        tb, cb, bnx, bny = _cast_bitmap(ox, oy, dx, dy, min(t, tmax), geo.bitmap, geo.bitmap_f[0], geo.bitmap_f[1], geo.bitmap_f[2])
        if tb < t:
            return tb, cb, geo.bitmap_cos_threshold, bnx, bny
    return t, c, thr, nx, ny


@numba.njit(cache=True, inline="always", _nrt=False)
def trace_sub_ray(ox, oy, dx, dy, limit, max_bounces, geo):
    """Follow one sub-ray (unit direction): echo at the first hit within its surface's
    threshold, else mirror-bounce, up to ``max_bounces`` times, over a total path <= limit.

    Returns (first_t, echo, bounces, cos_incidence): the distance of the first surface hit
    (inf if none within limit), the one-way path length to the echoing surface (inf if none
    within limit), the number of bounces before it and the cosine of the echo's incidence angle
    on that surface (0 when there is no echo).
    """
    first = np.inf
    path = 0.0
    for bounce in range(max_bounces + 1):
        t, c, cthr, nx, ny = first_hit(ox, oy, dx, dy, limit - path, geo)
        if t == np.inf:
            break
        if bounce == 0:
            first = t
        path += t
        if c >= cthr:
            return first, path, bounce, c
        dn = dx * nx + dy * ny
        side = 1.0 if dn > 0.0 else -1.0
        ox = ox + t * dx - side * BOUNCE_OFFSET * nx
        oy = oy + t * dy - side * BOUNCE_OFFSET * ny
        dx = dx - 2.0 * dn * nx
        dy = dy - 2.0 * dn * ny
    return first, np.inf, 0, 0.0
