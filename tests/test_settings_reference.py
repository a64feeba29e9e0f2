"""docs/settings.md is kept equal to the code: every leaf setting of ``aogm_cli.map_params()`` (the
forward model's fields under ``em.``) has a row, every row is a setting, and each row's type and
default are the code's."""

import dataclasses
import re
from pathlib import Path

import pytest
import yaml

import aogm_cli

ROOT = Path(__file__).resolve().parents[1]
PAGE = ROOT / "docs" / "settings.md"
TYPES = {"float": float, "int": int, "str": str, "bool": bool}


def leaf_settings(config=None, prefix: str = "") -> dict[str, tuple[str, object]]:
    """{key as --params writes it: (declared type name, default)} of the nested dataclasses; a
    nested config's fields go under its parent's section (``em.forward.sigma`` is ``em.sigma``)."""
    config = aogm_cli.map_params() if config is None else config
    out: dict[str, tuple[str, object]] = {}
    for f in dataclasses.fields(config):
        value = getattr(config, f.name)
        if dataclasses.is_dataclass(value):
            section = prefix if prefix else f"{f.name}."
            out |= leaf_settings(value, section)
        else:
            kind = f.type if isinstance(f.type, str) else f.type.__name__
            out[prefix + f.name] = (kind, value)
    return out


def table_rows() -> dict[str, tuple[str, str]]:
    """{key: (type cell, default cell)} of the page's settings table (rows whose first cell is a key in backticks)."""
    rows = {}
    for line in PAGE.read_text().splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) >= 3 and re.fullmatch(r"`[a-z0-9_.]+`", cells[0]):
            key = cells[0].strip("`")
            assert key not in rows, f"two rows for {key}"
            rows[key] = (cells[1], cells[2])
    return rows


def test_the_walk_finds_nested_and_forward_model_fields():
    settings = leaf_settings()
    assert settings["resolution"] == ("float", 0.05)
    assert settings["em.sigma"] == ("float", 0.03)  # a forward-model field, under em.
    assert settings["em.max_sweeps"] == ("int", 20)  # one of EMConfig's own
    assert settings["calibration.enabled"] == ("bool", True)
    assert not any(k.startswith(("em.forward", "forward.")) for k in settings)


def test_the_table_is_read():
    rows = table_rows()
    assert rows["em.sigma"] == ("float", "0.03")
    assert rows["calibration.learn"][1] == "sigma,p_rand,p_hit,p_max,lobe_deg"


@pytest.mark.parametrize("key", sorted(leaf_settings()))
def test_every_setting_has_a_row(key):
    assert key in table_rows(), f"docs/settings.md has no row for {key}"


@pytest.mark.parametrize("key", sorted(table_rows()))
def test_every_row_is_a_setting(key):
    assert key in leaf_settings(), f"docs/settings.md has a row for {key}, which is no setting"


@pytest.mark.parametrize("key", sorted(set(table_rows()) & set(leaf_settings())))
def test_each_rows_type_and_default_are_the_codes(key):
    kind, default = leaf_settings()[key]
    type_cell, default_cell = table_rows()[key]
    assert type_cell == kind, f"{key}: the page says {type_cell}, the code declares {kind}"
    written = yaml.safe_load(default_cell)  # as a --params file would read it
    assert isinstance(written, TYPES[kind]) or (kind == "float" and type(written) is int), (key, written)
    assert written == default, f"{key}: the page says {default_cell}, the code's default is {default!r}"
