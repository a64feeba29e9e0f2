"""The sonar simulator: readings, causes and ideal ranges on hand-computable worlds; determinism."""

from __future__ import annotations

import math

import numpy as np
import pytest
from numpy.testing import assert_array_equal

from aogm_cli.core.log import CAUSE_ECHO, CAUSE_NO_ECHO, CAUSE_RANDOM, CAUSE_SPECULAR, SensorSpec
from aogm_cli.io.logfile import read_log, write_log
from aogm_cli.simulation.sonar import readings_from_echoes, simulate, sub_ray_offsets
from aogm_cli.world.config import Sonar
from aogm_cli.world.loader import parse_world

EXACT = {"noise_sigma": 0.0, "random_rate": 0.0}


def one_sonar_world(pose, sonar=None, **geometry):
    """A world with a single sonar at the robot's centre facing forward, seen at ``pose``."""
    raw = {
        "bounds": [-10, -10, 10, 10],
        "trajectory": {"poses": [pose]},
        "sonar": {"mounts": [[0, 0, 0]], "max_range": 8.0, **EXACT, **(sonar or {})},
    }
    raw.update(geometry)
    return parse_world(raw, file="test.yaml")


def test_sub_ray_offsets_span_the_cone():
    assert np.degrees(sub_ray_offsets(math.radians(30), 11)) == pytest.approx(np.arange(-15, 16, 3))
    assert sub_ray_offsets(0.5, 1).tolist() == [0.0]


def test_sonar_square_to_a_wall():
    w = one_sonar_world([1, 1, 0], walls=[{"points": [[3, -5], [3, 7]], "thickness": 0.1}])
    log = simulate(w, seed=0)
    assert log.ranges.dtype == np.float32 and log.truth.cause.dtype == np.int8
    assert log.ranges[0, 0] == pytest.approx(1.95, abs=1e-6)
    assert log.truth.ideal_range[0, 0] == pytest.approx(1.95, abs=1e-6)
    assert log.truth.cause[0, 0] == CAUSE_ECHO


def test_mount_is_composed_with_the_pose():
    # robot at (1, 1) facing +y; the sonar sits 0.5 m to its right (world +x), facing its right (world +x)
    w = one_sonar_world(
        [1, 1, 90],
        sonar={"mounts": [[0, -0.5, -90]]},
        walls=[{"points": [[3, -5], [3, 7]], "thickness": 0.1}],
    )
    assert simulate(w, seed=0).ranges[0, 0] == pytest.approx(1.45, abs=1e-6)


def test_cone_straddling_a_door_frame_reads_the_frame():
    # wall at x = 3 (faces at 2.95, 3.05) with a 0.5 m opening centred on y = 1; back wall at x = 6
    w = one_sonar_world(
        [1, 1, 0],
        walls=[
            {"points": [[3, -5], [3, 7]], "thickness": 0.1, "openings": [{"at": 6.0, "width": 0.5}]},
            {"points": [[6, -5], [6, 7]], "thickness": 0.1},
        ],
    )
    log = simulate(w, seed=0)
    # sub-rays at 0, +-3, +-6 deg pass the opening (1.95 tan 6 = 0.205 < 0.25); +-9 deg hit the frame
    frame = 1.95 / math.cos(math.radians(9))
    assert log.ranges[0, 0] == pytest.approx(frame, abs=1e-5)
    assert log.truth.ideal_range[0, 0] == pytest.approx(frame, abs=1e-5)
    assert log.truth.cause[0, 0] == CAUSE_ECHO
    # a narrow beam sees through the door to the back wall
    narrow = one_sonar_world([1, 1, 0], sonar={"beam_width_deg": 2}, walls=w_raw_walls(w))
    assert simulate(narrow, seed=0).ranges[0, 0] == pytest.approx(4.95, abs=1e-5)


def w_raw_walls(w):
    return [
        {"points": [list(p) for p in wall.points], "thickness": wall.thickness, "openings": [{"at": o.at, "width": o.width} for o in wall.openings]}
        for wall in w.walls
    ]


def test_smooth_wall_at_grazing_incidence_gives_no_echo():
    # sonar looking 10 deg above +x at a glass wall 0.95 m away: incidence 75..85 deg > 15
    w = one_sonar_world(
        [0, 0, 10],
        sonar={"beam_width_deg": 10, "max_range": 5.0},
        surfaces={"glass": {"specular_threshold_deg": 15}},
        walls=[{"points": [[-10, 1], [10, 1]], "thickness": 0.1, "surface": "glass"}],
    )
    log = simulate(w, seed=0)
    assert log.ranges[0, 0] == np.inf
    assert log.truth.cause[0, 0] == CAUSE_NO_ECHO
    assert log.truth.ideal_range[0, 0] == pytest.approx(0.95 / math.sin(math.radians(15)), abs=1e-5)


def test_mirror_bounce_gives_a_long_reading():
    # a glass face x - y = 3 at 45 deg mirrors the beam up onto a rough wall face y = 1.95
    off = 0.05 * math.sqrt(2)
    w = one_sonar_world(
        [0, 0, 0],
        sonar={"sub_rays": 1},
        surfaces={"glass": {"specular_threshold_deg": 15}},
        walls=[
            {"points": [[2 + off, -1], [4 + off, 1]], "thickness": 0.1, "surface": "glass"},
            {"points": [[2, 2], [4, 2]], "thickness": 0.1},
        ],
    )
    log = simulate(w, seed=0)
    assert log.ranges[0, 0] == pytest.approx(3.0 + 1.95, abs=1e-5)
    assert log.truth.ideal_range[0, 0] == pytest.approx(3.0, abs=1e-5)
    assert log.truth.cause[0, 0] == CAUSE_SPECULAR


def test_direct_echo_behind_a_silent_smooth_surface_is_too_long():
    # a glass strip (face y = 0.45, x in [1, 3]) is the nearest surface of the upper sub-rays, at
    # 75..81 deg incidence; the central sub-ray echoes from a rough wall face at x = 3.95
    w = one_sonar_world(
        [0, 0, 0],
        surfaces={"glass": {"specular_threshold_deg": 15}},
        walls=[
            {"points": [[1, 0.5], [3, 0.5]], "thickness": 0.1, "surface": "glass"},
            {"points": [[4, -5], [4, 5]], "thickness": 0.1},
        ],
    )
    log = simulate(w, seed=0)
    assert log.truth.ideal_range[0, 0] == pytest.approx(0.45 / math.sin(math.radians(15)), abs=1e-5)
    assert log.ranges[0, 0] == pytest.approx(3.95, abs=1e-5)
    assert log.truth.cause[0, 0] == CAUSE_SPECULAR


def test_circle_hit():
    w = one_sonar_world([0, 0, 0], circles=[{"center": [3, 0], "radius": 0.5}])
    log = simulate(w, seed=0)
    assert log.ranges[0, 0] == pytest.approx(2.5, abs=1e-6)
    assert log.truth.cause[0, 0] == CAUSE_ECHO


def test_nothing_in_range_is_inf():
    w = one_sonar_world([0, 0, 0], circles=[{"center": [9, 0], "radius": 0.5}])
    log = simulate(w, seed=0)
    assert log.ranges[0, 0] == np.inf and log.truth.ideal_range[0, 0] == np.inf
    assert log.truth.cause[0, 0] == CAUSE_NO_ECHO


def test_readings_from_echoes_random_noise_and_limits():
    sonar = Sonar(mounts=((0, 0, 0),), min_range=0.2, max_range=5.0, noise_sigma=0.1, random_rate=0.5, cause_tolerance=0.1)
    echo = np.array([[1.0, 2.0, np.inf, 4.95, 0.1, 3.0, 1.0]])
    ideal = np.array([[1.0, 1.5, 2.0, 4.95, 0.1, 3.0, 1.0]])
    multipath = np.array([[False, False, False, False, False, False, True]])
    u_random = np.array([[0.9, 0.9, 0.9, 0.9, 0.9, 0.1, 0.9]])
    u_range = np.full((1, 7), 0.5)
    noise = np.array([[1.0, 0.0, 0.0, 1.0, -1.0, 0.0, 0.0]])
    ranges, cause = readings_from_echoes(echo, ideal, multipath, u_random, u_range, noise, sonar)
    assert ranges.dtype == np.float32 and cause.dtype == np.int8
    np.testing.assert_allclose(ranges[0], [1.1, 2.0, np.inf, np.inf, 0.2, 2.6, 1.0], rtol=1e-6)
    assert_array_equal(cause[0], [CAUSE_ECHO, CAUSE_SPECULAR, CAUSE_NO_ECHO, CAUSE_NO_ECHO, CAUSE_ECHO, CAUSE_RANDOM, CAUSE_SPECULAR])
    # a random reading pushed past max_range stays random
    ranges, cause = readings_from_echoes(
        np.array([[1.0]]), np.array([[1.0]]), np.array([[False]]), np.array([[0.0]]), np.array([[1.0]]), np.array([[1.0]]), sonar
    )
    assert ranges[0, 0] == np.inf and cause[0, 0] == CAUSE_RANDOM


def corridor_world():
    return parse_world(
        {
            "bounds": [0, 0, 20, 8],
            "surfaces": {"glass": {"specular_threshold_deg": 15}},
            "walls": [
                {"points": [[0, 2], [20, 2]]},
                {"points": [[0, 4], [20, 4]], "openings": [{"at": 10.0, "width": 1.0}], "surface": "glass"},
            ],
            "boxes": [{"center": [12, 6], "size": [1.2, 0.6], "yaw_deg": 30}],
            "circles": [{"center": [16, 6], "radius": 0.2}],
            "trajectory": {"waypoints": [[1, 3], [19, 3]], "speed": 0.3, "scan_period": 0.5},
            "sonar": {"random_rate": 0.05},
            "checks": [{"name": "door_passable", "passable": {"from": [10, 3], "to": [10, 6]}}],
        },
        file="worlds/corridor.yaml",
        text="name: corridor\n",
    )


def test_a_world_without_sonar_simulates_a_log_with_the_sensor_defaults():
    raw = {"bounds": [0, 0, 4, 4], "walls": [{"points": [[0, 0], [4, 0]]}], "trajectory": {"poses": [[2, 2, 0]]}}
    sensor = simulate(parse_world(raw, file="w.yaml"), seed=0).sensor
    assert sensor.kind == SensorSpec.kind and sensor.count == 24
    for key in ("beam_width", "min_range", "max_range", "noise_sigma"):
        assert getattr(sensor, key) == getattr(SensorSpec, key), key


def test_simulate_is_deterministic_and_seed_changes_the_noise():
    w = corridor_world()
    a = simulate(w, seed=5)
    b = simulate(w, seed=5)
    c = simulate(w, seed=6)
    for x, y in ((a.ranges, b.ranges), (a.truth.cause, b.truth.cause), (a.truth.ideal_range, b.truth.ideal_range)):
        assert x.tobytes() == y.tobytes()
    finite = np.isfinite(a.ranges) & np.isfinite(c.ranges)
    assert (a.ranges[finite] != c.ranges[finite]).mean() > 0.9
    assert a.truth.ideal_range.tobytes() == c.truth.ideal_range.tobytes()


def test_simulated_log_contents_and_round_trip(tmp_path):
    w = corridor_world()
    calls = []
    log = simulate(w, seed=11, progress=calls.append)
    n = log.n_scans
    assert n == 121  # 18 m at 0.15 m per scan
    assert calls[-1] == n
    assert log.ranges.shape == (n, 24) and log.pose.shape == (n, 3)
    assert log.source == "aogm simulate worlds/corridor.yaml" and log.seed == 11
    assert log.sensor.count == 24 and log.sensor.max_range == 5.0
    assert log.truth.occupancy.shape == (160, 400)
    assert log.truth.world == "name: corridor\n"
    assert log.truth.checks == ({"name": "door_passable", "passable": {"from": [10, 3], "to": [10, 6], "robot_radius": 0.25}},)
    causes = np.bincount(log.truth.cause.ravel(), minlength=4)
    assert all(causes > 0)  # echoes, no echoes, random and specular readings all occur
    rnd = log.truth.cause == CAUSE_RANDOM
    assert rnd.mean() == pytest.approx(0.05, abs=0.02)
    ok = log.truth.cause == CAUSE_ECHO
    assert np.all(np.abs(log.ranges[ok] - log.truth.ideal_range[ok]) < 0.1 + 0.1)
    assert np.all(log.ranges[np.isfinite(log.ranges)] >= 0.15)
    write_log(tmp_path / "a.h5", log)
    back = read_log(tmp_path / "a.h5")
    assert back.ranges.tobytes() == log.ranges.tobytes()
    assert back.truth.cause.tobytes() == log.truth.cause.tobytes()


def test_floorplan_world_simulates(tmp_path):
    from PIL import Image

    img = np.full((10, 10), 254, np.uint8)
    img[:, 9] = 0  # right column: x in [4.5, 5)
    Image.fromarray(img).save(tmp_path / "map.pgm")
    (tmp_path / "map.yaml").write_text(
        "image: map.pgm\nresolution: 0.5\norigin: [0.0, 0.0, 0.0]\nnegate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n"
    )
    w = parse_world(
        {
            "bounds": [0, 0, 5, 5],
            "floorplan": {"map": "map.yaml"},
            "trajectory": {"poses": [[1, 2.5, 0]]},
            "sonar": {"mounts": [[0, 0, 0]], **EXACT},
        },
        file=str(tmp_path / "w.yaml"),
        base_dir=tmp_path,
    )
    log = simulate(w, seed=0)
    assert log.ranges[0, 0] == pytest.approx(3.5, abs=1e-6)
    assert log.truth.cause[0, 0] == CAUSE_ECHO
    assert log.truth.occupancy[:, -10:].all() and not log.truth.occupancy[:, :-10].any()


def test_echo_block_matches_unpruned_sub_ray_tracing():
    """The kernel bounds each sub-ray's search by the best echo so far; that must not change results:
    the same kernel given one sub-ray at a time traces each up to max_range."""
    from aogm_cli.simulation.raycast import geometry
    from aogm_cli.simulation.sonar import NO_ERRORS, echo_block
    from aogm_cli.world.scene import build_scene

    rng = np.random.default_rng(12)
    walls = [
        {"points": rng.uniform(0, 10, (3, 2)).tolist(), "thickness": float(rng.uniform(0.02, 0.3)), "surface": ["rough", "glass", "door"][k % 3]}
        for k in range(14)
    ]
    circles = [{"center": rng.uniform(0, 10, 2).tolist(), "radius": 0.3, "surface": "glass"} for _ in range(4)]
    w = parse_world(
        {
            "bounds": [0, 0, 10, 10],
            "surfaces": {"glass": {"specular_threshold_deg": 10}, "door": {"specular_threshold_deg": 30}},
            "walls": walls,
            "circles": circles,
            "trajectory": {"poses": [[1, 1, 0]]},
            "sonar": {"max_bounces": 2},
        },
        file="test.yaml",
    )
    geo = geometry(build_scene(w))
    pose = np.column_stack([rng.uniform(0, 10, (300, 2)), rng.uniform(-np.pi, np.pi, 300)])
    mount = np.asarray(w.sonar.mounts)
    off = sub_ray_offsets(w.sonar.beam_width, w.sonar.sub_rays)
    co, so = np.cos(off), np.sin(off)
    echo, ideal, multi = np.empty((300, 24)), np.empty((300, 24)), np.empty((300, 24), dtype=bool)
    echo_block(pose, mount, co, so, 5.0, 2, geo, echo, ideal, multi, *NO_ERRORS)
    # per sub-ray r, unpruned: (first hit, echo path, echo after a bounce) of every reading
    traced = np.empty((len(co), 3, 300, 24))
    for r in range(len(co)):
        one = np.empty((300, 24)), np.empty((300, 24)), np.empty((300, 24), dtype=bool)
        echo_block(pose, mount, co[r : r + 1], so[r : r + 1], 5.0, 2, geo, *one, *NO_ERRORS)
        traced[r] = one[1], one[0], one[2]
    assert_array_equal(ideal, traced[:, 0].min(axis=0))
    assert_array_equal(echo, traced[:, 1].min(axis=0))
    # after a bounce: the nearest echo, unless some sub-ray echoes as near without one
    direct = (traced[:, 1] == echo) & (traced[:, 2] == 0)
    assert_array_equal(multi, np.isfinite(echo) & ~direct.any(axis=0))
    assert multi.any() and np.isinf(echo).any()
