"""The surfaces of the forward model's angle of incidence (``sensor_models.surface``): which cells
are surfaces and their normals, from the directions they echoed in, and which passes they hide."""

import math

import numpy as np
import pytest

from aogm_cli.core.errors import InputError
from aogm_cli.core.grid import GridSpec
from aogm_cli.sensor_models.cone import build_cone_templates, flat_offsets
from aogm_cli.sensor_models.surface import SurfaceConfig, cos2_of, hidden, surface_normals

GRID = GridSpec(0.0, 0.0, 0.1, 40, 40)


def normals_of(rows, cols, yaw, z, config=None, beam_deg=10.0):
    tpl = build_cone_templates(GRID.resolution, math.radians(beam_deg), 3.0)
    cones = (np.array(rows), np.array(cols), tpl.heading_bin(np.array(yaw)), np.array(z, dtype=float))
    return surface_normals(tpl.kernel_arrays, flat_offsets(tpl, GRID.width), GRID.shape, cones, 3.0,
                           GRID.resolution, config or SurfaceConfig())


def test_hidden_by_hand():
    # a wall along the columns at row 10 (normal along the rows), the sensor at cell (0, 0)
    normal = np.full((2, 400), np.nan)
    width = 20
    for col in range(width):
        normal[:, 10 * width + col] = (1.0, 0.0)
    cos2 = cos2_of(30.0)
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
    assert not hidden(normal, cos2_of(90.0), 10 * width + 19, 0, 0, width)


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
    assert not np.isfinite(one[0]).any()  # heard once: min_echoes 2
    assert np.isfinite(normals_of([5], [20], [math.pi / 2], [1.5], SurfaceConfig(min_echoes=1))[0]).any()
    none = normals_of([5, 5], [20, 20], [math.pi / 2] * 2, [np.inf, np.nan])
    assert not np.isfinite(none[0]).any()


@pytest.mark.parametrize("key,value", [("min_echoes", 0), ("min_echoes", 1.5), ("min_coherence", 1.5),
                                       ("enabled", "yes")])
def test_bad_surface_config_names_its_key(key, value):
    with pytest.raises(InputError) as err:
        SurfaceConfig(**{key: value}).validate()
    assert err.value.key == key
