"""What simulating a world would cost, from its configuration alone (no pose is sampled), so that
``core.budget.check`` can refuse an absurd world before the simulator allocates anything."""

from __future__ import annotations

import math

from aogm_cli.core.budget import Estimate
from aogm_cli.world.config import World
from aogm_cli.world.trajectory import Polyline

BYTES_PER_READING = 112  # draws, echoes, readings and causes (float64 scratch), the log and its file
BYTES_PER_SCAN = 200  # time, pose and the trajectory sampler's scratch
BYTES_PER_TRUTH_CELL = 4  # the raster, its copy in the log file, and scratch
BYTES_PER_SUB_RAY = 32  # offsets, their cosines and sines
BYTES_PER_CROSSTALK_READING = 48  # crosstalk's draws, neighbours and echoes (when it is on)
BYTES_PER_ODOMETRY_SCAN = 160  # odometry's draws, relative motions and estimate (when it is on)
BYTES_PER_FIRING_READING = 80  # each reading's age, source scan and pose when it fired (when firing is on)


def scan_count(world: World) -> float:
    """The number of scans ``trajectory.trajectory_poses`` makes (as a float: it may be huge)."""
    traj = world.trajectory
    if traj.poses:
        return float(len(traj.poses))
    length = sum(math.dist(a, b) for a, b in zip(traj.waypoints[:-1], traj.waypoints[1:], strict=True))
    if traj.turn_rate > 0.0:  # the drives and the turns in place
        return math.floor(Polyline(traj.waypoints).duration(traj) / traj.scan_period + 1e-9) + 1.0
    return math.floor(length / (traj.speed * traj.scan_period) + 1e-9) + 1.0


def simulation_estimate(world: World) -> Estimate:
    """Memory (bytes) and work (sub-ray casts = scans x sonars x sub-rays) of ``simulate(world)``."""
    n_scans = scan_count(world)
    sonar = world.sonar
    n_sensors = float(len(sonar.mounts)) if sonar else 0.0
    sub_rays = float(sonar.sub_rays) if sonar else 0.0
    if world.errors.side_lobes.range > 0.0:
        sub_rays += 2.0 * world.errors.side_lobes.sub_rays
    x0, y0, x1, y1 = world.bounds
    cells = math.ceil((x1 - x0) / world.truth_resolution) * math.ceil((y1 - y0) / world.truth_resolution)
    readings = n_scans * n_sensors
    memory = (readings * BYTES_PER_READING + n_scans * BYTES_PER_SCAN + cells * BYTES_PER_TRUTH_CELL
              + sub_rays * BYTES_PER_SUB_RAY)
    if world.errors.crosstalk_rate > 0.0:
        memory += readings * BYTES_PER_CROSSTALK_READING
    if not world.errors.odometry.off:
        memory += n_scans * BYTES_PER_ODOMETRY_SCAN
    if world.errors.firing.on:
        memory += readings * BYTES_PER_FIRING_READING
    work = readings * sub_rays * (1 + (sonar.max_bounces if sonar else 0))
    detail = (f"{n_scans:.3g} scans x {n_sensors:.0f} sonars x {sub_rays:.0f} sub-rays, "
              f"{cells:.3g} truth cells")
    return Estimate("simulating this world", memory, work, "ray casts", detail)


def load_checked_world(path, limits=None) -> World:
    """The world of the file at ``path``, refused (``InputError`` naming the file) before any work
    when simulating it would exceed ``limits`` (default: the limits in force,
    ``core.budget.active_limits``). ``aogm simulate`` and ``aogm_cli.simulate`` load worlds here."""
    from aogm_cli.core.budget import check
    from aogm_cli.world.loader import load_world

    world = load_world(path)
    check(simulation_estimate(world), limits, file=str(path))
    return world
