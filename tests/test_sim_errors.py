"""The errors of a real robot in the simulator (world key ``errors:``): each off by default and
then the log of before; odometry drift (random and systematic), range noise growing with range,
crosstalk, a minimum echo strength, a ring that fires one sonar after another and side lobes each
doing what worlds/README.md says; bad values named by their key path."""

from __future__ import annotations

import math

import h5py
import numpy as np
import pytest
import yaml
from click.testing import CliRunner

from aogm_cli.cli import main
from aogm_cli.core.log import CAUSE_ECHO, CAUSE_NO_ECHO, CAUSE_SPECULAR
from aogm_cli.simulation.firing import schedule
from aogm_cli.simulation.odometry import dead_reckoning
from aogm_cli.simulation.sonar import simulate
from aogm_cli.world.config import Firing, Odometry
from aogm_cli.world.loader import parse_world
from aogm_cli.world.trajectory import poses_before, trajectory_poses

BOX = {
    "bounds": [-0.5, -0.5, 6.5, 4.5],
    "walls": [{"points": [[0, 0], [6, 0], [6, 4], [0, 4], [0, 0]], "thickness": 0.1}],
    "boxes": [{"center": [4.0, 2.6], "size": [0.6, 0.4], "yaw_deg": 20}],
    "circles": [{"center": [2.0, 1.2], "radius": 0.15}],
    "trajectory": {"waypoints": [[0.8, 2.0], [5.0, 2.0], [5.0, 3.2], [1.0, 3.2]]},
    "sonar": {"count": 8, "max_range": 5.0, "sub_rays": 5},
}
ALL_ON = {
    "odometry": {"translation": 0.05, "rotation": 0.05, "rotation_per_metre_deg": 2.0},
    "noise_per_metre": 0.02,
    "crosstalk_rate": 0.3,
    "echo_strength": {"min_strength": 0.05},
    "firing": {"interval": 0.1},
    "side_lobes": {"range": 1.5},
}


def world(errors=None, **over):
    raw = {**BOX, **over}
    if errors is not None:
        raw["errors"] = errors
    return parse_world(raw, file="w.yaml", text=yaml.safe_dump(raw))


def arrays(log):
    return {
        "time": log.time, "pose": log.pose, "ranges": log.ranges, "cause": log.truth.cause,
        "ideal_range": log.truth.ideal_range, "occupancy": log.truth.occupancy,
    }


def assert_same_log(a, b, but=()):
    for name, x in arrays(a).items():
        y = arrays(b)[name]
        same = x.dtype == y.dtype and np.array_equal(x, y, equal_nan=True)
        assert same == (name not in but), name


# --- each error off: the log of before -----------------------------------------------------------


def test_every_error_at_its_default_gives_the_log_without_an_errors_section():
    plain = simulate(world(), seed=3)
    zeros = {
        "odometry": {"translation": 0, "rotation": 0, "rotation_per_metre_deg": 0, "heading_bias_per_metre_deg": 0,
                     "turn_bias": 0},
        "noise_per_metre": 0, "crosstalk_rate": 0,
        "echo_strength": {"min_strength": 0, "beam_deg": 5, "incidence_exponent": 7},
        "firing": {"interval": 0, "slots": [7, 6, 5, 4, 3, 2, 1, 0]},
        "side_lobes": {"range": 0, "angle_deg": 30, "width_deg": 10, "sub_rays": 5},
    }
    for errors in ({}, zeros, {"odometry": {}}, {"echo_strength": {}}, {"firing": {}}, {"side_lobes": {}}):
        assert_same_log(plain, simulate(world(errors), seed=3))


@pytest.mark.parametrize("key", sorted(ALL_ON))
def test_each_error_changes_only_what_it_should(key):
    plain = simulate(world(), seed=3)
    log = simulate(world({key: ALL_ON[key]}), seed=3)
    changed = {"odometry": {"pose"}, "noise_per_metre": {"ranges"}, "crosstalk_rate": {"ranges", "cause"},
               "echo_strength": {"ranges", "cause"}, "firing": {"ranges", "cause", "ideal_range"},
               "side_lobes": {"ranges", "cause"}}[key]
    assert_same_log(plain, log, but=changed)


def test_the_cli_log_of_a_world_with_errors_off_equals_the_plain_one(tmp_path):
    paths = []
    off = {"crosstalk_rate": 0, "odometry": {"rotation": 0, "turn_bias": 0}, "firing": {"interval": 0},
           "side_lobes": {"range": 0}}
    for name, errors in (("plain", None), ("off", off)):
        raw = {**BOX, **({"errors": errors} if errors is not None else {})}
        (tmp_path / f"{name}.yaml").write_text(yaml.safe_dump(raw))
        out = tmp_path / f"{name}.h5"
        r = CliRunner().invoke(main, ["simulate", str(tmp_path / f"{name}.yaml"), "-o", str(out), "--seed", "2", "-q"])
        assert r.exit_code == 0, r.output
        paths.append(out)
    with h5py.File(paths[0]) as a, h5py.File(paths[1]) as b:
        for name in ("scans/time", "scans/pose", "scans/ranges", "truth/cause", "truth/ideal_range", "truth/occupancy"):
            assert np.array_equal(a[name][...], b[name][...], equal_nan=True), name


# --- odometry drift ----------------------------------------------------------------------------


def straight_line(steps, step=0.1):
    x = np.arange(steps + 1) * step
    return np.column_stack([x, np.zeros_like(x), np.zeros_like(x)])


def test_translation_drift_grows_as_the_square_root_of_the_steps():
    # std of each 0.1 m step's error: 0.1 * 0.1 = 0.01 m; after n steps 0.01 sqrt(n) m along the line
    pose = straight_line(400)
    runs = np.array([dead_reckoning(pose, Odometry(translation=0.1), np.random.default_rng(s)) for s in range(300)])
    along = runs[:, :, 0] - pose[None, :, 0]
    for n in (25, 100, 400):
        assert along[:, n].std() == pytest.approx(0.01 * math.sqrt(n), rel=0.15)
    assert np.allclose(runs[:, :, 1], 0.0) and np.allclose(runs[:, :, 2], 0.0)  # no turn error


def test_heading_drift_per_metre_and_per_radian():
    pose = straight_line(400)
    k = math.radians(2.0)  # rad per metre: heading std 2 degrees after the first metre, per step k * 0.1
    runs = np.array([dead_reckoning(pose, Odometry(rotation_per_metre=k), np.random.default_rng(s)) for s in range(300)])
    for n in (25, 100, 400):
        assert runs[:, n, 2].std() == pytest.approx(k * 0.1 * math.sqrt(n), rel=0.15)
    lateral = np.abs(runs[:, :, 1]).mean(axis=0)
    assert lateral[400] > lateral[100] > lateral[25] > 0
    # turning in place: pi/2 per step, std 0.05 * pi/2 per step
    turns = np.column_stack([np.zeros(101), np.zeros(101), np.arange(101) * (math.pi / 2)])
    runs = np.array([dead_reckoning(turns, Odometry(rotation=0.05), np.random.default_rng(s)) for s in range(300)])
    error = (runs[:, -1, 2] - turns[-1, 2] + math.pi) % (2 * math.pi) - math.pi
    assert error.std() == pytest.approx(0.05 * math.pi / 2 * math.sqrt(100), rel=0.15)
    assert np.all(runs[:, :, :2] == 0.0)


def test_simulated_odometry_drifts_with_distance_is_seeded_and_leaves_the_truth():
    errors = {"odometry": ALL_ON["odometry"]}
    w = world(errors)
    _, true = trajectory_poses(w)
    logs = [simulate(w, seed=s) for s in (5, 5, 6)]
    assert_same_log(logs[0], logs[1])
    assert not np.array_equal(logs[0].pose, logs[2].pose)
    plain = simulate(world(), seed=5)
    assert_same_log(plain, logs[0], but={"pose"})  # readings cast from the true poses
    assert np.array_equal(logs[0].pose[0], true[0])
    runs = np.array([dead_reckoning(true, w.errors.odometry, np.random.default_rng(s)) for s in range(200)])
    dist = np.hypot(runs[:, :, 0] - true[:, 0], runs[:, :, 1] - true[:, 1]).mean(axis=0)
    n = len(dist)
    assert 0 < dist[n // 4] < dist[n // 2] < dist[-1]
    assert np.array_equal(dead_reckoning(true, Odometry(), np.random.default_rng(1)), true)


def test_backing_up_is_driven_backwards_not_turned_round():
    pose = np.array([[0.0, 0.0, 0.0], [-0.1, 0.0, 0.0], [-0.2, 0.0, 0.0]])
    est = dead_reckoning(pose, Odometry(rotation=0.5, translation=1e-9), np.random.default_rng(0))
    assert np.allclose(est, pose, atol=1e-6)


def test_a_wheel_diameter_bias_curves_the_logged_path_into_a_circle():
    # 1 m steps straight along x; 2 degrees of heading per metre: after n steps the logged heading
    # is n * 2 degrees, and every logged position is a chord of one circle through the start,
    # tangent to x, of radius 1 / (2 sin(1 degree)) (each 1 m chord turns by 2 degrees)
    k = math.radians(2.0)
    pose = straight_line(40, step=1.0)
    est = dead_reckoning(pose, Odometry(heading_bias_per_metre=k), np.random.default_rng(0))
    assert np.allclose(np.unwrap(est[:, 2]), np.arange(41) * k)
    radius = 1.0 / (2.0 * math.sin(k / 2))
    assert np.allclose(np.hypot(est[:, 0], est[:, 1] - radius), radius)
    assert np.all(est[1:, 1] > 0)  # positive: the logged path curves left (counter-clockwise)
    # systematic errors draw nothing: any generator gives the same path
    assert np.array_equal(est, dead_reckoning(pose, Odometry(heading_bias_per_metre=k), np.random.default_rng(9)))
    # backing up, the same wheels turn the logged heading the other way
    back = dead_reckoning(pose[::-1], Odometry(heading_bias_per_metre=k), np.random.default_rng(0))
    assert np.allclose(np.unwrap(back[:, 2]), -np.arange(41) * k)


def test_a_wheelbase_bias_scales_every_logged_turn():
    turns = np.column_stack([np.zeros(5), np.zeros(5), np.arange(5) * (math.pi / 2)])
    est = dead_reckoning(turns, Odometry(turn_bias=0.01), np.random.default_rng(0))
    assert np.allclose(np.unwrap(est[:, 2]), np.arange(5) * (math.pi / 2) * 1.01)
    assert np.all(est[:, :2] == 0.0)
    # with the random errors on too, the bias adds to the same draws
    both = dead_reckoning(turns, Odometry(rotation=0.05, turn_bias=0.01), np.random.default_rng(3))
    alone = dead_reckoning(turns, Odometry(rotation=0.05), np.random.default_rng(3))
    assert np.allclose(np.diff(np.unwrap(both[:, 2])), np.diff(np.unwrap(alone[:, 2])) * 1.01)


def test_systematic_odometry_changes_only_the_logged_poses():
    plain = simulate(world(), seed=3)
    log = simulate(world({"odometry": {"heading_bias_per_metre_deg": 1.0, "turn_bias": -0.02}}), seed=3)
    assert_same_log(plain, log, but={"pose"})
    assert np.array_equal(log.pose[0], plain.pose[0])


# --- range noise growing with range ---------------------------------------------------------------


def test_range_noise_spread_grows_with_range():
    # one sonar at the robot's centre, one sub-ray, facing a wall face at x = 4.95: 200 scans at
    # 1 m and 200 at 4 m. sigma(z) = 0.01 + 0.05 z: 0.06 m at 1 m, 0.21 m at 4 m
    poses = [[3.95, 2.0, 0.0]] * 200 + [[0.95, 2.0, 0.0]] * 200
    w = world(
        {"noise_per_metre": 0.05},
        walls=[{"points": [[5.0, -0.4], [5.0, 4.4]], "thickness": 0.1}], boxes=[], circles=[],
        trajectory={"poses": poses},
        sonar={"mounts": [[0, 0, 0]], "sub_rays": 1, "noise_sigma": 0.01, "random_rate": 0.0, "max_range": 5.5},
    )
    log = simulate(w, seed=1)
    err = (log.ranges[:, 0] - log.truth.ideal_range[:, 0]).astype(np.float64)
    assert np.allclose(log.truth.ideal_range[:200], 1.0) and np.allclose(log.truth.ideal_range[200:], 4.0)
    assert err[:200].std() == pytest.approx(0.06, rel=0.15)
    assert err[200:].std() == pytest.approx(0.21, rel=0.15)


# --- crosstalk ---------------------------------------------------------------------------------


def test_crosstalk_at_rate_one_gives_readings_no_longer_than_the_own_echo():
    sonar = {"count": 8, "max_range": 5.0, "sub_rays": 5, "noise_sigma": 0.0, "random_rate": 0.0}
    plain = simulate(world(sonar=sonar), seed=4)
    log = simulate(world({"crosstalk_rate": 1.0}, sonar=sonar), seed=4)
    assert np.all(log.ranges <= plain.ranges)
    shorter = log.ranges < plain.ranges
    assert shorter.mean() > 0.2
    assert np.all(log.truth.cause[shorter] == CAUSE_SPECULAR)
    assert np.array_equal(log.truth.cause[~shorter], plain.truth.cause[~shorter])
    # each shorter reading is a ring neighbour's echo
    n = plain.ranges.shape[1]
    left, right = np.roll(plain.ranges, 1, axis=1), np.roll(plain.ranges, -1, axis=1)
    assert np.all((log.ranges == left) | (log.ranges == right) | ~shorter)
    assert np.any(shorter & (log.ranges == left)) and np.any(shorter & (log.ranges == right)) and n == 8


# --- a minimum echo strength ---------------------------------------------------------------------


def one_ray_world(poses, min_strength):
    return world(
        {"echo_strength": {"min_strength": min_strength}},
        bounds=[-5, -5, 5, 5], walls=[{"points": [[-5, 2], [5, 2]], "thickness": 0.1}], boxes=[], circles=[],
        trajectory={"poses": poses},
        sonar={"mounts": [[0, 0, 0]], "sub_rays": 1, "noise_sigma": 0.0, "random_rate": 0.0, "max_range": 5.0},
    )


def test_a_far_or_steep_wall_gives_no_echo_above_the_threshold():
    # the wall's face is y = 1.95: straight up from y = 0 at 1.95 m (strength 1 / 1.95^2 = 0.26) and
    # from y = -2.05 at 4 m (0.0625); at 60 degrees incidence from y = 0, 3.9 m away
    # (cos^2 60 / 3.9^2 = 0.016)
    poses = [[0, 0, 90], [0, -2.05, 90], [0, 0, 30]]
    expected = [1.95, 4.0, 3.9]
    off = simulate(one_ray_world(poses, 0.0), seed=1)
    assert np.allclose(off.ranges[:, 0], expected, atol=1e-5)
    assert np.all(off.truth.cause == CAUSE_ECHO)
    on = simulate(one_ray_world(poses, 0.1), seed=1)
    assert on.ranges[0, 0] == pytest.approx(1.95, abs=1e-5) and on.truth.cause[0, 0] == CAUSE_ECHO
    assert np.all(np.isinf(on.ranges[1:, 0])) and np.all(on.truth.cause[1:, 0] == CAUSE_NO_ECHO)
    assert np.array_equal(on.truth.ideal_range, off.truth.ideal_range)  # the surface is still there
    # between: 0.02 keeps the far wall straight on (0.0625) and drops the steep one (0.016)
    mid = simulate(one_ray_world(poses, 0.02), seed=1)
    assert np.isfinite(mid.ranges[1, 0]) and np.isinf(mid.ranges[2, 0])


def test_the_beam_pattern_drops_off_axis_echoes_first():
    # 3 sub-rays at -15, 0, +15 degrees; theta0 = 15 degrees: the side rays' echoes are e^-2 weaker
    raw = {"echo_strength": {"min_strength": 0.05, "beam_deg": 15}}
    poses = [[0, -1.05, 75]]  # the left sub-ray (+15) hits the wall straight on at 3 m; the axis at 15 deg
    w = world(raw, bounds=[-5, -5, 5, 5], walls=[{"points": [[-5, 2], [5, 2]], "thickness": 0.1}], boxes=[],
              circles=[], trajectory={"poses": poses},
              sonar={"mounts": [[0, 0, 0]], "sub_rays": 3, "beam_width_deg": 30, "noise_sigma": 0.0,
                     "random_rate": 0.0, "max_range": 5.0})
    log = simulate(w, seed=1)
    # left ray: exp(-2) / 9 = 0.015 < 0.05, dropped; axis: cos^2(15) / (3 / cos 15)^2 = 0.097, kept
    assert log.truth.ideal_range[0, 0] == pytest.approx(3.0, abs=1e-5)
    assert log.ranges[0, 0] == pytest.approx(3.0 / math.cos(math.radians(15)), abs=1e-5)


# --- a ring that fires one sonar after another ---------------------------------------------------


def test_the_schedule_of_a_ring_fired_slot_after_slot():
    # 3 sonars fire 0.1 s apart, a 0.3 s cycle; scans every 0.2 s. At t = 0.4 sonar 0 fired at
    # 0.3 (age 0.1), sonar 1 at 0.4 (age 0), sonar 2 at 0.2 (age 0.2: the scan at 0.2 holds it too);
    # at t = 0 sonars 1 and 2 last fired before the log started (-0.2 and -0.1 s)
    time = np.arange(5) * 0.2
    ages, source = schedule(Firing(0.1), time, 3)
    assert np.allclose(ages, [[0, 0.2, 0.1], [0.2, 0.1, 0], [0.1, 0, 0.2], [0, 0.2, 0.1], [0.2, 0.1, 0]])
    assert source.tolist() == [[0, 0, 0], [0, 1, 1], [2, 2, 1], [3, 2, 3], [3, 4, 4]]
    # sonars sharing a slot fire together: two slots, a 0.2 s cycle
    ages, _ = schedule(Firing(0.1, (0, 1, 0)), np.array([0.4, 0.5]), 3)
    assert np.allclose(ages, [[0.0, 0.1, 0.0], [0.1, 0.0, 0.1]])


def turning_room(errors, poses, scan_period):
    """A robot turning in place in an asymmetric room (each heading reads differently): 4 sonars
    on a 0.2 m ring, one sub-ray, no noise and no random readings."""
    return world(errors, bounds=[-1, -1, 5, 4], walls=[{"points": [[-0.5, -0.5], [4.5, -0.5], [4.5, 3.5],
                                                                   [-0.5, 3.5], [-0.5, -0.5]]}],
                 boxes=[{"center": [2.0, 2.5], "size": [0.8, 0.4], "yaw_deg": 30}],
                 circles=[{"center": [3.0, 0.5], "radius": 0.3}],
                 trajectory={"poses": poses, "scan_period": scan_period},
                 sonar={"count": 4, "ring_radius": 0.2, "sub_rays": 1, "noise_sigma": 0.0, "random_rate": 0.0})


def test_each_reading_is_cast_from_the_pose_where_its_sonar_fired():
    # turning in place 90 degrees per 0.4 s scan; 4 sonars 0.1 s apart (a 0.4 s cycle): at scan n
    # sonar 0 fires at the scan's pose and sonar k >= 1 fired 0.4 - 0.1 k s earlier, k/4 of the
    # way from the previous scan's heading (22.5 k degrees past it); before the first scan the
    # robot stood at its first pose
    poses = [[1.0, 1.0, 90.0 * n] for n in range(5)]
    log = simulate(turning_room({"firing": {"interval": 0.1}}, poses, 0.4), seed=1)
    assert np.array_equal(log.pose, np.array([[1.0, 1.0, math.radians(90.0 * n)] for n in range(5)]))
    fired = [[1.0, 1.0, 90.0 * n if k == 0 else 0.0 if n == 0 else 90.0 * (n - 1) + 22.5 * k]
             for n in range(5) for k in range(4)]
    one_by_one = simulate(turning_room(None, fired, 0.4), seed=1)  # each firing pose scanned on its own
    expected = one_by_one.ranges.reshape(5, 4, 4)[:, np.arange(4), np.arange(4)]
    assert np.array_equal(log.ranges, expected)
    assert np.array_equal(log.truth.ideal_range, one_by_one.truth.ideal_range.reshape(5, 4, 4)[:, np.arange(4), np.arange(4)])
    at_scan = simulate(turning_room(None, poses, 0.4), seed=1)
    assert np.array_equal(log.ranges[:, 0], at_scan.ranges[:, 0])  # sonar 0 fires at the scan
    assert not np.array_equal(log.ranges[1:, 1:], at_scan.ranges[1:, 1:])


def test_a_cycle_longer_than_the_scan_period_repeats_readings_exactly():
    # 8 sonars 0.1 s apart (0.8 s) and a scan every 0.5 s: most scans hold an earlier scan's
    # reading for some sonars, value and cause, noise and random readings included
    w = world({"firing": {"interval": 0.1}}, sonar={"count": 8, "max_range": 5.0, "sub_rays": 5, "random_rate": 0.2})
    log = simulate(w, seed=2)
    time, _ = trajectory_poses(w)
    _, source = schedule(w.errors.firing, time, 8)
    repeated = source != np.arange(len(time))[:, None]
    assert 0.2 < repeated.mean() < 0.6
    for arr in (log.ranges, log.truth.cause, log.truth.ideal_range):
        assert np.array_equal(arr, np.take_along_axis(arr, source, axis=0))
    assert simulate(w, seed=2).ranges.tobytes() == log.ranges.tobytes()


def test_poses_before_a_scan_along_waypoints_and_in_place_turns():
    w = world(trajectory={"waypoints": [[1.0, 1.0], [4.0, 1.0], [4.0, 3.0]], "speed": 0.5, "scan_period": 0.5})
    time, pose = trajectory_poses(w)
    ages = np.zeros((len(time), 2))
    ages[:, 1] = 1.0
    back = poses_before(w, ages)
    assert np.array_equal(back[:, 0], pose)  # age 0: the scan's pose, bit for bit
    assert np.allclose(back[:2, 1], [[1.0, 1.0, 0.0]] * 2)  # before the start: the first waypoint
    assert np.allclose(back[8, 1], [2.5, 1.0, 0.0])  # 4 s in: 2 m along, and 0.5 m back along the leg
    # turning in place at 90 degrees/s: 6 s on the first leg, 1 s turning, 4 s up the second
    turn = world(trajectory={"waypoints": [[1.0, 1.0], [4.0, 1.0], [4.0, 3.0]], "speed": 0.5, "scan_period": 0.25,
                             "turn_rate_deg": 90})
    time, pose = trajectory_poses(turn)
    assert len(time) == 45 and time[-1] == pytest.approx(11.0)
    assert np.allclose(pose[24:29], [[4.0, 1.0, math.radians(a)] for a in (0, 22.5, 45, 67.5, 90)])
    assert np.allclose(pose[-1], [4.0, 3.0, math.pi / 2])
    before = poses_before(turn, np.full((len(time), 1), 0.5))
    assert np.allclose(before[26, 0], [4.0, 1.0, math.radians(0.0)])  # 6.5 s: the turn started at 6 s
    assert np.allclose(before[29, 0], [4.0, 1.0, math.radians(67.5)])  # 7.25 s: 0.75 s into the turn
    # the default turns at once: the trajectory of before
    assert np.array_equal(trajectory_poses(world())[1], trajectory_poses(world(trajectory=dict(BOX["trajectory"])))[1])


# --- side lobes ----------------------------------------------------------------------------------


def lobe_world(side_lobes, post=(0.9, 19.5)):
    """One sonar (one sub-ray, on the axis) facing a wall 4 m ahead, and a post 6 cm across whose
    centre lies ``post`` = (distance to its surface + 0.03 m, bearing in degrees) off the axis."""
    dist, bearing = post[0] + 0.03, math.radians(post[1])
    return world(
        {"side_lobes": side_lobes} if side_lobes is not None else None,
        bounds=[-1, -3, 5, 3], walls=[{"points": [[4.05, -3], [4.05, 3]], "thickness": 0.1}], boxes=[],
        circles=[{"center": [dist * math.cos(bearing), dist * math.sin(bearing)], "radius": 0.03}],
        trajectory={"poses": [[0, 0, 0]]},
        sonar={"mounts": [[0, 0, 0]], "sub_rays": 1, "noise_sigma": 0.0, "random_rate": 0.0, "max_range": 5.0},
    )


def test_a_side_lobe_hears_a_near_post_off_the_cone():
    # the post at 19.5 degrees is outside the 30-degree cone: without side lobes the reading is
    # the wall at 4 m; the lobe's middle sub-ray (19.5 degrees) meets the post square on at 0.9 m
    off = simulate(lobe_world(None), seed=1)
    assert off.ranges[0, 0] == pytest.approx(4.0, abs=1e-5) and off.truth.cause[0, 0] == CAUSE_ECHO
    lobe = {"range": 1.3, "angle_deg": 19.5, "width_deg": 8}  # sub-rays at 15.5, 19.5 and 23.5 degrees
    on = simulate(lobe_world(lobe), seed=1)
    assert on.ranges[0, 0] == pytest.approx(0.9, abs=1e-5)
    assert on.truth.cause[0, 0] == CAUSE_SPECULAR  # nearer than the cone's nearest surface
    assert np.array_equal(on.truth.ideal_range, off.truth.ideal_range)  # the cone still sees the wall first
    # too far for the lobe (0.9 m > 0.8 m), or out of the lobe (a post at 30 degrees): the wall
    assert simulate(lobe_world({**lobe, "range": 0.8}), seed=1).ranges[0, 0] == pytest.approx(4.0, abs=1e-5)
    assert simulate(lobe_world(lobe, post=(0.9, 30.0)), seed=1).ranges[0, 0] == pytest.approx(4.0, abs=1e-5)
    # the lobe's edge ray hears a post at 23.5 degrees; width 0 is the middle ray alone
    assert simulate(lobe_world(lobe, post=(0.9, 23.5)), seed=1).ranges[0, 0] == pytest.approx(0.9, abs=1e-5)
    narrow = lobe_world({**lobe, "width_deg": 0}, post=(0.9, 23.5))
    assert simulate(narrow, seed=1).ranges[0, 0] == pytest.approx(4.0, abs=1e-5)
    # the default lobe (17.5 +- 2.75 degrees) hears a post at 20.25 degrees, not one at 23.5
    assert simulate(lobe_world({"range": 1.3}, post=(0.9, 20.25)), seed=1).ranges[0, 0] == pytest.approx(0.9, abs=1e-5)
    assert simulate(lobe_world({"range": 1.3}, post=(0.9, 23.5)), seed=1).ranges[0, 0] == pytest.approx(4.0, abs=1e-5)


# --- bad values --------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "errors, key, what",
    [
        ({"odometry": {"translation": -1}}, "errors.odometry.translation", "expected a number >= 0, got -1"),
        ({"odometry": {"rotation": "lots"}}, "errors.odometry.rotation", "expected a number"),
        ({"odometry": {"rotation_per_metre": 0.1}}, "errors.odometry.rotation_per_metre", "unknown key"),
        ({"odometry": [0.1]}, "errors.odometry", "expected a mapping"),
        ({"noise_per_metre": -0.01}, "errors.noise_per_metre", ">= 0"),
        ({"crosstalk_rate": 1.5}, "errors.crosstalk_rate", "<= 1"),
        ({"crosstalk_rate": True}, "errors.crosstalk_rate", "expected a number"),
        ({"echo_strength": {"min_strength": -1}}, "errors.echo_strength.min_strength", ">= 0"),
        ({"echo_strength": {"beam_deg": 0}}, "errors.echo_strength.beam_deg", "positive"),
        ({"echo_strength": {"threshold": 1}}, "errors.echo_strength.threshold", "unknown key"),
        ({"odometry": {"heading_bias_per_metre_deg": "left"}}, "errors.odometry.heading_bias_per_metre_deg",
         "expected a number"),
        ({"odometry": {"turn_bias": 0.9}}, "errors.odometry.turn_bias", "<= 0.5"),
        ({"firing": {"interval": -0.04}}, "errors.firing.interval", ">= 0"),
        ({"firing": {"interval": "40 ms"}}, "errors.firing.interval", "expected a number"),
        ({"firing": {"slots": [0, 1]}}, "errors.firing.slots", "expected one slot per sonar (8), got 2"),
        ({"firing": {"slots": [0, 1, 2, 3, 0, 1, 2, -3]}}, "errors.firing.slots[7]", ">= 0"),
        ({"firing": {"slots": [0, 1, 2, 3, 0, 1, 2, 0.5]}}, "errors.firing.slots[7]", "expected a whole number"),
        ({"firing": {"period": 0.3}}, "errors.firing.period", "unknown key"),
        ({"side_lobes": {"range": -1}}, "errors.side_lobes.range", ">= 0"),
        ({"side_lobes": {"angle_deg": 10, "width_deg": 30}}, "errors.side_lobes.width_deg", "clear of the axis"),
        ({"side_lobes": {"sub_rays": 0}}, "errors.side_lobes.sub_rays", ">= 1"),
        ({"side_lobes": [1.3]}, "errors.side_lobes", "expected a mapping"),
        ({"drift": 1}, "errors.drift", "unknown key"),
        (3, "errors", "expected a mapping"),
    ],
)
def test_bad_errors_exit_2_naming_the_key(tmp_path, errors, key, what):
    assert_refused(tmp_path, {**BOX, "errors": errors}, key, what)


def assert_refused(tmp_path, raw, key, what):
    """``aogm simulate`` of the world ``raw`` exits 2 naming the file, ``key`` and ``what``, writing nothing."""
    path = tmp_path / "w.yaml"
    path.write_text(yaml.safe_dump(raw))
    out = tmp_path / "log.h5"
    r = CliRunner().invoke(main, ["simulate", str(path), "-o", str(out), "-q"])
    assert r.exit_code == 2, r.output
    assert f"{path}: {key}: " in r.output and what in r.output, r.output
    assert "Traceback" not in r.output and not out.exists()


@pytest.mark.parametrize(
    "trajectory, key, what",
    [
        ({"turn_rate_deg": -5}, "trajectory.turn_rate_deg", "positive"),
        ({"turn_rate_deg": "fast"}, "trajectory.turn_rate_deg", "expected a number"),
        ({"turn_rate_deg": 30, "poses": [[1, 1, 0]], "waypoints": None}, "trajectory.turn_rate_deg", "only with 'waypoints'"),
    ],
)
def test_bad_turn_rates_exit_2_naming_the_key(tmp_path, trajectory, key, what):
    traj = {k: v for k, v in {**BOX["trajectory"], **trajectory}.items() if v is not None}
    assert_refused(tmp_path, {**BOX, "trajectory": traj}, key, what)
