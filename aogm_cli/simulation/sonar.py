"""The sonar simulator: a world in, a log with its truth out (``simulate``): a fan of sub-rays per
reading, the nearest echo strong enough to be detected after specular bounces, then a real robot's
errors; the truth keeps every reading's cause and noise-free range, the log the odometry's poses."""

from __future__ import annotations

import math
from collections.abc import Callable

import numba
import numpy as np

from aogm_cli.core.budget import check
from aogm_cli.core.errors import InputError
from aogm_cli.core.log import (
    CAUSE_ECHO,
    CAUSE_NO_ECHO,
    CAUSE_RANDOM,
    CAUSE_SPECULAR,
    SIMULATED_SOURCE,
    Log,
    SensorSpec,
    Truth,
)
from aogm_cli.simulation import firing
from aogm_cli.simulation.odometry import dead_reckoning
from aogm_cli.simulation.raycast import geometry, trace_sub_ray
from aogm_cli.world.config import SideLobes, SimulationErrors, Sonar, World
from aogm_cli.world.scene import build_scene
from aogm_cli.world.simulation_cost import simulation_estimate
from aogm_cli.world.trajectory import poses_before, trajectory_poses
from aogm_cli.world.truth import truth_occupancy

BLOCK_SCANS = 2048  # scans per kernel call (progress is reported between blocks)
# The errors of a real robot draw from their own children of the seed's SeedSequence, so that
# the draws of the ideal simulator (random readings, their ranges, noise) stay as they were.
ODOMETRY_STREAM = 1
CROSSTALK_STREAM = 2


def sub_ray_offsets(beam_width: float, sub_rays: int) -> np.ndarray:
    """Angles (rad) of the sub-rays relative to the sensor axis, evenly across the cone."""
    if sub_rays == 1:
        return np.zeros(1)
    return np.linspace(-beam_width / 2, beam_width / 2, sub_rays)


# echo_block's last arguments for a sonar without echo-strength, firing or side-lobe errors (the
# types the simulator passes: one compiled signature)
NO_ERRORS = (0.0, 1.0, 2.0, np.zeros((0, 0, 3)), np.zeros(0), np.zeros(0), 0.0)


@numba.njit(cache=True, _nrt=False)
def echo_block(pose, mount, cos_off, sin_off, max_range, max_bounces, geo, echo, ideal, multipath,
               min_strength, beam, incidence_exponent, reading_pose, cos_side, sin_side, side_range):
    """Noise-free readings of a block of scans (every sensor, every sub-ray), in one call.

    pose (B, 3) robot poses; mount (S, 3) sensor mounts; cos_off, sin_off (R,) sub-ray
    offsets. Writes per reading (B, S): ``echo`` the nearest detected echo over the sub-rays
    (one-way path, inf if none within max_range), ``ideal`` the nearest first hit of any sub-ray
    regardless of angle (inf if none) and ``multipath`` whether that echo came after a bounce.
    With ``min_strength`` > 0 a sub-ray's echo is detected only when its strength
    ``exp(-2 theta^2 / beam^2) cos(incidence)^incidence_exponent / path^2`` (theta the sub-ray's
    angle off the axis) is at least ``min_strength``; 0 detects every echo. ``reading_pose``
    (B, S, 3), unless empty, is each reading's own robot pose (then ``pose`` is unused). The
    side-lobe sub-rays ``cos_side``, ``sin_side`` (R2,; empty: none) add echoes detected when
    ``cos(incidence)^incidence_exponent / path^2 >= 1 / side_range^2``; they change ``echo``
    only (``ideal`` is the cone's). Every argument has one type whichever errors are on: one
    compiled signature (each took 18 s to compile).
    """
    n_sub = cos_off.shape[0]
    for i in range(pose.shape[0]):
        c = math.cos(pose[i, 2])
        s = math.sin(pose[i, 2])
        for j in range(mount.shape[0]):
            if reading_pose.shape[0] == 0:
                px, py, pyaw, cj, sj = pose[i, 0], pose[i, 1], pose[i, 2], c, s
            else:
                px, py, pyaw = reading_pose[i, j, 0], reading_pose[i, j, 1], reading_pose[i, j, 2]
                cj, sj = math.cos(pyaw), math.sin(pyaw)
            sx = px + cj * mount[j, 0] - sj * mount[j, 1]
            sy = py + sj * mount[j, 0] + cj * mount[j, 1]
            yaw = pyaw + mount[j, 2]
            ca = math.cos(yaw)
            sa = math.sin(yaw)
            best = np.inf
            best_bounces = 0
            nearest = np.inf
            for r in range(n_sub):
                dx = ca * cos_off[r] - sa * sin_off[r]
                dy = sa * cos_off[r] + ca * sin_off[r]
                # a surface farther than the best echo so far can change neither result
                first, path, bounces, cos_inc = trace_sub_ray(sx, sy, dx, dy, min(max_range, best), max_bounces, geo)
                if first < nearest:
                    nearest = first
                if min_strength > 0.0 and path < np.inf:
                    theta = math.atan2(sin_off[r], cos_off[r]) / beam
                    if math.exp(-2.0 * theta * theta) * cos_inc**incidence_exponent < min_strength * path * path:
                        path = np.inf  # too weak to be detected
                if path < best or (path == best and bounces < best_bounces):
                    best = path
                    best_bounces = bounces
            for r in range(cos_side.shape[0]):
                dx = ca * cos_side[r] - sa * sin_side[r]
                dy = sa * cos_side[r] + ca * sin_side[r]
                # a side-lobe echo beyond side_range is never detected
                _, path, bounces, cos_inc = trace_sub_ray(sx, sy, dx, dy, min(max_range, best, side_range),
                                                          max_bounces, geo)
                if path < best and cos_inc**incidence_exponent * side_range * side_range >= path * path:
                    best = path
                    best_bounces = bounces
            echo[i, j] = best
            ideal[i, j] = nearest
            multipath[i, j] = best_bounces > 0


def readings_from_echoes(
    echo: np.ndarray,
    ideal: np.ndarray,
    multipath: np.ndarray,
    u_random: np.ndarray,
    u_range: np.ndarray,
    noise: np.ndarray,
    sonar: Sonar,
    noise_per_metre: float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Turn noise-free echoes into readings (float32) and their causes (int8).

    Cause: no echo -> 1 (+inf); an echo after a bounce (``multipath``, which includes a
    neighbour's echo, see ``crosstalk``) or farther than ``cause_tolerance`` from ``ideal`` (too
    long, or too short: a side lobe's) -> 3; else 0. Then a
    reading with ``u_random < random_rate`` becomes ``min_range + u_range * (max_range -
    min_range)`` (cause 2); ``(noise_sigma + noise_per_metre * z) * noise`` is added (z the
    reading so far); readings are clipped to >= min_range and those >= max_range become +inf
    (cause 1 unless random).
    """
    cause = np.full(echo.shape, CAUSE_ECHO, dtype=np.int8)
    with np.errstate(invalid="ignore"):
        cause[multipath | (np.abs(echo - ideal) > sonar.cause_tolerance)] = CAUSE_SPECULAR
    no_echo = ~np.isfinite(echo)
    cause[no_echo] = CAUSE_NO_ECHO
    reading = echo.astype(np.float64, copy=True)
    random = u_random < sonar.random_rate
    reading[random] = sonar.min_range + u_range[random] * (sonar.max_range - sonar.min_range)
    cause[random] = CAUSE_RANDOM
    with np.errstate(invalid="ignore"):
        sigma = sonar.noise_sigma + noise_per_metre * np.where(np.isfinite(reading), reading, 0.0)
        reading = reading + sigma * noise
    reading = np.maximum(reading, sonar.min_range)
    too_far = reading >= sonar.max_range
    reading[too_far] = np.inf
    cause[too_far & ~random] = CAUSE_NO_ECHO
    return reading.astype(np.float32), cause


def crosstalk(echo: np.ndarray, u: np.ndarray, right: np.ndarray, rate: float) -> tuple[np.ndarray, np.ndarray]:
    """Echoes (T, S) after crosstalk, and which readings it changed.

    A reading with ``u < rate`` hears the echo of a ring neighbour (sonar j+1 where ``right``,
    else j-1, wrapping: the order of the mounts), arriving first when it is nearer: the reading
    becomes the lesser of the two. ``u`` and ``right`` are draws of the shape of ``echo``.
    """
    n_sensors = echo.shape[1]
    j = np.arange(n_sensors)
    neighbour = np.where(right, (j + 1) % n_sensors, (j - 1) % n_sensors)
    other = np.take_along_axis(echo, neighbour, axis=1)
    crossed = (u < rate) & (other < echo)
    return np.where(crossed, other, echo), crossed


def error_stream(seed: int, stream: int) -> np.random.Generator:
    """The generator of one error of a real robot: child ``stream`` of the seed's SeedSequence."""
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(stream,)))


def side_lobe_offsets(lobes: SideLobes) -> np.ndarray:
    """Angles (rad) of the side-lobe sub-rays relative to the sensor axis, both sides."""
    one = sub_ray_offsets(lobes.width, lobes.sub_rays) + lobes.angle
    return np.concatenate([one, -one])


# Each reading casts a fan of sub-rays across the cone (and its side lobes, when they are on) from
# the robot's pose when its sonar fires; the nearest echo strong enough to be detected (after specular
# bounces) is the reading, then crosstalk, random readings, Gaussian noise and the range limits apply.
# The cause and the noise-free range of the nearest surface of every reading are kept as truth; the
# logged poses are the odometry's (``simulation.odometry``).
def _echoes(world: World, time: np.ndarray, pose: np.ndarray, mount: np.ndarray,
            progress: Callable[[int], None] | None) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]:
    """(echo, ideal range, multipath flag) per (scan, sonar), cast block by block from the true
    poses (from each sonar's last firing, with ``errors.firing``: then also the scan each reading
    repeats, else None)."""
    sonar, errors = world.sonar, world.errors
    strength = errors.echo_strength
    n_scans, n_sensors = pose.shape[0], mount.shape[0]
    geo = geometry(build_scene(world))
    offsets = sub_ray_offsets(sonar.beam_width, sonar.sub_rays)
    # the central sub-rays first: their echoes bound the search of the others
    offsets = offsets[np.argsort(np.abs(offsets), kind="stable")]
    cos_off, sin_off = np.cos(offsets), np.sin(offsets)
    reading_pose, source = np.zeros((0, 0, 3)), None  # empty: every reading from its scan's pose
    if errors.firing.on:
        ages, source = firing.schedule(errors.firing, time, n_sensors)
        reading_pose = poses_before(world, ages)
    lobes = errors.side_lobes
    side = side_lobe_offsets(lobes) if lobes.range > 0 else None
    cos_side, sin_side = (np.zeros(0), np.zeros(0)) if side is None else (np.cos(side), np.sin(side))
    echo = np.empty((n_scans, n_sensors))
    ideal = np.empty((n_scans, n_sensors))
    multipath = np.empty((n_scans, n_sensors), dtype=np.bool_)
    for start in range(0, n_scans, BLOCK_SCANS):
        stop = min(n_scans, start + BLOCK_SCANS)
        echo_block(
            pose[start:stop], mount, cos_off, sin_off, float(sonar.max_range), int(sonar.max_bounces), geo,
            echo[start:stop], ideal[start:stop], multipath[start:stop],
            float(strength.min_strength), float(strength.beam), float(strength.incidence_exponent),
            reading_pose[start:stop], cos_side, sin_side, float(lobes.range),
        )
        if progress is not None:
            progress(stop)
    return echo, ideal, multipath, source


def simulate(world: World, seed: int, progress: Callable[[int], None] | None = None) -> Log:
    """Simulate the world's sonar along its trajectory: the log, with its truth.

    Random numbers are drawn up front from ``numpy.random.default_rng(seed)`` in a fixed
    order (random-reading draws, random ranges, noise, each (T, S)), so a seed gives the same
    arrays bit for bit; the errors of ``world.errors`` draw from their own streams
    (``error_stream``), only when they are on, so a world without errors gives the same log
    as before they existed. The readings are cast from the true poses; the log holds the
    odometry's estimate of them (``odometry.dead_reckoning``); with ``errors.firing`` each
    reading is cast from the true pose when its sonar last fired (``firing.schedule``,
    ``trajectory.poses_before``) and repeated while it has not fired again, while the log keeps
    one pose per scan. ``progress(n_scans_done)`` after each block of scans. A world whose
    estimate exceeds the limits in force (``core.budget``) is refused first."""
    sonar = world.sonar
    if sonar is None:
        raise InputError("the world has no sonar", file=world.source, key="sonar")
    check(simulation_estimate(world), file=world.source)
    time, pose = trajectory_poses(world)
    mount = np.asarray(sonar.mounts, dtype=np.float64).reshape(-1, 3)
    n_scans, n_sensors = pose.shape[0], mount.shape[0]

    rng = np.random.default_rng(seed)
    u_random = rng.random((n_scans, n_sensors))
    u_range = rng.random((n_scans, n_sensors))
    noise = rng.standard_normal((n_scans, n_sensors))

    errors: SimulationErrors = world.errors
    grid, occupancy = truth_occupancy(world)
    echo, ideal, multipath, source = _echoes(world, time, pose, mount, progress)

    if errors.crosstalk_rate > 0.0:
        rng_crosstalk = error_stream(seed, CROSSTALK_STREAM)
        u_crosstalk = rng_crosstalk.random((n_scans, n_sensors))
        right = rng_crosstalk.random((n_scans, n_sensors)) < 0.5
        echo, crossed = crosstalk(echo, u_crosstalk, right, errors.crosstalk_rate)
        multipath = multipath | crossed  # a neighbour's echo is recorded as cause 3, as a bounce is
    ranges, cause = readings_from_echoes(echo, ideal, multipath, u_random, u_range, noise, sonar,
                                         errors.noise_per_metre)
    if errors.firing.on:  # a scan repeats the reading of a sonar that has not fired since an earlier scan
        ranges, cause, ideal = (np.take_along_axis(a, source, axis=0) for a in (ranges, cause, ideal))
    logged_pose = dead_reckoning(pose, errors.odometry, error_stream(seed, ODOMETRY_STREAM))
    truth = Truth(
        grid=grid,
        occupancy=occupancy,
        cause=cause,
        ideal_range=ideal.astype(np.float32),
        world=world.text,
        checks=tuple(c.as_json() for c in world.checks),
    )
    sensor = SensorSpec(mount=mount, kind="sonar", beam_width=float(sonar.beam_width), min_range=float(sonar.min_range),
                        max_range=float(sonar.max_range), noise_sigma=float(sonar.noise_sigma))
    return Log(
        time=time,
        pose=logged_pose,
        ranges=ranges,
        sensor=sensor,
        source=f"{SIMULATED_SOURCE}{world.source}",
        truth=truth,
        seed=int(seed),
    )
