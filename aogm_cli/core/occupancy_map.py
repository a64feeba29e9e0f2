"""A finished occupancy map in memory: probabilities, observed mask and each mode's layers. Domain
type only (no file I/O); ``aogm_cli.io.mapfile`` reads and writes it as HDF5."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from aogm_cli.core.grid import GridSpec

MODES = ("standard", "em", "adaptive")


@dataclass
class OccupancyMap:
    """A finished map: probabilities and observed mask on ``grid``, plus mode-specific layers."""

    grid: GridSpec
    probability: np.ndarray  # (H, W) float32, 0.5 where unobserved
    observed: np.ndarray  # (H, W) bool
    mode: str
    params: dict = field(default_factory=dict)
    runtime_s: float = 0.0
    source_log: str = ""
    log_odds: np.ndarray | None = None  # standard, adaptive
    occupied: np.ndarray | None = None  # em, adaptive
    clusters: np.ndarray | None = None  # adaptive
    stats: dict = field(default_factory=dict)
    learned: dict | None = None  # what the map learned from its log, apart from params (``mapping.learned``)
    plan: dict | None = None  # what the map decided before its first stage (``mapping.plan``)
