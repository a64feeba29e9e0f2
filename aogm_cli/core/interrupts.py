"""SIGINT, SIGTERM and SIGHUP: remove the run's temporaries, end its workers, one line on stderr,
exit 128 + N. Stdlib only, so that ``aogm`` installs the handlers before any heavy import.
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys
from collections.abc import Callable, Iterator

SIGNALS = tuple(getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, name))
PR_SET_PDEATHSIG = 1  # linux/prctl.h

_cleanups: list[Callable[[], None]] = []  # run by the handler before it exits (io.atomic's temporaries)
_owner: list[int] = []  # the pid that installed the handlers (a forked worker inherits them)
_deferred: list[int] = []  # > 0: a commit is under way; signals wait for its end
_pending: list[int] = []


def on_interrupt(cleanup: Callable[[], None]) -> None:
    """Run ``cleanup`` (fast, never raising) when a signal ends the run."""
    if cleanup not in _cleanups:
        _cleanups.append(cleanup)


def exit_status(signum: int) -> int:
    return 128 + int(signum)


def _end(signum: int) -> None:
    """Clean up and leave now: no exception unwinds through numba, HDF5 or matplotlib frames
    (a KeyboardInterrupt raised inside numba's dispatch was measured to crash with SIGSEGV)."""
    for sig in SIGNALS:
        signal.signal(sig, signal.SIG_IGN)  # a second signal cannot interrupt the clean-up
    for cleanup in _cleanups:
        with contextlib.suppress(Exception):
            cleanup()
    end_workers()
    if _owner and _owner[0] == os.getpid():  # a worker forked before its initializer stays silent
        line = f"aogm: interrupted ({signal.Signals(signum).name})\n"
        with contextlib.suppress(OSError):
            os.write(2, (("\n" if os.isatty(2) else "") + line).encode())
    os._exit(exit_status(signum))


def _handler(signum: int, frame) -> None:
    if _deferred:
        _pending.append(signum)
        return
    _end(signum)


def install() -> dict[int, object]:
    """Install the handlers; return the previous ones (for ``restore``)."""
    previous = {sig: signal.getsignal(sig) for sig in SIGNALS}
    _owner[:] = [os.getpid()]
    for sig in SIGNALS:
        signal.signal(sig, _handler)
    return previous


def installed() -> bool:
    return bool(SIGNALS) and signal.getsignal(SIGNALS[0]) is _handler


def restore(previous: dict[int, object]) -> None:
    for sig, handler in previous.items():
        signal.signal(sig, handler)


@contextlib.contextmanager
def deferred() -> Iterator[None]:
    """Hold a signal until the block ends (the renames of a commit), then act on it."""
    _deferred.append(1)
    try:
        yield
    finally:
        _deferred.pop()
        if not _deferred and _pending:
            _end(_pending[0])


def end_workers() -> None:
    """Terminate the multiprocessing children of this process (compare's workers)."""
    mp = sys.modules.get("multiprocessing")
    if mp is None:
        return
    for child in mp.active_children():
        with contextlib.suppress(Exception):
            child.terminate()


def worker_init(parent: int) -> None:
    """Pool initializer: the parent handles SIGINT (ignored here), SIGTERM and SIGHUP kill, and
    the worker gets SIGTERM when its parent dies, even by SIGKILL (Linux prctl)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    for sig in SIGNALS:
        if sig != signal.SIGINT:
            signal.signal(sig, signal.SIG_DFL)
    if sys.platform.startswith("linux"):
        import ctypes

        with contextlib.suppress(OSError, AttributeError):
            ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, int(signal.SIGTERM), 0, 0, 0)
    if os.getppid() != parent:  # the parent died before prctl took effect
        os._exit(exit_status(signal.SIGTERM))
