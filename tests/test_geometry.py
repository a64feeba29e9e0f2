"""World geometry: wall pieces and openings, the scene's bucket grid, the truth raster, the path."""

from __future__ import annotations

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal
from PIL import Image
from scipy import ndimage

from aogm_cli.world.config import Opening, Wall
from aogm_cli.world.loader import parse_world
from aogm_cli.world.scene import build_scene
from aogm_cli.world.solids import wall_pieces
from aogm_cli.world.trajectory import trajectory_poses
from aogm_cli.world.truth import truth_occupancy


def world(**geometry):
    raw = {"bounds": geometry.pop("bounds", [0, 0, 4, 4]), "trajectory": geometry.pop("trajectory", {"poses": [[0.1, 0.1, 0]]})}
    raw.update(geometry)
    if not any(k in raw for k in ("walls", "boxes", "polygons", "circles", "floorplan")):
        raw["circles"] = [{"center": [3.5, 3.5], "radius": 0.1}]
    return parse_world(raw, file="test.yaml")


# -- wall pieces ----------------------------------------------------------------------------


def test_opening_cuts_the_wall_into_two_rectangles():
    wall = Wall(((0.0, 1.0), (4.0, 1.0)), 0.1, "rough", (Opening(2.0, 1.0),))
    pieces = wall_pieces(wall)
    assert len(pieces) == 2
    (c0, l0), (c1, l1) = pieces
    assert_allclose(l0, [[0, 1], [1.5, 1]])
    assert_allclose(l1, [[2.5, 1], [4, 1]])
    assert_allclose(sorted(map(tuple, c0.round(9))), [(0, 0.95), (0, 1.05), (1.5, 0.95), (1.5, 1.05)])


def test_joint_extension_closes_a_corner_but_not_free_ends():
    wall = Wall(((0.0, 0.0), (2.0, 0.0), (2.0, 2.0)), 0.2, "rough")
    (c0, _), (c1, _) = wall_pieces(wall)
    # the first leg runs from its free end x=0 to x=2.1 (past the joint by thickness/2)
    assert_allclose(c0[:, 0].min(), 0.0)
    assert_allclose(c0[:, 0].max(), 2.1)
    # the second starts 0.1 before the joint and ends at its free end y=2
    assert_allclose(c1[:, 1].min(), -0.1)
    assert_allclose(c1[:, 1].max(), 2.0)


def test_opening_at_a_joint_is_not_filled_by_the_extension():
    wall = Wall(((0.0, 0.0), (2.0, 0.0), (2.0, 2.0)), 0.2, "rough", (Opening(2.0, 1.0),))
    pieces = wall_pieces(wall)
    assert len(pieces) == 2
    assert_allclose(pieces[0][0][:, 0].max(), 1.5)
    assert_allclose(pieces[1][0][:, 1].min(), 0.5)


# -- scene ----------------------------------------------------------------------------------


def test_scene_segments_thresholds_and_circles():
    w = world(
        surfaces={"glass": {"specular_threshold_deg": 15}},
        boxes=[{"center": [1, 1], "size": [0.4, 0.2], "surface": "glass"}],
        circles=[{"center": [3, 3], "radius": 0.2}],
    )
    scene = build_scene(w)
    assert scene.n_segments == 4
    assert_allclose(scene.segment_threshold, math.radians(15))
    assert_allclose(scene.circles, [[3, 3, 0.2]])
    assert_allclose(scene.circle_threshold, [math.pi / 2])


def test_bucket_grid_lists_every_segment_in_every_bucket_it_touches():
    rng = np.random.default_rng(3)
    walls = [{"points": rng.uniform(0, 10, (3, 2)).tolist(), "thickness": 0.05} for _ in range(15)]
    scene = build_scene(world(bounds=[0, 0, 10, 10], walls=walls), bucket_size=0.7)
    ny, nx = scene.bucket_shape
    x0, y0 = scene.bucket_origin
    size = scene.bucket_size
    for k, (ax, ay, bx, by) in enumerate(scene.segments):
        # dense samples along the segment: each sample's bucket must list segment k
        s = np.linspace(0, 1, 400)
        ix = np.floor((ax + s * (bx - ax) - x0) / size).astype(int)
        iy = np.floor((ay + s * (by - ay) - y0) / size).astype(int)
        for b in set((iy * nx + ix).tolist()):
            ids = scene.bucket_segment_ids[scene.bucket_segment_start[b] : scene.bucket_segment_start[b + 1]]
            assert k in ids
    # the per-bucket copies hold (x0, y0, ex, ey) of the listed segment
    seg = scene.segments[scene.bucket_segment_ids]
    assert_allclose(scene.bucket_segments[:, :2], seg[:, :2])
    assert_allclose(scene.bucket_segments[:, 2:], seg[:, 2:] - seg[:, :2])


# -- truth raster ---------------------------------------------------------------------------


def test_truth_of_a_small_box():
    w = world(bounds=[0, 0, 2, 2], truth_resolution=0.1, boxes=[{"center": [1, 1], "size": [0.4, 0.2]}])
    grid, occ = truth_occupancy(w)
    assert occ.shape == (20, 20) and occ.dtype == np.uint8
    expected = np.zeros((20, 20), np.uint8)
    expected[9:11, 8:12] = 1  # centres x 0.85..1.15, y 0.95, 1.05
    assert_array_equal(occ, expected)


def test_truth_of_a_rotated_box_and_a_circle_match_centre_sampling():
    w = world(
        bounds=[0, 0, 4, 4],
        truth_resolution=0.05,
        boxes=[{"center": [1.2, 1.3], "size": [1.0, 0.5], "yaw_deg": 30}],
        circles=[{"center": [3.0, 3.0], "radius": 0.43}],
        polygons=[{"points": [[2.213, 0.317], [3.71, 0.523], [2.631, 1.617], [2.911, 0.833]]}],
    )
    grid, occ = truth_occupancy(w)
    X, Y = grid.centres()
    c, s = math.cos(math.radians(30)), math.sin(math.radians(30))
    u = (X - 1.2) * c + (Y - 1.3) * s
    v = -(X - 1.2) * s + (Y - 1.3) * c
    box = (np.abs(u) < 0.5) & (np.abs(v) < 0.25)
    circle = np.hypot(X - 3, Y - 3) < 0.43
    from matplotlib.path import Path as MplPath

    poly = MplPath([[2.213, 0.317], [3.71, 0.523], [2.631, 1.617], [2.911, 0.833]]).contains_points(np.column_stack([X.ravel(), Y.ravel()])).reshape(X.shape)
    assert_array_equal(occ.astype(bool), box | circle | poly)


def test_thin_wall_marks_the_cells_its_centre_line_crosses_without_gaps():
    w = world(bounds=[0, 0, 2, 2], truth_resolution=0.1, walls=[{"points": [[0.03, 0.17], [1.91, 1.52]], "thickness": 0.01}])
    grid, occ = truth_occupancy(w)
    s = np.linspace(0, 1, 5001)
    r, c = grid.world_to_cell(0.03 + s * 1.88, 0.17 + s * 1.35)
    assert occ[r, c].all()
    # nothing far from the line
    X, Y = grid.centres()
    dist = np.abs((X - 0.03) * 1.35 - (Y - 0.17) * 1.88) / math.hypot(1.88, 1.35)
    assert not occ[dist > 0.1].any()
    # the free cells on either side are not 4-connected through the wall
    labels, n = ndimage.label(occ == 0)
    assert labels[0, 19] != labels[19, 0]


def test_opening_leaves_a_gap_of_its_width_in_the_truth():
    w = world(
        bounds=[0, 0, 4, 2],
        truth_resolution=0.05,
        walls=[{"points": [[0, 1], [4, 1]], "thickness": 0.1, "openings": [{"at": 2.0, "width": 1.0}]}],
    )
    grid, occ = truth_occupancy(w)
    rows = np.flatnonzero(occ.any(axis=1))
    assert_array_equal(rows, [19, 20])  # centres 0.975 and 1.025
    for r in rows:
        free = np.flatnonzero(occ[r] == 0)
        assert_array_equal(free, np.arange(30, 50))  # x in [1.5, 2.5): 20 cells = 1.0 m


def test_thin_wall_opening_keeps_its_gap():
    w = world(
        bounds=[0, 0, 4, 2],
        truth_resolution=0.05,
        walls=[{"points": [[0, 1.01], [4, 1.01]], "thickness": 0.01, "openings": [{"at": 2.0, "width": 1.0}]}],
    )
    grid, occ = truth_occupancy(w)
    assert_array_equal(np.flatnonzero(occ.any(axis=1)), [20])
    assert_array_equal(np.flatnonzero(occ[20] == 0), np.arange(30, 50))


def test_truth_of_a_large_office_world_is_fast():
    import time

    walls = []
    for k in range(21):
        doors = [{"at": 5 * i + 2.5, "width": 0.9} for i in range(20)]
        walls.append({"points": [[0, 5 * k], [100, 5 * k]], "openings": doors})
        walls.append({"points": [[5 * k, 0], [5 * k, 100]], "openings": doors})
    w = world(bounds=[0, 0, 100, 100], walls=walls, trajectory={"poses": [[2.5, 2.5, 0]]})
    truth_occupancy(w)  # compile
    start = time.perf_counter()
    grid, occ = truth_occupancy(w)
    assert time.perf_counter() - start < 5.0
    assert grid.shape == (2000, 2000)
    # a door in the middle of the grid is open, the wall beside it is closed
    r, c = grid.world_to_cell(52.5, 50.0)
    assert occ[r, c] == 0
    r, c = grid.world_to_cell(51.0, 50.0)
    assert occ[r, c] == 1


def test_floorplan_truth_and_scene(tmp_path):
    # 4 x 3 pixels of 0.5 m, origin (1, 2); the top image row is the highest y
    img = np.full((3, 4), 254, np.uint8)
    img[0, 3] = 0  # top-right pixel: x [2.5, 3), y [3, 3.5)
    Image.fromarray(img).save(tmp_path / "map.pgm")
    (tmp_path / "map.yaml").write_text(
        "image: map.pgm\nresolution: 0.5\norigin: [1.0, 2.0, 0.0]\nnegate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n"
    )
    w = parse_world(
        {"bounds": [0, 0, 4, 4], "truth_resolution": 0.25, "floorplan": {"map": "map.yaml"}, "trajectory": {"poses": [[0.5, 0.5, 0]]}},
        file=str(tmp_path / "w.yaml"),
        base_dir=tmp_path,
    )
    grid, occ = truth_occupancy(w)
    expected = np.zeros((16, 16), np.uint8)
    expected[12:14, 10:12] = 1
    assert_array_equal(occ, expected)
    scene = build_scene(w)
    assert scene.bitmap.shape == (3, 4) and scene.bitmap.sum() == 1 and scene.bitmap[2, 3] == 1
    assert scene.bitmap_grid.origin == (1.0, 2.0)


def test_fine_floorplan_pixels_still_mark_the_truth(tmp_path):
    img = np.full((10, 10), 254, np.uint8)
    img[4, 2] = 0  # a 0.01 m pixel
    Image.fromarray(img).save(tmp_path / "map.pgm")
    (tmp_path / "map.yaml").write_text(
        "image: map.pgm\nresolution: 0.01\norigin: [0.0, 0.0, 0.0]\nnegate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n"
    )
    w = parse_world(
        {"bounds": [0, 0, 1, 1], "truth_resolution": 0.5, "floorplan": {"map": "map.yaml"}, "trajectory": {"poses": [[0.5, 0.5, 0]]}},
        file=str(tmp_path / "w.yaml"),
        base_dir=tmp_path,
    )
    _, occ = truth_occupancy(w)
    assert_array_equal(occ, [[1, 0], [0, 0]])


# -- trajectory -----------------------------------------------------------------------------


def test_waypoint_poses_are_evenly_spaced_along_the_path():
    w = world(trajectory={"waypoints": [[0, 0], [1, 0], [1, 1]], "speed": 0.5, "scan_period": 0.2})
    time, pose = trajectory_poses(w)
    assert pose.shape == (21, 3)
    assert_allclose(time, np.arange(21) * 0.2)
    step = np.hypot(*np.diff(pose[:, :2], axis=0).T)
    assert_allclose(step, 0.1, atol=1e-12)
    assert_allclose(pose[5], [0.5, 0, 0], atol=1e-12)
    assert_allclose(pose[10], [1, 0, math.pi / 2], atol=1e-12)  # a waypoint: the leg starting there
    assert_allclose(pose[15], [1, 0.5, math.pi / 2], atol=1e-12)
    assert_allclose(pose[20], [1, 1, math.pi / 2], atol=1e-12)


def test_waypoint_spacing_that_does_not_divide_the_path():
    w = world(trajectory={"waypoints": [[0, 0], [1, 0]], "speed": 0.3, "scan_period": 1.0})
    time, pose = trajectory_poses(w)
    assert_allclose(pose[:, 0], [0, 0.3, 0.6, 0.9])
    assert_allclose(time, [0, 1, 2, 3])


def test_explicit_poses():
    w = world(trajectory={"poses": [[1, 1, 90], [2, 1, 0]], "scan_period": 0.25})
    time, pose = trajectory_poses(w)
    assert_allclose(time, [0, 0.25])
    assert_allclose(pose, [[1, 1, math.pi / 2], [2, 1, 0]])


@pytest.mark.parametrize("bucket_size", [0.3, 1.0, 5.0])
def test_bucket_size_does_not_change_the_scene_segments(bucket_size):
    w = world(walls=[{"points": [[0.5, 0.5], [3.5, 0.5], [3.5, 3.5]]}])
    scene = build_scene(w, bucket_size=bucket_size)
    assert scene.n_segments == 8


@pytest.mark.parametrize("distance", [0.0, 0.04, 0.1, 0.15, 0.333])
def test_cells_within_a_distance_stamped_as_the_distance_transform_finds_them(distance):
    # a few marked cells get discs stamped (the robot's footprint), many the distance transform:
    # the same cells, edges and corners of the grid included
    from aogm_cli.core.grid import GridSpec

    grid = GridSpec(-1.0, -2.0, 0.05, 37, 53)
    rng = np.random.default_rng(5)
    for n in (1, 3, 12, 400):  # 400: more discs' cells than the grid has, the distance transform's way
        mask = np.zeros(grid.shape, dtype=bool)
        mask[rng.integers(0, grid.height, n), rng.integers(0, grid.width, n)] = True
        mask[0, -1] = True  # a corner: its disc is cut by two edges
        expected = ndimage.distance_transform_edt(~mask) * grid.resolution <= distance + 1e-9
        assert_array_equal(grid.within(mask, distance), expected)
    assert not grid.within(np.zeros(grid.shape, dtype=bool), 0.2).any()
