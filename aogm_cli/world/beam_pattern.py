"""World variants with a transducer's beam pattern: a world file's YAML with ``errors.echo_strength``'s
Kuc & Siegel pattern (theta0, the weakest echo heard) and a random-reading rate merged in
(``bench/bench_beam.py``; the keys are described in ``worlds/README.md``, "Beam patterns")."""

from __future__ import annotations

import copy
from collections.abc import Mapping
from typing import Any

import yaml

from aogm_cli.core.errors import InputError

MIN_STRENGTH = 0.01  # 1/m^2: a wall square on, on the axis, is heard out to 10 m (the *_real worlds')
RANDOM_RATE = 0.05


def with_beam_pattern(world: str | Mapping[str, Any], beam_deg: float | None, min_strength: float = MIN_STRENGTH,
                      random_rate: float = RANDOM_RATE) -> dict[str, Any]:
    """A copy of ``world`` (a world file's YAML text, or its parsed mapping) whose sonar has the beam
    pattern theta0 = ``beam_deg`` (degrees) and hears no echo weaker than ``min_strength`` (1/m^2):
    ``errors.echo_strength`` gets ``{min_strength, beam_deg}`` merged in, keeping its other keys
    (``incidence_exponent``) and every other key of ``errors``; ``sonar.random_rate`` is set to
    ``random_rate``. ``beam_deg`` None keeps the world's own pattern (its echo_strength untouched;
    the bundled worlds without one hear every echo) and sets the random rate only. The name is kept.

    Nothing is checked here: ``world.loader.parse_world`` checks the variant as any world (a
    ``beam_deg`` outside (0, 90] is refused naming ``errors.echo_strength.beam_deg``).

    >>> v = with_beam_pattern({"errors": {"crosstalk_rate": 0.02}, "sonar": {"count": 8}}, 8)
    >>> v["errors"], v["sonar"]
    ({'crosstalk_rate': 0.02, 'echo_strength': {'min_strength': 0.01, 'beam_deg': 8}}, {'count': 8, 'random_rate': 0.05})
    """
    raw = yaml.safe_load(world) if isinstance(world, str) else copy.deepcopy(dict(world))
    if not isinstance(raw, dict):
        raise InputError(f"expected a world (a mapping), got {type(raw).__name__}")
    _section(raw, "sonar")["random_rate"] = random_rate
    if beam_deg is not None:
        errors = _section(raw, "errors")
        echo = _section(errors, "echo_strength", "errors.")
        echo.update(min_strength=min_strength, beam_deg=beam_deg)
    return raw


def _section(parent: dict, key: str, path: str = "") -> dict:
    """``parent[key]``, a mapping (made empty when missing or null)."""
    value = parent.get(key)
    if value is None:
        value = parent[key] = {}
    if not isinstance(value, dict):
        raise InputError(f"expected a mapping, got {type(value).__name__}", key=path + key)
    return value
