"""The robot's path through the world: scan times and poses sampled from the trajectory config."""

from __future__ import annotations

import math

import numpy as np

from aogm_cli.world.config import World


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
