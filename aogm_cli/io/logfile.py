"""The log file (HDF5) of CONTRACT.md: scans, sensors and, for simulated logs, the truth.

``write_log`` writes a whole ``Log`` atomically; ``LogReader`` reads the header and the truth,
and streams scans in chunks so that mappers need memory for one chunk only.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path

import h5py
import numpy as np

from aogm_cli import __version__
from aogm_cli.core.errors import InputError
from aogm_cli.core.grid import GridSpec
from aogm_cli.core.log import Log, SensorSpec, Truth
from aogm_cli.io.atomic import write_files_atomically
from aogm_cli.io.h5file import hdf5_bytes, open_input, text

FORMAT = "aogm-log"
FORMAT_VERSION = 1

def log_bytes(log: Log) -> bytes:
    """The log file of ``log`` (CONTRACT.md) as sealed HDF5 bytes."""

    def fill(f: h5py.File) -> None:
        f.attrs["format"] = FORMAT
        f.attrs["format_version"] = FORMAT_VERSION
        f.attrs["aogm_version"] = __version__
        f.attrs["source"] = log.source
        if log.seed is not None:
            f.attrs["seed"] = int(log.seed)
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

    return hdf5_bytes(fill)


def write_log(path: str | Path, log: Log) -> None:
    """Write ``log`` to ``path`` in the format of CONTRACT.md (atomically)."""
    write_files_atomically([(Path(path), log_bytes(log))])


class LogReader:
    """An open log file: header and truth on demand, scans streamed in chunks.

    Use as a context manager: ``with LogReader(path) as log: for chunk in log.chunks(): ...``
    """

    def __init__(self, path: str | Path):
        self.path = str(path)
        self._f = open_input(self.path, FORMAT, FORMAT_VERSION)
        try:
            self._check()
        except BaseException:
            self._f.close()
            raise

    def _error(self, key: str, message: str) -> InputError:
        return InputError(message, file=self.path, key=key)

    def _check(self) -> None:
        f = self._f
        for name in ("scans/time", "scans/pose", "scans/ranges", "sensors/mount"):
            if name not in f:
                raise self._error("/" + name, "missing dataset")
        t = f["scans/time"].shape
        if len(t) != 1:
            raise self._error("/scans/time", f"expected shape (T,), got {t}")
        if f["scans/pose"].shape != (t[0], 3):
            raise self._error("/scans/pose", f"expected shape ({t[0]}, 3), got {f['scans/pose'].shape}")
        mount = f["sensors/mount"].shape
        if len(mount) != 2 or mount[1] != 3:
            raise self._error("/sensors/mount", f"expected shape (S, 3), got {mount}")
        if f["scans/ranges"].shape != (t[0], mount[0]):
            raise self._error("/scans/ranges", f"expected shape ({t[0]}, {mount[0]}), got {f['scans/ranges'].shape}")
        for k in ("kind", "beam_width", "min_range", "max_range", "noise_sigma"):
            if k not in f["sensors"].attrs:
                raise self._error(f"/sensors.{k}", "missing attribute")

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
        return text(self._f.attrs.get("source", ""))

    @property
    def seed(self) -> int | None:
        s = self._f.attrs.get("seed")
        return None if s is None else int(s)

    @property
    def sensor(self) -> SensorSpec:
        a = self._f["sensors"].attrs
        return SensorSpec(
            mount=self._f["sensors/mount"][...],
            kind=text(a["kind"]),
            beam_width=float(a["beam_width"]),
            min_range=float(a["min_range"]),
            max_range=float(a["max_range"]),
            noise_sigma=float(a["noise_sigma"]),
        )

    @property
    def has_truth(self) -> bool:
        return "truth" in self._f

    def truth_grid(self) -> GridSpec | None:
        """The truth grid's geometry (without loading any array), or None."""
        if not self.has_truth:
            return None
        g = self._f["truth"]
        h, w = g["occupancy"].shape
        ox, oy = (float(v) for v in g.attrs["origin"])
        return GridSpec(ox, oy, float(g.attrs["resolution"]), int(h), int(w))

    def truth(self) -> Truth | None:
        if not self.has_truth:
            return None
        g = self._f["truth"]
        try:
            checks = tuple(json.loads(text(g.attrs.get("checks", "[]"))))
        except json.JSONDecodeError:
            raise self._error("/truth.checks", "expected a JSON list") from None
        return Truth(
            grid=self.truth_grid(),
            occupancy=g["occupancy"][...],
            cause=g["cause"][...],
            ideal_range=g["ideal_range"][...],
            world=text(g.attrs.get("world", "")),
            checks=checks,
        )

    def poses(self) -> np.ndarray:
        return self._f["scans/pose"][...]

    def chunks(self, size: int = 4096) -> Iterator[tuple[int, np.ndarray, np.ndarray, np.ndarray]]:
        """Yield (first scan index, time, pose, ranges) for consecutive chunks of ``size`` scans."""
        n = self.n_scans
        ds_t, ds_p, ds_r = self._f["scans/time"], self._f["scans/pose"], self._f["scans/ranges"]
        for start in range(0, n, size):
            stop = min(n, start + size)
            yield start, ds_t[start:stop], ds_p[start:stop], ds_r[start:stop].astype(np.float32, copy=False)

    def read(self) -> Log:
        """The whole log in memory."""
        return Log(
            time=self._f["scans/time"][...],
            pose=self._f["scans/pose"][...],
            ranges=self._f["scans/ranges"][...].astype(np.float32, copy=False),
            sensor=self.sensor,
            source=self.source,
            truth=self.truth(),
            seed=self.seed,
        )


def read_log(path: str | Path) -> Log:
    """Read the whole log at ``path``."""
    with LogReader(path) as reader:
        return reader.read()


