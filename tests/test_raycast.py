"""Ray casting: segment, circle and bitmap hits with their distance, incidence and mirror direction."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from aogm_cli.core.grid import GridSpec
from aogm_cli.simulation.raycast import cast_ray, first_hit, geometry, trace_sub_ray
from aogm_cli.world.geometry import build_scene
from aogm_cli.world.loader import parse_world


def scene_of(**geometry_keys):
    raw = {"bounds": [-10, -10, 10, 10], "trajectory": {"poses": [[0, 0, 0]]}}
    raw.update(geometry_keys)
    return build_scene(parse_world(raw, file="test.yaml"))


def test_ray_square_to_a_wall():
    geo = geometry(scene_of(walls=[{"points": [[2, -3], [2, 3]], "thickness": 0.1}]))
    t, incidence, threshold, hx, hy, mx, my = cast_ray(0.0, 0.0, 1.0, 0.0, 5.0, geo)
    assert t == pytest.approx(1.95)
    assert incidence == pytest.approx(0.0)
    assert threshold == pytest.approx(math.pi / 2)
    assert (hx, hy) == pytest.approx((1.95, 0.0))
    assert (mx, my) == pytest.approx((-1.0, 0.0))


def test_oblique_hit_incidence_threshold_and_mirror():
    geo = geometry(
        scene_of(
            surfaces={"glass": {"specular_threshold_deg": 15}},
            walls=[{"points": [[-5, 1], [5, 1]], "thickness": 0.2, "surface": "glass"}],
        )
    )
    a = math.radians(30)  # 30 degrees above +x: 60 degrees from the wall's normal
    t, incidence, threshold, hx, hy, mx, my = cast_ray(0.0, 0.0, math.cos(a), math.sin(a), 5.0, geo)
    assert t == pytest.approx(0.9 / math.sin(a))
    assert incidence == pytest.approx(math.radians(60))
    assert threshold == pytest.approx(math.radians(15))
    assert (hx, hy) == pytest.approx((0.9 / math.tan(a), 0.9))
    assert (mx, my) == pytest.approx((math.cos(a), -math.sin(a)))


def test_nothing_within_max_range_is_a_miss():
    geo = geometry(scene_of(walls=[{"points": [[2, -3], [2, 3]]}]))
    assert cast_ray(0.0, 0.0, 1.0, 0.0, 1.9, geo)[0] == math.inf
    assert cast_ray(0.0, 0.0, -1.0, 0.0, 50.0, geo)[0] == math.inf
    assert cast_ray(0.0, 0.0, 0.0, 1.0, 50.0, geo)[0] == math.inf


def test_circle_hit_distance_and_incidence():
    geo = geometry(scene_of(circles=[{"center": [3, 0], "radius": 0.5}]))
    assert cast_ray(0.0, 0.0, 1.0, 0.0, 5.0, geo)[0] == pytest.approx(2.5)
    t, incidence, _, hx, hy, mx, my = cast_ray(0.0, 0.3, 1.0, 0.0, 5.0, geo)
    assert t == pytest.approx(2.6)  # 3 - sqrt(0.5^2 - 0.3^2)
    assert incidence == pytest.approx(math.asin(0.3 / 0.5))
    nx, ny = (hx - 3) / 0.5, hy / 0.5
    assert (mx, my) == pytest.approx((1 - 2 * nx * nx, -2 * nx * ny))
    assert cast_ray(0.0, 0.6, 1.0, 0.0, 5.0, geo)[0] == math.inf


def test_far_wall_through_many_buckets():
    geo = geometry(scene_of(bounds=[0, 0, 40, 40], walls=[{"points": [[35, 0], [35, 40]], "thickness": 0.1}]))
    t = cast_ray(1.0, 1.0, 1.0, 1.0, 60.0, geo)[0]  # not unit: normalised inside
    assert t == pytest.approx(33.95 * math.sqrt(2))


def test_random_rays_agree_with_brute_force():
    rng = np.random.default_rng(7)
    walls = [{"points": rng.uniform(0, 10, (3, 2)).tolist(), "thickness": float(rng.uniform(0.02, 0.3))} for _ in range(12)]
    circles = [{"center": rng.uniform(0, 10, 2).tolist(), "radius": float(rng.uniform(0.05, 0.5))} for _ in range(5)]
    raw = {"bounds": [0, 0, 10, 10], "trajectory": {"poses": [[0, 0, 0]]}, "walls": walls, "circles": circles}
    for bucket_size in (0.37, 1.0, 20.0):
        scene = build_scene(parse_world(raw, file="test.yaml"), bucket_size=bucket_size)
        geo = geometry(scene)
        seg = scene.segments
        for _ in range(300):
            ox, oy = rng.uniform(-1, 11, 2)
            a = rng.uniform(0, 2 * math.pi)
            dx, dy = math.cos(a), math.sin(a)
            # brute force over every segment and circle
            ex, ey = seg[:, 2] - seg[:, 0], seg[:, 3] - seg[:, 1]
            denom = dx * ey - dy * ex
            wx, wy = seg[:, 0] - ox, seg[:, 1] - oy
            with np.errstate(divide="ignore", invalid="ignore"):
                t = (wx * ey - wy * ex) / denom
                s = (wx * dy - wy * dx) / denom
            ok = (t > 0) & (s >= 0) & (s <= 1)
            best = t[ok].min() if ok.any() else math.inf
            for cx, cy, r in scene.circles:
                b = dx * (ox - cx) + dy * (oy - cy)
                c = (ox - cx) ** 2 + (oy - cy) ** 2 - r * r
                if c > 0 and b * b - c >= 0 and -b - math.sqrt(b * b - c) > 0:
                    best = min(best, -b - math.sqrt(b * b - c))
            got = cast_ray(ox, oy, dx, dy, 8.0, geo)[0]
            if best > 8.0:
                assert got == math.inf
            else:
                assert got == pytest.approx(best, abs=1e-9)


def bitmap_scene(bitmap, origin=(0.0, 0.0), resolution=1.0, threshold=math.pi / 2):
    """A scene with only a bitmap (its geometry is one circle far away)."""
    scene = scene_of(bounds=[0, 0, 1, 1], circles=[{"center": [500, 500], "radius": 0.1}])
    h, w = bitmap.shape
    return dataclasses.replace(
        scene,
        bitmap=np.asarray(bitmap, dtype=np.uint8),
        bitmap_grid=GridSpec(origin[0], origin[1], resolution, h, w),
        bitmap_threshold=threshold,
    )


def test_bitmap_dda_hit_distance_and_face_normal():
    bm = np.zeros((5, 5), np.uint8)
    bm[2, 4] = 1  # x in [4, 5), y in [2, 3)
    bm[4, 1] = 1  # x in [1, 2), y in [4, 5)
    geo = geometry(bitmap_scene(bm))
    t, incidence, _, hx, hy, mx, my = cast_ray(0.5, 2.5, 1.0, 0.0, 10.0, geo)
    assert t == pytest.approx(3.5) and incidence == pytest.approx(0.0)
    assert (mx, my) == pytest.approx((-1.0, 0.0))
    assert cast_ray(1.5, 0.5, 0.0, 1.0, 10.0, geo)[0] == pytest.approx(3.5)
    assert cast_ray(1.5, 0.5, 0.0, 1.0, 3.0, geo)[0] == math.inf
    # oblique: from (0.5, 2.5) towards (4, 3): enters x = 4 at y = 2.5 + 3.5 * 0.4 / 3.5 = 2.9
    d = np.array([3.5, 0.4]) / math.hypot(3.5, 0.4)
    t, incidence, _, hx, hy, mx, my = cast_ray(0.5, 2.5, d[0], d[1], 10.0, geo)
    assert (hx, hy) == pytest.approx((4.0, 2.9))
    assert incidence == pytest.approx(math.atan2(0.4, 3.5))
    assert (mx, my) == pytest.approx((-d[0], d[1]))
    # the top face of the pixel at row 4 col 1, hit from above the bitmap
    t, incidence, _, hx, hy, mx, my = cast_ray(1.25, 7.0, 0.0, -1.0, 10.0, geo)
    assert t == pytest.approx(2.0) and (hx, hy) == pytest.approx((1.25, 5.0))
    assert (mx, my) == pytest.approx((0.0, 1.0))


def test_bitmap_with_origin_and_resolution():
    bm = np.zeros((4, 4), np.uint8)
    bm[:, 3] = 1  # x in [1.75, 2.0) with origin x 1.0 and 0.25 m pixels
    geo = geometry(bitmap_scene(bm, origin=(1.0, -0.5), resolution=0.25))
    assert cast_ray(0.0, 0.0, 1.0, 0.0, 10.0, geo)[0] == pytest.approx(1.75)
    assert cast_ray(0.0, 0.6, 1.0, 0.0, 10.0, geo)[0] == math.inf  # above the bitmap


def test_bitmap_pixel_holding_the_origin_is_not_tested():
    bm = np.zeros((3, 3), np.uint8)
    bm[1, 1] = 1
    bm[1, 2] = 1
    geo = geometry(bitmap_scene(bm))
    assert cast_ray(1.5, 1.5, 1.0, 0.0, 10.0, geo)[0] == pytest.approx(0.5)


def test_bitmap_and_geometry_nearest_wins():
    bm = np.zeros((3, 10), np.uint8)
    bm[:, 6] = 1
    scene = dataclasses.replace(
        scene_of(bounds=[0, 0, 10, 3], walls=[{"points": [[4, 0], [4, 1]], "thickness": 0.2}]),
        bitmap=bm,
        bitmap_grid=GridSpec(0.0, 0.0, 1.0, 3, 10),
        bitmap_threshold=0.1,
    )
    geo = geometry(scene)
    assert cast_ray(0.5, 0.5, 1.0, 0.0, 10.0, geo)[0] == pytest.approx(3.4)
    t, _, threshold, *_ = cast_ray(0.5, 2.5, 1.0, 0.0, 10.0, geo)
    assert t == pytest.approx(5.5) and threshold == pytest.approx(0.1)


def test_trace_sub_ray_follows_a_mirror_to_a_rough_wall():
    # glass face x - y = 3 (thickness 0.1, centre line offset by 0.05 * sqrt 2), a rough wall face y = 1.95
    off = 0.05 * math.sqrt(2)
    geo = geometry(
        scene_of(
            surfaces={"glass": {"specular_threshold_deg": 15}},
            walls=[
                {"points": [[2 + off, -1], [4 + off, 1]], "thickness": 0.1, "surface": "glass"},
                {"points": [[2, 2], [4, 2]], "thickness": 0.1},
            ],
        )
    )
    first, echo, bounces = trace_sub_ray(0.0, 0.0, 1.0, 0.0, 8.0, 2, geo)
    assert first == pytest.approx(3.0) and echo == pytest.approx(4.95) and bounces == 1
    # no bounce allowed: no echo
    first, echo, bounces = trace_sub_ray(0.0, 0.0, 1.0, 0.0, 8.0, 0, geo)
    assert first == pytest.approx(3.0) and echo == math.inf
    # the path is limited: 4.95 > 4.9
    assert trace_sub_ray(0.0, 0.0, 1.0, 0.0, 4.9, 2, geo)[1] == math.inf


def test_bounce_off_a_bitmap_face():
    bm = np.zeros((6, 6), np.uint8)
    bm[0, :] = 1  # floor y in [0, 1), smooth
    geo = geometry(bitmap_scene(bm, threshold=math.radians(20)))
    # a ray going down-right at 45 degrees hits y = 1 at x = 2, mirrors up-right, leaves the bitmap
    d = 1 / math.sqrt(2)
    first, echo, _ = trace_sub_ray(1.0, 2.0, d, -d, 20.0, 2, geo)
    assert first == pytest.approx(math.sqrt(2)) and echo == math.inf
    t, c, cthr, nx, ny = first_hit(1.0, 2.0, d, -d, 20.0, geo)
    assert c == pytest.approx(d) and cthr == pytest.approx(math.cos(math.radians(20)))
    assert abs(ny) == pytest.approx(1.0)
