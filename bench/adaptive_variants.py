"""Adaptive variants against EM, per log: accuracy, leak, block, checks, the clusters' share of the
observed cells and where the time goes. Measures which clusters the adaptive mapper needs (issue 36).

Usage: ``python bench/adaptive_variants.py VARIANTS.json LOG.h5 ...`` where VARIANTS.json maps a
label to ``[mode, params, detector]``: ``params`` a ``--params`` mapping (sections of dicts), ``detector``
as ``--detector`` (null: the packaged one). Logs must be simulated (scored against their truth), e.g.
``{"em": ["em", {}, null], "thin0": ["adaptive", {"exact": {"thin": true}, "adaptive": {"contested": 0,
"weak": 0, "grow": 0}}, null]}`` on the bundled worlds without a Pioneer at seed 1.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from aogm_cli.evaluation.metrics import evaluate
from aogm_cli.evaluation.planner import ROBOT_RADIUS, planner_metrics
from aogm_cli.io.logfile import LogReader
from aogm_cli.map_files import map_file
from aogm_cli.mapping.params import params_from


def main() -> None:
    variants = json.loads(Path(sys.argv[1]).read_text())
    for path in map(Path, sys.argv[2:]):
        with LogReader(path) as reader:
            truth, poses = reader.truth(), reader.poses()
        for label, (mode, raw, detector) in variants.items():
            m = map_file(path, mode, params_from(raw), detector)
            metrics = evaluate(m, truth)
            planner = planner_metrics(m.grid, m.probability, m.observed, truth.occupancy, poses, ROBOT_RADIUS)
            checks = f"{sum(c['passed'] for c in metrics['checks'])}/{len(metrics['checks'])}"
            share = m.stats.get("cells_in_clusters", 0) / max(1, m.stats.get("observed_cells", 1))
            phases = m.stats["phase_seconds"]
            print(f"{path.stem:22s} {label:10s} acc {metrics['accuracy']:.4f} leak {planner['leak']:.3f} "
                  f"block {planner['block']:.3f} checks {checks} share {share:.3f} t {m.runtime_s:.3f} "
                  f"cal {phases.get('calibration', 0):.3f} sw {phases.get('sweeps', 0):.3f} "
                  f"thin {phases.get('thinning', 0):.3f}", flush=True)


if __name__ == "__main__":
    main()
