"""What blocks a planner in a map of a simulated log: cells the map shows occupied on free floor, or free floor
it leaves unobserved (docs/algorithms.md, "The lobe that hears": office_doors theta0 12); with ``--leak``, what
it leaks through (worlds/README.md, the Pioneer worlds).

    python bench/block_causes.py [--leak [--region X0,X1,Y0,Y1]] LOG.h5 MAP.h5 [LOG.h5 MAP.h5 ...]

Per map: ``block`` (``evaluation.planner.planner_metrics``, a 0.2 m disk), and the block left when the
cells it shows occupied (p > 0.5) on truth-free floor are made free, when its unobserved truth-free cells
are, and when both are; and how many of those occupied cells EM holds occupied (``/map/occupied``) and how
many the view shows occupied where EM holds them free (the standard map's estimate at cells EM leaves
undecided, ``em.hidden: unobserved``). With ``--leak``: ``leak``, and the true wall cells the map shows free
within ``LEAK_NEAR`` of a cell the planner reaches beyond the truth's reach, with how many of them are walls
(log-odds > 0) in the em map's standard map and how many have a surface normal (``beam_model.surfaces``: some
reading echoed from them head-on enough to tell their direction), both as the map's own stages made them;
with ``--region``, how many leaked cells lie in that box (x0, x1, y0, y1 in metres: a glass cabinet, a room).
"""

from __future__ import annotations

import argparse

import h5py
import numpy as np

import aogm_cli
from aogm_cli.evaluation.planner import (
    ROBOT_RADIUS,
    drivable,
    map_free,
    map_reach,
    near_trajectory,
    reachable,
    truth_reach,
)
from aogm_cli.io.logfile import LogReader
from aogm_cli.io.mapfile import read_map_file
from aogm_cli.map_files import sensor_model
from aogm_cli.mapping import beam_model as B
from aogm_cli.mapping.modes import resolved_params, state_before
from aogm_cli.mapping.params import MapParams

LEAK_NEAR = 0.3  # m: a wall cell shown free this close to a leaked cell is one the leak goes through


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


def region_cells(grid, region: tuple[float, float, float, float]) -> np.ndarray:
    """(H, W) bool: the cells whose centre lies in ``region`` = (x0, x1, y0, y1), metres."""
    rows, cols = np.indices(grid.shape)
    x, y = grid.cell_centre(rows, cols)
    return (x >= region[0]) & (x <= region[1]) & (y >= region[2]) & (y <= region[3])


def leak_causes(log_path: str, map_path: str, region: tuple[float, float, float, float] | None = None) -> str:
    log = aogm_cli.load_log(log_path)
    m = read_map_file(map_path)
    grid, truth, poses = m.grid, np.asarray(log.truth.occupancy), log.poses()
    in_truth = truth_reach(grid, truth, poses, ROBOT_RADIUS) & m.observed
    leaked = map_reach(grid, m.probability, m.observed, poses, ROBOT_RADIUS) & ~in_truth
    erased = (truth != 0) & m.observed & (m.probability < 0.5) & grid.within(leaked, LEAK_NEAR)
    params = resolved_params(log, MapParams())
    s = state_before(log, "em", params, "walls", given=sensor_model("em", params, log, log_path))
    wall = (s.standard.log_odds > 0).reshape(grid.shape)
    normal = np.isfinite(B.surfaces(s.readings, s.in_use, s.standard.log_odds)[0]).reshape(grid.shape)
    n_truth = int(in_truth.sum())
    inside = "" if region is None else (f"; leaked cells in the region {int((leaked & region_cells(grid, region)).sum())}"
                                        f" of {int(leaked.sum())}")
    return (f"{map_path}: leak {leaked.sum() / n_truth:.3f}; true wall cells shown free within {LEAK_NEAR} m of the "
            f"leak {int(erased.sum())}: walls in the standard map {int((erased & wall).sum())}, with a surface "
            f"normal {int((erased & normal).sum())}{inside}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("pairs", nargs="+", help="LOG.h5 MAP.h5, repeated")
    parser.add_argument("--leak", action="store_true", help="also what the map leaks through")
    parser.add_argument("--region", help="with --leak: X0,X1,Y0,Y1 (m), the leaked cells inside it counted apart")
    args = parser.parse_args()
    if len(args.pairs) % 2:
        parser.error("expected LOG.h5 MAP.h5 pairs")
    for log_path, map_path in zip(args.pairs[::2], args.pairs[1::2], strict=True):
        print(causes(log_path, map_path))
        if args.leak:
            region = None if args.region is None else tuple(float(v) for v in args.region.split(","))
            print(leak_causes(log_path, map_path, region))


if __name__ == "__main__":
    main()
