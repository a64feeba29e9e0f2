"""The world's solids in world coordinates: walls cut at their openings into rectangles, boxes, polygons
and circles, and the centre lines of those thinner than a truth cell's diagonal. Both the ray-castable
scene (``world.scene``) and the truth raster (``world.truth``) start here."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from aogm_cli.world.config import Wall, World

SQRT2 = math.sqrt(2.0)


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
