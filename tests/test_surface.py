"""The surfaces of the forward model's angle of incidence (``sensor_models.surface``): which cells
are surfaces and their normals, from the directions they echoed in, and which passes they hide."""

import math

import numpy as np
import pytest

from aogm_cli.core.errors import InputError
from aogm_cli.core.grid import GridSpec
from aogm_cli.core.log import SensorSpec
from aogm_cli.map_files import resolve_params
from aogm_cli.sensor_models.cone import flat_offsets
from aogm_cli.sensor_models.cone_build import build_cone_templates
from aogm_cli.sensor_models.forward_model import ForwardModelConfig, cone_limits, deflect
from aogm_cli.sensor_models.readings import LaidOutReadings
from aogm_cli.sensor_models.surface import (
    SurfaceConfig,
    hidden,
    reading_shadows,
    surface_normals,
)

GRID = GridSpec(0.0, 0.0, 0.1, 40, 40)


def normals_of(rows, cols, yaw, z, beam_deg=10.0):
    tpl = build_cone_templates(GRID.resolution, math.radians(beam_deg), 3.0)
    cones = (np.array(rows), np.array(cols), tpl.heading_bin(np.array(yaw)), np.array(z, dtype=float))
    return surface_normals(tpl.kernel_arrays, flat_offsets(tpl, GRID.width), GRID.shape, cones, 3.0,
                           GRID.resolution, np.ones(GRID.shape, dtype=bool))


def test_hidden_by_hand():
    # a wall along the columns at row 10 (normal along the rows), the sensor at cell (0, 0)
    normal = np.full((2, 400), np.nan)
    width = 20
    for col in range(width):
        normal[:, 10 * width + col] = (1.0, 0.0)
    cos2 = math.cos(math.radians(30.0)) ** 2
    assert cos2 == pytest.approx(0.75)
    # straight on (incidence 0) and at 26.6 deg (offset 10 rows, 5 columns) the wall echoes
    assert not hidden(normal, cos2, 10 * width + 0, 0, 0, width)
    assert not hidden(normal, cos2, 10 * width + 5, 0, 0, width)
    # at 45 deg (10, 10) and 63 deg (10, 19) it does not: the pass says nothing of the cell
    assert hidden(normal, cos2, 10 * width + 10, 0, 0, width)
    assert hidden(normal, cos2, 10 * width + 19, 0, 0, width)
    # the sign of the normal and the side of the wall do not matter
    assert hidden(-normal, cos2, 10 * width + 19, 19, 0, width)
    # no surface (NaN) or a specular angle of 90 deg: every cell counts
    assert not hidden(normal, cos2, 5 * width + 19, 0, 0, width)
    assert not hidden(normal, 0.0, 10 * width + 19, 0, 0, width)


def test_a_wall_heard_head_on_gets_its_normal():
    # three sensors in a row below a wall 1.5 m away, facing it (yaw 90 deg: +rows), two readings
    # each: the wall cells each reading's arc covers get the normal along the rows; cells no echo
    # covers get none
    rows, cols = [5, 5, 5] * 2, [10, 20, 30] * 2
    normal = normals_of(rows, cols, [math.pi / 2] * 6, [1.5] * 6).reshape(2, *GRID.shape)
    heard = np.isfinite(normal[0])
    assert heard[20, 20] and heard[20, 10]
    assert abs(normal[0, 20, 20]) == pytest.approx(1.0)
    assert normal[1, 20, 20] == pytest.approx(0.0, abs=1e-12)
    assert not heard[5:15].any() and not heard[25:].any()  # before and beyond the arcs


def test_a_cell_heard_from_across_is_no_surface():
    # one cell heard head-on from below and from the left (axes 90 deg apart: doubled angles
    # cancel) is a corner, visible at any angle; heard from below and from above (one axis), a wall
    below_and_left = normals_of([5, 20], [20, 5], [math.pi / 2, 0.0], [1.5, 1.5])
    assert math.isnan(below_and_left[0, 20 * GRID.width + 20])
    below_and_above = normals_of([5, 35], [20, 20], [math.pi / 2, -math.pi / 2], [1.5, 1.5])
    assert abs(below_and_above[0, 20 * GRID.width + 20]) == pytest.approx(1.0)


def test_min_echoes_and_no_echo():
    one = normals_of([5], [20], [math.pi / 2], [1.5])
    assert not np.isfinite(one[0]).any()  # heard once: MIN_ECHOES 2
    assert np.isfinite(normals_of([5, 5], [20, 20], [math.pi / 2] * 2, [1.5, 1.5])[0]).any()  # heard twice
    none = normals_of([5, 5], [20, 20], [math.pi / 2] * 2, [np.inf, np.nan])
    assert not np.isfinite(none[0]).any()


@pytest.mark.parametrize("key,value", [("core", 1.5), ("core", -0.1), ("min_echoes", 1),  # a constant, no setting
                                       ("enabled", True), ("core", True)])  # enabled: em.specular_deg 90 turns it off
def test_bad_surface_config_names_the_file_and_key(key, value, tmp_path):
    params = tmp_path / "p.yaml"
    params.write_text(f"surface:\n  {key}: {value!r}\n".replace("True", "true"))
    with pytest.raises(InputError) as err:
        resolve_params(str(params))
    assert err.value.key == f"surface.{key}" and err.value.file == str(params)


def wall_run(yaw, z, beam_deg=10.0):
    """One sensor at cell (5, 2) of GRID with readings at ``yaw`` and ranges ``z``, and a wall along
    the columns at row 20 whose normal lies along the rows (a surface the readings may meet)."""
    tpl = build_cone_templates(GRID.resolution, math.radians(beam_deg), 3.0)
    n = len(z)
    sensor = SensorSpec(mount=np.zeros((1, 3)), beam_width=math.radians(beam_deg), max_range=3.0)
    run = LaidOutReadings(GRID, sensor, tpl, np.zeros((n, 1)), np.full(n, 5), np.full(n, 2),
                          tpl.heading_bin(np.array(yaw)), np.array(z, dtype=float))
    normal = np.full((2, GRID.height * GRID.width), np.nan)
    normal[0, 20 * GRID.width:21 * GRID.width] = 1.0
    normal[1, 20 * GRID.width:21 * GRID.width] = 0.0
    return run, normal


def test_a_beam_that_grazes_a_surface_before_its_echo_is_deflected_there():
    # head-on (yaw 90 deg) to the wall 1.5 m away, echo there: nothing deflected; at yaw 50 deg (40
    # deg off the normal) the beam meets the wall at 1.5 / sin 50 = 1.96 m, before its echo at 2.9 m:
    # deflected where its cone first meets a wall cell (its nearest edge, a little nearer); at yaw
    # 30 deg (60 deg off) its axis meets the wall at 3.0 m, beyond the echo, its near edge at 2.6 m
    run, normal = wall_run([math.pi / 2, math.radians(30), math.radians(50), math.radians(50)],
                           [1.5, 2.9, 2.9, 1.9])
    shadow = reading_shadows(run, normal, ForwardModelConfig(specular_deg=30.0), 1.0)
    assert shadow[0] == np.inf
    assert 2.5 < shadow[1] < 2.78
    assert 1.7 < shadow[2] < 1.96
    assert shadow[3] == np.inf  # the wall lies within its window (1.9 m): the echo may be the wall's
    # a specular angle of 50 deg keeps the 40-deg pass
    assert reading_shadows(run, normal, ForwardModelConfig(specular_deg=50.0), 1.0)[2] == np.inf


def test_by_default_a_beam_that_meets_a_surface_over_15_degrees_off_its_normal_is_deflected():
    # the defaults a map takes (em.specular_deg 15, surface.core 0.1 of a 30-degree cone: +-1.5 deg about the
    # axis): the wall 1.5 m away, every echo at 2.9 m beyond it. Head-on, and 11.3 deg off the normal (the
    # axis through the wall cell 3 columns over), the beam passes it; 18.4 deg off (through the cell 5 columns
    # over, 1.58 m away) it stops there
    assert ForwardModelConfig().specular_deg == 15.0 and "specular_deg" not in resolve_params().calibration.learned
    run, normal = wall_run([math.pi / 2, math.atan2(15, 3), math.atan2(15, 5)], [2.9, 2.9, 2.9], beam_deg=30.0)
    shadow = reading_shadows(run, normal, resolve_params().em.forward, SurfaceConfig().core)
    assert shadow[0] == np.inf and shadow[1] == np.inf
    assert 1.5 < shadow[2] <= 1.59


def test_a_map_counts_the_readings_it_deflected(corridor_door_log):
    # /stats deflected_readings: corridor_door's grazing and random readings met beyond 15 deg; at 90 deg (Thrun's
    # model) the angle of incidence is off (no deflections stage, no count), as in the standard mode, Elfes' baseline
    from aogm_cli.map_files import map_file

    em = map_file(corridor_door_log, "em", resolve_params())
    assert 0 < em.stats["deflected_readings"] < em.stats["em_readings"]
    thrun = map_file(corridor_door_log, "em", resolve_params(overrides={"em": {"specular_deg": 90}}))
    assert "deflected_readings" not in thrun.stats and "deflections" not in thrun.plan["stages"]
    assert "deflected_readings" not in map_file(corridor_door_log, "standard", resolve_params()).stats


def test_deflect_makes_max_range_readings_that_end_before_the_shadow():
    z, limit = deflect(np.array([2.9, 1.5, np.nan]), np.array([1.9, np.inf, 1.0]), 3.0)
    assert z[0] == np.inf and limit[0] == np.nextafter(1.9, 0.0)
    assert z[1] == 1.5 and limit[1] == np.inf
    assert np.isnan(z[2]) and limit[2] == np.inf  # a NaN reading stays out
    z, limits = cone_limits(np.array([2.9, 1.5]), 3.0, ForwardModelConfig(sigma=0.05),
                            np.array([1.9, np.inf]))
    assert limits[0] == np.nextafter(1.9, 0.0) and limits[1] == pytest.approx(1.7)


def test_a_doorway_passed_head_on_is_no_surface():
    # echoes from a wall 1.5 m ahead of sensors at columns 10..30 (two readings each: the arcs of
    # those at columns 19..21 cover cell (20, 20) six times), and eight readings at column 20 that
    # pass straight through it (echo 2.9 m): cells passed head-on more often than heard are a
    # doorway, not a surface; the cells only echoes reach stay one
    cols = list(range(10, 31)) * 2 + [20] * 8
    z = [1.5] * 42 + [2.9] * 8
    tpl = build_cone_templates(GRID.resolution, math.radians(10.0), 3.0)
    cones = (np.full(len(z), 5), np.array(cols), tpl.heading_bin(np.full(len(z), math.pi / 2)), np.array(z))
    normal = surface_normals(tpl.kernel_arrays, flat_offsets(tpl, GRID.width), GRID.shape, cones, 3.0,
                             GRID.resolution, np.ones(GRID.shape, dtype=bool)).reshape(2, *GRID.shape)
    assert np.isnan(normal[0, 20, 20])
    assert abs(normal[0, 20, 12]) == pytest.approx(1.0) and abs(normal[0, 20, 28]) == pytest.approx(1.0)
    believed = np.zeros(GRID.shape, dtype=bool)
    believed[20, 25:] = True  # only where a map believes the cells occupied
    only = surface_normals(tpl.kernel_arrays, flat_offsets(tpl, GRID.width), GRID.shape, cones, 3.0,
                           GRID.resolution, believed).reshape(2, *GRID.shape)
    assert np.isnan(only[0, 20, 12]) and abs(only[0, 20, 28]) == pytest.approx(1.0)


def test_only_the_core_of_a_cone_is_deflected():
    # at yaw 33 deg (57 deg off the wall's normal), echo 2.7 m: the cone's near edge (38 deg) meets
    # the wall at 1.5 / sin 38 = 2.44 m, before the window (from 2.58 m), the axis only at 2.75 m
    run, normal = wall_run([math.radians(33)], [2.7])
    forward = ForwardModelConfig(specular_deg=30.0)
    assert 2.3 < reading_shadows(run, normal, forward, 1.0)[0] < 2.58
    assert reading_shadows(run, normal, forward, core=0.25)[0] == np.inf
