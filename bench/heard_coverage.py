"""How low block can go on a simulated log when a map may only call free what some reading heard: the planner's
block (and leak) of the truth itself, shown only where a reading's lobe covers a cell (docs/algorithms.md, "The
lobe that hears": what office_doors' block is made of).

    python bench/heard_coverage.py LOG.h5 [LOG.h5 ...] [--lobe DEG RANGE] ...

Per log and lobe (theta0 in degrees, its axis range R0 in m; 0 0: the whole cone): the cells covered are those the
exact inverse model's pass observes with that lobe (``standard.exact_pass``: each reading's heard cells,
``heard.heard_templates``, out to its Gaussian window; no beam deflected), and the robot's footprint; the oracle
map is the truth there, unobserved elsewhere. Its ``block`` is what no map that infers free floor only from what
its readings hear can go below, whatever else its sensor model does; ``leak`` is 0.
"""

from __future__ import annotations

import argparse
import dataclasses

import numpy as np

import aogm_cli
from aogm_cli.evaluation.planner import ROBOT_RADIUS, planner_metrics
from aogm_cli.mapping.params import MapParams
from aogm_cli.mapping.standard import exact_pass
from aogm_cli.mapping.view import footprint


def with_lobe(params: MapParams, lobe_deg: float, lobe_range: float) -> MapParams:
    """``params`` with EM's forward model hearing the lobe (``lobe_deg`` 0: the whole cone)."""
    forward = dataclasses.replace(params.em.forward, lobe_deg=lobe_deg, lobe_range=lobe_range)
    return dataclasses.replace(params, em=dataclasses.replace(params.em, forward=forward))


def oracle(log_path: str, lobes: list[tuple[float, float]]) -> list[str]:
    log = aogm_cli.load_log(log_path)
    grid, truth = log.truth.grid, np.asarray(log.truth.occupancy)
    body = footprint(grid, log.pose, log.sensor)
    lines = []
    for theta0, r0 in lobes:
        observed = exact_pass(log, grid, with_lobe(MapParams(), theta0, r0 if r0 > 0 else 10.0)).observed | body
        probability = np.where(truth != 0, 1.0, 0.0)
        probability[~observed] = 0.5
        m = planner_metrics(grid, probability, observed, truth, log.poses(), ROBOT_RADIUS)
        lobe = "whole cone" if theta0 <= 0 else f"theta0 {theta0:g} deg, R0 {r0:g} m"
        lines.append(f"{log_path}: {lobe}: block {m['block']:.3f}, leak {m['leak']:.3f}, covered "
                     f"{int(observed.sum())} cells")
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("logs", nargs="+")
    parser.add_argument("--lobe", nargs=2, type=float, action="append", metavar=("DEG", "RANGE"),
                        help="theta0 (deg) and R0 (m); repeat; 0 0: the whole cone (default: 0 0)")
    args = parser.parse_args()
    for path in args.logs:
        for line in oracle(path, [tuple(x) for x in args.lobe] if args.lobe else [(0.0, 0.0)]):
            print(line)


if __name__ == "__main__":
    main()
