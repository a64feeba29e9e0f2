"""The ray-castable scene: the world's solids compiled into flat arrays for ``simulation.raycast``:
``Scene`` (edge segments, circles, a floor-plan bitmap and a uniform bucket grid in CSR form) and
``build_scene``, with the kernels that sort segments and circles into buckets."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

from aogm_cli.core.grid import GridSpec
from aogm_cli.world.config import World
from aogm_cli.world.solids import world_solids

DEFAULT_BUCKET_SIZE = 1.0  # m; see bench/bench_simulate.py
MAX_BUCKETS = 1 << 20


@dataclass(frozen=True)
class Scene:
    """The world's solids as arrays for the ray-casting kernels.

    Edge segments (N, 4) = (x0, y0, x1, y1) with each one's specular threshold (rad); circles
    (M, 3) = (cx, cy, r) with theirs; an optional bitmap (H, W) uint8, 1 = occupied, on
    ``bitmap_grid``. A uniform bucket grid (origin, square ``bucket_size``, ``bucket_shape`` =
    (ny, nx)) lists in CSR form the segments and circles touching each bucket, bucket
    b = iy * nx + ix holding ``bucket_segment_ids[bucket_segment_start[b]:bucket_segment_start[b+1]]``.
    ``bucket_segments`` (K, 4) repeats (x0, y0, x1 - x0, y1 - y0) of those segments in the same
    order and ``bucket_circles`` (Kc, 3) the circles, so a ray reads memory in sequence.
    """

    segments: np.ndarray
    segment_threshold: np.ndarray
    circles: np.ndarray
    circle_threshold: np.ndarray
    bucket_origin: tuple[float, float]
    bucket_size: float
    bucket_shape: tuple[int, int]
    bucket_segment_start: np.ndarray
    bucket_segment_ids: np.ndarray
    bucket_segments: np.ndarray
    bucket_circle_start: np.ndarray
    bucket_circle_ids: np.ndarray
    bucket_circles: np.ndarray
    bitmap: np.ndarray
    bitmap_grid: GridSpec | None
    bitmap_threshold: float

    @property
    def n_segments(self) -> int:
        return int(self.segments.shape[0])

    @property
    def n_circles(self) -> int:
        return int(self.circles.shape[0])


def _edges(polygons: list[tuple[np.ndarray, str]], surfaces) -> tuple[np.ndarray, np.ndarray]:
    segs, thr = [], []
    for pts, surface in polygons:
        nxt = np.roll(pts, -1, axis=0)
        e = np.concatenate([pts, nxt], axis=1)
        e = e[np.hypot(e[:, 2] - e[:, 0], e[:, 3] - e[:, 1]) > 0]
        segs.append(e)
        thr.append(np.full(len(e), surfaces[surface].specular_threshold))
    if not segs:
        return np.zeros((0, 4)), np.zeros(0)
    return np.concatenate(segs).astype(np.float64), np.concatenate(thr).astype(np.float64)


def build_scene(world: World, bucket_size: float = DEFAULT_BUCKET_SIZE) -> Scene:
    """Compile ``world`` into a ``Scene``: edge segments, circles, floor-plan bitmap, bucket grid."""
    solids = world_solids(world)
    segments, seg_thr = _edges(solids.polygons, world.surfaces)
    circles = np.array([c[:3] for c in solids.circles], dtype=np.float64).reshape(-1, 3)
    circ_thr = np.array([world.surfaces[c[3]].specular_threshold for c in solids.circles], dtype=np.float64)

    bitmap, bitmap_grid, bitmap_thr = _floorplan_bitmap(world)
    x_lo, y_lo, x_hi, y_hi = _bucket_extent(world.bounds, segments, circles)
    size = float(bucket_size)
    while math.ceil((x_hi - x_lo) / size) * math.ceil((y_hi - y_lo) / size) > MAX_BUCKETS:
        size *= 2
    nx = max(1, math.ceil((x_hi - x_lo) / size))
    ny = max(1, math.ceil((y_hi - y_lo) / size))
    seg_start, seg_ids = _bucket_segments(segments, x_lo, y_lo, size, nx, ny)
    circ_start, circ_ids = _bucket_circles(circles, x_lo, y_lo, size, nx, ny)
    b_seg = segments[seg_ids]
    b_seg = np.ascontiguousarray(np.stack([b_seg[:, 0], b_seg[:, 1], b_seg[:, 2] - b_seg[:, 0], b_seg[:, 3] - b_seg[:, 1]], axis=1))
    return Scene(
        segments=segments,
        segment_threshold=seg_thr,
        circles=circles,
        circle_threshold=circ_thr,
        bucket_origin=(x_lo, y_lo),
        bucket_size=size,
        bucket_shape=(ny, nx),
        bucket_segment_start=seg_start,
        bucket_segment_ids=seg_ids,
        bucket_segments=b_seg.reshape(-1, 4),
        bucket_circle_start=circ_start,
        bucket_circle_ids=circ_ids,
        bucket_circles=np.ascontiguousarray(circles[circ_ids]).reshape(-1, 3),
        bitmap=bitmap,
        bitmap_grid=bitmap_grid,
        bitmap_threshold=float(bitmap_thr),
    )


def _floorplan_bitmap(world: World) -> tuple[np.ndarray, GridSpec | None, float]:
    """The floor plan's occupied pixels (H, W) uint8, their grid and specular threshold; a 1 x 1
    empty bitmap without a grid when the world has no floor plan."""
    if world.floorplan is None:
        return np.zeros((1, 1), dtype=np.uint8), None, math.pi / 2
    rosmap = world.floorplan.plan
    bitmap = np.ascontiguousarray(np.asarray(rosmap.data) == 100, dtype=np.uint8)
    return bitmap, rosmap.grid_spec(), world.surfaces[world.floorplan.surface].specular_threshold


def _bucket_extent(bounds, segments: np.ndarray, circles: np.ndarray) -> tuple[float, float, float, float]:
    """(x_lo, y_lo, x_hi, y_hi) the bucket grid covers: the bounds and every segment and circle, padded."""
    x_lo, y_lo, x_hi, y_hi = (float(v) for v in bounds)
    if len(segments):
        x_lo = min(x_lo, float(segments[:, [0, 2]].min()))
        x_hi = max(x_hi, float(segments[:, [0, 2]].max()))
        y_lo = min(y_lo, float(segments[:, [1, 3]].min()))
        y_hi = max(y_hi, float(segments[:, [1, 3]].max()))
    if len(circles):
        x_lo = min(x_lo, float((circles[:, 0] - circles[:, 2]).min()))
        x_hi = max(x_hi, float((circles[:, 0] + circles[:, 2]).max()))
        y_lo = min(y_lo, float((circles[:, 1] - circles[:, 2]).min()))
        y_hi = max(y_hi, float((circles[:, 1] + circles[:, 2]).max()))
    pad = 1e-6 * max(1.0, x_hi - x_lo, y_hi - y_lo)
    return x_lo - pad, y_lo - pad, x_hi + pad, y_hi + pad


@numba.njit(cache=True)
def _segment_touches_box(x0, y0, x1, y1, bx0, by0, bx1, by1):
    """Whether segment (x0, y0)-(x1, y1) touches the box [bx0, bx1] x [by0, by1]."""
    if max(x0, x1) < bx0 or min(x0, x1) > bx1 or max(y0, y1) < by0 or min(y0, y1) > by1:
        return False
    ex = x1 - x0
    ey = y1 - y0
    pos = False
    neg = False
    for cx, cy in ((bx0, by0), (bx1, by0), (bx1, by1), (bx0, by1)):
        side = ex * (cy - y0) - ey * (cx - x0)
        if side >= 0.0:
            pos = True
        if side <= 0.0:
            neg = True
    return pos and neg


@numba.njit(cache=True)
def _bucket_segments_kernel(segments, x_lo, y_lo, size, nx, ny, counts, ids, fill):
    """Count (fill=False) or write (fill=True) each segment into every bucket it touches."""
    eps = 1e-9 * size
    for k in range(segments.shape[0]):
        x0, y0, x1, y1 = segments[k, 0], segments[k, 1], segments[k, 2], segments[k, 3]
        ix0 = max(0, int(math.floor((min(x0, x1) - x_lo) / size)))
        ix1 = min(nx - 1, int(math.floor((max(x0, x1) - x_lo) / size)))
        iy0 = max(0, int(math.floor((min(y0, y1) - y_lo) / size)))
        iy1 = min(ny - 1, int(math.floor((max(y0, y1) - y_lo) / size)))
        for iy in range(iy0, iy1 + 1):
            for ix in range(ix0, ix1 + 1):
                bx = x_lo + ix * size
                by = y_lo + iy * size
                if _segment_touches_box(x0, y0, x1, y1, bx - eps, by - eps, bx + size + eps, by + size + eps):
                    b = iy * nx + ix
                    if fill:
                        ids[counts[b]] = k
                    counts[b] += 1


def _bucket_segments(segments, x_lo, y_lo, size, nx, ny):
    counts = np.zeros(nx * ny, dtype=np.int64)
    ids = np.zeros(0, dtype=np.int32)
    _bucket_segments_kernel(segments, x_lo, y_lo, size, nx, ny, counts, ids, False)
    start = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    ids = np.zeros(int(start[-1]), dtype=np.int32)
    cursor = start[:-1].copy()
    _bucket_segments_kernel(segments, x_lo, y_lo, size, nx, ny, cursor, ids, True)
    return start, ids


def _bucket_circles(circles, x_lo, y_lo, size, nx, ny):
    """Circles by the buckets their bounding box touches (CSR start, ids)."""
    rows: list[np.ndarray] = []
    buckets: list[np.ndarray] = []
    for k, (cx, cy, r) in enumerate(circles):
        ix0 = max(0, math.floor((cx - r - x_lo) / size))
        ix1 = min(nx - 1, math.floor((cx + r - x_lo) / size))
        iy0 = max(0, math.floor((cy - r - y_lo) / size))
        iy1 = min(ny - 1, math.floor((cy + r - y_lo) / size))
        iy, ix = np.mgrid[iy0 : iy1 + 1, ix0 : ix1 + 1]
        b = (iy * nx + ix).ravel()
        buckets.append(b)
        rows.append(np.full(b.size, k))
    if not buckets:
        return np.zeros(nx * ny + 1, dtype=np.int64), np.zeros(0, dtype=np.int32)
    b = np.concatenate(buckets)
    k = np.concatenate(rows)
    order = np.lexsort((k, b))
    counts = np.bincount(b, minlength=nx * ny)
    start = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    return start, k[order].astype(np.int32)
