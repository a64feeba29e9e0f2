"""Benchmark of the sonar simulator: simulated readings per second against a compiled ceiling.

Run as ``python bench/bench_simulate.py [--poses N] [--bucket-size M]``. Worlds: the bundled
corridor_door.yaml (its path resampled to N poses), a corridor with doors and smooth walls,
and a generated office floor of about 100 m x 100 m (a grid of rooms with doors, desks and
pillars). The ceiling is a kernel doing the least possible work
per sub-ray (one ray-segment intersection) for the same readings.
"""

from __future__ import annotations

import argparse
import math
import time

import numba
import numpy as np

from aogm_cli.simulation.raycast import geometry
from aogm_cli.simulation.sonar import BLOCK_SCANS, NO_ERRORS, echo_block, simulate, sub_ray_offsets
from aogm_cli.world.loader import parse_world
from aogm_cli.world.scene import build_scene
from aogm_cli.world.trajectory import trajectory_poses
from aogm_cli.world.truth import truth_occupancy


def bundled_world(name: str, n_poses: int = 20000):
    """A bundled world with its waypoint path resampled to ``n_poses`` explicit poses."""
    from pathlib import Path

    import yaml

    path = Path(__file__).resolve().parents[1] / "worlds" / f"{name}.yaml"
    raw = yaml.safe_load(path.read_text())
    pts = np.array(raw["trajectory"]["waypoints"], dtype=float)
    seg = np.diff(pts, axis=0)
    length = np.concatenate([[0.0], np.cumsum(np.hypot(seg[:, 0], seg[:, 1]))])
    s = np.linspace(0.0, length[-1], n_poses)
    leg = np.clip(np.searchsorted(length, s, side="right") - 1, 0, len(seg) - 1)
    frac = (s - length[leg]) / np.maximum(length[leg + 1] - length[leg], 1e-12)
    xy = pts[leg] + frac[:, None] * seg[leg]
    yaw = np.degrees(np.arctan2(seg[leg, 1], seg[leg, 0]))
    raw["trajectory"] = {"poses": [[float(x), float(y), float(a)] for (x, y), a in zip(xy, yaw, strict=True)]}
    return parse_world(raw, file=str(path))


def office_world(rooms: int = 20, room: float = 5.0, n_poses: int = 20000):
    """A square floor of rooms x rooms offices with a door in the middle of every inner wall."""
    size = rooms * room
    walls = []
    doors = [{"at": room * i + room / 2, "width": 0.9} for i in range(rooms)]
    for k in range(rooms + 1):
        inner = 0 < k < rooms
        surface = "smooth" if k % 3 == 1 else "rough"
        walls.append({"points": [[0, room * k], [size, room * k]], "openings": doors if inner else [], "surface": surface})
        walls.append({"points": [[room * k, 0], [room * k, size]], "openings": doors if inner else [], "surface": surface})
    boxes, circles, waypoints = [], [], []
    for j in range(rooms):
        for i in range(rooms):
            x0, y0 = room * i, room * j
            boxes.append({"center": [x0 + 1.2, y0 + 1.0], "size": [1.2, 0.6], "yaw_deg": 10.0 * ((i + j) % 4)})
            circles.append({"center": [x0 + 4.0, y0 + 4.0], "radius": 0.15})
        cols = range(rooms) if j % 2 == 0 else reversed(range(rooms))
        waypoints.extend([[room * i + room / 2, room * j + room / 2] for i in cols])
    length = sum(math.dist(a, b) for a, b in zip(waypoints, waypoints[1:], strict=False))
    period = 0.5
    speed = length / (n_poses - 1) / period * (1 - 1e-9)
    return parse_world(
        {
            "name": "offices",
            "bounds": [0, 0, size, size],
            "surfaces": {"smooth": {"specular_threshold_deg": 20}},
            "walls": walls,
            "boxes": boxes,
            "circles": circles,
            "trajectory": {"waypoints": waypoints, "speed": speed, "scan_period": period},
        },
        file="offices.yaml",
    )


def corridor_world(n_poses: int = 20000):
    """A 60 m corridor with glass on one side, rooms with doors on the other."""
    doors = [{"at": 3.0 + 6.0 * i, "width": 0.9} for i in range(10)]
    walls = [
        {"points": [[0, 2], [60, 2]], "surface": "glass"},
        {"points": [[0, 4], [60, 4]], "openings": doors},
        {"points": [[0, 9], [60, 9]]},
    ]
    walls += [{"points": [[6.0 * i, 4], [6.0 * i, 9]]} for i in range(11)]
    circles = [{"center": [6.0 * i + 1.0, 8.0], "radius": 0.2} for i in range(10)]
    speed = 58.0 / (n_poses - 1) / 0.5 * (1 - 1e-9)
    return parse_world(
        {
            "name": "corridor",
            "bounds": [0, 0, 60, 10],
            "surfaces": {"glass": {"specular_threshold_deg": 15}},
            "walls": walls,
            "circles": circles,
            "trajectory": {"waypoints": [[1, 3], [59, 3]], "speed": speed, "scan_period": 0.5},
        },
        file="corridor.yaml",
    )


@numba.njit(cache=True)
def ceiling_block(pose, mount, cos_off, sin_off, seg, out):
    """The least work per reading: sub-ray directions and one ray-segment intersection each."""
    for i in range(pose.shape[0]):
        c = math.cos(pose[i, 2])
        s = math.sin(pose[i, 2])
        for j in range(mount.shape[0]):
            sx = pose[i, 0] + c * mount[j, 0] - s * mount[j, 1]
            sy = pose[i, 1] + s * mount[j, 0] + c * mount[j, 1]
            yaw = pose[i, 2] + mount[j, 2]
            ca = math.cos(yaw)
            sa = math.sin(yaw)
            best = np.inf
            for r in range(cos_off.shape[0]):
                dx = ca * cos_off[r] - sa * sin_off[r]
                dy = sa * cos_off[r] + ca * sin_off[r]
                ex = seg[2] - seg[0]
                ey = seg[3] - seg[1]
                denom = dx * ey - dy * ex
                if denom == 0.0:
                    continue
                wx = seg[0] - sx
                wy = seg[1] - sy
                t = (wx * ey - wy * ex) / denom
                u = (wx * dy - wy * dx) / denom
                if 0.0 < t < best and 0.0 <= u <= 1.0:
                    best = t
            out[i, j] = best


def run_kernel(world, bucket_size):
    sonar = world.sonar
    _, pose = trajectory_poses(world)
    mount = np.asarray(sonar.mounts, dtype=np.float64)
    geo = geometry(build_scene(world, bucket_size=bucket_size))
    off = sub_ray_offsets(sonar.beam_width, sonar.sub_rays)
    off = off[np.argsort(np.abs(off), kind="stable")]
    cos_off, sin_off = np.cos(off), np.sin(off)
    n, s = pose.shape[0], mount.shape[0]
    echo, ideal, multi = np.empty((n, s)), np.empty((n, s)), np.empty((n, s), dtype=np.bool_)
    start = time.perf_counter()
    for a in range(0, n, BLOCK_SCANS):
        b = min(n, a + BLOCK_SCANS)
        echo_block(pose[a:b], mount, cos_off, sin_off, float(sonar.max_range), int(sonar.max_bounces), geo, echo[a:b],
                   ideal[a:b], multi[a:b], *NO_ERRORS)  # every echo heard, no side lobes: the clean kernel
    elapsed = time.perf_counter() - start
    seg = np.array([pose[:, 0].max() + 3.0, -1e3, pose[:, 0].max() + 3.0, 1e3])
    out = np.empty((n, s))
    ceiling_block(pose[:2], mount, cos_off, sin_off, seg, out[:2])
    start = time.perf_counter()
    ceiling_block(pose, mount, cos_off, sin_off, seg, out)
    ceiling = time.perf_counter() - start
    return n * s, elapsed, ceiling, echo


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--poses", type=int, default=20000)
    parser.add_argument("--bucket-size", type=float, default=None, help="m (default: the scene's default)")
    args = parser.parse_args()
    from aogm_cli.world.scene import DEFAULT_BUCKET_SIZE

    bucket = args.bucket_size or DEFAULT_BUCKET_SIZE

    # compile (or load the cache) on a tiny world first
    tiny = corridor_world(n_poses=3)
    simulate(tiny, seed=0)
    run_kernel(tiny, bucket)

    for world in (bundled_world("corridor_door", args.poses), corridor_world(args.poses), office_world(n_poses=args.poses)):
        start = time.perf_counter()
        scene = build_scene(world, bucket_size=bucket)
        t_scene = time.perf_counter() - start
        start = time.perf_counter()
        truth_occupancy(world)
        t_truth = time.perf_counter() - start
        readings, elapsed, ceiling, echo = run_kernel(world, bucket)
        start = time.perf_counter()
        log = simulate(world, seed=1)
        t_sim = time.perf_counter() - start
        rays = readings * world.sonar.sub_rays
        rate, ceil_rate = readings / elapsed, readings / ceiling
        print(f"{world.name}: {scene.n_segments} segments, {scene.n_circles} circles, buckets {scene.bucket_shape} of {scene.bucket_size:g} m, {log.n_scans} scans x {len(world.sonar.mounts)} sonars x {world.sonar.sub_rays} sub-rays")
        print(f"  kernel   {rate:12,.0f} readings/s  {rays / elapsed:14,.0f} rays/s   ({elapsed:.2f} s)")
        print(f"  ceiling  {ceil_rate:12,.0f} readings/s  {rays / ceiling:14,.0f} rays/s   ratio kernel/ceiling {rate / ceil_rate:.3f}")
        print(f"  simulate {readings / t_sim:12,.0f} readings/s end to end ({t_sim:.2f} s; scene {t_scene:.2f} s, truth {t_truth:.2f} s)")
        print(f"  echoes {np.isfinite(echo).mean():.1%}, causes {np.bincount(log.truth.cause.ravel(), minlength=4).tolist()}")


if __name__ == "__main__":
    main()
