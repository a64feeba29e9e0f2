"""What a planner sees in each map of a folder: leak / block / surface_recall per world and mode.

    python bench/planner_table.py out/*.h5 --maps-dir out/maps [--robot-radius 0.2]

Maps are found as MAPS_DIR/<log stem>_<mode>.h5 (compare --maps-dir's names); logs with truth
get leak/block/surface; every mode also gets walls_kept, leak_vs_standard and far_leak against the
standard map.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from aogm_cli.evaluation.metrics import run_checks
from aogm_cli.evaluation.planner import against_standard, planner_metrics
from aogm_cli.io.logfile import LogReader
from aogm_cli.io.mapfile import read_map_file


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("logs", nargs="+")
    ap.add_argument("--maps-dir", required=True)
    ap.add_argument("--modes", default="standard,em,adaptive")
    ap.add_argument("--robot-radius", type=float, default=0.2)
    a = ap.parse_args()
    modes = a.modes.split(",")
    print(f"| world | {' | '.join(modes)} |  (leak / block / surface / walls_kept / leak_vs_std / far_leak / checks failed)")
    print("|---|" + "---|" * len(modes))
    for log_path in a.logs:
        stem = Path(log_path).stem
        with LogReader(log_path) as r:
            poses = r.poses()
            truth = r.truth()
        maps = {m: read_map_file(Path(a.maps_dir) / f"{stem}_{m}.h5") for m in modes
                if (Path(a.maps_dir) / f"{stem}_{m}.h5").exists()}
        std = maps.get("standard")
        cells = []
        for mode in modes:
            m = maps.get(mode)
            if m is None:
                cells.append("-")
                continue
            parts = []
            if truth is not None:
                pm = planner_metrics(m.grid, m.probability, m.observed, truth.occupancy, poses, a.robot_radius)
                parts.append(f"{pm['leak']:.3f} / {pm['block']:.3f} / {pm['surface_recall']:.2f}")
            if std is not None:
                s = against_standard(m.grid, m.probability, m.observed, std.probability, std.observed, poses, a.robot_radius)
                parts.append(f"{s['walls_kept']:.2f} / {s['leak_vs_standard']:.3f} / {s['far_leak']:.3f}")
            if truth is not None:
                failed = [c["name"] for c in run_checks(m.grid, m.probability, m.observed, truth.checks) if not c["passed"]]
                parts.append(",".join(failed) or "ok")
            cells.append(" / ".join(parts))
        print(f"| {stem} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
