"""Benchmark: the adaptive mapper's phases against one standard pass (same run).

Run as ``python bench/bench_adaptive.py``. Simulates corridor_door and corridor_specular
(seed 1), compiles every kernel first, then maps each log five times and keeps each phase's
best time: the standard pass, the detector, the clusters, the restricted forward index, and
EM inside the clusters. The issue's target is the whole at most 1.5 x the standard map.
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from seed_logs import for_each_seed_log  # noqa: E402

from aogm_cli.logfile import LogReader  # noqa: E402
from aogm_cli.mapping import mapper  # noqa: E402
from aogm_cli.mapping.params import resolve_params  # noqa: E402


def bench(world_name: str, log_path: Path) -> None:
    params = resolve_params()
    runs = [mapper.map_adaptive(log_path, params) for _ in range(5)]
    with LogReader(log_path) as reader:  # the standard map's own clock: mapping work, no I/O
        grid = mapper.log_grid(reader, params.resolution)
        t_std = min(mapper.standard_pass(reader, grid, params)[2] for _ in range(5))
    phases = {k: min(r.stats["phase_seconds"][k] for r in runs) for k in runs[0].stats["phase_seconds"]}
    stats = runs[0].stats
    total = sum(phases.values())
    print(f"\n{world_name}: {stats['readings']} readings, {stats['flagged_readings']} flagged, "
          f"{stats['cells_in_clusters']} cluster cells of {stats['observed_cells']} observed, "
          f"{stats['index_entries']} (reading, cell) entries, EM sweeps {stats['em_sweeps_per_group']}")
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
