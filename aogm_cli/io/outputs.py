"""The one check of a command's output paths, made before any work starts: no output is an input
or another output, each lies in an existing writable folder, none is an existing folder.
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from pathlib import Path

from aogm_cli.core.errors import InputError

PathLike = str | Path
Named = tuple[str | None, PathLike | None]  # (option that names the path, the path)


class _Seen:
    """Paths already taken (inputs, earlier outputs): by real path and, if they exist, by inode."""

    def __init__(self):
        self.real: dict[str, str] = {}
        self.stat: list[tuple[os.stat_result, str]] = []

    def add(self, path: PathLike, what: str) -> None:
        self.real.setdefault(os.path.realpath(path), what)
        if os.path.exists(path):
            self.stat.append((os.stat(path), what))

    def find(self, path: PathLike) -> str | None:
        """What ``path`` already is (same real path, or the same file by hard or symbolic link)."""
        what = self.real.get(os.path.realpath(path))
        if what is None and os.path.exists(path):
            st = os.stat(path)
            what = next((w for s, w in self.stat if os.path.samestat(s, st)), None)
        return what


def _folder(path: Path) -> Path:
    return path.parent if str(path.parent) else Path(".")


def _check_folder(folder: Path, path: Path, option: str | None) -> None:
    if not folder.exists():
        raise InputError(f"the output folder {str(folder)!r} does not exist", file=str(path), key=option)
    if not folder.is_dir():
        raise InputError(f"{str(folder)!r} is not a folder", file=str(path), key=option)
    if not os.access(folder, os.W_OK):
        raise InputError(f"the output folder {str(folder)!r} is not writable", file=str(path), key=option)


def _check_created_folder(folder: Path, option: str | None) -> None:
    """A folder the command makes (``mkdir -p``): a writable folder already, or one to make in one."""
    if folder.exists() and not folder.is_dir():
        raise InputError("exists and is not a folder", file=str(folder), key=option)
    existing = folder
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if not existing.is_dir() or not os.access(existing, os.W_OK):
        raise InputError(f"cannot be made: {str(existing)!r} is not a writable folder", file=str(folder), key=option)


def resolve_outputs(
    inputs: Iterable[PathLike | None], outputs: Iterable[Named], made_folders: Iterable[Named] = ()
) -> list[Path]:
    """Check every output of a command against all its inputs and the other outputs; return the
    outputs as paths. ``None`` entries are skipped. ``made_folders`` are folders the command
    creates (``compare --maps-dir``); outputs inside them need not have a folder yet.

    Raises InputError (exit 2) naming the output path and its option when an output is one of
    the inputs or another output (same real path, or the same file through a link), when its
    folder is missing, not a folder or not writable, or when it is an existing folder.
    """
    taken = _Seen()
    for inp in inputs:
        if inp is not None:
            taken.add(inp, f"the input {inp}")
    made = set()
    for option, folder in made_folders:
        if folder is not None:
            _check_created_folder(Path(folder), option)
            made.add(os.path.realpath(folder))
    resolved = []
    for option, out in outputs:
        if out is None:
            continue
        path = Path(out)
        if path.is_dir():
            raise InputError("is a folder; expected a file to write", file=str(path), key=option)
        folder = _folder(path)
        if os.path.realpath(folder) not in made:
            _check_folder(folder, path, option)
        what = taken.find(path)
        if what is not None:
            raise InputError(f"is also {what}; choose another output", file=str(path), key=option)
        taken.add(path, f"the output of {option}" if option else "another output")
        resolved.append(path)
    return resolved
