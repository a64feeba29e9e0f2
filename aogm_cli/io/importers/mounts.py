"""Sensor mount tables for the importers' ``--mounts``: a file of rows ``x y yaw``, or the name of a
robot preset packaged with aogm (``aogm_cli/data/mounts/NAME.txt``, in m and degrees, each file
citing the parameter file or driver it was copied from).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from aogm_cli.core.errors import InputError
from aogm_cli.io.importers import wrap_angle
from aogm_cli.io.importers.table import ANGLE_UNITS, LENGTH_UNITS, read_table, unit_scale

PRESETS_DIR = Path(__file__).resolve().parents[2] / "data" / "mounts"


def presets() -> list[str]:
    """The names of the packaged mount tables (``p3dx``, ``p3at``, ...)."""
    return sorted(p.stem for p in PRESETS_DIR.glob("*.txt"))


def mounts_path(spec: str) -> tuple[str, bool]:
    """(the file to read, whether it is a packaged preset) for ``--mounts SPEC``: an existing file
    wins; else a preset's name; else an InputError naming the file and the presets."""
    if Path(spec).exists():
        return spec, False
    if spec in presets():
        return str(PRESETS_DIR / f"{spec}.txt"), True
    raise InputError(f"no such file, and not a robot preset (presets: {', '.join(presets())})", file=spec,
                     key="mounts")


def read_mounts(
    path: str | Path, position_unit: str = "m", bearing_unit: str = "deg", delimiter: str = "auto"
) -> np.ndarray:
    """(S, 3) sensor mounts from a table with columns x, y, yaw (one row per sensor) -> metres, radians."""
    table = read_table(path, delimiter)
    if table.width != 3:
        raise InputError(f"expected 3 columns (x, y, yaw), got {table.width}", file=str(path), key="mounts")
    m = np.column_stack([table.column(c) for c in range(3)])
    m[:, :2] *= unit_scale(LENGTH_UNITS, position_unit, "position_unit")
    m[:, 2] = wrap_angle(m[:, 2] * unit_scale(ANGLE_UNITS, bearing_unit, "bearing_unit"))
    return m


def load_mounts(spec: str, position_unit: str = "m", bearing_unit: str = "deg",
                delimiter: str = "auto") -> tuple[np.ndarray, str]:
    """(mounts (S, 3) in m and rad, how the source names them) of ``--mounts SPEC``: a preset is
    in m and degrees whatever the units given for files."""
    path, preset = mounts_path(spec)
    if preset:
        return read_mounts(path), f"--mounts {spec} (aogm's {spec} preset)"
    return read_mounts(path, position_unit, bearing_unit, delimiter), "--mounts"
