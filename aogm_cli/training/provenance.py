"""Which logs a detector was trained on (its file's ``training_logs`` attribute): per training and
validation log its file, world, whether that world is a realistic variant (an ``errors:`` section),
its seed and its scan count."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from aogm_cli.core.log import SIMULATED_SOURCE, Log


def log_provenance(name: str, log: Log) -> dict:
    """JSON-able facts about one log: ``file`` (its file name), ``world`` (the ``name:`` of the
    world text in its truth, else the world file named by its source, else its source),
    ``realistic`` (the world has a non-empty ``errors:`` section; None without the world text),
    ``errors`` (that section's keys), ``seed``, ``scans`` and ``source``."""
    world = log.truth.world_mapping() if log.truth is not None else None
    errors = world.get("errors") if isinstance(world, dict) else None
    return {
        "file": Path(name).name if name else "",
        "world": _world_name(log, name),
        "realistic": bool(errors) if isinstance(world, dict) else None,
        "errors": sorted(map(str, errors)) if isinstance(errors, dict) else [],
        "seed": None if log.seed is None else int(log.seed),
        "scans": log.n_scans,
        "source": log.source,
    }


def training_logs(train: Sequence[tuple[str, Log]], validation: Sequence[tuple[str, Log]] = ()) -> dict:
    """``{"train": [...], "validation": [...]}``: ``log_provenance`` of each (name, log), in order."""
    return {
        "train": [log_provenance(name, log) for name, log in train],
        "validation": [log_provenance(name, log) for name, log in validation],
    }


def _world_name(log: Log, name: str) -> str:
    """The world's ``name:``, else the world file a simulated log's source names, else the source."""
    found = log.truth.world_name() if log.truth is not None else None
    if found:
        return found
    source = log.source
    if source.startswith(SIMULATED_SOURCE) and source[len(SIMULATED_SOURCE):].strip():
        return Path(source[len(SIMULATED_SOURCE):].strip()).stem
    return source or Path(name).stem
