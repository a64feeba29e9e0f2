"""The measurements behind the default parameters: standard and EM maps over a parameter grid.

Run as ``python bench/params_sweep.py [standard|em]``. Simulates every bundled world (seed 1)
into a temporary folder, maps it with each parameter set and prints, per set, the accuracy and
occupied F1 on every world (in file-name order) and how many world checks pass.
"""

from __future__ import annotations

import itertools
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from aogm_cli.evaluation import evaluate  # noqa: E402
from aogm_cli.logfile import read_log, write_log  # noqa: E402
from aogm_cli.mapping import mapper  # noqa: E402
from aogm_cli.mapping.params import resolve_params  # noqa: E402
from aogm_cli.simulation.sonar import simulate  # noqa: E402
from aogm_cli.world.loader import load_world  # noqa: E402

STANDARD_GRID = [{"inverse_model": {"alpha": a, "l_occ": lo}} for a, lo in itertools.product([0.05, 0.07, 0.1], [0.85, 0.6, 0.4])]
EM_GRID = [{"em": {"sigma": s, "p_hit": h, "p_max": m}}
           for s, h, m in itertools.product([0.03, 0.05], [0.3, 0.5, 0.7], [0.0, 0.1, 0.2])]


def main() -> None:
    which = sys.argv[1] if len(sys.argv) > 1 else "em"
    grid, make = (STANDARD_GRID, mapper.map_standard) if which == "standard" else (EM_GRID, mapper.map_em)
    worlds = sorted((ROOT / "worlds").glob("*.yaml"))
    print("worlds:", " ".join(w.stem for w in worlds))
    with tempfile.TemporaryDirectory() as folder:
        logs = []
        for w in worlds:
            path = Path(folder) / f"{w.stem}.h5"
            write_log(path, simulate(load_world(w), seed=1))
            logs.append((path, read_log(path).truth))
        for overrides in grid:
            params = resolve_params(None, overrides)
            results = [evaluate(make(path, params), truth) for path, truth in logs]
            checks = [c["passed"] for r in results for c in r["checks"]]
            print(overrides, "acc", " ".join(f"{r['accuracy']:.3f}" for r in results),
                  "f1", " ".join(f"{r['occupied_f1']:.2f}" for r in results), f"checks {sum(checks)}/{len(checks)}", flush=True)


if __name__ == "__main__":
    main()
