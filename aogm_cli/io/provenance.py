"""Provenance: what made an output file, recorded in its root attribute ``provenance`` (JSON).

``provenance(inputs)`` gathers the command line, each input file's sha256, aogm's version and
git commit (when run from a checkout), the libraries' versions, the platform and the time;
``write_provenance`` / ``read_provenance`` put it into an HDF5 file and read it back. Arrays are
never touched: a seed still fixes every output array bit for bit.
"""

from __future__ import annotations

import hashlib
import json
import platform
import subprocess
import sys
from datetime import UTC, datetime
from importlib import metadata
from pathlib import Path

import h5py

from aogm_cli import __version__
from aogm_cli.io.h5file import json_attr

ATTRIBUTE = "provenance"  # the root attribute of logs, maps and detectors
LIBRARIES = ("numpy", "numba", "h5py", "scipy")
_GIT_SECONDS = 5.0


def file_sha256(path: str | Path) -> str | None:
    """The file's sha256 (hex); None when there is no such file (any more)."""
    if not Path(path).is_file():
        return None
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def content_sha256(path: str | Path) -> str:
    """The sha256 of an HDF5 file's data: every dataset's name, dtype, shape and bytes, in name order. The same for
    the same data whatever the attributes (a log simulated again with the same seed has another provenance)."""
    digest = hashlib.sha256()
    with h5py.File(path, "r") as f:
        names: list[str] = []
        f.visititems(lambda name, obj: names.append(name) if isinstance(obj, h5py.Dataset) else None)
        for name in sorted(names):
            data = f[name][()]
            digest.update(f"{name}|{getattr(data, 'dtype', '')}|{getattr(data, 'shape', '')}|".encode())
            digest.update(data.tobytes() if hasattr(data, "tobytes") else repr(data).encode())
    return digest.hexdigest()


def provenance(inputs, argv: list[str] | None = None, hashed: dict | None = None) -> dict:
    """What makes an output from ``inputs`` (paths; None entries are skipped, a folder stands for
    the files in it) by the command line ``argv`` (default ``sys.argv``, as run): a JSON-able dict

    ``{"command": [...], "inputs": [{"path", "sha256"}], "aogm_version", "git_commit"
    (absent outside a checkout; "-dirty" appended when the checkout has changes),
    "libraries": {name: version or None}, "platform", "python", "time" (now, UTC, ISO 8601)}``.
    Call it before the work starts: the hashes are of the inputs as read, the time the start.
    ``hashed``: the sha256 of inputs read already (path -> hex), not read again.
    """
    hashed = {str(p): h for p, h in (hashed or {}).items()}
    record = {
        "command": [str(a) for a in (sys.argv if argv is None else argv)],
        "inputs": [{"path": str(p), "sha256": hashed.get(str(p)) or file_sha256(p)} for p in _files(inputs)],
        "aogm_version": __version__,
    }
    commit = git_commit()
    if commit is not None:
        record["git_commit"] = commit
    record["libraries"] = {name: _version(name) for name in LIBRARIES}
    record["platform"] = platform.platform()
    record["python"] = platform.python_version()
    record["time"] = datetime.now(UTC).isoformat(timespec="seconds").replace("+00:00", "Z")
    return record


def _files(inputs) -> list[Path | str]:
    """The input paths, None skipped, a folder (a ROS 2 bag) replaced by the files in it (sorted)."""
    files: list[Path | str] = []
    for p in inputs:
        if p is not None and Path(p).is_dir():
            files += sorted(f for f in Path(p).rglob("*") if f.is_file())
        elif p is not None:
            files.append(p)
    return files


def _version(name: str) -> str | None:
    """An installed distribution's version, without importing it (None when not installed)."""
    try:
        return metadata.version(name)
    except metadata.PackageNotFoundError:
        return None


def _git(folder: Path, *args: str) -> str | None:
    """``git args`` run in ``folder``: its stdout, or None for any failure (no git, not a
    checkout, a timeout)."""
    try:
        done = subprocess.run(["git", *args], cwd=folder, capture_output=True, text=True, timeout=_GIT_SECONDS,
                              check=False, stdin=subprocess.DEVNULL)
    except (OSError, subprocess.SubprocessError, ValueError):
        return None
    return done.stdout if done.returncode == 0 else None


def git_commit(folder: str | Path | None = None) -> str | None:
    """The commit checked out where the package's source lives (``folder``: default the package's
    own folder), with "-dirty" when ``git status --porcelain`` lists anything; None when that
    folder is not a git checkout whose files include the package (e.g. installed into an ignored
    site-packages) or git is missing. Never raises."""
    folder = Path(__file__).resolve().parent.parent if folder is None else Path(folder)
    head = _git(folder, "rev-parse", "HEAD")
    if not head or _git(folder, "ls-files", "--error-unmatch", "__init__.py") is None:
        return None
    status = _git(folder, "status", "--porcelain")
    return head.strip() + ("-dirty" if status is None or status.strip() else "")


def write_header(f: h5py.File, file_format: str, version: int) -> None:
    """The root attributes every aogm file starts with: its format, the format's version and
    the aogm version that wrote it (CONTRACT.md)."""
    from aogm_cli import __version__

    f.attrs["format"] = file_format
    f.attrs["format_version"] = version
    f.attrs["aogm_version"] = __version__


def write_provenance(f: h5py.File, record: dict | None) -> None:
    """Put ``record`` (from ``provenance``) into ``f``'s root attribute; nothing when None."""
    if record is not None:
        f.attrs[ATTRIBUTE] = json.dumps(record, sort_keys=True)


def read_provenance(f: h5py.File, path: str) -> dict | None:
    """The provenance recorded in ``f`` (None in files written before aogm recorded it);
    InputError naming ``path`` when it is not a JSON object."""
    return json_attr(f, ATTRIBUTE, path, ATTRIBUTE, dict, required=False)
