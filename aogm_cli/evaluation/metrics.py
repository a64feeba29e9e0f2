"""Map quality against simulated truth: accuracy, occupied precision/recall/F1, Brier, checks, whatever
made the map: it takes probabilities, the observed mask and the truth, as CONTRACT.md ("Metrics") defines them."""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from aogm_cli.core.grid import GridSpec
from aogm_cli.core.log import check_kind
from aogm_cli.evaluation.planner import EIGHT, drivable, map_free


def map_metrics(probability: np.ndarray, observed: np.ndarray, truth: np.ndarray) -> dict:
    """Accuracy, occupied precision/recall/F1 and Brier over observed cells (occupied: p > 0.5)."""
    obs = np.asarray(observed, dtype=bool)
    p = np.asarray(probability, dtype=np.float64)[obs]
    t = np.asarray(truth)[obs].astype(bool)
    n = int(obs.sum())
    if n == 0:
        return {"accuracy": float("nan"), "occupied_precision": float("nan"), "occupied_recall": float("nan"),
                "occupied_f1": float("nan"), "brier": float("nan"), "observed_cells": 0}
    believed = p > 0.5
    tp = int(np.sum(believed & t))
    fp = int(np.sum(believed & ~t))
    fn = int(np.sum(~believed & t))
    precision = tp / (tp + fp) if tp + fp else 0.0
    recall = tp / (tp + fn) if tp + fn else 0.0
    f1 = 2 * precision * recall / (precision + recall) if precision + recall else 0.0
    return {
        "accuracy": float(np.mean(believed == t)),
        "occupied_precision": float(precision),
        "occupied_recall": float(recall),
        "occupied_f1": float(f1),
        "brier": float(np.mean((p - t) ** 2)),
        "observed_cells": n,
    }


def passable(grid: GridSpec, probability, observed, start, goal, robot_radius: float) -> bool:
    """Is there an 8-connected path from ``start`` to ``goal`` (world x, y) through cells that are
    observed, believed free (p < 0.5) and farther than ``robot_radius`` from every cell that is not?
    Cells outside the grid count as not free."""
    ok = drivable(map_free(probability, observed), grid.resolution, robot_radius)
    r0, c0 = (int(v) for v in grid.world_to_cell(*start))
    r1, c1 = (int(v) for v in grid.world_to_cell(*goal))
    if not (grid.contains(r0, c0) and grid.contains(r1, c1)) or not (ok[r0, c0] and ok[r1, c1]):
        return False
    labels, _ = ndimage.label(ok, structure=EIGHT)
    return bool(labels[r0, c0] == labels[r1, c1])


def run_checks(grid: GridSpec, probability, observed, checks) -> list[dict]:
    """Evaluate the world's checks (JSON dicts as in the world file) on a map: a ``passable``
    check passes when the path exists, a ``blocked`` one when it does not."""
    results = []
    for check in checks:
        kind = check_kind(check)
        p = check[kind]
        ok = passable(grid, probability, observed, p["from"], p["to"], float(p["robot_radius"]))
        results.append({"name": check["name"], "passed": ok == (kind == "passable")})
    return results


def evaluate(m, truth) -> dict:
    """All metrics of CONTRACT.md for map ``m`` (OccupancyMap) against ``truth`` (logfile.Truth)."""
    if m.grid.shape != truth.grid.shape:
        raise ValueError(f"map grid {m.grid.shape} does not match the truth grid {truth.grid.shape}")
    metrics = map_metrics(m.probability, m.observed, truth.occupancy)
    metrics["checks"] = run_checks(m.grid, m.probability, m.observed, truth.checks)
    return metrics
