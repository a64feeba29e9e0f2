"""aogm's HDF5 files (logs, maps, detectors): built in memory and sealed, opened with the checks
every reader needs. ``hdf5_bytes`` builds a file with a checksum in its user block (HDF5
ignores it); ``open_input`` verifies that seal before the HDF5 library reads anything, then
checks the ``format`` and ``format_version`` attributes; ``text`` reads a string attribute.
"""

from __future__ import annotations

import io
import json
import math
import os
import signal
import struct
import time
import zlib
from collections.abc import Callable
from contextlib import contextmanager
from pathlib import Path

import h5py
import numpy as np

from aogm_cli.core.errors import InputError


def text(value) -> str:
    """A string attribute as str (h5py may give bytes); "" for a missing one."""
    if value is None:
        return ""
    return value.decode() if isinstance(value, bytes) else str(value)


# The seal: the first bytes of the 512-byte user block are SEAL_MAGIC, then the length and the
# CRC-32 of everything after the user block (little-endian uint64, uint32). A damaged file is
# refused in one linear pass, before the HDF5 library can spin on a corrupt header.
USER_BLOCK = 512
SEAL_MAGIC = b"aogm-sealed-hdf5\n"
_SEAL = struct.Struct("<QI")
_CHUNK = 1 << 22


def hdf5_bytes(fill: Callable[[h5py.File], None]) -> bytes:
    """The bytes of a sealed HDF5 file that ``fill(f)`` writes into (built in memory, so that a
    full disk is an ordinary OSError of the caller's write, never a failure inside HDF5)."""
    buffer = io.BytesIO()
    with h5py.File(buffer, "w", userblock_size=USER_BLOCK) as f:
        fill(f)
    data = bytearray(buffer.getbuffer())
    body = memoryview(data)[USER_BLOCK:]
    seal = SEAL_MAGIC + _SEAL.pack(len(body), zlib.crc32(body))
    data[: len(seal)] = seal
    return bytes(data)


def is_sealed_intact(file: str, digest=None) -> bool:
    """True when ``file`` carries aogm's seal and its length and checksum agree with its contents;
    with ``digest`` (a ``hashlib`` hash) every byte of the file is fed to it in the same read."""
    with open(file, "rb") as fh:
        block = fh.read(USER_BLOCK)  # the user block, which holds the seal
        head = block[:len(SEAL_MAGIC) + _SEAL.size]
        sealed = len(head) == len(SEAL_MAGIC) + _SEAL.size and head.startswith(SEAL_MAGIC)
        if not sealed and digest is None:
            return False  # not sealed, or cut inside the seal (then the header walk refuses it)
        found, size = 0, 0
        while True:
            if digest is not None:
                digest.update(block)
            block = fh.read(_CHUNK)
            if not block:
                break
            found = zlib.crc32(block, found)
            size += len(block)
    if not sealed:
        return False
    length, crc = _SEAL.unpack(head[len(SEAL_MAGIC):])
    return size == length and found == crc


WATCHDOG_SECONDS = 20.0  # AOGM_HDF5_WATCHDOG_SECONDS overrides it


def _walk(file: str) -> None:
    """Read every object header and attribute of ``file``, as a reader would."""

    def visit(_name, obj):
        for key in obj.attrs:
            obj.attrs[key]
        if isinstance(obj, h5py.Dataset):
            obj.shape, obj.dtype  # noqa: B018

    with h5py.File(file, "r") as f:
        for key in f.attrs:
            f.attrs[key]
        f.visititems(visit)


def check_structure(file: str, seconds: float | None = None) -> None:
    """Raise InputError unless the HDF5 library can walk ``file``'s headers and attributes within
    ``seconds`` in a forked child process: a damaged header can make the library spin without
    end, and only a process can be stopped from outside. Used for files whose seal is missing or
    broken (written before aogm sealed its files, edited since, or damaged)."""
    if seconds is None:
        seconds = float(os.environ.get("AOGM_HDF5_WATCHDOG_SECONDS", WATCHDOG_SECONDS))
    read_end, write_end = os.pipe()
    pid = os.fork()
    if pid == 0:  # the child: walk, report, and leave without running the parent's exit handlers
        for signum in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
            signal.signal(signum, signal.SIG_DFL)  # the parent's handlers (cleanup, a message) are not the child's
        os.close(read_end)
        code = 0
        try:
            _walk(file)
        except BaseException as exc:  # noqa: BLE001 - any failure is the answer
            os.write(write_end, _reason(exc).encode(errors="replace")[:400])
            code = 1
        os._exit(code)
    os.close(write_end)
    try:
        status = _wait(pid, seconds)
        message = os.read(read_end, 400).decode(errors="replace")
    finally:
        os.close(read_end)
    if status is None:
        raise InputError(f"the file is damaged: reading its headers did not finish in {seconds:g} s", file=file)
    if status != 0:
        raise InputError(f"the file is damaged or not HDF5: {message or 'the reader crashed'}", file=file)


def _wait(pid: int, seconds: float) -> int | None:
    """The child's exit status, or None (and the child killed) after ``seconds``."""
    deadline = time.monotonic() + seconds
    while True:
        done, status = os.waitpid(pid, os.WNOHANG)
        if done:
            return os.waitstatus_to_exitcode(status)
        if time.monotonic() > deadline:
            os.kill(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
            return None
        time.sleep(0.002)


# What h5py raises for a damaged file or an object of an unexpected kind, at open or later
# (a corrupt compressed chunk fails only when it is read: "filter returned failure during read").
H5_ERRORS = (OSError, KeyError, TypeError, ValueError, RuntimeError, AttributeError)


def _reason(exc: BaseException) -> str:
    return (str(exc).strip().splitlines() or [exc.__class__.__name__])[-1][:200]


@contextmanager
def reading(file: str, key: str):
    """Turn any h5py/HDF5 error inside the block into an InputError naming ``file`` and ``key``."""
    try:
        yield
    except InputError:
        raise
    except H5_ERRORS as exc:
        raise InputError(f"cannot be read, the file is damaged ({_reason(exc)})", file=file, key=key) from None


def read_dataset(f: h5py.File, name: str, file: str, selection=Ellipsis) -> np.ndarray:
    """``f[name][selection]``, an HDF5 error becoming an InputError naming ``file`` and ``/name``."""
    with reading(file, "/" + name.lstrip("/")):
        return f[name][selection]


def dataset(f: h5py.File, name: str, file: str, shape: tuple, kinds: str, what: str,
            dims: dict | None = None) -> h5py.Dataset:
    """The dataset ``name`` of ``f``, checked: present, of ``shape`` (ints, or names bound in
    ``dims`` on first use and compared after) and of a dtype kind in ``kinds`` ("f", "iu", "b")."""
    key = "/" + name.lstrip("/")
    dims = {} if dims is None else dims
    with reading(file, key):
        obj = f.get(name)
        if obj is None:
            raise InputError("missing dataset", file=file, key=key)
        if not isinstance(obj, h5py.Dataset):
            raise InputError(f"expected a dataset, got a {type(obj).__name__}", file=file, key=key)
        got, dtype = obj.shape, obj.dtype
    want = "(" + ", ".join(str(dims.get(d, d)) for d in shape) + ("," if len(shape) == 1 else "") + ")"
    if got is None or len(got) != len(shape):
        raise InputError(f"expected shape {want}, got {got}", file=file, key=key)
    for d, n in zip(shape, got, strict=True):
        if isinstance(d, str) and d not in dims:
            dims[d] = n
        if dims.get(d, d) != n:
            raise InputError(f"expected shape {want}, got {got}", file=file, key=key)
    if dtype.kind not in kinds:
        raise InputError(f"expected {what}, got dtype {dtype}", file=file, key=key)
    return obj


def attribute(obj, name: str, file: str, key: str, required: bool = True):
    """The attribute ``name`` of ``obj`` (None when absent and not ``required``)."""
    with reading(file, key):
        if name not in obj.attrs:
            if required:
                raise InputError("missing attribute", file=file, key=key)
            return None
        return obj.attrs[name]


def number_attr(obj, name: str, file: str, key: str, required: bool = True) -> float | None:
    """A finite number attribute as float (not a string, a bool or an array)."""
    value = attribute(obj, name, file, key, required)
    if value is None:
        return None
    if isinstance(value, np.ndarray) and value.shape in ((), (1,)):
        value = value.reshape(-1)[0]
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise InputError(f"expected a number, got {value!r}", file=file, key=key)
    if not math.isfinite(float(value)):
        raise InputError(f"expected a finite number, got {float(value)}", file=file, key=key)
    return float(value)


def text_attr(obj, name: str, file: str, key: str, required: bool = True) -> str | None:
    """A string attribute as str."""
    value = attribute(obj, name, file, key, required)
    if value is None:
        return None
    if not isinstance(value, (str, bytes)):
        raise InputError(f"expected a string, got {value!r}", file=file, key=key)
    try:
        return text(value)
    except UnicodeDecodeError:
        raise InputError("expected UTF-8 text", file=file, key=key) from None


def vector_attr(obj, name: str, file: str, key: str, n: int) -> tuple[float, ...]:
    """An attribute of ``n`` finite numbers."""
    value = np.asarray(attribute(obj, name, file, key))
    if value.shape != (n,) or value.dtype.kind not in "iuf":
        raise InputError(f"expected {n} numbers, got {value.tolist()!r}", file=file, key=key)
    if not np.all(np.isfinite(value)):
        raise InputError(f"expected {n} finite numbers, got {value.tolist()!r}", file=file, key=key)
    return tuple(float(v) for v in value)


def json_attr(obj, name: str, file: str, key: str, kind: type, required: bool = True):
    """A JSON attribute decoded, of type ``kind`` (dict or list); None when absent and optional."""
    raw = text_attr(obj, name, file, key, required)
    if raw is None:
        return None
    try:
        value = json.loads(raw)
    except ValueError:
        raise InputError(f"expected JSON (a {'JSON object' if kind is dict else 'JSON list'})", file=file, key=key) from None
    if not isinstance(value, kind):
        raise InputError(f"expected a JSON {'object' if kind is dict else 'list'}, got {type(value).__name__}",
                         file=file, key=key)
    return value


def _open_checked(file: str, expected: str, digest=None) -> h5py.File:
    """The HDF5 file ``file``, open for reading, after checking its seal (or, without an intact
    seal, walking its headers; ``digest``: see ``is_sealed_intact``); InputError saying it is not
    HDF5 and that ``expected`` was."""
    try:
        if not is_sealed_intact(file, digest):
            check_structure(file)
        return h5py.File(file, "r")
    except FileNotFoundError:
        raise InputError("no such file", file=file) from None
    except (OSError, ValueError, RuntimeError) as exc:
        raise InputError(f"not an HDF5 file ({exc.__class__.__name__}); expected {expected}", file=file) from None


def file_format(path: str | Path, expected: str, read: Callable[[h5py.File], object] | None = None):
    """The ``format`` attribute of the HDF5 file at ``path`` (None when it has none, or not a
    string); InputError when the file is missing, damaged or not HDF5 (``expected`` says what
    the caller wanted). With ``read``, (format, ``read(file)``) from the same open (one check
    of the seal for both)."""
    file = str(path)
    with _open_checked(file, expected) as f:
        with reading(file, "format"):
            raw = f.attrs.get("format")
            fmt = text(raw) if isinstance(raw, (str, bytes)) else None
        return fmt if read is None else (fmt, read(f))


def open_input(path: str | Path, fmt: str, version: int, digest=None) -> h5py.File:
    """The HDF5 file at ``path``, open for reading, after checking its seal (``digest``: a hash
    fed every byte of the file on that read) and that it is ``fmt`` ``version``."""
    file = str(path)
    f = _open_checked(file, repr(fmt), digest)
    try:
        with reading(file, "format"):
            raw = f.attrs.get("format")
            found = text(raw) if isinstance(raw, (str, bytes)) else raw
            found_version = f.attrs.get("format_version")
        if not isinstance(found, str) or found != fmt:
            raise InputError(f"expected {fmt!r}, got {found!r}", file=file, key="format")
        numeric = isinstance(found_version, (int, float, np.integer, np.floating))
        if not numeric or isinstance(found_version, (bool, np.bool_)) or found_version != version:
            raise InputError(f"expected {version}, got {found_version!r}", file=file, key="format_version")
    except BaseException:
        f.close()
        raise
    return f
