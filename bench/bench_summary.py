"""Benchmark of aogm compare's conclusions over many results: the summary, its CSV rows and Markdown, a baseline
and aggregate gates, on 2,001 synthetic results (667 logs of 20 worlds in three modes, seeded).

Run as ``python bench/bench_summary.py [--results N] [--repeat R]``. Prints each step's best time of R, their
sum, and that sum against the standard maps those logs would need (one corridor_door standard map, made and timed
here, per log): what the summary adds beside the maps.
"""

from __future__ import annotations

import argparse
import random
import time

import aogm_cli
from aogm_cli.io.results import ModeResult
from aogm_cli.report.baseline import TOLERANCES, compare_to_baseline
from aogm_cli.report.gates import evaluate_gates, gate_values, parse_gate
from aogm_cli.report.summary import summarize
from aogm_cli.report.summary_table import csv_rows, markdown

MODES = ("standard", "em", "adaptive")
GATES = ("mean(adaptive.accuracy - em.accuracy) >= -1", "ci_low(em.accuracy - standard.accuracy) > -1",
         "min(em.checks_passed) >= 0", "adaptive.leak <= 1")


def synthetic_results(n: int, seed: int = 1) -> list[ModeResult]:
    """At least ``n`` results, whole logs of three modes (2,001 for 2,000), 20 worlds, metrics and runtimes drawn
    from ``seed``."""
    rng = random.Random(seed)
    out = []
    for i in range(-(-n // len(MODES))):
        for mode in MODES:
            metrics = {"accuracy": rng.random(), "occupied_precision": rng.random(), "occupied_recall": rng.random(),
                       "occupied_f1": rng.random(), "brier": rng.random(), "ece": rng.random(),
                       "checks": [{"name": "door_passable", "passed": rng.random() > 0.3}]}
            out.append(ModeResult(f"logs/w{i % 20}_s{i}.h5", f"w{i % 20}", mode, 0.01 + rng.random(), metrics, None,
                                  planner={"leak": rng.random(), "block": rng.random(), "surface_recall": rng.random()},
                                  log_content=f"{i:064x}"))
    return out


def best(repeat: int, step) -> float:
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        step()
        times.append(time.perf_counter() - t)
    return min(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--results", type=int, default=2000)
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    results = synthetic_results(args.results)
    gates = [parse_gate(g) for g in GATES]
    summary = summarize(results)  # and scipy.special's import, which a compare run has made already
    steps = {
        "summary": lambda: summarize(results),
        "csv rows and Markdown": lambda: (csv_rows(summary), markdown(summary, None)),
        "baseline (the run against itself)": lambda: compare_to_baseline(results, results, "old.json", TOLERANCES),
        "gates (3 aggregates, 1 per log)": lambda: evaluate_gates(gates, gate_values(results)),
    }
    logs = len({r.log for r in results})
    print(f"{len(results)} results ({logs} logs, {len({r.world for r in results})} worlds), best of {args.repeat}")
    total = 0.0
    for name, step in steps.items():
        seconds = best(args.repeat, step)
        total += seconds
        print(f"  {name:36s} {seconds * 1e3:8.1f} ms")
    log = aogm_cli.simulate(aogm_cli.bundled_world("corridor_door"), seed=1)
    aogm_cli.map_log(log, "standard")  # compiled and templates built
    standard = min(aogm_cli.map_log(log, "standard").runtime_s for _ in range(args.repeat))
    print(f"  all of it                            {total * 1e3:8.1f} ms: x{total / (standard * logs):.3f} of {logs} "
          f"standard maps of corridor_door ({standard * 1e3:.2f} ms each), target under 1 s: "
          f"{'held' if total < 1.0 else 'NOT held'}")


if __name__ == "__main__":
    main()
