"""Cone templates: cells inside the cone, complete, in range order; heading bins; clipping."""

import math

import numpy as np
import pytest
from cone_views import bin_heading, cells, reading_cells

from aogm_cli.core.errors import InputError
from aogm_cli.core.grid import GridSpec
from aogm_cli.core.log import SensorSpec
from aogm_cli.sensor_models.cone import cone_cells, range_search, reading_geometry
from aogm_cli.sensor_models.cone_build import build_cone_templates, heading_bins_for

BEAM = math.radians(30.0)


def wrap(a):
    return (np.asarray(a) + math.pi) % (2 * math.pi) - math.pi


def brute_force_cone(resolution, beam, reach, heading):
    """Set of (drow, dcol) whose centre lies in the cone, from first principles."""
    n = int(reach / resolution) + 2
    cells = set()
    for dr in range(-n, n + 1):
        for dc in range(-n, n + 1):
            d = resolution * math.hypot(dr, dc)
            if d > reach + 1e-9:
                continue
            if dr == 0 and dc == 0:
                cells.add((0, 0))
                continue
            if abs(wrap(math.atan2(dr, dc) - heading)) <= beam / 2 + 1e-9:
                cells.add((dr, dc))
    return cells


def test_heading_bins_quantisation_below_a_quarter_cell():
    for res, reach in [(0.05, 5.0), (0.1, 5.0), (0.02, 8.0), (0.5, 1.0)]:
        n = heading_bins_for(res, reach)
        assert n % 8 == 0 and n >= 64
        assert reach * math.pi / n <= res / 4 + 1e-12
    assert heading_bins_for(0.05, 5.0) == 1264


@pytest.mark.parametrize("n_bins", [64, 72])
def test_template_is_the_cone_for_every_heading_bin(n_bins):
    tpl = build_cone_templates(0.1, BEAM, 1.0, n_bins=n_bins)
    for k in range(n_bins):
        drow, dcol, rng, bearing = cells(tpl, k)
        got = set(zip(drow.tolist(), dcol.tolist(), strict=True))
        assert len(got) == drow.size  # each cell once
        assert got == brute_force_cone(0.1, BEAM, 1.0, bin_heading(tpl, k))
        # ranges and bearings describe the cells, and ranges are sorted
        np.testing.assert_allclose(rng, 0.1 * np.hypot(drow, dcol), atol=1e-12)
        assert np.all(np.diff(rng) >= 0)
        assert np.all(rng <= 1.0 + 1e-9)
        off = np.where(rng > 0, wrap(np.arctan2(drow, dcol) - bin_heading(tpl, k)), 0.0)
        np.testing.assert_allclose(bearing, off, atol=1e-9)
        assert np.all(np.abs(bearing) <= BEAM / 2 + 1e-9)


def test_template_first_cell_is_the_sensor_cell_and_axis_cells_follow():
    tpl = build_cone_templates(0.1, BEAM, 0.5, n_bins=64)
    drow, dcol, rng, _ = cells(tpl, 0)  # pointing +x
    assert (drow[0], dcol[0], rng[0]) == (0, 0, 0.0)
    on_axis = [(r, c) for r, c in zip(drow.tolist(), dcol.tolist(), strict=True) if r == 0]
    assert on_axis == [(0, i) for i in range(6)]
    # pointing +y (bin 16 of 64), the cone is the +x cone turned a quarter
    drow_y, dcol_y, rng_y, _ = cells(tpl, 16)
    assert set(zip(drow_y.tolist(), dcol_y.tolist(), strict=True)) == set(zip(dcol.tolist(), (-drow).tolist(), strict=True))
    np.testing.assert_array_equal(np.sort(rng_y), np.sort(rng))


def test_margin_extends_the_reach():
    a = build_cone_templates(0.1, BEAM, 1.0, n_bins=64)
    b = build_cone_templates(0.1, BEAM, 1.0, margin=0.2, n_bins=64)
    assert b.reach == pytest.approx(1.2)
    assert cells(b, 0)[2].max() > 1.1 >= cells(a, 0)[2].max()


def test_heading_bins_cover_all_yaws():
    tpl = build_cone_templates(0.1, BEAM, 1.0, n_bins=64)
    yaw = np.linspace(-4 * math.pi, 4 * math.pi, 100_001)
    k = tpl.heading_bin(yaw)
    assert k.min() >= 0 and k.max() < 64
    assert set(np.unique(k).tolist()) == set(range(64))
    err = np.abs(wrap(yaw - bin_heading(tpl, k)))
    assert err.max() <= math.pi / 64 + 1e-12
    np.testing.assert_array_equal(tpl.heading_bin(bin_heading(tpl, np.arange(64))), np.arange(64))
    assert tpl.heading_bin(-1e-9) == 0 and tpl.heading_bin(2 * math.pi) == 0


def test_reading_cells_in_range_order_clipped_to_the_grid():
    grid = GridSpec(0.0, 0.0, 0.1, 8, 8)
    tpl = build_cone_templates(0.1, BEAM, 1.0, n_bins=64)
    k = 8  # 45 degrees
    index, rng = reading_cells(tpl, grid, 1, 1, k, 0.75)
    drow, dcol, full_rng, _ = cells(tpl, k)
    rows, cols = 1 + drow, 1 + dcol
    keep = grid.contains(rows, cols) & (full_rng <= 0.75)
    np.testing.assert_array_equal(index, (rows * 8 + cols)[keep])
    np.testing.assert_array_equal(rng, full_rng[keep])
    assert np.all(np.diff(rng) >= 0)
    # a sensor cell outside the grid still sees the cells of its cone that are inside
    index, _ = reading_cells(tpl, grid, -2, 3, 16, 1.0)  # pointing +y from below the grid
    assert index.size > 0 and np.all(index // 8 >= 0)
    # a cone pointing away from the grid sees nothing
    assert reading_cells(tpl, grid, -2, 3, 48, 1.0)[0].size == 0


def test_cone_cells_kernel_matches_the_wrapper():
    grid = GridSpec(0.0, 0.0, 0.1, 20, 20)
    tpl = build_cone_templates(0.1, BEAM, 1.0, n_bins=64)
    out_i = np.empty(500, dtype=np.int64)
    out_r = np.empty(500, dtype=np.float64)
    n = cone_cells(tpl.kernel_arrays, 20, 20, 10, 10, 40, 0.6, out_i, out_r, -1.0)
    index, rng = reading_cells(tpl, grid, 10, 10, 40, 0.6)
    np.testing.assert_array_equal(out_i[:n], index)
    np.testing.assert_array_equal(out_r[:n], rng)


def test_reading_geometry_composes_pose_and_mount():
    grid = GridSpec(0.0, 0.0, 0.1, 30, 30)
    tpl = build_cone_templates(0.1, BEAM, 1.0, n_bins=64)
    sensor = SensorSpec(mount=np.array([[0.2, 0.0, 0.0], [0.0, 0.0, math.pi / 2]]))
    pose = np.array([[1.05, 1.05, math.pi / 2], [np.nan, 1.0, 0.0]])
    rows, cols, bins, valid, _ = reading_geometry(pose, sensor, grid, tpl)
    assert rows.shape == (2, 2)
    # sensor 0 sits 0.2 m ahead of the robot, which faces +y: at (1.05, 1.25), pointing +y
    assert (rows[0, 0], cols[0, 0], bins[0, 0]) == (12, 10, 16)
    # sensor 1 sits at the robot's centre, pointing -x
    assert (rows[0, 1], cols[0, 1], bins[0, 1]) == (10, 10, 32)
    assert valid.tolist() == [[True, True], [False, False]]


def test_reading_geometry_axis_offset():
    grid = GridSpec(0.0, 0.0, 0.1, 10, 10)
    tpl = build_cone_templates(0.1, BEAM, 1.0, n_bins=64)
    sensor = SensorSpec(mount=np.zeros((1, 3)))
    pose = np.array([[0.25, 0.55, 0.0], [0.29, 0.55, 0.0], [0.29, 0.55, math.pi], [0.25, 0.58, math.pi / 2]])
    *_, offset = reading_geometry(pose, sensor, grid, tpl)
    np.testing.assert_allclose(offset[:, 0], [0.0, 0.04, -0.04, 0.03], atol=1e-12)


def test_far_away_sensors_do_not_overflow():
    grid = GridSpec(0.0, 0.0, 0.1, 10, 10)
    tpl = build_cone_templates(0.1, BEAM, 1.0, n_bins=64)
    sensor = SensorSpec(mount=np.zeros((1, 3)))
    rows, cols, _, valid, _ = reading_geometry(np.array([[1e300, -1e300, 0.0]]), sensor, grid, tpl)
    assert valid.all()
    assert rows[0, 0] < -tpl.extent and cols[0, 0] > 10 + tpl.extent


@pytest.mark.parametrize(
    "kwargs, key",
    [
        (dict(resolution=0.0), "resolution"),
        (dict(beam_width=-1.0), "beam_width"),
        (dict(max_range=float("inf")), "max_range"),
        (dict(n_bins=60), "n_bins"),
    ],
)
def test_bad_template_parameters(kwargs, key):
    args = dict(resolution=0.1, beam_width=BEAM, max_range=1.0) | kwargs
    n_bins = args.pop("n_bins", None)
    with pytest.raises(InputError) as err:
        build_cone_templates(args["resolution"], args["beam_width"], args["max_range"], n_bins=n_bins)
    assert err.value.key == key


def test_range_search_is_searchsorted():
    tpl = build_cone_templates(0.05, BEAM, 2.0)
    rng = np.random.default_rng(1)
    for b in (0, 3, tpl.offsets.size - 2):
        r = tpl.ranges[tpl.offsets[b] : tpl.offsets[b + 1]]
        values = np.r_[rng.uniform(-0.1, 2.2, 300), r[::7], r[::11] + 1e-12, [0.0, 2.0, 5.0, np.inf, np.nan]]
        for v in values:
            for right in (False, True):
                want = np.searchsorted(r, v, side="right" if right else "left") if v >= 0 else 0
                assert range_search(r, tpl.range_index[b], tpl.resolution, v, right) == want


def test_a_narrow_beams_cone_holds_every_cell_its_ray_crosses():
    """A 0.5-degree beam's cone on a 5 cm grid (narrower than a cell up to 5.7 m): with ray=True
    it holds every cell a grid traversal of its axis crosses, at every heading tried; without,
    cells along the axis go missing (gaps of over a metre)."""
    import math

    from aogm_cli.core.grid import GridSpec
    from aogm_cli.sensor_models.cone_build import build_cone_templates
    from aogm_cli.sensor_models.ray import ray_cells

    grid = GridSpec(-10.0, -10.0, 0.05, 400, 400)
    narrow = build_cone_templates(0.05, math.radians(0.5), 8.0, margin=0.05)
    ray = build_cone_templates(0.05, math.radians(0.5), 8.0, margin=0.05, ray=True)
    row, col = grid.world_to_cell(0.0, 0.0)
    missing_narrow = 0
    for k in range(0, ray.n_bins, 97):
        yaw = float(bin_heading(ray, k))
        rows, cols, _, _ = ray_cells(grid, 0.025, 0.025, yaw, 7.5)  # from the cell's centre
        crossed = set(zip((rows - row).tolist(), (cols - col).tolist(), strict=True))
        drow, dcol, _, _ = cells(ray, k)
        assert crossed <= set(zip(drow.tolist(), dcol.tolist(), strict=True)), k
        drow, dcol, _, _ = cells(narrow, k)
        missing_narrow += len(crossed - set(zip(drow.tolist(), dcol.tolist(), strict=True)))
    assert missing_narrow > 0


def test_a_template_store_gives_back_the_templates_bit_identical(tmp_path):
    """io.template_store keeps templates of 100,000 to 3 million entries beside the source's
    ``__pycache__``, named by a digest of the arguments, the source and numpy's version; read back,
    every array is the one built, dtype and bits. Smaller templates are not kept."""
    from pathlib import Path

    from aogm_cli.io.template_store import STORE, TemplateStore
    from aogm_cli.sensor_models import cone_build

    assert Path(cone_build.__file__).samefile(STORE.source)  # the digest is of the module that builds them
    source = tmp_path / "cone_build.py"
    source.write_bytes(Path(cone_build.__file__).read_bytes())
    store = TemplateStore(source)
    args = (0.05, BEAM, 5.0, 1264, False)  # a 5 m sonar at 0.05 m: 416,374 entries
    built = cone_build._template_arrays(*args)
    assert store.load(args, cone_build._TEMPLATE_ARRAYS) is None
    store.save(args, built)
    assert [p.name for p in (tmp_path / "__pycache__").iterdir()] == [store.paths(args)[0].name]
    back = store.load(args, cone_build._TEMPLATE_ARRAYS)
    assert back.keys() == built.keys()
    for name, a in built.items():
        assert back[name].dtype == a.dtype and back[name].tobytes() == a.tobytes(), name
    source.write_bytes(source.read_bytes() + b"\n")  # another source: another name, built anew
    assert store.load(args, cone_build._TEMPLATE_ARRAYS) is None
    small = (0.1, BEAM, 1.0, 64, False)
    store.save(small, cone_build._template_arrays(*small))
    assert len(list((tmp_path / "__pycache__").iterdir())) == 1


def test_the_cone_module_takes_its_store_and_builds_without_one(monkeypatch):
    """sensor_models.cone_build reads and writes no file: a store installed with ``use_store`` is asked
    first and given what is built; with none, templates are built (and kept in memory only)."""
    from aogm_cli.sensor_models import cone_build

    class Store:
        def __init__(self):
            self.calls = []

        def load(self, args, dtypes):
            self.calls.append(("load", args))
            return None

        def save(self, args, arrays):
            self.calls.append(("save", args, arrays["ranges"].size))

    store = Store()
    monkeypatch.setattr(cone_build, "_STORE", store)
    tpl = build_cone_templates(0.1, BEAM, 1.3, n_bins=72)  # arguments no other test uses: not cached yet
    args = (0.1, BEAM, 1.3, 72, False)
    assert store.calls == [("load", args), ("save", args, tpl.ranges.size)]
    cone_build.use_store(None)
    assert cone_build._STORE is None
    again = build_cone_templates(0.1, BEAM, 1.4, n_bins=72)
    assert again.ranges.size > tpl.ranges.size and len(store.calls) == 2
