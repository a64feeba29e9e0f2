"""Benchmark: the adaptive mapper's phases against one standard pass (same run).

Run as ``python bench/bench_adaptive.py``. Simulates corridor_door and corridor_specular
(seed 1), compiles every kernel first, then maps each log five times and keeps each phase's
best time: the standard pass, the detector, the clusters, EM's set-up over the readings near
the clusters (their likelihood state), and EM inside the clusters; and the sweeps EM took
with the candidates each scored.
"""

from __future__ import annotations

from pathlib import Path

from seed_logs import for_each_seed_log, standard_pass

from aogm_cli.io.logfile import LogReader
from aogm_cli.map_files import map_file, resolve_params
from aogm_cli.mapping.pipeline import log_grid


def bench(world_name: str, log_path: Path) -> None:
    params = resolve_params()
    runs = [map_file(log_path, "adaptive", params) for _ in range(5)]  # the packaged detector
    with LogReader(log_path) as reader:  # the standard map's own clock: mapping work, no I/O
        grid = log_grid(reader, params.resolution)
        t_std = min(standard_pass(reader, grid, params)[2] for _ in range(5))
    phases = {k: min(r.stats["phase_seconds"][k] for r in runs) for k in runs[0].stats["phase_seconds"]}
    stats = runs[0].stats
    total = sum(phases.values())
    print(f"\n{world_name}: {stats['readings']} readings, {stats['flagged_readings']} flagged, "
          f"{stats['cells_in_clusters']} cluster cells of {stats['observed_cells']} observed, "
          f"{stats['em_readings']} readings in EM, at most {stats['index_entries']} window pairs in a tile, "
          f"EM sweeps {stats['sweeps']}, candidates scored per sweep {stats['scored_per_sweep']}")
    print(f"  standard map (ceiling)  {t_std * 1e3:8.2f} ms")
    for name, seconds in phases.items():
        print(f"  {name:22s}  {seconds * 1e3:8.2f} ms  = {seconds / t_std:5.2f} x standard map")
    print(f"  adaptive total          {total * 1e3:8.2f} ms  = {total / t_std:5.2f} x standard map "
          f"(target 1.50 x: {1.5 * t_std * 1e3:.2f} ms)")


def main() -> None:
    print("Adaptive mapping benchmark (the ceiling is the standard map of the same log, same run)")
    for_each_seed_log(bench)


if __name__ == "__main__":
    main()
