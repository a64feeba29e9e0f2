"""How low block can go on a simulated log when a map may only call free what some reading heard pass: the
planner's block (and leak) of the truth itself, shown only where a reading's lobe covers a cell
(docs/algorithms.md, "The lobe that hears": what office_doors' block is made of).

    python bench/heard_coverage.py LOG.h5 [LOG.h5 ...] [--lobe DEG RANGE] ...

Per log and lobe (theta0 in degrees, its axis range R0 in m; 0 0: the whole cone): a cell counts as covered
when a reading's cone holds it no farther than the reading's range plus half a cell and
``sensor_models.heard.heard_cells`` hears it (a cell at range r and angle phi off the axis, r <= R0 exp(-(phi /
theta0)^2)); the oracle map is the truth at covered cells and the robot's footprint, unobserved elsewhere.
Its ``block`` is what no map that infers free floor only from heard passes can go below, whatever its
sensor model (a reading passing a cell it could not have heard says nothing about it); ``leak`` is 0.
"""

from __future__ import annotations

import argparse
import math

import numba
import numpy as np

from aogm_cli.core.frames import sensor_poses
from aogm_cli.evaluation.planner import ROBOT_RADIUS, planner_metrics
from aogm_cli.io.logfile import LogReader
from aogm_cli.mapping.view import footprint


@numba.njit(cache=True)
def _cover(sx, sy, yaw, z, half, max_range, theta0, r0, ox, oy, res, out):
    """Mark in ``out`` (H, W) the cells each reading's cone covers out to its range and its lobe hears."""
    h, w = out.shape
    for t in range(sx.shape[0]):
        reach = min(z[t], max_range) + 0.5 * res if math.isfinite(z[t]) else max_range
        if theta0 > 0.0:
            reach = min(reach, r0)
        c0 = max(0, int((sx[t] - reach - ox) / res))
        c1 = min(w - 1, int((sx[t] + reach - ox) / res))
        r_0 = max(0, int((sy[t] - reach - oy) / res))
        r_1 = min(h - 1, int((sy[t] + reach - oy) / res))
        for row in range(r_0, r_1 + 1):
            dy = oy + (row + 0.5) * res - sy[t]
            for col in range(c0, c1 + 1):
                dx = ox + (col + 0.5) * res - sx[t]
                r = math.hypot(dx, dy)
                if r > reach:
                    continue
                phi = abs((math.atan2(dy, dx) - yaw[t] + math.pi) % (2.0 * math.pi) - math.pi)
                if phi > half:
                    continue
                if theta0 > 0.0 and r > r0 * math.exp(-(phi / theta0) ** 2):
                    continue
                out[row, col] = True


def coverage(log, theta0_deg: float, r0: float) -> np.ndarray:
    """Bool (H, W) on the log's truth grid: the cells some reading covers under the lobe (0: the whole cone)."""
    grid = log.truth.grid
    poses = sensor_poses(log.pose, log.sensor.mount)
    z = np.asarray(log.ranges, dtype=np.float64)
    ok = np.isfinite(poses).all(axis=2) & ~np.isnan(z)
    out = np.zeros(grid.shape, dtype=bool)
    _cover(poses[..., 0][ok], poses[..., 1][ok], poses[..., 2][ok], z[ok], 0.5 * log.sensor.beam_width,
           log.sensor.max_range, math.radians(theta0_deg), r0, grid.origin_x, grid.origin_y, grid.resolution, out)
    return out


def oracle(log_path: str, lobes: list[tuple[float, float]]) -> list[str]:
    with LogReader(log_path) as reader:
        log = reader.read()
    grid, truth = log.truth.grid, np.asarray(log.truth.occupancy)
    body = footprint(grid, log.pose, log.sensor)
    lines = []
    for theta0, r0 in lobes:
        observed = coverage(log, theta0, r0) | body
        probability = np.where(truth != 0, 1.0, 0.0)
        probability[~observed] = 0.5
        m = planner_metrics(grid, probability, observed, truth, log.poses(), ROBOT_RADIUS)
        lobe = "whole cone" if theta0 <= 0 else f"theta0 {theta0:g} deg, R0 {r0:g} m"
        lines.append(f"{log_path}: {lobe}: block {m['block']:.3f}, leak {m['leak']:.3f}, covered "
                     f"{int(observed.sum())} cells")
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("logs", nargs="+")
    parser.add_argument("--lobe", nargs=2, type=float, action="append", metavar=("DEG", "RANGE"),
                        help="theta0 (deg) and R0 (m); repeat; 0 0: the whole cone (default: 0 0)")
    args = parser.parse_args()
    for path in args.logs:
        for line in oracle(path, [tuple(x) for x in args.lobe] if args.lobe else [(0.0, 0.0)]):
            print(line)


if __name__ == "__main__":
    main()
