"""Where a run's tasks execute, as ``concurrent.futures`` executors: this process, a local process pool
(``--jobs N``) or a Dask cluster (``--scheduler ADDRESS``). Each task's outcome comes back on its own:
a failed task (bad input, a lost worker) is a ``Failure`` and the others still finish."""

from __future__ import annotations

import contextlib
import os
from collections.abc import Callable, Hashable, Iterator
from dataclasses import dataclass

from aogm_cli.core.errors import InputError
from aogm_cli.core.interrupts import end_workers, worker_init

SCHEDULER_ENV = "AOGM_SCHEDULER"
DASK_MISSING = "needs Dask distributed, which is not installed: pip install aogm[dask] (or pip install \"dask[distributed]\")"


@dataclass(frozen=True)
class Task:
    """One call ``function(*args)`` run as a unit of work; ``key`` names it in the outcome."""

    key: Hashable
    function: Callable
    args: tuple


@dataclass(frozen=True)
class Failure:
    """A task that raised: the error's text and whether it was bad input (InputError)."""

    key: Hashable
    message: str
    bad_input: bool


def failure_status(failures: list[Failure]) -> int:
    """The exit status of a run with ``failures``: 0 without any, 2 when every one was bad input
    (an InputError raised in the task), else 1 (a lost worker, an OS error, a bug)."""
    if not failures:
        return 0
    return 2 if all(f.bad_input for f in failures) else 1


def _failure(key: Hashable, exc: BaseException) -> Failure:
    text = str(exc) or exc.__class__.__name__
    if isinstance(exc, InputError):
        return Failure(key, text, True)
    return Failure(key, f"{exc.__class__.__name__}: {text}", False)


@contextlib.contextmanager
def dask_executor(address: str) -> Iterator:
    """``distributed.Client(address).get_executor()`` (tasks not deduplicated: ``pure=False``);
    InputError (key --scheduler) when Dask is not installed or the scheduler cannot be reached."""
    try:
        import distributed
    except ImportError:
        raise InputError(DASK_MISSING, key="--scheduler") from None
    try:
        client = distributed.Client(address, timeout=30, set_as_default=False)
    except (OSError, TimeoutError, ValueError) as exc:
        raise InputError(f"cannot reach the Dask scheduler at {address!r} ({exc.__class__.__name__}: {exc}); "
                         "expected the address of a running scheduler, e.g. tcp://host:8786", key="--scheduler") from None
    try:
        yield client.get_executor(pure=False)
    finally:
        with contextlib.suppress(Exception):
            client.close()


def run_tasks(tasks: list[Task], jobs: int = 1, scheduler: str | None = None,
              on_done: Callable[[Hashable, object], None] | None = None) -> tuple[dict, list[Failure]]:
    """Run every task and return ({key: result}, failures in order of completion).

    ``scheduler`` (a Dask scheduler's address): every task on that cluster; else with ``jobs`` > 1
    in a local process pool (workers end with this process, ``core.interrupts``); else here, one
    after another. ``on_done(key, result)`` is called in this process as each task succeeds.
    A local worker that dies breaks its pool: the tasks it took down are run again, each in a
    pool of its own, so that only the one that kills its worker fails (Dask reschedules by itself).
    A signal or an interrupt cancels the tasks not yet started and ends the local workers."""
    results: dict = {}
    failures: list[Failure] = []

    def record(key, outcome: Callable[[], object]) -> None:
        try:
            value = outcome()
        except Exception as exc:  # noqa: BLE001 - one task's failure, reported per task
            failures.append(_failure(key, exc))
            return
        results[key] = value
        if on_done:
            on_done(key, value)

    if not tasks:
        return results, failures
    if scheduler is None and (jobs <= 1 or len(tasks) <= 1):
        for t in tasks:
            record(t.key, lambda t=t: t.function(*t.args))
        return results, failures
    if scheduler is not None:
        with dask_executor(scheduler) as executor:
            _run_on(executor, tasks, record)
        return results, failures
    from concurrent.futures.process import BrokenProcessPool

    broken: list = []  # keys of the tasks a lost worker took down with the pool

    def record_local(key, outcome: Callable[[], object]) -> None:
        def checked():
            try:
                return outcome()
            except BrokenProcessPool:
                broken.append(key)
                raise
        record(key, checked)

    _run_in_pool(tasks, min(jobs, len(tasks)), record_local)
    if broken:  # a worker died (killed, out of memory): each of those tasks again in a pool of its own
        again = [t for t in tasks if t.key in set(broken)]
        failures[:] = [f for f in failures if f.key not in set(broken)]
        for t in again:
            _run_in_pool([t], 1, record)
    return results, failures


def _run_in_pool(tasks: list[Task], workers: int, record: Callable) -> None:
    """The tasks in a local process pool of ``workers`` (``core.interrupts.worker_init``)."""
    from concurrent.futures import ProcessPoolExecutor

    pool = ProcessPoolExecutor(max_workers=workers, initializer=worker_init, initargs=(os.getpid(),))
    try:
        _run_on(pool, tasks, record)
    except BaseException:
        pool.shutdown(wait=False, cancel_futures=True)
        end_workers()  # the tasks still running are not waited for
        raise
    pool.shutdown()


def _run_on(executor, tasks: list[Task], record: Callable) -> None:
    """Submit every task to a ``concurrent.futures`` executor and record each outcome as it comes."""
    from concurrent.futures import as_completed

    futures = {executor.submit(t.function, *t.args): t.key for t in tasks}
    try:
        for fut in as_completed(futures):
            record(futures[fut], fut.result)
    except BaseException:
        for fut in futures:
            fut.cancel()
        raise
