"""World geometry compiled for the simulator: the ray-castable scene, the truth raster, the path.

``build_scene`` turns walls, boxes, polygons, circles and a floor plan into flat arrays (edge
segments, circles, a bitmap and a bucket grid) for ``simulation.raycast``; ``truth_occupancy``
rasterises the same solids onto the truth grid; ``trajectory_poses`` samples the robot's path.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

from aogm_cli.core.grid import GridSpec, dda_steps
from aogm_cli.world.config import Wall, World

SQRT2 = math.sqrt(2.0)
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


@dataclass(frozen=True)
class Solids:
    """The world's solids in world coordinates, before they become kernel arrays.

    ``polygons`` are closed outlines (wall pieces, boxes, polygons) with their surface names;
    ``centre_lines`` (L, 4) are the segments to mark on the truth grid because their shape is
    thinner than a cell's diagonal.
    """

    polygons: list[tuple[np.ndarray, str]]
    circles: list[tuple[float, float, float, str]]
    centre_lines: np.ndarray


# -- solids ---------------------------------------------------------------------------------


def _solid_intervals(length: float, openings) -> list[tuple[float, float]]:
    """[0, length] minus every opening [at - width/2, at + width/2], as sorted intervals."""
    cuts = sorted((max(0.0, o.at - o.width / 2), min(length, o.at + o.width / 2)) for o in openings)
    intervals = []
    start = 0.0
    for a, b in cuts:
        if a > start:
            intervals.append((start, a))
        start = max(start, b)
    if length > start:
        intervals.append((start, length))
    return intervals


def wall_pieces(wall: Wall) -> list[tuple[np.ndarray, np.ndarray]]:
    """The wall as rectangles: one per polyline leg of each piece between openings.

    Returns (corners (4, 2), centre line (2, 2)) per rectangle. A rectangle is extended by
    thickness/2 past a polyline joint that lies inside a piece (and past the closing joint of
    a closed polyline), so that corners close; it is not extended at openings or free ends.
    """
    pts = [tuple(map(float, p)) for p in wall.points]
    dedup = [pts[0]]
    for p in pts[1:]:
        if math.dist(p, dedup[-1]) > 0.0:
            dedup.append(p)
    pts = np.asarray(dedup, dtype=np.float64)
    n = len(pts)
    if n < 2:
        return []
    leg = np.hypot(*np.diff(pts, axis=0).T)
    cum = np.concatenate([[0.0], np.cumsum(leg)])
    length = float(cum[-1])
    closed = n > 2 and math.dist(tuple(pts[0]), tuple(pts[-1])) < 1e-9
    intervals = _solid_intervals(length, wall.openings)
    closing_solid = closed and intervals and intervals[0][0] == 0.0 and intervals[-1][1] == length
    h = wall.thickness / 2
    out = []
    for a, b in intervals:
        for i in range(n - 1):
            s0, s1 = max(a, cum[i]), min(b, cum[i + 1])
            if s1 - s0 <= 1e-12:
                continue
            u = (pts[i + 1] - pts[i]) / leg[i]
            p0 = pts[i] + u * (s0 - cum[i])
            p1 = pts[i] + u * (s1 - cum[i])
            ext0 = h if ((i > 0 and a < cum[i] <= s0) or (i == 0 and s0 == 0.0 and closing_solid)) else 0.0
            ext1 = h if ((i + 1 < n - 1 and b > cum[i + 1] >= s1) or (i + 1 == n - 1 and s1 == length and closing_solid)) else 0.0
            v = np.array([-u[1], u[0]]) * h
            q0 = p0 - u * ext0
            q1 = p1 + u * ext1
            corners = np.array([q0 + v, q1 + v, q1 - v, q0 - v])
            out.append((corners, np.array([p0, p1])))
    return out


def box_corners(center, size, yaw) -> np.ndarray:
    """The four corners (4, 2) of a box, counter-clockwise."""
    c, s = math.cos(yaw), math.sin(yaw)
    hx, hy = size[0] / 2, size[1] / 2
    local = np.array([[-hx, -hy], [hx, -hy], [hx, hy], [-hx, hy]])
    rot = np.array([[c, -s], [s, c]])
    return local @ rot.T + np.asarray(center, dtype=np.float64)


def world_solids(world: World, resolution: float | None = None) -> Solids:
    """Every solid of ``world`` as an outline or circle; centre lines of shapes thinner than a
    cell's diagonal at ``resolution`` (default: the truth resolution)."""
    res = world.truth_resolution if resolution is None else resolution
    thin = res * SQRT2
    polygons: list[tuple[np.ndarray, str]] = []
    lines: list[np.ndarray] = []
    for wall in world.walls:
        for corners, centre in wall_pieces(wall):
            polygons.append((corners, wall.surface))
            if wall.thickness < thin:
                lines.append(centre.reshape(4))
    for box in world.boxes:
        corners = box_corners(box.center, box.size, box.yaw)
        polygons.append((corners, box.surface))
        if min(box.size) < thin:
            # the medial axis along the longer side
            if box.size[0] >= box.size[1]:
                a, b = (corners[0] + corners[3]) / 2, (corners[1] + corners[2]) / 2
            else:
                a, b = (corners[0] + corners[1]) / 2, (corners[3] + corners[2]) / 2
            lines.append(np.concatenate([a, b]))
    for poly in world.polygons:
        pts = np.asarray(poly.points, dtype=np.float64)
        polygons.append((pts, poly.surface))
        nxt = np.roll(pts, -1, axis=0)
        perimeter = float(np.hypot(*(nxt - pts).T).sum())
        area = 0.5 * abs(float(np.sum(pts[:, 0] * nxt[:, 1] - nxt[:, 0] * pts[:, 1])))
        if perimeter > 0 and 2 * area / perimeter < thin:
            # a sliver: its edges lie within half its width of its centre line
            lines.extend(np.concatenate([pts, nxt], axis=1))
    circles = [(float(c.center[0]), float(c.center[1]), float(c.radius), c.surface) for c in world.circles]
    centre_lines = np.asarray(lines, dtype=np.float64).reshape(-1, 4)
    return Solids(polygons, circles, centre_lines)


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


# -- scene ----------------------------------------------------------------------------------


def build_scene(world: World, bucket_size: float = DEFAULT_BUCKET_SIZE) -> Scene:
    """Compile ``world`` into a ``Scene``: edge segments, circles, floor-plan bitmap, bucket grid."""
    solids = world_solids(world)
    segments, seg_thr = _edges(solids.polygons, world.surfaces)
    circles = np.array([c[:3] for c in solids.circles], dtype=np.float64).reshape(-1, 3)
    circ_thr = np.array([world.surfaces[c[3]].specular_threshold for c in solids.circles], dtype=np.float64)

    bitmap = np.zeros((1, 1), dtype=np.uint8)
    bitmap_grid = None
    bitmap_thr = math.pi / 2
    if world.floorplan is not None:
        from aogm_cli.io.map_server import read_map_yaml

        rosmap = read_map_yaml(world.floorplan.map)
        bitmap = np.ascontiguousarray(np.asarray(rosmap.data) == 100, dtype=np.uint8)
        bitmap_grid = rosmap.grid_spec()
        bitmap_thr = world.surfaces[world.floorplan.surface].specular_threshold

    # the bucket grid covers the bounds and every segment and circle
    x_lo, y_lo, x_hi, y_hi = (float(v) for v in world.bounds)
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
    x_lo, y_lo, x_hi, y_hi = x_lo - pad, y_lo - pad, x_hi + pad, y_hi + pad
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


# -- truth raster ---------------------------------------------------------------------------


@numba.njit(cache=True)
def _fill_polygons(occ, ox, oy, res, xy, start):
    """Mark the cells whose centre lies inside each polygon (even-odd rule, half-open edges).

    Polygon p has vertices ``xy[start[p]:start[p+1]]``; each is filled by scanlines through
    the cell centres over its bounding box only.
    """
    h, w = occ.shape
    for p in range(start.shape[0] - 1):
        a = start[p]
        n = start[p + 1] - a
        if n < 3:
            continue
        ymin = xy[a, 1]
        ymax = xy[a, 1]
        for k in range(a, a + n):
            ymin = min(ymin, xy[k, 1])
            ymax = max(ymax, xy[k, 1])
        r0 = max(0, int(math.ceil((ymin - oy) / res - 0.5)))
        r1 = min(h - 1, int(math.floor((ymax - oy) / res - 0.5)))
        xs = np.empty(n)
        for r in range(r0, r1 + 1):
            yc = oy + (r + 0.5) * res
            m = 0
            for k in range(n):
                x0, y0 = xy[a + k, 0], xy[a + k, 1]
                k1 = a + (k + 1) % n
                x1, y1 = xy[k1, 0], xy[k1, 1]
                if (y0 <= yc < y1) or (y1 <= yc < y0):
                    xs[m] = x0 + (yc - y0) * (x1 - x0) / (y1 - y0)
                    m += 1
            if m < 2:
                continue
            cross = np.sort(xs[:m])
            for q in range(0, m - 1, 2):
                c0 = max(0, int(math.ceil((cross[q] - ox) / res - 0.5)))
                c1 = min(w, int(math.ceil((cross[q + 1] - ox) / res - 0.5)))
                for c in range(c0, c1):
                    occ[r, c] = 1


@numba.njit(cache=True)
def _fill_circles(occ, ox, oy, res, circles):
    """Mark the cells whose centre lies inside each circle, and the cell holding its centre."""
    h, w = occ.shape
    for k in range(circles.shape[0]):
        cx, cy, rad = circles[k, 0], circles[k, 1], circles[k, 2]
        r0 = max(0, int(math.ceil((cy - rad - oy) / res - 0.5)))
        r1 = min(h - 1, int(math.floor((cy + rad - oy) / res - 0.5)))
        for r in range(r0, r1 + 1):
            dy = oy + (r + 0.5) * res - cy
            if dy * dy > rad * rad:
                continue
            half = math.sqrt(rad * rad - dy * dy)
            c0 = max(0, int(math.ceil((cx - half - ox) / res - 0.5)))
            c1 = min(w, int(math.ceil((cx + half - ox) / res - 0.5)))
            for c in range(c0, c1):
                occ[r, c] = 1
        cr = int(math.floor((cy - oy) / res))
        cc = int(math.floor((cx - ox) / res))
        if 0 <= cr < h and 0 <= cc < w:
            occ[cr, cc] = 1


@numba.njit(cache=True)
def _mark_lines(occ, ox, oy, res, lines):
    """Mark every cell each segment passes through (a 4-connected grid traversal).

    A segment ending exactly on a cell boundary does not mark the cell beyond it.
    """
    h, w = occ.shape
    for k in range(lines.shape[0]):
        x0, y0, x1, y1 = lines[k, 0], lines[k, 1], lines[k, 2], lines[k, 3]
        dx = x1 - x0
        dy = y1 - y0
        u0 = (x0 - ox) / res
        v0 = (y0 - oy) / res
        u1 = (x1 - ox) / res
        v1 = (y1 - oy) / res
        ix = int(math.floor(u0)) if dx >= 0 else int(math.ceil(u0)) - 1
        iy = int(math.floor(v0)) if dy >= 0 else int(math.ceil(v0)) - 1
        ex = int(math.ceil(u1)) - 1 if dx > 0 else int(math.floor(u1))
        ey = int(math.ceil(v1)) - 1 if dy > 0 else int(math.floor(v1))
        if dx > 0:
            ex = max(ex, ix)
        elif dx < 0:
            ex = min(ex, ix)
        if dy > 0:
            ey = max(ey, iy)
        elif dy < 0:
            ey = min(ey, iy)
        sx, sy, tx, ty, tdx, tdy = dda_steps(ix, iy, x0, y0, dx, dy, ox, oy, res)
        steps = abs(ex - ix) + abs(ey - iy)
        if 0 <= iy < h and 0 <= ix < w:
            occ[iy, ix] = 1
        for _ in range(steps):
            if (tx < ty and ix != ex) or iy == ey:
                ix += sx
                tx += tdx
            else:
                iy += sy
                ty += tdy
            if 0 <= iy < h and 0 <= ix < w:
                occ[iy, ix] = 1


def truth_occupancy(world: World) -> tuple[GridSpec, np.ndarray]:
    """The truth grid over ``world.bounds`` and its occupancy (H, W) uint8, 1 = occupied.

    A cell is occupied when a solid (wall piece, box, polygon, circle, occupied floor-plan
    pixel) covers its centre. Shapes thinner than a cell's diagonal also mark every cell their
    centre line crosses, a circle the cell holding its centre and a floor-plan pixel the cell
    holding the pixel's centre, so thin solids leave no gaps.
    """
    grid = GridSpec.covering(*world.bounds, world.truth_resolution)
    occ = np.zeros(grid.shape, dtype=np.uint8)
    ox, oy, res = grid.origin_x, grid.origin_y, grid.resolution
    solids = world_solids(world, res)
    if solids.polygons:
        xy = np.ascontiguousarray(np.concatenate([p for p, _ in solids.polygons]), dtype=np.float64)
        start = np.concatenate([[0], np.cumsum([len(p) for p, _ in solids.polygons])]).astype(np.int64)
        _fill_polygons(occ, ox, oy, res, xy, start)
    if solids.circles:
        _fill_circles(occ, ox, oy, res, np.array([c[:3] for c in solids.circles], dtype=np.float64))
    if len(solids.centre_lines):
        _mark_lines(occ, ox, oy, res, solids.centre_lines)
    if world.floorplan is not None:
        from aogm_cli.io.map_server import read_map_yaml

        rosmap = read_map_yaml(world.floorplan.map)
        _mark_bitmap(occ, grid, np.asarray(rosmap.data) == 100, rosmap.grid_spec())
    return grid, occ


def _mark_bitmap(occ: np.ndarray, grid: GridSpec, occupied: np.ndarray, fgrid: GridSpec) -> None:
    """Mark truth cells whose centre lies in an occupied pixel, and cells holding an occupied pixel's centre."""
    xs = grid.origin_x + (np.arange(grid.width) + 0.5) * grid.resolution
    ys = grid.origin_y + (np.arange(grid.height) + 0.5) * grid.resolution
    fc = np.floor((xs - fgrid.origin_x) / fgrid.resolution).astype(np.int64)
    fr = np.floor((ys - fgrid.origin_y) / fgrid.resolution).astype(np.int64)
    cols = np.flatnonzero((fc >= 0) & (fc < fgrid.width))
    rows = np.flatnonzero((fr >= 0) & (fr < fgrid.height))
    if cols.size and rows.size:
        sub = occupied[np.ix_(fr[rows], fc[cols])]
        occ[np.ix_(rows, cols)] |= sub.astype(np.uint8)
    pr, pc = np.nonzero(occupied)
    if pr.size:
        x, y = fgrid.cell_centre(pr, pc)
        r, c = grid.world_to_cell(x, y)
        inside = grid.contains(r, c)
        occ[r[inside], c[inside]] = 1


# -- trajectory -----------------------------------------------------------------------------


def trajectory_poses(world: World) -> tuple[np.ndarray, np.ndarray]:
    """Scan times (T,) and robot poses (T, 3) of the world's trajectory.

    Waypoints are driven in straight legs at ``speed``, with a scan every ``scan_period``
    seconds, that is every speed * scan_period metres along the polyline from the first
    waypoint (the last waypoint gets a scan only if it falls on that spacing); the yaw is the
    heading of the leg being driven (at a waypoint, of the leg that starts there). Explicit
    poses are scanned ``scan_period`` seconds apart.
    """
    traj = world.trajectory
    if traj.poses:
        pose = np.asarray(traj.poses, dtype=np.float64).reshape(-1, 3)
        return np.arange(len(pose), dtype=np.float64) * traj.scan_period, pose
    pts = [tuple(map(float, traj.waypoints[0]))]
    for p in traj.waypoints[1:]:
        if math.dist(p, pts[-1]) > 0.0:
            pts.append(tuple(map(float, p)))
    wp = np.asarray(pts, dtype=np.float64)
    d = np.diff(wp, axis=0)
    leg = np.hypot(d[:, 0], d[:, 1])
    cum = np.concatenate([[0.0], np.cumsum(leg)])
    step = traj.speed * traj.scan_period
    n = int(math.floor(cum[-1] / step + 1e-9)) + 1
    idx = np.arange(n)
    s = np.minimum(idx * step, cum[-1])
    i = np.clip(np.searchsorted(cum, s, side="right") - 1, 0, len(leg) - 1)
    frac = (s - cum[i]) / leg[i]
    xy = wp[i] + d[i] * frac[:, None]
    yaw = np.arctan2(d[i, 1], d[i, 0])
    pose = np.column_stack([xy, yaw])
    return idx * traj.scan_period, pose
