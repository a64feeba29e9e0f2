"""What blocks a planner in a map of a simulated log: cells the map shows occupied on free floor, or free floor
it leaves unobserved (docs/algorithms.md, "The lobe that hears": office_doors theta0 12).

    python bench/block_causes.py LOG.h5 MAP.h5 [LOG.h5 MAP.h5 ...]

Per map: ``block`` (``evaluation.planner.planner_metrics``, a 0.2 m disk), and the block left when the
cells it shows occupied (p > 0.5) on truth-free floor are made free, when its unobserved truth-free cells
are, and when both are; and how many of those occupied cells EM holds occupied (``/map/occupied``) and how
many the view shows occupied where EM holds them free (the standard map's estimate at cells EM leaves
undecided, ``em.hidden: unobserved``).
"""

from __future__ import annotations

import argparse

import h5py
import numpy as np

from aogm_cli.evaluation.planner import (
    ROBOT_RADIUS,
    drivable,
    map_free,
    near_trajectory,
    reachable,
    truth_reach,
)
from aogm_cli.io.logfile import LogReader
from aogm_cli.io.mapfile import read_map_file


def causes(log_path: str, map_path: str) -> str:
    with LogReader(log_path) as reader:
        log = reader.read()
    m = read_map_file(map_path)
    grid, truth, poses = m.grid, np.asarray(log.truth.occupancy), log.poses()
    in_truth = truth_reach(grid, truth, poses, ROBOT_RADIUS) & m.observed
    free_floor = truth == 0
    shown_occupied = free_floor & m.observed & (m.probability > 0.5)
    unobserved = free_floor & ~m.observed

    def block(extra_free: np.ndarray) -> float:
        drive = drivable(map_free(m.probability, m.observed) | extra_free, grid.resolution, ROBOT_RADIUS)
        return float(np.sum(in_truth & ~reachable(drive, near_trajectory(grid, poses))) / in_truth.sum())

    with h5py.File(map_path, "r") as f:
        em_occupied = f["map/occupied"][...].astype(bool) if "map/occupied" in f else np.zeros(grid.shape, bool)
    nothing = np.zeros(grid.shape, bool)
    return (f"{map_path}: block {block(nothing):.3f}; occupied cells freed {block(shown_occupied):.3f}, unobserved "
            f"freed {block(unobserved):.3f}, both {block(shown_occupied | unobserved):.3f}; occupied on free floor "
            f"{int(shown_occupied.sum())}: EM's {int((shown_occupied & em_occupied).sum())}, "
            f"the view's where EM holds free {int((shown_occupied & ~em_occupied).sum())}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("pairs", nargs="+", help="LOG.h5 MAP.h5, repeated")
    args = parser.parse_args()
    if len(args.pairs) % 2:
        parser.error("expected LOG.h5 MAP.h5 pairs")
    for log_path, map_path in zip(args.pairs[::2], args.pairs[1::2], strict=True):
        print(causes(log_path, map_path))


if __name__ == "__main__":
    main()
