"""Atomic output files: write to a temporary name in the target folder, rename when complete.

A failed command therefore never leaves a partial output file, and never touches its inputs.
``atomic_output`` makes one file; ``write_files_atomically`` writes several, all or none.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path

from aogm_cli.core.errors import InputError
from aogm_cli.io.outputs import resolve_outputs


@contextlib.contextmanager
def atomic_output(path: str | Path, inputs: tuple[str | Path, ...] = ()) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; on success rename it to ``path``, else delete it.

    ``path`` is checked by ``outputs.resolve_outputs`` against ``inputs`` (files the command
    reads); commands run that check on all their outputs before any work, this is the last guard.
    """
    path = resolve_outputs(inputs, [(None, path)])[0]
    tmp_path = _temporary_beside(path)
    try:
        yield tmp_path
        os.replace(tmp_path, path)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp_path.unlink()
        raise


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _temporary_beside(path: Path) -> Path:
    """A new empty file in ``path``'s folder, named ``.NAME.XXXX.tmp``, with the usual permissions."""
    folder = path.parent if str(path.parent) else Path(".")
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=folder)
    os.close(fd)
    os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes 0600; outputs get the usual permissions
    return Path(tmp)


def write_files_atomically(outputs: list[tuple[Path, bytes]]) -> None:
    """Write every (path, content) under a temporary name in its folder, then rename them all;
    on any failure no temporary file is left and no output is renamed into place."""
    resolve_outputs((), [(None, target) for target, _ in outputs])
    temps: list[tuple[Path, Path]] = []
    try:
        for target, content in outputs:
            temp = _temporary_beside(Path(target))
            temps.append((temp, Path(target)))
            with open(temp, "wb") as fh:
                fh.write(content)
                fh.flush()
                os.fsync(fh.fileno())
        while temps:
            temp, target = temps[0]
            os.replace(temp, target)
            temps.pop(0)
    except OSError as exc:
        raise InputError(f"cannot write the output: {exc}", file=str(outputs[0][0].parent)) from None
    finally:
        for temp, _ in temps:
            with contextlib.suppress(OSError):
                temp.unlink()
