"""Ray casting: segment, circle and bitmap hits with their distance, incidence and mirror direction,
through the simulator's own kernel (``sonar.echo_block``, which inlines ``raycast.trace_sub_ray``):
a hit's incidence shows as whether the surface echoes (incidence within its threshold) or mirrors
the ray, and the mirror direction as where the bounced ray lands."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from aogm_cli.core.grid import GridSpec
from aogm_cli.simulation.raycast import geometry
from aogm_cli.simulation.sonar import NO_ERRORS, echo_block
from aogm_cli.world.loader import parse_world
from aogm_cli.world.scene import build_scene


def scene_of(**geometry_keys):
    raw = {"bounds": [-10, -10, 10, 10], "trajectory": {"poses": [[0, 0, 0]]}}
    raw.update(geometry_keys)
    return build_scene(parse_world(raw, file="test.yaml"))


def trace(geo, ox, oy, dx, dy, limit, max_bounces=0):
    """One sub-ray from (ox, oy) along the unit (dx, dy), traced by ``echo_block``: one robot pose
    facing +x with a sensor at its centre, one sub-ray whose offset has cosine dx and sine dy.

    Returns (first, echo, bounced): the distance of the first surface hit (inf: none within
    ``limit``), the one-way path to the surface that echoes (inf: none within ``limit`` after at
    most ``max_bounces`` mirror bounces) and whether that echo came after a bounce."""
    echo, first, bounced = np.empty((1, 1)), np.empty((1, 1)), np.empty((1, 1), dtype=np.bool_)
    echo_block(np.array([[ox, oy, 0.0]]), np.zeros((1, 3)), np.array([dx]), np.array([dy]), float(limit),
               int(max_bounces), geo, echo, first, bounced, *NO_ERRORS)
    return float(first[0, 0]), float(echo[0, 0]), bool(bounced[0, 0])


def first_hits(geo, pose, limit):
    """The first hit of one ray per row (x, y, heading) of ``pose``, within ``limit``."""
    n = pose.shape[0]
    echo, first, bounced = np.empty((n, 1)), np.empty((n, 1)), np.empty((n, 1), dtype=np.bool_)
    echo_block(np.ascontiguousarray(pose, dtype=np.float64), np.zeros((1, 3)), np.ones(1), np.zeros(1), float(limit),
               0, geo, echo, first, bounced, *NO_ERRORS)
    return first[:, 0]


def test_ray_square_to_a_wall():
    # a rough wall echoes at any incidence: first hit and echo at its face x = 1.95
    geo = geometry(scene_of(walls=[{"points": [[2, -3], [2, 3]], "thickness": 0.1}]))
    assert trace(geo, 0.0, 0.0, 1.0, 0.0, 5.0) == (pytest.approx(1.95), pytest.approx(1.95), False)
    # a smooth wall hit square on (incidence 0, within any threshold) echoes too
    glass = geometry(
        scene_of(
            surfaces={"glass": {"specular_threshold_deg": 15}},
            walls=[{"points": [[2, -3], [2, 3]], "thickness": 0.1, "surface": "glass"}],
        )
    )
    assert trace(glass, 0.0, 0.0, 1.0, 0.0, 5.0) == (pytest.approx(1.95), pytest.approx(1.95), False)


def test_oblique_hit_incidence_threshold_and_mirror():
    # glass face y = 0.9 (threshold 15 deg); a rough block below whose top face y = -0.9 spans x in [4.4, 5.0]
    geo = geometry(
        scene_of(
            surfaces={"glass": {"specular_threshold_deg": 15}},
            walls=[
                {"points": [[-5, 1], [5, 1]], "thickness": 0.2, "surface": "glass"},
                {"points": [[4.5, -1], [4.9, -1]], "thickness": 0.2},
            ],
        )
    )
    a = math.radians(30)  # 30 degrees above +x: 60 degrees from the wall's normal, past its threshold
    first, echo, _ = trace(geo, 0.0, 0.0, math.cos(a), math.sin(a), 8.0)
    assert first == pytest.approx(0.9 / math.sin(a)) and echo == math.inf
    # the mirror direction (cos a, -sin a) from the hit (0.9 / tan a, 0.9) lands on the block at
    # x = 2.7 / tan a = 4.68, after 1.8 / sin a more
    first, echo, bounced = trace(geo, 0.0, 0.0, math.cos(a), math.sin(a), 8.0, max_bounces=1)
    assert first == pytest.approx(0.9 / math.sin(a)) and echo == pytest.approx(2.7 / math.sin(a)) and bounced
    # the threshold: 14 degrees from the normal echoes, 16 degrees does not
    for incidence, echoes in ((14.0, True), (16.0, False)):
        b = math.radians(90.0 - incidence)
        first, echo, _ = trace(geo, 0.0, 0.0, math.cos(b), math.sin(b), 8.0)
        assert first == pytest.approx(0.9 / math.sin(b))
        assert echo == (pytest.approx(first) if echoes else math.inf)


def test_nothing_within_max_range_is_a_miss():
    geo = geometry(scene_of(walls=[{"points": [[2, -3], [2, 3]]}]))
    assert trace(geo, 0.0, 0.0, 1.0, 0.0, 1.9)[:2] == (math.inf, math.inf)
    assert trace(geo, 0.0, 0.0, -1.0, 0.0, 50.0)[:2] == (math.inf, math.inf)
    assert trace(geo, 0.0, 0.0, 0.0, 1.0, 50.0)[:2] == (math.inf, math.inf)


def circle_scene(threshold_deg):
    """A circle at (3, 0) of radius 0.5 with the given threshold; a rough block above, its
    lower face y = 1.95 spanning x in [1.8, 2.4]."""
    return geometry(
        scene_of(
            surfaces={"shiny": {"specular_threshold_deg": threshold_deg}},
            circles=[{"center": [3, 0], "radius": 0.5, "surface": "shiny"}],
            walls=[{"points": [[1.85, 2], [2.35, 2]], "thickness": 0.1}],
        )
    )


def test_circle_hit_distance_and_incidence():
    geo = circle_scene(38.0)
    assert trace(geo, 0.0, 0.0, 1.0, 0.0, 5.0)[:2] == (pytest.approx(2.5), pytest.approx(2.5))
    # from y = 0.3: hit at (2.6, 0.3) (3 - sqrt(0.5^2 - 0.3^2)), normal (-0.8, 0.6): incidence
    # asin(0.3 / 0.5) = 36.87 deg, within 38 deg (an echo) but past 36 deg (a mirror bounce)
    assert trace(geo, 0.0, 0.3, 1.0, 0.0, 5.0)[:2] == (pytest.approx(2.6), pytest.approx(2.6))
    first, echo, _ = trace(circle_scene(36.0), 0.0, 0.3, 1.0, 0.0, 5.0)
    assert first == pytest.approx(2.6) and echo == math.inf
    # the mirror direction d - 2 (d.n) n = (-0.28, 0.96) reaches y = 1.95 at x = 2.12 after 1.65 / 0.96
    first, echo, bounced = trace(circle_scene(36.0), 0.0, 0.3, 1.0, 0.0, 5.0, max_bounces=1)
    assert first == pytest.approx(2.6) and echo == pytest.approx(2.6 + 1.65 / 0.96) and bounced
    assert trace(geo, 0.0, 0.6, 1.0, 0.0, 5.0)[0] == math.inf


def test_far_wall_through_many_buckets():
    geo = geometry(scene_of(bounds=[0, 0, 40, 40], walls=[{"points": [[35, 0], [35, 40]], "thickness": 0.1}]))
    d = 1.0 / math.sqrt(2.0)
    assert trace(geo, 1.0, 1.0, d, d, 60.0)[0] == pytest.approx(33.95 * math.sqrt(2))


def test_random_rays_agree_with_brute_force():
    rng = np.random.default_rng(7)
    walls = [{"points": rng.uniform(0, 10, (3, 2)).tolist(), "thickness": float(rng.uniform(0.02, 0.3))} for _ in range(12)]
    circles = [{"center": rng.uniform(0, 10, 2).tolist(), "radius": float(rng.uniform(0.05, 0.5))} for _ in range(5)]
    raw = {"bounds": [0, 0, 10, 10], "trajectory": {"poses": [[0, 0, 0]]}, "walls": walls, "circles": circles}
    for bucket_size in (0.37, 1.0, 20.0):
        scene = build_scene(parse_world(raw, file="test.yaml"), bucket_size=bucket_size)
        seg = scene.segments
        pose = np.column_stack([rng.uniform(-1, 11, (300, 2)), rng.uniform(0, 2 * math.pi, 300)])
        got = first_hits(geometry(scene), pose, 8.0)
        for (ox, oy, a), t_got in zip(pose, got, strict=True):
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
            if best > 8.0:
                assert t_got == math.inf
            else:
                assert t_got == pytest.approx(best, abs=1e-9)


def bitmap_scene(bitmap, origin=(0.0, 0.0), resolution=1.0, threshold=math.pi / 2, **geometry_keys):
    """A scene with a bitmap and ``geometry_keys`` (by default only one circle far away)."""
    geometry_keys = geometry_keys or {"bounds": [0, 0, 1, 1], "circles": [{"center": [500, 500], "radius": 0.1}]}
    scene = scene_of(**geometry_keys)
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
    assert trace(geo, 0.5, 2.5, 1.0, 0.0, 10.0) == (pytest.approx(3.5), pytest.approx(3.5), False)
    assert trace(geo, 1.5, 0.5, 0.0, 1.0, 10.0)[0] == pytest.approx(3.5)
    assert trace(geo, 1.5, 0.5, 0.0, 1.0, 3.0)[0] == math.inf
    # the top face of the pixel at row 4 col 1, hit from above the bitmap
    assert trace(geo, 1.25, 7.0, 0.0, -1.0, 10.0)[:2] == (pytest.approx(2.0), pytest.approx(2.0))
    # oblique: from (0.5, 2.5) towards (4, 2.9), entering x = 4 at y = 2.5 + 3.5 * 0.4 / 3.5 = 2.9,
    # at atan2(0.4, 3.5) = 6.5 deg from the face's normal (-1, 0): past a 5 deg threshold, it
    # mirrors to (-3.5, 0.4) / |.|, onto a rough block whose face x = 1 spans y in [3.0, 3.6]
    # (reached at y = 2.9 + 3 * 0.4 / 3.5 = 3.24)
    block = {"bounds": [0, 0, 5, 5], "walls": [{"points": [[0.9, 3.0], [0.9, 3.6]], "thickness": 0.2}]}
    norm = math.hypot(3.5, 0.4)
    d = (3.5 / norm, 0.4 / norm)
    for threshold_deg, echo in ((7.0, norm), (5.0, norm * (1.0 + 3.0 / 3.5))):
        geo = geometry(bitmap_scene(bm, threshold=math.radians(threshold_deg), **block))
        first, got, bounced = trace(geo, 0.5, 2.5, d[0], d[1], 10.0, max_bounces=1)
        assert first == pytest.approx(norm) and got == pytest.approx(echo) and bounced == (threshold_deg < 6.5)


def test_bitmap_with_origin_and_resolution():
    bm = np.zeros((4, 4), np.uint8)
    bm[:, 3] = 1  # x in [1.75, 2.0) with origin x 1.0 and 0.25 m pixels
    geo = geometry(bitmap_scene(bm, origin=(1.0, -0.5), resolution=0.25))
    assert trace(geo, 0.0, 0.0, 1.0, 0.0, 10.0)[0] == pytest.approx(1.75)
    assert trace(geo, 0.0, 0.6, 1.0, 0.0, 10.0)[0] == math.inf  # above the bitmap


def test_bitmap_pixel_holding_the_origin_is_not_tested():
    bm = np.zeros((3, 3), np.uint8)
    bm[1, 1] = 1
    bm[1, 2] = 1
    geo = geometry(bitmap_scene(bm))
    assert trace(geo, 1.5, 1.5, 1.0, 0.0, 10.0)[0] == pytest.approx(0.5)


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
    assert trace(geo, 0.5, 0.5, 1.0, 0.0, 10.0)[:2] == (pytest.approx(3.4), pytest.approx(3.4))  # the rough wall
    # above the wall, the bitmap's face x = 6 with the bitmap's threshold (0.1 rad): echoes at
    # 0.05 rad from its normal, not at 0.15 rad
    assert trace(geo, 0.5, 2.5, 1.0, 0.0, 10.0)[:2] == (pytest.approx(5.5), pytest.approx(5.5))
    for angle, echoes in ((0.05, True), (0.15, False)):
        first, echo, _ = trace(geo, 0.5, 2.5, math.cos(angle), -math.sin(angle), 10.0)
        assert first == pytest.approx(5.5 / math.cos(angle))
        assert echo == (pytest.approx(first) if echoes else math.inf)


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
    assert trace(geo, 0.0, 0.0, 1.0, 0.0, 8.0, max_bounces=2) == (pytest.approx(3.0), pytest.approx(4.95), True)
    # exactly one bounce: one allowed is enough, none gives no echo
    assert trace(geo, 0.0, 0.0, 1.0, 0.0, 8.0, max_bounces=1)[1] == pytest.approx(4.95)
    first, echo, _ = trace(geo, 0.0, 0.0, 1.0, 0.0, 8.0, max_bounces=0)
    assert first == pytest.approx(3.0) and echo == math.inf
    # the path is limited: 4.95 > 4.9
    assert trace(geo, 0.0, 0.0, 1.0, 0.0, 4.9, max_bounces=2)[1] == math.inf


def test_bounce_off_a_bitmap_face():
    bm = np.zeros((6, 6), np.uint8)
    bm[0, :] = 1  # floor y in [0, 1), smooth
    d = 1 / math.sqrt(2)
    # a ray going down-right at 45 degrees hits y = 1 at x = 2: 45 degrees from the face's normal
    for threshold_deg, echo in ((46.0, math.sqrt(2)), (44.0, math.inf)):
        geo = geometry(bitmap_scene(bm, threshold=math.radians(threshold_deg)))
        first, got, _ = trace(geo, 1.0, 2.0, d, -d, 20.0, max_bounces=2)
        assert first == pytest.approx(math.sqrt(2)) and got == pytest.approx(echo)
    # past the threshold it mirrors up-right (the normal is (0, 1)), onto a rough wall face x = 3.95
    # at y = 2.95
    wall = {"bounds": [0, 0, 6, 6], "walls": [{"points": [[4, 2], [4, 4]], "thickness": 0.1}]}
    geo = geometry(bitmap_scene(bm, threshold=math.radians(20), **wall))
    assert trace(geo, 1.0, 2.0, d, -d, 20.0, max_bounces=2) == (
        pytest.approx(math.sqrt(2)), pytest.approx(2.95 * math.sqrt(2)), True)
