"""The budget of one run: ``Limits`` on its memory, work and threads (defaults sized for a 2-core, 24 GB machine),
and ``check``, which refuses an ``Estimate`` over them before any work with an ``InputError`` saying
what the run would need; ``in_parts`` runs parts of a job on the threads; ``parse_size`` reads sizes such as 16G."""

from __future__ import annotations

import concurrent.futures
import math
import os
import re
import threading
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
from dataclasses import dataclass

from aogm_cli.core.errors import InputError

GB = 1e9
DEFAULT_MAX_MEMORY = 16 * GB  # bytes
# about an hour of work on this machine, by unit: simulate casts ~2e7 sub-rays (bounces counted)
# per second, the mappers make ~1.4e8 cone cell updates per second (EM counted at max_sweeps)
DEFAULT_MAX_WORK = {"ray casts": 7e10, "cell updates": 5e11}

_UNITS = {"": 1.0, "B": 1.0, "K": 1e3, "M": 1e6, "G": 1e9, "T": 1e12, "P": 1e15}


@dataclass(frozen=True)
class Limits:
    max_memory: float = DEFAULT_MAX_MEMORY
    max_work: float | None = None  # None: DEFAULT_MAX_WORK of the estimate's unit
    threads: int | None = None  # threads EM's sweeps and parts (``in_parts``) may use; None: every core this process may run on

    def work_limit(self, unit: str) -> float:
        return float(self.max_work) if self.max_work is not None else DEFAULT_MAX_WORK[unit]

    def thread_count(self) -> int:
        if self.threads is not None:
            return max(1, int(self.threads))
        try:
            return len(os.sched_getaffinity(0))
        except (AttributeError, OSError):  # not Linux
            return os.cpu_count() or 1


@dataclass(frozen=True)
class Estimate:
    """What a run would need: ``memory`` (bytes) and ``work`` (``unit``, e.g. ray casts)."""

    what: str  # "simulating this world", "the em map of this log"
    memory: float
    work: float
    unit: str
    detail: str = ""  # what the estimate is made of, for the message
    advice: str = ""  # besides a higher --max-memory, what makes it fit ("a coarser --resolution ...")


_active = Limits()


def active_limits() -> Limits:
    """The limits in force (the defaults unless a command set others with ``using``)."""
    return _active


@contextmanager
def using(limits: Limits):
    """Make ``limits`` the ones in force for the block (worker processes forked inside inherit them)."""
    global _active
    previous, _active = _active, limits
    try:
        yield limits
    finally:
        _active = previous


def in_parts(parts: int, work: Callable[[int, threading.Event], object]) -> list:
    """``[work(k, stop) for k in range(parts)]``, the parts on up to ``Limits.threads`` threads (the
    limits in force). ``work`` returns to Python now and then and ends early once ``stop`` is set:
    the main thread waits in steps of 0.05 s, so a signal's handler runs (``core.interrupts``), and
    sets it when that raises. The results come in part order."""
    threads = min(active_limits().thread_count(), parts)
    stop = threading.Event()
    if threads <= 1:
        return [work(k, stop) for k in range(parts)]
    futures = [_pool(threads).submit(work, k, stop) for k in range(parts)]
    try:
        return _results_waking(futures, stop)
    except BaseException:
        concurrent.futures.wait(futures)  # stop is set: the parts end at their next pause, none outlives the call
        raise


# the pools of ``in_parts``, by (process, threads): kept for the process, as starting the threads
# cost each call about 0.7 ms (an adaptive map of a seed world makes about seven such calls); made
# again in a forked child, whose copy of its parent's pool has no threads
_pools: dict[tuple[int, int], ThreadPoolExecutor] = {}
_pools_lock = threading.Lock()


def _pool(threads: int) -> ThreadPoolExecutor:
    key = (os.getpid(), threads)
    with _pools_lock:
        if key not in _pools:
            _pools[key] = ThreadPoolExecutor(threads, thread_name_prefix="aogm-part")
        return _pools[key]


def _results_waking(futures: list, stop: threading.Event) -> list:
    """The results of ``futures`` in their order, the main thread waking every 0.05 s while it
    waits, so that a signal's handler runs (``core.interrupts``); ``stop`` is set on the way out,
    so that the other tasks end at their next pause when the wait raised."""
    try:
        while concurrent.futures.wait(futures, timeout=0.05).not_done:
            pass
    finally:
        stop.set()
    return [f.result() for f in futures]


def parse_size(text: str) -> float:
    """Bytes of a size such as ``16G``, ``16GB``, ``500 MB``, ``1.5T`` or ``2000000`` (units of 1000)."""
    m = re.fullmatch(r"\s*([0-9]*\.?[0-9]+(?:[eE][+-]?[0-9]+)?)\s*([kKmMgGtTpP]?)(?:i?[bB])?\s*", str(text))
    if not m:
        raise ValueError(f"expected a size such as 16G, 500MB or 2e9, got {text!r}")
    value = float(m.group(1)) * _UNITS[m.group(2).upper()]
    if not (math.isfinite(value) and value > 0):
        raise ValueError(f"expected a positive, finite size, got {text!r}")
    return value


def format_bytes(n: float) -> str:
    """``3.2 TB``, ``16 GB``, ``512 MB`` (units of 1000)."""
    if not math.isfinite(n):
        return "an unbounded amount"
    for unit, size in (("PB", 1e15), ("TB", 1e12), ("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if n >= size:
            return f"{n / size:.2g} {unit}" if n / size < 10 else f"{n / size:.0f} {unit}"
    return f"{n:.0f} B"


def format_count(n: float) -> str:
    return "an unbounded number" if not math.isfinite(n) else (f"{n:.2g}" if n >= 1e4 else f"{n:.0f}")


def check(estimate: Estimate, limits: Limits | None = None, *, file: str | None = None) -> None:
    """Raise an ``InputError`` (exit 2) when ``estimate`` exceeds ``limits`` (default: ``active_limits()``)."""
    limits = limits or active_limits()
    what = f"{estimate.what} ({estimate.detail})" if estimate.detail else estimate.what
    if not estimate.memory <= limits.max_memory:
        raise InputError(
            f"{what} would need about {format_bytes(estimate.memory)} of memory "
            f"(limit {format_bytes(limits.max_memory)}); use --max-memory to raise the limit"
            + (f", or {estimate.advice}" if estimate.advice else ""), file=file)
    max_work = limits.work_limit(estimate.unit)
    if not estimate.work <= max_work:
        hours = estimate.work / DEFAULT_MAX_WORK[estimate.unit]
        hours_text = f", about {hours:.2g} h here" if math.isfinite(hours) and hours >= 0.5 else ""
        raise InputError(
            f"{what} would take about {format_count(estimate.work)} {estimate.unit}{hours_text} "
            f"(limit {format_count(max_work)}); use --max-work to raise the limit", file=file)
