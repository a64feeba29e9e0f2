"""Issue 14's table: every log mapped in every mode with calibration on and off, once whole
(accuracy, occupied recall) and once with --holdout 0.1 (held-out AUC and log-likelihood), and
the targets checked: with calibration, em and adaptive accuracy and held-out AUC at least the
standard map's, occupied recall at least the standard map's minus 0.05.

    python bench/calibration_report.py LOG.h5 ... [--jobs 2] [--workdir out/calibration]

Logs without truth (the intel log) get the held-out scores only.
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
from pathlib import Path

AOGM = str(Path(sys.executable).with_name("aogm"))


def compare(logs: list[str], out: Path, *extra: str, jobs: int) -> dict:
    """{(world, mode): metrics and runtime} of one ``aogm compare`` run."""
    cmd = [AOGM, "compare", *logs, "--modes", "standard,em,adaptive", "--jobs", str(jobs), "--json", str(out), "-q",
           *extra]
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    results = json.loads(out.read_text())["results"]
    return {(r["world"] or Path(r["log"]).stem, r["mode"]): {**(r["metrics"] or {}), "runtime_s": r["runtime_s"]} for r in results}


def fmt(v, digits=4) -> str:
    return "n/a" if v is None or (isinstance(v, float) and math.isnan(v)) else f"{v:.{digits}f}"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("logs", nargs="+")
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--workdir", default="out/calibration")
    args = ap.parse_args()
    work = Path(args.workdir)
    work.mkdir(parents=True, exist_ok=True)
    runs = {}
    for cal in ("calibrate", "no-calibrate"):
        runs[cal, "whole"] = compare(args.logs, work / f"{cal}.json", f"--{cal}", jobs=args.jobs)
        runs[cal, "holdout"] = compare(args.logs, work / f"{cal}_holdout.json", f"--{cal}", "--holdout", "0.1",
                                       "--seed", "1", jobs=args.jobs)
    print("| world | mode | accuracy cal / no-cal | occ. recall cal / no-cal | held-out AUC cal / no-cal |"
          " held-out loglik cal / no-cal | runtime s cal / no-cal | targets (cal) |")
    print("|---|---|---|---|---|---|---|---|")
    failed = 0
    for world, mode in runs["calibrate", "whole"]:
        row = {key: runs[key].get((world, mode), {}) for key in runs}
        std = {key: runs[key].get((world, "standard"), {}) for key in runs}
        cal, off = row["calibrate", "whole"], row["no-calibrate", "whole"]
        hcal, hoff = row["calibrate", "holdout"], row["no-calibrate", "holdout"]
        checks = []
        if mode != "standard":
            scal, shcal = std["calibrate", "whole"], std["calibrate", "holdout"]
            if "accuracy" in cal:
                checks.append(("accuracy", cal["accuracy"] >= scal["accuracy"]))
                checks.append(("recall", cal["occupied_recall"] >= scal["occupied_recall"] - 0.05))
            checks.append(("AUC", hcal["holdout_auc"] >= shcal["holdout_auc"]))
        failed += sum(not ok for _, ok in checks)
        targets = ", ".join(f"{name} {'ok' if ok else 'NO'}" for name, ok in checks) or "-"
        print(f"| {world} | {mode} | {fmt(cal.get('accuracy'))} / {fmt(off.get('accuracy'))} |"
              f" {fmt(cal.get('occupied_recall'), 3)} / {fmt(off.get('occupied_recall'), 3)} |"
              f" {fmt(hcal.get('holdout_auc'))} / {fmt(hoff.get('holdout_auc'))} |"
              f" {fmt(hcal.get('holdout_loglik'), 3)} / {fmt(hoff.get('holdout_loglik'), 3)} |"
              f" {fmt(cal.get('runtime_s'), 2)} / {fmt(off.get('runtime_s'), 2)} | {targets} |")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
