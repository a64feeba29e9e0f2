"""The robot's path through the world: scan times and poses sampled from the trajectory config."""

from __future__ import annotations

import math

import numpy as np

from aogm_cli.world.config import Trajectory, World


def trajectory_poses(world: World) -> tuple[np.ndarray, np.ndarray]:
    """Scan times (T,) and robot poses (T, 3) of the world's trajectory.

    Waypoints are driven in straight legs at ``speed``, with a scan every ``scan_period``
    seconds, that is every speed * scan_period metres along the polyline from the first
    waypoint (the last waypoint gets a scan only if it falls on that spacing); the yaw is the
    heading of the leg being driven (at a waypoint, of the leg that starts there). With a
    ``turn_rate`` the robot stops at each waypoint and turns in place to the next leg's heading
    (the shorter way) at that rate, and scans every ``scan_period`` seconds of the drives and
    turns. Explicit poses are scanned ``scan_period`` seconds apart.
    """
    traj = world.trajectory
    if traj.poses:
        pose = np.asarray(traj.poses, dtype=np.float64).reshape(-1, 3)
        return np.arange(len(pose), dtype=np.float64) * traj.scan_period, pose
    path = Polyline(traj.waypoints)
    if traj.turn_rate > 0.0:
        time = np.arange(int(math.floor(path.duration(traj) / traj.scan_period + 1e-9)) + 1) * traj.scan_period
        return time, path.poses_at(time, traj)
    step = traj.speed * traj.scan_period
    n = int(math.floor(path.length / step + 1e-9)) + 1
    idx = np.arange(n)
    return idx * traj.scan_period, path.poses(np.minimum(idx * step, path.length))


def poses_before(world: World, ages: np.ndarray) -> np.ndarray:
    """The robot's true poses (T, S, 3) ``ages[t, k]`` seconds (>= 0) before scan t's.

    Along waypoints the robot is ``speed * ages`` metres back along the path (at the first
    waypoint before it started), with the heading of the leg it was on, or, with a turn rate,
    where the drives and turns in place put it then; between explicit poses x and y are
    interpolated linearly in time and yaw along the shorter arc (the first pose before the
    first scan). An age of 0 gives the scan's pose bit for bit.
    """
    traj = world.trajectory
    ages = np.asarray(ages, dtype=np.float64)
    n, n_sensors = ages.shape
    if traj.poses:
        pose = np.asarray(traj.poses, dtype=np.float64).reshape(-1, 3)
        u = np.maximum(np.arange(n, dtype=np.float64)[:, None] - ages / traj.scan_period, 0.0)
        i = np.minimum(np.floor(u).astype(np.int64), n - 1)
        frac = (u - i)[..., None]
        j = np.minimum(i + 1, n - 1)
        delta = pose[j] - pose[i]
        delta[..., 2] = (delta[..., 2] + math.pi) % (2.0 * math.pi) - math.pi
        return pose[i] + frac * delta
    path = Polyline(traj.waypoints)
    if traj.turn_rate > 0.0:
        time = np.arange(n)[:, None] * traj.scan_period - ages
        return path.poses_at(np.maximum(time, 0.0).ravel(), traj).reshape(n, n_sensors, 3)
    s = np.minimum(np.arange(n) * (traj.speed * traj.scan_period), path.length)
    back = np.maximum(s[:, None] - traj.speed * ages, 0.0)
    return path.poses(back.ravel()).reshape(n, n_sensors, 3)


class Polyline:
    """The waypoints driven in straight legs (repeated points dropped)."""

    def __init__(self, waypoints):
        pts = [tuple(map(float, waypoints[0]))]
        for p in waypoints[1:]:
            if math.dist(p, pts[-1]) > 0.0:
                pts.append(tuple(map(float, p)))
        self.wp = np.asarray(pts, dtype=np.float64)
        self.d = np.diff(self.wp, axis=0)
        self.leg = np.hypot(self.d[:, 0], self.d[:, 1])
        self.cum = np.concatenate([[0.0], np.cumsum(self.leg)])
        self.length = self.cum[-1]

    def poses(self, s: np.ndarray) -> np.ndarray:
        """Poses (N, 3) ``s`` metres along (0 <= s <= length), heading along the leg (at a
        waypoint, of the leg that starts there)."""
        i = np.clip(np.searchsorted(self.cum, s, side="right") - 1, 0, len(self.leg) - 1)
        frac = (s - self.cum[i]) / self.leg[i]
        xy = self.wp[i] + self.d[i] * frac[:, None]
        yaw = np.arctan2(self.d[i, 1], self.d[i, 0])
        return np.column_stack([xy, yaw])

    def turns(self) -> np.ndarray:
        """The turn (rad, the shorter way) at each interior waypoint, from one leg's heading to the next's."""
        heading = np.arctan2(self.d[:, 1], self.d[:, 0])
        return (np.diff(heading) + math.pi) % (2.0 * math.pi) - math.pi

    def durations(self, traj: Trajectory) -> np.ndarray:
        """Seconds of each part of the drive: leg 0, turn 1, leg 1, turn 2, ..., the last leg."""
        parts = np.zeros(2 * len(self.leg) - 1)
        parts[0::2] = self.leg / traj.speed
        parts[1::2] = np.abs(self.turns()) / traj.turn_rate
        return parts

    def duration(self, traj: Trajectory) -> float:
        return float(self.durations(traj).sum())

    def poses_at(self, time: np.ndarray, traj: Trajectory) -> np.ndarray:
        """Poses (N, 3) at ``time`` (s, from 0 to ``duration``) of a robot that drives each leg at
        ``speed`` and turns in place at each waypoint at ``turn_rate``."""
        parts = self.durations(traj)
        start = np.concatenate([[0.0], np.cumsum(parts)])
        part = np.clip(np.searchsorted(start, time, side="right") - 1, 0, len(parts) - 1)
        into = np.clip(time - start[part], 0.0, parts[part])
        leg = part // 2
        heading = np.arctan2(self.d[leg, 1], self.d[leg, 0])
        driving = part % 2 == 0
        frac = np.where(driving, np.minimum(into * traj.speed / self.leg[leg], 1.0), 1.0)
        turns = self.turns()
        turn = np.where(driving, 0.0, np.sign(turns[np.minimum(leg, len(turns) - 1)]) if len(turns) else 0.0)
        yaw = heading + turn * traj.turn_rate * into
        xy = self.wp[leg] + self.d[leg] * frac[:, None]
        return np.column_stack([xy, (yaw + math.pi) % (2.0 * math.pi) - math.pi])
