"""The sonar inverse model as a plain function, and its configuration."""

import json
import math

import numpy as np
import pytest

from aogm_cli.core.errors import InputError
from aogm_cli.core.log import SensorSpec
from aogm_cli.mapping.params import params_from
from aogm_cli.sensor_models.inverse_model import (
    InverseModelConfig,
    InverseUpdate,
    angular_profile,
    inverse_model,
    inverse_update,
    range_profile,
)

BEAM = math.radians(30.0)
GEOM = dict(beam_width=BEAM, min_range=0.05, max_range=5.0)

# A sensor at a cell centre pointing +x, a reading at z = 0.5 m, a 0.1 m grid; cells named by
# (drow, dcol) from the sensor's cell, described by their range d and bearing theta.
CELLS = {
    (0, 0): (0.0, 0.0),
    (0, 1): (0.1, 0.0),
    (0, 4): (0.4, 0.0),
    (0, 5): (0.5, 0.0),
    (0, 6): (0.6, 0.0),
    (1, 4): (math.hypot(0.1, 0.4), math.atan2(1, 4)),
    (1, 5): (math.hypot(0.1, 0.5), math.atan2(1, 5)),
    (1, 3): (math.hypot(0.1, 0.3), math.atan2(1, 3)),  # 18.4 degrees: outside the 30 degree cone
}


def model_at(cell, z, config, **geom):
    d, theta = CELLS[cell]
    return float(inverse_model(d, theta, z, config, **(GEOM | geom)))


def test_constant_model_by_hand():
    cfg = InverseModelConfig(alpha=0.1, model="constant")
    # free space: d < z - alpha/2 = 0.45; occupied arc: 0.45 <= d <= 0.55
    assert model_at((0, 1), 0.5, cfg) == pytest.approx(-0.41)
    assert model_at((0, 4), 0.5, cfg) == pytest.approx(-0.41)
    assert model_at((1, 4), 0.5, cfg) == pytest.approx(-0.41)  # d = 0.412, 14.0 degrees
    assert model_at((0, 5), 0.5, cfg) == pytest.approx(0.85)
    assert model_at((1, 5), 0.5, cfg) == pytest.approx(0.85)  # d = 0.510, 11.3 degrees
    assert model_at((0, 6), 0.5, cfg) == 0.0  # beyond the arc
    assert model_at((1, 3), 0.5, cfg) == 0.0  # outside the cone
    assert model_at((0, 0), 0.5, cfg) == 0.0  # blind zone, d < min_range = 0.05


def test_elfes_model_by_hand():
    cfg = InverseModelConfig(alpha=0.1)  # elfes
    span = 0.45 - 0.05  # z - alpha/2 - Rmin
    assert model_at((0, 1), 0.5, cfg) == pytest.approx(-0.41 * (1 - (0.05 / span) ** 2))  # -0.40359
    assert model_at((0, 4), 0.5, cfg) == pytest.approx(-0.41 * (1 - (0.35 / span) ** 2))  # -0.09609
    e_a = 1 - (2 * math.atan2(1, 4) / BEAM) ** 2  # 0.1244
    e_r = 1 - ((math.hypot(0.1, 0.4) - 0.05) / span) ** 2  # 0.1796
    assert model_at((1, 4), 0.5, cfg) == pytest.approx(-0.41 * e_a * e_r)  # -0.00916
    assert model_at((0, 5), 0.5, cfg) == pytest.approx(0.85)
    assert model_at((1, 5), 0.5, cfg) == pytest.approx(0.85 * (1 - (2 * math.atan2(1, 5) / BEAM) ** 2))  # 0.3668
    assert model_at((0, 6), 0.5, cfg) == 0.0
    assert model_at((1, 3), 0.5, cfg) == 0.0
    assert model_at((0, 0), 0.5, cfg) == 0.0


def test_prior_enters_as_the_no_information_value():
    cfg = InverseModelConfig(alpha=0.1, model="constant", l0=0.2, l_occ=1.0, l_free=-0.5)
    assert model_at((0, 6), 0.5, cfg) == pytest.approx(0.2)
    assert model_at((0, 1), 0.5, cfg) == pytest.approx(-0.5)
    elfes = InverseModelConfig(alpha=0.1, l0=0.2, l_occ=1.0, l_free=-0.5)
    e_a = 1 - (2 * math.atan2(1, 5) / BEAM) ** 2
    assert model_at((1, 5), 0.5, elfes) == pytest.approx(0.2 + e_a * (1.0 - 0.2))


@pytest.mark.parametrize("model", ["elfes", "constant"])
def test_max_range_reading_only_clears(model):
    cfg = InverseModelConfig(alpha=0.1, model=model)
    d = np.linspace(0.0, 6.0, 601)
    theta = np.linspace(-BEAM / 2, BEAM / 2, 7)[:, None]
    for z in (np.inf, 5.0, 7.5):  # no echo; a reading at or beyond max_range is one too
        out = inverse_model(d, theta, z, cfg, **GEOM)
        assert out.max() <= 0.0
        inside = (d >= 0.05) & (d < 5.0)
        assert np.all(out[3, inside] < 0)  # on the axis, every cell up to max_range is freer
        assert np.all(out[:, d > 5.0] == 0.0)
    if model == "elfes":  # Elfes' E_r runs to max_range
        out = inverse_model(np.array([0.05, 2.525]), 0.0, np.inf, cfg, **GEOM)
        np.testing.assert_allclose(out, [-0.41, -0.41 * (1 - 0.5**2)])


def test_nan_and_negative_readings_carry_no_information():
    cfg = InverseModelConfig(alpha=0.1)
    d = np.linspace(0.0, 5.0, 51)
    for z in (np.nan, -1.0, -np.inf):
        assert np.all(inverse_model(d, 0.0, z, cfg, **GEOM) == 0.0)


def test_occupied_arc_stops_at_max_range():
    cfg = InverseModelConfig(alpha=0.1, model="constant")
    out = inverse_model(np.array([4.94, 4.99, 5.01]), 0.0, 4.98, cfg, **GEOM)
    np.testing.assert_allclose(out, [0.85, 0.85, 0.0])


def test_short_reading_has_no_free_region():
    cfg = InverseModelConfig(alpha=0.1)
    # z - alpha/2 = 0.05 = min_range: nothing is free, the arc is still occupied
    out = inverse_model(np.array([0.0, 0.04, 0.06, 0.1, 0.16]), 0.0, 0.1, cfg, **GEOM)
    np.testing.assert_allclose(out, [0.0, 0.0, 0.85, 0.85, 0.0])


def test_profiles():
    np.testing.assert_allclose(angular_profile([0.0, BEAM / 4, BEAM / 2, BEAM], BEAM), [1.0, 0.75, 0.0, 0.0])
    np.testing.assert_allclose(range_profile([0.0, 0.05, 0.25, 0.45, 0.5], 0.45, 0.05), [0.0, 1.0, 0.75, 0.0, 0.0])
    assert range_profile(0.1, 0.05, 0.05) == 0.0  # empty free region


def test_config_defaults_and_record():
    cfg = InverseModelConfig()
    assert cfg.validate() is cfg
    d = cfg.as_dict()
    assert d == {"model": "elfes", "l_occ": 0.85, "l_free": -0.41, "l0": 0.0,
                 "clamp_min": -2.0, "clamp_max": 3.5, "alpha": 0.05}
    assert json.loads(json.dumps(d)) == d
    # OctoMap's hit / miss probabilities
    assert 1 / (1 + math.exp(-cfg.l_occ)) == pytest.approx(0.7, abs=0.001)
    assert 1 / (1 + math.exp(-cfg.l_free)) == pytest.approx(0.4, abs=0.002)


@pytest.mark.parametrize(
    "kwargs, key",
    [
        (dict(model="bayes"), "model"),
        (dict(alpha=0.0), "alpha"),
        (dict(alpha=-0.1), "alpha"),
        (dict(l_occ=float("nan")), "l_occ"),
        (dict(l_occ="high"), "l_occ"),
        (dict(l_occ=-0.1), "l_occ"),
        (dict(l_free=0.3), "l_free"),
        (dict(clamp_min=4.0), "clamp_min"),
        (dict(clamp_min=0.5, l0=0.0), "l0"),
        (dict(clamp_max=float("inf")), "clamp_max"),
    ],
)
def test_impossible_values_are_rejected(kwargs, key):
    with pytest.raises(InputError) as err:
        params_from({"inverse_model": kwargs}, "p.yaml")
    assert err.value.key == f"inverse_model.{key}" and err.value.file == "p.yaml"


@pytest.mark.parametrize("model", ["elfes", "constant"])
def test_inverse_update_names_the_kernels_constants(model):
    config = InverseModelConfig(model=model, l_occ=1.2, l_free=-0.7, l0=0.25, clamp_min=-1.5, clamp_max=2.5, alpha=0.08)
    sensor = SensorSpec(mount=np.zeros((1, 3)), min_range=0.2, max_range=4.0)
    u = inverse_update(config, sensor, 0.1)
    assert isinstance(u, InverseUpdate)
    assert u.half_alpha == 0.08 / 2
    assert (u.min_range, u.max_range) == (0.2, 4.0)
    assert u.l_free_minus_l0 == -0.7 - 0.25 and u.l_occ_minus_l0 == 1.2 - 0.25
    assert (u.clamp_min, u.clamp_max, u.l0) == (-1.5, 2.5, 0.25)
    assert u.elfes is (model == "elfes")
    assert u.resolution == 0.1
    assert all(type(v) is float for k, v in u._asdict().items() if k != "elfes")  # one compiled signature
