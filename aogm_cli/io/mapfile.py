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
from aogm_cli.io.h5file import hdf5_bytes, open_input, text

FORMAT = "aogm-map"
FORMAT_VERSION = 1


@dataclass(frozen=True)
class MapHeader:
    """A map file's root attributes: what made it and from which log."""

    mode: str
    source_log: str
    params: dict
    runtime_s: float


def map_bytes(m: OccupancyMap) -> bytes:
    """The map file of ``m`` (CONTRACT.md) as sealed HDF5 bytes."""

    def fill(f: h5py.File) -> None:
        f.attrs["format"] = FORMAT
        f.attrs["format_version"] = FORMAT_VERSION
        f.attrs["mode"] = m.mode
        f.attrs["aogm_version"] = __version__
        f.attrs["source_log"] = m.source_log
        f.attrs["runtime_s"] = float(m.runtime_s)
        f.attrs["params"] = json.dumps(m.params, sort_keys=True)
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


def write_map_file(path: str | Path, m: OccupancyMap) -> None:
    """Write ``m`` to ``path`` (atomically)."""
    write_files_atomically([(Path(path), map_bytes(m))])


def _header(f: h5py.File, path: str) -> MapHeader:
    mode = text(f.attrs.get("mode"))
    if mode not in MODES:
        raise InputError(f"expected one of {', '.join(MODES)}, got {mode!r}", file=path, key="mode")
    try:
        params = json.loads(text(f.attrs.get("params", "{}")))
    except json.JSONDecodeError as exc:
        raise InputError(f"expected JSON: {exc}", file=path, key="params") from None
    return MapHeader(mode, text(f.attrs.get("source_log", "")), params, float(f.attrs.get("runtime_s", 0.0)))


def read_map_header(path: str | Path) -> MapHeader:
    """Check a map file's format and read its root attributes, without its grids."""
    path = str(path)
    with open_input(path, FORMAT, FORMAT_VERSION) as f:
        return _header(f, path)


def read_map_file(path: str | Path) -> OccupancyMap:
    """Read and check a map file; InputError names the file and the missing or wrong item."""
    path = str(path)
    with open_input(path, FORMAT, FORMAT_VERSION) as f:
        header = _header(f, path)
        for name in ("map/probability", "map/observed"):
            if name not in f:
                raise InputError("missing dataset", file=path, key="/" + name)
        g = f["map"]
        prob = g["probability"][...]
        if prob.ndim != 2:
            raise InputError(f"expected a 2-D grid, got shape {prob.shape}", file=path, key="/map/probability")
        ox, oy = (float(v) for v in g.attrs["origin"])
        grid = GridSpec(ox, oy, float(g.attrs["resolution"]), prob.shape[0], prob.shape[1])

        def optional(name):
            return g[name][...] if name in g else None

        stats = {}
        if "stats" in f:
            for k, v in f["stats"].attrs.items():
                stats[k] = _stat(v)
        return OccupancyMap(
            grid=grid,
            probability=prob,
            observed=g["observed"][...].astype(bool),
            mode=header.mode,
            params=header.params,
            runtime_s=header.runtime_s,
            source_log=header.source_log,
            log_odds=optional("log_odds"),
            occupied=optional("occupied"),
            clusters=optional("clusters"),
            stats=stats,
        )


def is_map_file(path: str | Path) -> bool:
    """True when ``path`` is an HDF5 file whose format attribute says aogm-map."""
    try:
        with h5py.File(path, "r") as f:
            return text(f.attrs.get("format")) == FORMAT
    except OSError:
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
