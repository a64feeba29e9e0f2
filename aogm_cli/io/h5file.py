"""Opening aogm's HDF5 inputs (logs, maps, detectors): the checks every reader needs.

``open_input`` opens read-only and checks the ``format`` and ``format_version`` attributes,
with errors that name the file and the attribute; ``text`` reads a string attribute.
"""

from __future__ import annotations

from pathlib import Path

import h5py

from aogm_cli.core.errors import InputError


def text(value) -> str:
    """A string attribute as str (h5py may give bytes); "" for a missing one."""
    if value is None:
        return ""
    return value.decode() if isinstance(value, bytes) else str(value)


def open_input(path: str | Path, fmt: str, version: int) -> h5py.File:
    """The HDF5 file at ``path``, open for reading, after checking it is ``fmt`` ``version``."""
    file = str(path)
    try:
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
