"""The map file (HDF5) of CONTRACT.md: what ``aogm map`` writes and every later step reads.

``OccupancyMap`` holds a map in memory; ``write_map_file`` / ``read_map_file`` convert it;
``read_map_header`` reads the root attributes only (mode, source_log, params, runtime).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np

from aogm_cli import __version__
from aogm_cli.core.errors import InputError
from aogm_cli.core.grid import GridSpec
from aogm_cli.core.occupancy_map import MODES, OccupancyMap
from aogm_cli.io.atomic import write_files_atomically
from aogm_cli.io.h5file import (
    check_structure,
    dataset,
    hdf5_bytes,
    is_sealed_intact,
    json_attr,
    number_attr,
    open_input,
    read_dataset,
    reading,
    text,
    text_attr,
    vector_attr,
)
from aogm_cli.io.provenance import write_provenance

FORMAT = "aogm-map"
FORMAT_VERSION = 1


@dataclass(frozen=True)
class MapHeader:
    """A map file's root attributes: what made it and from which log."""

    mode: str
    source_log: str
    params: dict
    runtime_s: float


def map_bytes(m: OccupancyMap, provenance: dict | None = None) -> bytes:
    """The map file of ``m`` (CONTRACT.md) as sealed HDF5 bytes, with ``provenance``
    (``io.provenance.provenance``) in the root attribute of that name when given."""

    def fill(f: h5py.File) -> None:
        f.attrs["format"] = FORMAT
        f.attrs["format_version"] = FORMAT_VERSION
        f.attrs["mode"] = m.mode
        f.attrs["aogm_version"] = __version__
        f.attrs["source_log"] = m.source_log
        f.attrs["runtime_s"] = float(m.runtime_s)
        f.attrs["params"] = json.dumps(m.params, sort_keys=True)
        for key in ("learned", "plan"):
            if getattr(m, key) is not None:
                f.attrs[key] = json.dumps(getattr(m, key), sort_keys=True)
        write_provenance(f, provenance)
        g = f.create_group("map")
        for k, v in m.grid.attrs().items():
            g.attrs[k] = v
        opts = {"compression": "gzip", "compression_opts": 4}
        g.create_dataset("probability", data=np.asarray(m.probability, dtype=np.float32), **opts)
        g.create_dataset("observed", data=np.asarray(m.observed, dtype=bool), **opts)
        if m.log_odds is not None:
            g.create_dataset("log_odds", data=np.asarray(m.log_odds, dtype=np.float32), **opts)
        if m.occupied is not None:
            g.create_dataset("occupied", data=np.asarray(m.occupied, dtype=bool), **opts)
        if m.clusters is not None:
            g.create_dataset("clusters", data=np.asarray(m.clusters, dtype=np.int32), **opts)
        s = f.create_group("stats")
        for k, v in m.stats.items():
            s.attrs[k] = json.dumps(v) if isinstance(v, (dict, list, tuple)) else v

    return hdf5_bytes(fill)


def write_map_file(path: str | Path, m: OccupancyMap, provenance: dict | None = None) -> None:
    """Write ``m`` to ``path`` (atomically), with ``provenance``."""
    write_files_atomically([(Path(path), map_bytes(m, provenance))])


def _header(f: h5py.File, path: str) -> MapHeader:
    mode = text_attr(f, "mode", path, "mode")
    if mode not in MODES:
        raise InputError(f"expected one of {', '.join(MODES)}, got {mode!r}", file=path, key="mode")
    params = json_attr(f, "params", path, "params", dict, required=False) or {}
    runtime = number_attr(f, "runtime_s", path, "runtime_s", required=False)
    if runtime is not None and runtime < 0:
        raise InputError(f"expected a number of seconds >= 0, got {runtime}", file=path, key="runtime_s")
    source_log = text_attr(f, "source_log", path, "source_log", required=False) or ""
    if not source_log.isprintable():
        raise InputError("expected the path of the log, got unprintable characters", file=path, key="source_log")
    return MapHeader(mode, source_log, params, 0.0 if runtime is None else runtime)


def read_map_header(path: str | Path) -> MapHeader:
    """Check a map file's format and read its root attributes, without its grids."""
    path = str(path)
    with open_input(path, FORMAT, FORMAT_VERSION) as f:
        return _header(f, path)


# optional layers: (dtype kinds, what, check of the values or None, message when it fails)
_LAYERS = {
    "log_odds": ("f", "float log-odds", lambda a: not np.any(np.isnan(a)), "expected numbers, got NaN"),
    "occupied": ("b", "bool", None, ""),
    "clusters": ("iu", "integer cluster ids", lambda a: a.size == 0 or a.min() >= 0, "expected cluster ids >= 0"),
}


def _grids(f: h5py.File, path: str) -> dict:
    """/map's datasets and attributes, checked: probability (H, W) float in [0, 1], observed
    (H, W) bool, the optional layers (H, W) of their types, resolution > 0 and origin (x, y)."""
    dims: dict = {}
    dataset(f, "map/probability", path, ("H", "W"), "f", "float probabilities", dims)
    dataset(f, "map/observed", path, ("H", "W"), "b", "bool", dims)
    g = f["map"]
    prob = read_dataset(f, "map/probability", path)
    if not np.all((prob >= 0) & (prob <= 1)):  # NaN fails
        bad = prob[~((prob >= 0) & (prob <= 1))][0]
        raise InputError(f"expected probabilities in [0, 1], got {bad}", file=path, key="/map/probability")
    out = {"probability": prob, "observed": read_dataset(f, "map/observed", path).astype(bool)}
    for name, (kinds, what, ok, message) in _LAYERS.items():
        out[name] = None
        with reading(path, f"/map/{name}"):
            present = name in g
        if present:
            dataset(f, f"map/{name}", path, ("H", "W"), kinds, what, dims)
            out[name] = read_dataset(f, f"map/{name}", path)
            if ok is not None and not ok(out[name]):
                raise InputError(message, file=path, key=f"/map/{name}")
    resolution = number_attr(g, "resolution", path, "/map.resolution")
    if resolution <= 0:
        raise InputError(f"expected a positive resolution (m per cell), got {resolution}", file=path, key="/map.resolution")
    ox, oy = vector_attr(g, "origin", path, "/map.origin", 2)
    out["grid"] = GridSpec(ox, oy, resolution, int(dims["H"]), int(dims["W"]))
    return out


def read_map_file(path: str | Path) -> OccupancyMap:
    """Read and check a map file; InputError names the file and the missing or wrong item."""
    path = str(path)
    with open_input(path, FORMAT, FORMAT_VERSION) as f:
        header = _header(f, path)
        grids = _grids(f, path)
        stats = {}
        with reading(path, "/stats"):
            if "stats" in f:
                for k, v in f["stats"].attrs.items():
                    stats[k] = _stat(v)
        return OccupancyMap(
            mode=header.mode,
            params=header.params,
            runtime_s=header.runtime_s,
            source_log=header.source_log,
            stats=stats,
            learned=json_attr(f, "learned", path, "learned", dict, required=False),
            plan=json_attr(f, "plan", path, "plan", dict, required=False),
            **grids,
        )


def is_map_file(path: str | Path) -> bool:
    """True when ``path`` is an HDF5 file whose format attribute says aogm-map. A file whose
    seal is missing or broken has its headers walked first (``h5file.check_structure``), so a
    damaged file is an InputError naming it, not a hang."""
    path = str(path)
    try:
        if not is_sealed_intact(path):
            check_structure(path)
        with h5py.File(path, "r") as f:
            return text(f.attrs.get("format")) == FORMAT
    except (OSError, ValueError, RuntimeError, KeyError, TypeError):
        return False


def _stat(v):
    if isinstance(v, (bytes, str)):
        s = text(v)
        try:
            return json.loads(s)
        except json.JSONDecodeError:
            return s
    if isinstance(v, np.generic):
        return v.item()
    return v
