"""The runner of a mode's stages: each ``Stage`` names the ``State`` fields it reads and writes; ``run_stages`` runs
them in order, checks both, skips a stage whose condition does not hold, and times each (reading left out)."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import NamedTuple

from aogm_cli.mapping.state import MADE, State


class Stage(NamedTuple):
    """One step of a mode: the state's fields it ``reads`` (must be there; "?": may be None) and ``writes``
    (no other may change), whether its seconds are mapping work, and when it runs (None: always)."""

    name: str
    run: Callable[[State], State]
    reads: tuple[str, ...] = ()
    writes: tuple[str, ...] = ()
    timed: bool = True
    when: Callable[[State], bool] | None = None


class StageError(RuntimeError):
    """A stage read a field no stage had written, or wrote one it does not declare."""


def lacks(field: str) -> Callable[[State], bool]:
    """Run only when ``field`` is missing: made once, and again after a stage took it away."""
    return lambda s: getattr(s, field) is None


def has(field: str) -> Callable[[State], bool]:
    """Run only when ``field`` holds something (EM's region: the adaptive mode may find no cluster)."""
    return lambda s: getattr(s, field) is not None


def run_stages(stages: tuple[Stage, ...], state: State, clock=time.perf_counter) -> tuple[State, dict]:
    """Run ``stages`` in order: (the last state, the seconds of each timed stage, reading left out)."""
    phases: dict[str, float] = {}
    for stage in stages:
        if stage.when is not None and not stage.when(state):
            continue
        missing = [f for f in stage.reads if not f.endswith("?") and getattr(state, f) is None]
        if missing:
            raise StageError(f"stage {stage.name!r} reads {', '.join(missing)}, which no stage before it wrote")
        t0, io0 = clock(), state.source.io_seconds
        after = stage.run(state)
        if stage.timed:
            phases[stage.name] = phases.get(stage.name, 0.0) + clock() - t0 - (after.source.io_seconds - io0)
        changed = [f for f in MADE if getattr(after, f) is not getattr(state, f) and f not in stage.writes]
        if changed or after.plan is not state.plan or after.params is not state.params:
            raise StageError(f"stage {stage.name!r} wrote {', '.join(changed) or 'what it was given'}, "
                             f"which it does not declare")
        state = after
    return state, phases
