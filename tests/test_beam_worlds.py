"""World variants with a real sonar beam pattern (``world.beam_pattern.with_beam_pattern``, used by
bench/bench_beam.py): the variant loads as any world, really has the narrower beam (its cone's edges
hear fewer echoes than the default pattern's, its axis as many), keeps the world's other errors, and a
bad theta0 is refused by the loader naming the key."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from aogm_cli.core.errors import InputError
from aogm_cli.core.log import CAUSE_NO_ECHO, CAUSE_RANDOM
from aogm_cli.simulation.sonar import simulate
from aogm_cli.world.beam_pattern import with_beam_pattern
from aogm_cli.world.loader import load_world

ROOT = Path(__file__).resolve().parents[1]
CORRIDOR_DOOR = (ROOT / "worlds" / "corridor_door.yaml").read_text()


def loaded(variant: dict, tmp_path, name: str, sub_rays: int | None = None):
    """``variant`` written as a world file and read back by the loader; past the door only (27 scans),
    with ``sub_rays`` across the cone when given (2: its two edges only; 1: its axis only)."""
    variant = {**variant, "trajectory": {**variant["trajectory"], "waypoints": [[8.0, 1.0], [12.0, 1.0]]}}
    if sub_rays is not None:
        variant["sonar"] = {**variant["sonar"], "sub_rays": sub_rays}
    path = tmp_path / f"{name}.yaml"
    path.write_text(yaml.safe_dump(variant, sort_keys=False))
    return load_world(path)


def echoes(world) -> int:
    """Readings that heard an echo (random readings, the same ones at one seed, left out)."""
    cause = simulate(world, seed=1).truth.cause
    return int(np.count_nonzero((cause != CAUSE_NO_ECHO) & (cause != CAUSE_RANDOM)))


def test_the_narrow_variant_hears_fewer_echoes_at_the_cone_edge(tmp_path):
    narrow = with_beam_pattern(CORRIDOR_DOOR, 8)
    world = loaded(narrow, tmp_path, "narrow")
    assert world.errors.echo_strength.beam == pytest.approx(np.radians(8.0))
    assert world.errors.echo_strength.min_strength == 0.01 and world.sonar.random_rate == 0.05
    # the cone's two edges (15 degrees off the axis): theta0 8 hears them only within 0.3 m
    # (exp(-2 (15/8)^2) / 0.01 = 0.088 m^2); the default pattern hears every echo, theta0 15 out to 3.7 m
    edge = {name: echoes(loaded(v, tmp_path, name, sub_rays=2)) for name, v in [
        ("narrow", narrow), ("default", with_beam_pattern(CORRIDOR_DOOR, None)),
        ("half_cone", with_beam_pattern(CORRIDOR_DOOR, 15))]}
    assert edge["narrow"] < 0.2 * edge["half_cone"] and edge["half_cone"] < edge["default"]
    # on the axis theta0 changes nothing: the same log at 8 and 15 degrees
    axis = [simulate(loaded(with_beam_pattern(CORRIDOR_DOOR, b), tmp_path, f"axis{b}", sub_rays=1), seed=1)
            for b in (8, 15)]
    assert np.array_equal(axis[0].ranges, axis[1].ranges)
    # the whole cone (11 sub-rays): fewer readings hear the nearest surface than with the default pattern
    default = simulate(loaded(with_beam_pattern(CORRIDOR_DOOR, None), tmp_path, "default_cone"), seed=1)
    narrowed = simulate(world, seed=1)
    heard = [np.count_nonzero(np.abs(log.ranges - log.truth.ideal_range) < 0.1) for log in (default, narrowed)]
    assert heard[1] < heard[0]


def test_the_variant_keeps_the_worlds_other_errors_and_its_text_in():
    real = (ROOT / "worlds" / "corridor_door_real.yaml").read_text()
    variant = with_beam_pattern(yaml.safe_load(real), 12, min_strength=0.02, random_rate=0.1)
    assert variant["errors"] == {**yaml.safe_load(real)["errors"], "echo_strength": {
        "min_strength": 0.02, "incidence_exponent": 2, "beam_deg": 12}}
    assert variant["sonar"]["random_rate"] == 0.1 and variant["name"] == "corridor_door_real"
    assert with_beam_pattern(real, 12, 0.02, 0.1) == variant  # YAML text or its mapping alike
    assert with_beam_pattern(real, None)["errors"] == yaml.safe_load(real)["errors"]  # default: untouched


@pytest.mark.parametrize(("beam_deg", "what"), [(0, "positive"), (120, "<= 90"), ("wide", "expected a number")])
def test_a_bad_beam_deg_is_refused_naming_the_key(tmp_path, beam_deg, what):
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(with_beam_pattern(CORRIDOR_DOOR, beam_deg)))
    with pytest.raises(InputError, match=what) as caught:
        load_world(path)
    assert caught.value.key == "errors.echo_strength.beam_deg" and caught.value.file == str(path)
    assert "errors.echo_strength.beam_deg" in str(caught.value)
