"""ROS map_saver maps out: a trinary PGM + YAML as map_saver writes them, plus a "scale" PNG +
YAML that keeps the probabilities (read back by ``aogm_cli.io.map_server``).
"""

from __future__ import annotations

import io
import re
from pathlib import Path

import numpy as np
import yaml
from PIL import Image

from aogm_cli.core.errors import InputError
from aogm_cli.io.atomic import write_files_atomically
from aogm_cli.io.map_server import (
    MAP_SAVER_FREE_THRESH,
    MAP_SAVER_OCCUPIED_THRESH,
    PGM_FREE,
    PGM_OCCUPIED,
    PGM_UNKNOWN,
    finite_number,
)


def write_map(
    prefix: str | Path,
    probability: np.ndarray,
    observed: np.ndarray,
    resolution: float,
    origin,
    occupied_thresh: float = MAP_SAVER_OCCUPIED_THRESH,
    free_thresh: float = MAP_SAVER_FREE_THRESH,
) -> list[Path]:
    """Write a probability map as map_saver does, plus a "scale" PNG that keeps probabilities.

    Files (returned in this order, as ``export_paths`` names them):

    * ``PREFIX.pgm``: binary P5, top image row = highest y; 0 where p > occupied_thresh,
      254 where p < free_thresh, 205 elsewhere and wherever not observed.
    * ``PREFIX.yaml``: image, resolution, origin [x, y, yaw], negate 0, mode trinary, and
      map_saver's fixed thresholds 0.65 / 0.196 — the PGM is already thresholded, and these
      read 0 / 254 / 205 back as 100 / 0 / -1 whatever thresholds classified the map (a
      comment in the file records the ones used).
    * ``PREFIX.png``: 8-bit grey + alpha, pixel = round(255 * (1 - p)), alpha 255 where
      observed; unobserved pixels have alpha 0 and a grey level between the thresholds.
    * ``PREFIX_scale.yaml``: the PNG with ``mode: scale`` and the given thresholds, so
      map_server gives 0 / 100 outside the thresholds, 1..99 between them and -1 where
      unobserved; read back with ``read_map_yaml`` its occupancy_probability is within
      0.5/255 of p in observed cells.

    ``prefix``: the output path without extension (its folder must exist); ``probability``
    (H, W) in [0, 1] and ``observed`` (H, W) bool, row 0 = lowest y; ``resolution`` in metres
    per cell; ``origin`` (x, y) or (x, y, yaw) of the lower-left corner of cell [0, 0]. Every
    file is written under a temporary name in the target folder and renamed at the end."""
    pgm_path, yaml_path, png_path, scale_yaml_path = export_paths(prefix)
    p, obs = _checked_grids(probability, observed)
    resolution, (ox, oy, oyaw), occupied_thresh, free_thresh = _checked_placement(resolution, origin, occupied_thresh,
                                                                                 free_thresh)
    pgm_bytes = _pgm_bytes(p, obs, resolution, occupied_thresh, free_thresh)
    png_bytes = _png_bytes(p, obs, occupied_thresh, free_thresh)
    common = f"resolution: {_yaml_float(resolution)}\norigin: [{_yaml_float(ox)}, {_yaml_float(oy)}, {_yaml_float(oyaw)}]\nnegate: 0\n"
    yaml_text = (
        f"image: {_yaml_str(pgm_path.name)}\n{common}"
        f"occupied_thresh: {_yaml_float(MAP_SAVER_OCCUPIED_THRESH)}\n"
        f"free_thresh: {_yaml_float(MAP_SAVER_FREE_THRESH)}\n"
        "mode: trinary\n"
        f"# classified with occupied_thresh {_yaml_float(occupied_thresh)}, free_thresh {_yaml_float(free_thresh)}\n"
    )
    scale_text = (
        f"image: {_yaml_str(png_path.name)}\n{common}"
        f"occupied_thresh: {_yaml_float(occupied_thresh)}\n"
        f"free_thresh: {_yaml_float(free_thresh)}\n"
        "mode: scale\n"
    )
    outputs = [
        (pgm_path, pgm_bytes),
        (yaml_path, yaml_text.encode("utf-8")),
        (png_path, png_bytes),
        (scale_yaml_path, scale_text.encode("utf-8")),
    ]
    write_files_atomically(outputs)
    return [target for target, _ in outputs]


def _checked_placement(resolution, origin, occupied_thresh, free_thresh):
    """(resolution, (x, y, yaw), occupied_thresh, free_thresh) as finite numbers, after checking
    them; InputError naming the key otherwise."""
    resolution = finite_number(resolution, "resolution", None)
    if resolution <= 0:
        raise InputError(f"expected a positive number, got {resolution!r}", key="resolution")
    origin = list(origin)
    if len(origin) not in (2, 3):
        raise InputError(f"expected (x, y) or (x, y, yaw), got {origin!r}", key="origin")
    xyz = tuple(finite_number(v, f"origin[{i}]", None) for i, v in enumerate([*origin, 0.0][:3]))
    occupied_thresh = finite_number(occupied_thresh, "occupied_thresh", None)
    free_thresh = finite_number(free_thresh, "free_thresh", None)
    if not 0.0 <= free_thresh <= occupied_thresh <= 1.0:
        raise InputError(
            f"expected 0 <= free_thresh <= occupied_thresh <= 1, got {free_thresh!r} and {occupied_thresh!r}",
            key="free_thresh",
        )
    return resolution, xyz, occupied_thresh, free_thresh


def _checked_grids(probability, observed) -> tuple[np.ndarray, np.ndarray]:
    """(probability as float64, observed as bool), after checking shapes and observed values."""
    p = np.asarray(probability, dtype=np.float64)
    obs = np.asarray(observed)
    if p.ndim != 2 or p.size == 0:
        raise InputError(f"expected a non-empty (H, W) array, got shape {p.shape}", key="probability")
    if obs.shape != p.shape:
        raise InputError(f"expected shape {p.shape} like probability, got {obs.shape}", key="observed")
    obs = obs.astype(bool)
    seen = p[obs]
    if not np.all(np.isfinite(seen)) or np.any(seen < 0.0) or np.any(seen > 1.0):
        raise InputError("expected values in [0, 1] in every observed cell", key="probability")
    return p, obs


def _pgm_bytes(p: np.ndarray, obs: np.ndarray, resolution: float, occupied_thresh: float, free_thresh: float) -> bytes:
    """The trinary P5 PGM, top image row = highest y."""
    height, width = p.shape
    trinary = np.full(p.shape, PGM_UNKNOWN, dtype=np.uint8)
    trinary[obs & (p > occupied_thresh)] = PGM_OCCUPIED
    trinary[obs & (p < free_thresh)] = PGM_FREE
    header = f"P5\n# CREATOR: aogm {resolution:.3f} m/pix\n{width} {height}\n255\n".encode("ascii")
    return header + np.ascontiguousarray(trinary[::-1]).tobytes()


def _png_bytes(p: np.ndarray, obs: np.ndarray, occupied_thresh: float, free_thresh: float) -> bytes:
    """The scale PNG: grey + alpha, grey = round(255 * (1 - p)), unobserved transparent."""
    grey = np.full(p.shape, _unknown_grey(occupied_thresh, free_thresh), dtype=np.uint8)
    grey[obs] = np.clip(np.rint(255.0 * (1.0 - p[obs])), 0, 255).astype(np.uint8)
    alpha = np.where(obs, 255, 0).astype(np.uint8)
    buffer = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(np.stack([grey, alpha], axis=2)[::-1])).save(buffer, format="PNG")
    return buffer.getvalue()


def export_paths(prefix: str | Path) -> list[Path]:
    """The files ``write_map`` writes for ``prefix``: PREFIX.pgm, .yaml, .png and _scale.yaml."""
    prefix = Path(prefix)
    if not prefix.name:
        raise InputError("expected an output prefix (a path without extension)", file=str(prefix))
    return [prefix.parent / f"{prefix.name}{suffix}" for suffix in (".pgm", ".yaml", ".png", "_scale.yaml")]


def _unknown_grey(occupied_thresh: float, free_thresh: float) -> int:
    """A grey level that map_server reads as between the thresholds (so alpha 0 gives -1):
    128 (p about 0.5) when it fits, else the level nearest the middle of the band."""
    levels = np.arange(256)
    occ = (255 - levels.astype(np.float64)) / 255.0
    fits = levels[(occ >= free_thresh) & (occ <= occupied_thresh)]
    if fits.size == 0:
        raise InputError(
            f"no grey level lies between free_thresh {free_thresh!r} and occupied_thresh {occupied_thresh!r} "
            "to mark unobserved cells in the scale PNG; widen the gap to at least 1/255",
            key="free_thresh",
        )
    if 128 in fits:
        return 128
    middle = 255.0 * (1.0 - 0.5 * (occupied_thresh + free_thresh))
    return int(fits[np.argmin(np.abs(fits - middle))])


def _yaml_float(value: float) -> str:
    """repr of a float in a form that YAML 1.1 readers (PyYAML) also read as a float."""
    text = repr(float(value))
    if "e" in text:
        mantissa, exponent = text.split("e")
        if "." not in mantissa:
            mantissa += ".0"
        if exponent[0] not in "+-":
            exponent = "+" + exponent
        text = f"{mantissa}e{exponent}"
    return text


def _yaml_str(name: str) -> str:
    """``name`` bare when YAML reads it back as that same string, else double-quoted."""
    if re.fullmatch(r"[A-Za-z0-9_][A-Za-z0-9_.+-]*", name) and yaml.safe_load(name) == name:
        return name
    return '"' + name.replace("\\", "\\\\").replace('"', '\\"') + '"'
