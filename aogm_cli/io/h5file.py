"""aogm's HDF5 files (logs, maps, detectors): built in memory and sealed, opened with the checks
every reader needs. ``hdf5_bytes`` builds a file with a checksum in its user block (HDF5
ignores it); ``open_input`` verifies that seal before the HDF5 library reads anything, then
checks the ``format`` and ``format_version`` attributes; ``text`` reads a string attribute.
"""

from __future__ import annotations

import io
import struct
import subprocess
import sys
import zlib
from collections.abc import Callable
from pathlib import Path

import h5py

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


def is_sealed_intact(file: str) -> bool:
    """True when ``file`` carries aogm's seal and its length and checksum agree with its contents."""
    with open(file, "rb") as fh:
        head = fh.read(len(SEAL_MAGIC) + _SEAL.size)
        if not head.startswith(SEAL_MAGIC):
            return False
        length, crc = _SEAL.unpack(head[len(SEAL_MAGIC):])
        fh.seek(USER_BLOCK)
        found, size = 0, 0
        while block := fh.read(_CHUNK):
            found = zlib.crc32(block, found)
            size += len(block)
    return size == length and found == crc


# Walks every object header and attribute of a file, as a reader would, in a child process.
_WALK = """
import sys, h5py
def visit(name, obj):
    for key in obj.attrs:
        obj.attrs[key]
    if isinstance(obj, h5py.Dataset):
        obj.shape, obj.dtype
with h5py.File(sys.argv[1], "r") as f:
    for key in f.attrs:
        f.attrs[key]
    f.visititems(visit)
"""
WATCHDOG_SECONDS = 20.0


def check_structure(file: str, seconds: float = WATCHDOG_SECONDS) -> None:
    """Raise InputError unless the HDF5 library can walk ``file``'s headers and attributes within
    ``seconds`` in a child process: a damaged header can make the library spin without end, and
    only a process can be stopped from outside. Used for files whose seal is missing or broken
    (written before aogm sealed its files, edited since, or damaged); sealed intact files skip it."""
    try:
        done = subprocess.run([sys.executable, "-c", _WALK, file], capture_output=True, timeout=seconds)
    except subprocess.TimeoutExpired:
        raise InputError(f"the file is damaged: reading its headers did not finish in {seconds:g} s", file=file) from None
    if done.returncode != 0:
        last = (done.stderr.decode(errors="replace").strip().splitlines() or ["?"])[-1]
        raise InputError(f"the file is damaged or not HDF5: {last[:200]}", file=file)


def open_input(path: str | Path, fmt: str, version: int) -> h5py.File:
    """The HDF5 file at ``path``, open for reading, after checking its seal and that it is
    ``fmt`` ``version``."""
    file = str(path)
    try:
        if not is_sealed_intact(file):
            check_structure(file)
        f = h5py.File(file, "r")
    except FileNotFoundError:
        raise InputError("no such file", file=file) from None
    except OSError as exc:
        raise InputError(f"not an HDF5 file ({exc.__class__.__name__}); expected {fmt!r}", file=file) from None
    found = text(f.attrs.get("format")) or None
    if found != fmt:
        f.close()
        raise InputError(f"expected {fmt!r}, got {found!r}", file=file, key="format")
    found_version = f.attrs.get("format_version")
    if found_version != version:
        f.close()
        raise InputError(f"expected {version}, got {found_version!r}", file=file, key="format_version")
    return f
