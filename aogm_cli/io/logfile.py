"""The log file (HDF5) of CONTRACT.md: scans, sensors and, for simulated logs, the truth.

``write_log`` writes a whole ``Log`` atomically; ``LogReader`` reads the header and the truth,
and streams scans in chunks so that mappers need memory for one chunk only.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterator
from pathlib import Path

import h5py
import numpy as np

from aogm_cli.core.errors import InputError
from aogm_cli.core.grid import GridSpec
from aogm_cli.core.log import CAUSE_ECHO, CAUSE_SPECULAR, CHECK_KINDS, Log, SensorSpec, Truth
from aogm_cli.io import h5file
from aogm_cli.io.atomic import write_files_atomically
from aogm_cli.io.provenance import write_header, write_provenance

FORMAT = "aogm-log"
FORMAT_VERSION = 1

def log_bytes(log: Log, provenance: dict | None = None) -> bytes:
    """The log file of ``log`` (CONTRACT.md) as sealed HDF5 bytes, with ``provenance``
    (``io.provenance.provenance``) in the root attribute of that name when given."""

    def fill(f: h5py.File) -> None:
        write_header(f, FORMAT, FORMAT_VERSION)
        f.attrs["source"] = log.source
        if log.seed is not None:
            f.attrs["seed"] = int(log.seed)
        write_provenance(f, provenance)
        chunk_rows = max(1, min(log.n_scans, 4096))
        scans = f.create_group("scans")
        scans.create_dataset("time", data=np.asarray(log.time, dtype=np.float64))
        scans.create_dataset("pose", data=np.asarray(log.pose, dtype=np.float64))
        ranges = np.asarray(log.ranges, dtype=np.float32)
        scans.create_dataset("ranges", data=ranges, chunks=(chunk_rows, ranges.shape[1]) if ranges.size else None)
        sensors = f.create_group("sensors")
        sensors.create_dataset("mount", data=np.asarray(log.sensor.mount, dtype=np.float64))
        for k, v in log.sensor.as_dict().items():
            sensors.attrs[k] = v
        if log.truth is not None:
            t = log.truth
            g = f.create_group("truth")
            g.create_dataset("occupancy", data=np.asarray(t.occupancy, dtype=np.uint8), compression="gzip")
            g.create_dataset("cause", data=np.asarray(t.cause, dtype=np.int8))
            g.create_dataset("ideal_range", data=np.asarray(t.ideal_range, dtype=np.float32))
            for k, v in t.grid.attrs().items():
                g.attrs[k] = v
            g.attrs["world"] = t.world
            g.attrs["checks"] = json.dumps(list(t.checks))

    return h5file.hdf5_bytes(fill)


def write_log(path: str | Path, log: Log, provenance: dict | None = None) -> None:
    """Write ``log`` to ``path`` in the format of CONTRACT.md (atomically), with ``provenance``."""
    write_files_atomically([(Path(path), log_bytes(log, provenance))])


class LogReader:
    """An open log file: header and truth on demand, scans streamed in chunks.

    Use as a context manager: ``with LogReader(path) as log: for chunk in log.chunks(): ...``
    """

    def __init__(self, path: str | Path, digest=None):
        """``digest``: a ``hashlib`` hash fed every byte of the file in the read that checks its
        seal (``aogm map`` reads its log once for both)."""
        self.path = str(path)
        self._f = h5file.open_input(self.path, FORMAT, FORMAT_VERSION, digest)
        try:
            self._check()
        except BaseException:
            self._f.close()
            raise

    def _error(self, key: str, message: str) -> InputError:
        return InputError(message, file=self.path, key=key)

    def _check(self) -> None:
        """Check every dataset and attribute the readers rely on (ranges are checked as they
        are read, chunk by chunk); the sensor and the truth are read and kept."""
        f, file, dims = self._f, self.path, {}
        numbers = "numbers (integer or float)"
        h5file.dataset(f, "scans/time", file, ("T",), "iuf", numbers, dims)
        h5file.dataset(f, "scans/pose", file, ("T", 3), "iuf", numbers, dims)
        h5file.dataset(f, "sensors/mount", file, ("S", 3), "iuf", numbers, dims)
        h5file.dataset(f, "scans/ranges", file, ("T", "S"), "f", "float ranges (m)", dims)
        self._sensor = self._read_sensor()
        seed = h5file.attribute(f, "seed", file, "seed", required=False)
        if seed is not None and (isinstance(seed, (bool, np.bool_)) or not isinstance(seed, (int, np.integer))):
            raise self._error("seed", f"expected a whole number, got {seed!r}")
        self._truth = None
        with h5file.reading(file, "/truth"):
            has_truth = "truth" in f
        if has_truth:
            self._truth = self._read_truth(dims)

    def _read_sensor(self) -> SensorSpec:
        f, file = self._f, self.path
        a = f["sensors"]

        def key(k):
            return f"/sensors.{k}"

        kind = h5file.text_attr(a, "kind", file, key("kind"))
        values = {k: h5file.number_attr(a, k, file, key(k)) for k in ("beam_width", "min_range", "max_range", "noise_sigma")}
        mount = h5file.read_dataset(f, "sensors/mount", file).astype(np.float64, copy=False)
        try:
            return SensorSpec(mount=mount, kind=kind, **values).validate()
        except InputError as exc:
            raise self._error("/sensors/mount" if exc.key == "mount" else key(exc.key), exc.message) from None

    def _read_truth(self, dims: dict) -> Truth:
        """The truth, checked: occupancy (H, W) 0/1, cause (T, S) 0..3, ideal_range (T, S)
        >= 0 or +inf, resolution > 0, origin (x, y), checks a JSON list of passable/blocked checks."""
        f, file = self._f, self.path
        with h5file.reading(file, "/truth"):
            g = f["truth"]
            if not isinstance(g, h5py.Group):
                raise self._error("/truth", "expected a group")
        h5file.dataset(f, "truth/occupancy", file, ("H", "W"), "iub", "integers 0/1", dims)
        h5file.dataset(f, "truth/cause", file, ("T", "S"), "iu", "integers 0..3", dims)
        h5file.dataset(f, "truth/ideal_range", file, ("T", "S"), "f", "float ranges (m)", dims)
        if dims["H"] < 1 or dims["W"] < 1:
            raise self._error("/truth/occupancy", f"expected a non-empty grid, got shape ({dims['H']}, {dims['W']})")
        occupancy = h5file.read_dataset(f, "truth/occupancy", file)
        if not np.all((occupancy == 0) | (occupancy == 1)):
            raise self._error("/truth/occupancy", "expected 0 (free) or 1 (occupied) in every cell")
        cause = h5file.read_dataset(f, "truth/cause", file)
        if cause.size and not (cause.min() >= CAUSE_ECHO and cause.max() <= CAUSE_SPECULAR):
            raise self._error("/truth/cause", f"expected causes {CAUSE_ECHO}..{CAUSE_SPECULAR}, got {cause.min()}..{cause.max()}")
        ideal = h5file.read_dataset(f, "truth/ideal_range", file)
        if not np.all(ideal >= 0):  # NaN and negative fail
            raise self._error("/truth/ideal_range", "expected ranges >= 0 (m) or +inf (no surface), got NaN or a negative one")
        resolution = h5file.number_attr(g, "resolution", file, "/truth.resolution")
        if resolution <= 0:
            raise self._error("/truth.resolution", f"expected a positive resolution (m per cell), got {resolution}")
        ox, oy = h5file.vector_attr(g, "origin", file, "/truth.origin", 2)
        raw_checks = h5file.json_attr(g, "checks", file, "/truth.checks", list, required=False)
        checks = tuple(_check_checks([] if raw_checks is None else raw_checks, file))
        world = h5file.text_attr(g, "world", file, "/truth.world", required=False) or ""
        grid = GridSpec(ox, oy, resolution, int(dims["H"]), int(dims["W"]))
        return Truth(grid=grid, occupancy=occupancy, cause=cause, ideal_range=ideal, world=world, checks=checks)

    def __enter__(self) -> LogReader:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        self._f.close()

    @property
    def n_scans(self) -> int:
        return int(self._f["scans/time"].shape[0])

    @property
    def source(self) -> str:
        with h5file.reading(self.path, "source"):
            return h5file.text(self._f.attrs.get("source", ""))

    @property
    def seed(self) -> int | None:
        s = self._f.attrs.get("seed")
        return None if s is None else int(s)

    @property
    def sensor(self) -> SensorSpec:
        return self._sensor

    @property
    def has_truth(self) -> bool:
        return self._truth is not None

    def truth_grid(self) -> GridSpec | None:
        """The truth grid's geometry, or None."""
        return None if self._truth is None else self._truth.grid

    def truth(self) -> Truth | None:
        return self._truth

    def poses(self) -> np.ndarray:
        return h5file.read_dataset(self._f, "scans/pose", self.path)

    def scan_ranges(self, start: int, stop: int) -> np.ndarray:
        """Ranges of scans start:stop, checked (a log source's interface, ``mapping.pipeline``)."""
        return self._ranges(start, stop)

    def _ranges(self, start: int, stop: int) -> np.ndarray:
        """Ranges of scans start:stop as float32, checked: >= 0, +inf or NaN."""
        r = h5file.read_dataset(self._f, "scans/ranges", self.path, slice(start, stop)).astype(np.float32, copy=False)
        with np.errstate(invalid="ignore"):
            negative = r < 0
        if negative.any():
            t, s = (int(v[0]) for v in np.nonzero(negative))
            raise self._error("/scans/ranges", f"expected ranges >= 0 (m), +inf (no echo) or NaN (invalid); "
                                               f"got {r[t, s]} at scan {start + t}, sensor {s}")
        return r

    def chunks(self, size: int = 4096) -> Iterator[tuple[int, np.ndarray, np.ndarray, np.ndarray]]:
        """Yield (first scan index, time, pose, ranges) for consecutive chunks of ``size`` scans."""
        n = self.n_scans
        for start in range(0, n, size):
            stop = min(n, start + size)
            rows = slice(start, stop)
            yield (start, h5file.read_dataset(self._f, "scans/time", self.path, rows),
                   h5file.read_dataset(self._f, "scans/pose", self.path, rows), self._ranges(start, stop))

    def read(self) -> Log:
        """The whole log in memory."""
        return Log(
            time=h5file.read_dataset(self._f, "scans/time", self.path),
            pose=self.poses(),
            ranges=self._ranges(0, self.n_scans),
            sensor=self.sensor,
            source=self.source,
            truth=self.truth(),
            seed=self.seed,
        )


def _check_checks(checks: list, file: str) -> list[dict]:
    """The truth's checks, each ``{"name": str, "passable" or "blocked": {"from": [x, y],
    "to": [x, y], "robot_radius": r >= 0}}`` as ``aogm simulate`` writes them."""

    def point(v) -> bool:
        return (isinstance(v, list) and len(v) == 2
                and all(isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) for x in v))

    for i, c in enumerate(checks):
        key = f"/truth.checks[{i}]"
        kinds = [k for k in CHECK_KINDS if isinstance(c, dict) and k in c]
        if not isinstance(c, dict) or not isinstance(c.get("name"), str) or len(kinds) != 1:
            raise InputError("expected {\"name\": ..., \"passable\" or \"blocked\": {...}}", file=file, key=key)
        kind = kinds[0]
        p = c[kind]
        if not isinstance(p, dict):
            raise InputError("expected an object {from, to, robot_radius}", file=file, key=f"{key}.{kind}")
        for end in ("from", "to"):
            if not point(p.get(end)):
                raise InputError(f"expected [x, y] (finite), got {p.get(end)!r}", file=file, key=f"{key}.{kind}.{end}")
        r = p.get("robot_radius")
        if isinstance(r, bool) or not isinstance(r, (int, float)) or not (math.isfinite(r) and r >= 0):
            raise InputError(f"expected a number >= 0 (m), got {r!r}", file=file, key=f"{key}.{kind}.robot_radius")
    return checks


def read_log(path: str | Path) -> Log:
    """Read the whole log at ``path``."""
    with LogReader(path) as reader:
        return reader.read()


