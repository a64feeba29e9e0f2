"""Which logs a detector was trained on: per training and validation log its file, its world,
whether that world is a realistic variant (an ``errors:`` section), its seed and its scan count
(the detector file's ``training_logs`` attribute).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import yaml

from aogm_cli.core.log import Log

SIMULATED_SOURCE = "aogm simulate "  # the source of a simulated log: this, then the world file


def log_provenance(name: str, log: Log) -> dict:
    """JSON-able facts about one log: ``file`` (its file name), ``world`` (the ``name:`` of the
    world text in its truth, else the world file named by its source, else its source),
    ``realistic`` (the world has a non-empty ``errors:`` section; None without the world text),
    ``errors`` (that section's keys), ``seed``, ``scans`` and ``source``."""
    world = _world_of(log)
    errors = world.get("errors") if isinstance(world, dict) else None
    return {
        "file": Path(name).name if name else "",
        "world": _world_name(world, log.source, name),
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


def _world_of(log: Log):
    """The world file's YAML in the log's truth, parsed; None without it (or when it is not YAML)."""
    text = log.truth.world if log.truth is not None else ""
    if not text:
        return None
    try:
        return yaml.safe_load(text)
    except yaml.YAMLError:
        return None


def _world_name(world, source: str, name: str) -> str:
    if isinstance(world, dict) and isinstance(world.get("name"), str) and world["name"].strip():
        return world["name"].strip()
    if source.startswith(SIMULATED_SOURCE) and source[len(SIMULATED_SOURCE):].strip():
        return Path(source[len(SIMULATED_SOURCE):].strip()).stem
    return source or Path(name).stem
