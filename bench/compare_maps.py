"""Compare EM and adaptive maps made now with maps made earlier, world by world.

Run as ``python bench/compare_maps.py LOGS_DIR MAPS_DIR`` where MAPS_DIR holds the earlier
``<logstem>_<mode>.h5`` of every ``LOGS_DIR/*.h5`` (``aogm compare ... --maps-dir MAPS_DIR`` at
the earlier commit). Maps each log in em and adaptive with ``map_files.map_file`` and prints a
Markdown table: accuracy before and after (``evaluation.metrics.evaluate`` against the log's
truth), whether ``map/probability`` and ``map/occupied`` are identical, EM's objective at
convergence before and after, and both runtimes.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from aogm_cli.evaluation.metrics import evaluate
from aogm_cli.io.logfile import LogReader
from aogm_cli.io.mapfile import read_map_file
from aogm_cli.map_files import map_file, resolve_params


def main() -> None:
    logs, maps = Path(sys.argv[1]), Path(sys.argv[2])
    params = resolve_params()
    print("| world | mode | accuracy before | after | map identical | objective before | after | runtime before s | after s |")
    print("|---|---|---|---|---|---|---|---|---|")
    for log in sorted(logs.glob("*.h5")):
        with LogReader(log) as reader:
            truth = reader.truth()
        for mode in ("em", "adaptive"):
            old = read_map_file(maps / f"{log.stem}_{mode}.h5")
            new = map_file(log, mode, params)
            same = np.array_equal(new.probability, old.probability) and np.array_equal(new.occupied, old.occupied)
            objective = [m.stats.get("objective_per_sweep", [None])[-1] for m in (old, new)]
            shown = " | ".join("–" if v is None else f"{v:.6f}" for v in objective)
            print(f"| {log.stem} | {mode} | {evaluate(old, truth)['accuracy']:.4f} | {evaluate(new, truth)['accuracy']:.4f} "
                  f"| {'yes' if same else 'NO'} | {shown} | {old.runtime_s:.3f} | {new.runtime_s:.3f} |", flush=True)


if __name__ == "__main__":
    main()
