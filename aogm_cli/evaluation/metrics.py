"""Map quality against simulated truth: accuracy, occupied precision/recall/F1, Brier, the expected
calibration error, checks, whatever made the map: it takes probabilities, the observed mask and the
truth, as CONTRACT.md ("Metrics") defines them."""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from aogm_cli.core.grid import GridSpec
from aogm_cli.core.log import check_kind
from aogm_cli.evaluation.planner import EIGHT, drivable, map_free

ECE_BINS = 10  # equal-width bins of the probability for ``expected_calibration_error``


def expected_calibration_error(probability, truth, bins: int = ECE_BINS) -> float:
    """Expected calibration error of the probabilities ``probability`` of cells whose truth is
    ``truth`` (1 occupied, 0 free; arrays of one shape, typically the observed cells): the cells
    fall into ``bins`` equal-width bins of their probability, [0, 1/bins), [1/bins, 2/bins), ...,
    [1 - 1/bins, 1] (the last one closed), and

        ECE = sum over bins b of (n_b / n) * |mean probability in b - share of b truly occupied|,

    n_b the cells in bin b, n all of them. 0 when every probability is the frequency with which
    cells given it are occupied; NaN without cells.

    Examples
    --------
    >>> expected_calibration_error([0.25, 0.25, 0.75, 0.75], [0, 0, 1, 0])  # bins 2 and 7: (0.25 + 0.25) / 2
    0.25
    """
    p = np.asarray(probability, dtype=np.float64).reshape(-1)
    t = np.asarray(truth, dtype=np.float64).reshape(-1)
    if p.size == 0:
        return float("nan")
    b = np.minimum((p * bins).astype(np.int64), bins - 1)
    gap = np.bincount(b, weights=p - t, minlength=bins)  # n_b * (mean probability - share occupied)
    return float(np.sum(np.abs(gap)) / p.size)


def map_metrics(probability: np.ndarray, observed: np.ndarray, truth: np.ndarray) -> dict:
    """Accuracy, occupied precision/recall/F1, Brier and the expected calibration error
    (``expected_calibration_error``) over observed cells (occupied: p > 0.5)."""
    obs = np.asarray(observed, dtype=bool)
    p = np.asarray(probability, dtype=np.float64)[obs]
    t = np.asarray(truth)[obs].astype(bool)
    n = int(obs.sum())
    if n == 0:
        return {"accuracy": float("nan"), "occupied_precision": float("nan"), "occupied_recall": float("nan"),
                "occupied_f1": float("nan"), "brier": float("nan"), "ece": float("nan"), "observed_cells": 0}
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
        "ece": expected_calibration_error(p, t),
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
