"""Importers: real range logs (CARMEN, plain text tables) -> the aogm log of CONTRACT.md.

Owns what the importers share: reading text lines from a plain or gzipped file with a
progress callback, cleaning readings (+inf = no echo, NaN = invalid) and interpolating poses by time.
"""

from __future__ import annotations

import gzip
import io
import os
import zlib
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np

from aogm_cli.core.errors import InputError

Progress = Callable[[int], object]

_GZIP_MAGIC = b"\x1f\x8b"


def read_lines(path: str | Path, progress: Progress | None = None) -> Iterator[str]:
    """Yield the text lines of ``path`` (gzip is recognised by its magic bytes), without newlines.

    ``progress(n)`` is called with the number of kilobytes of the file read since the last call.
    """
    path = str(path)
    try:
        raw = open(path, "rb")  # noqa: SIM115 - closed below
    except FileNotFoundError:
        raise InputError("no such file", file=path) from None
    except IsADirectoryError:
        raise InputError("is a folder; expected a text log", file=path) from None
    except OSError as exc:
        raise InputError(f"cannot read ({exc.strerror})", file=path) from None
    with raw:
        compressed = raw.read(2) == _GZIP_MAGIC
        raw.seek(0)
        binary = gzip.GzipFile(fileobj=raw, mode="rb") if compressed else raw
        text = io.TextIOWrapper(binary, encoding="utf-8-sig", newline=None)  # a BOM is not text
        done_kb = 0
        try:
            for n, line in enumerate(text, start=1):
                yield line.rstrip("\n")
                if progress is not None and n % 2000 == 0:
                    kb = raw.tell() // 1024
                    progress(kb - done_kb)
                    done_kb = kb
        except UnicodeDecodeError:
            raise InputError("not a UTF-8 text file", file=path) from None
        except (gzip.BadGzipFile, EOFError, zlib.error) as exc:
            raise InputError(f"corrupt or truncated gzip data ({exc.__class__.__name__})", file=path) from None
        if progress is not None:
            progress(max(0, file_kilobytes(path) - done_kb))


def file_kilobytes(path: str | Path) -> int:
    """The size of ``path`` in kilobytes (the total of ``read_lines``'s progress)."""
    try:
        return os.path.getsize(path) // 1024
    except OSError:
        return 0


def clean_ranges(ranges: np.ndarray, max_range: float | np.ndarray) -> np.ndarray:
    """Readings in metres -> the log's convention: >= max_range -> +inf, negative or NaN -> NaN.

    ``max_range`` is a scalar or one value per row.
    """
    r = np.array(ranges, dtype=np.float64, copy=True)
    limit = np.asarray(max_range, dtype=np.float64)
    if limit.ndim == 1:
        limit = limit[:, None]
    with np.errstate(invalid="ignore"):
        r[r < 0] = np.nan
        r[r >= limit] = np.inf
    return r.astype(np.float32)


def wrap_angle(a):
    """Angles wrapped into [-pi, pi)."""
    return (np.asarray(a, dtype=np.float64) + np.pi) % (2 * np.pi) - np.pi


def interpolate_poses(src_time: np.ndarray, src_pose: np.ndarray, time: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Poses at ``time`` by linear interpolation of poses (N, 3) taken at ``src_time`` (N,).

    x and y are interpolated linearly, yaw along the shorter arc. Returns (poses (T, 3), inside (T,)):
    ``inside`` is false for times before the first or after the last source pose (their pose is the
    nearest end's, but should not be used).
    """
    src_time = np.asarray(src_time, dtype=np.float64)
    src_pose = np.asarray(src_pose, dtype=np.float64).reshape(-1, 3)
    time = np.asarray(time, dtype=np.float64)
    if src_time.size == 0:
        return np.zeros((time.size, 3)), np.zeros(time.size, dtype=bool)
    order = np.argsort(src_time, kind="stable")
    st, sp = src_time[order], src_pose[order]
    yaw = np.unwrap(sp[:, 2])
    out = np.empty((time.size, 3))
    out[:, 0] = np.interp(time, st, sp[:, 0])
    out[:, 1] = np.interp(time, st, sp[:, 1])
    out[:, 2] = wrap_angle(np.interp(time, st, yaw))
    inside = (time >= st[0]) & (time <= st[-1])
    return out, inside
