"""Outputs all or nothing: ``write_files_atomically`` writes every file of a command beside its
target as ``.NAME.aogm-<pid>-<tag>.tmp``, then renames them all; live temporaries are registered
so that an error, a signal or the exit removes them, and those of a killed run are removed later.
"""

from __future__ import annotations

import atexit
import contextlib
import os
import re
import secrets
import time
from collections.abc import Iterator
from pathlib import Path

from aogm_cli.core import interrupts
from aogm_cli.core.errors import OutputError
from aogm_cli.io.outputs import resolve_outputs

RUN_START = time.time()  # temporaries of dead processes older than this are stale
TEMPORARY = re.compile(r"^\.(?P<name>.+)\.aogm-(?P<pid>\d+)-(?P<tag>[0-9a-f]+)\.tmp$")
_live: dict[Path, int] = {}  # temporary -> pid of the process that made it


def remove_temporaries() -> None:
    """Remove every live temporary this process made (at exit, on a signal, after an error)."""
    for temp, pid in list(_live.items()):
        if pid == os.getpid():
            _discard(temp)


atexit.register(remove_temporaries)
interrupts.on_interrupt(remove_temporaries)


def _discard(temp: Path) -> None:
    with contextlib.suppress(OSError):
        os.unlink(temp)
    _live.pop(temp, None)


def _folder(path: Path) -> Path:
    return path.parent if str(path.parent) else Path(".")


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # EPERM: someone else's process
        return True
    return True


def remove_stale_temporaries(path: Path) -> list[Path]:
    """Remove the temporaries of ``path`` left by runs that were killed (SIGKILL, power loss):
    named like ours, their pid no longer alive and older than this run's start."""
    removed = []
    with contextlib.suppress(OSError), os.scandir(_folder(path)) as it:
        for entry in it:
            m = TEMPORARY.match(entry.name)
            if not m or m["name"] != path.name or int(m["pid"]) in (0, os.getpid()):
                continue
            with contextlib.suppress(OSError):
                if entry.stat(follow_symlinks=False).st_mtime < RUN_START and not _alive(int(m["pid"])):
                    os.unlink(entry.path)
                    removed.append(Path(entry.path))
    return removed


def _temporary_beside(path: Path) -> Path:
    """A new empty file ``.NAME.aogm-<pid>-<tag>.tmp`` in ``path``'s folder (registered before it
    exists), with the usual permissions (0666 less the umask)."""
    temp = _folder(path) / f".{path.name}.aogm-{os.getpid()}-{secrets.token_hex(4)}.tmp"
    _live[temp] = os.getpid()
    try:
        os.close(os.open(temp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_CLOEXEC", 0), 0o666))
    except BaseException:
        _live.pop(temp, None)
        raise
    return temp


def _reason(exc: OSError) -> str:
    """The OS's message, as ``no space left on device``."""
    text = os.strerror(exc.errno) if exc.errno else (exc.strerror or str(exc))
    return text[:1].lower() + text[1:] if text[1:2].islower() else text


@contextlib.contextmanager
def _naming(target: Path) -> Iterator[None]:
    """OSError -> OutputError naming ``target`` (exit status 1)."""
    try:
        yield
    except OSError as exc:
        raise OutputError(_reason(exc), file=str(target)) from None


def _write(temp: Path, content: bytes) -> None:
    with open(temp, "r+b") as fh:
        fh.write(content)
        fh.flush()
        os.fsync(fh.fileno())


def _backup(target: Path) -> Path | None:
    """A hard link to an existing ``target``, so that a failed commit can put it back."""
    if not os.path.lexists(target):
        return None
    backup = _folder(target) / f".{target.name}.aogm-{os.getpid()}-{secrets.token_hex(4)}.tmp"
    _live[backup] = os.getpid()
    try:
        os.link(target, backup, follow_symlinks=False)
    except OSError:
        _live.pop(backup, None)
        return None
    return backup


def _commit(pairs: list[tuple[Path, Path]]) -> None:
    """Rename every temporary onto its target, signals held until the end; when one rename
    fails, the targets renamed so far are put back as they were."""
    done: list[tuple[Path | None, Path]] = []
    with interrupts.deferred():
        try:
            for temp, target in pairs:
                with _naming(target):
                    backup = _backup(target)
                    os.replace(temp, target)
                _live.pop(temp, None)
                done.append((backup, target))
        except BaseException:
            for backup, target in reversed(done):
                with contextlib.suppress(OSError):
                    os.replace(backup, target) if backup else os.unlink(target)
                _live.pop(backup, None)
            raise
        finally:
            for backup, _ in done:
                if backup is not None:
                    _discard(backup)


def write_files_atomically(outputs: list[tuple[Path, bytes]]) -> None:
    """Write every (path, content) under a temporary name in its folder, then rename them all:
    on any failure (OutputError naming the file, exit 1) no temporary is left and no output
    renamed into place. Stale temporaries of the targets (``remove_stale_temporaries``) go first."""
    targets = resolve_outputs((), [(None, target) for target, _ in outputs])
    temps: list[Path] = []
    try:
        for target, (_, content) in zip(targets, outputs, strict=True):
            remove_stale_temporaries(target)
            with _naming(target):
                temps.append(_temporary_beside(target))
                _write(temps[-1], content)
        _commit(list(zip(temps, targets, strict=True)))
    finally:
        for temp in temps:
            if temp in _live:
                _discard(temp)
