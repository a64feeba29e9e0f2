"""The modes' costs and targets on a real laser log: the intel log (Intel Research Lab, ../shared/data) at
0.1 m with its sensor's model learned once (``aogm calibrate -o``) and given (``--forward-model``).

    python bench/bench_intel.py [--runs 3] [--workdir out/bench-intel]

Imports the log (``aogm import carmen ... --max-range 30``) into the workdir (kept: a second run
reuses it) and calibrates it there (every run: the model is this code's), then maps it in the
standard, em and adaptive modes with the model given, and in the em mode calibrating on the log
(its ``calibration`` phase is what calibrating costs), round after round (``--runs``, best
``runtime_s`` of each and of each phase);
then ``aogm compare --holdout 0.1 --seed 1`` for the held-out scores. Prints each mode's time,
its ratio to the standard map of the same run and its phases, and the targets: adaptive at most
15 x the standard map, EM at most 30 x, the calibration alone at most 30 x, and EM's and adaptive's
held-out band AUC (``holdout_auc_band``) at least the standard map's. The standard map of this log
takes about 50 ms, so its ratios move with the machine's noise: compare runs of one session.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

from aogm_cli.map_files import map_file
from aogm_cli.mapping.params import params_from

ROOT = Path(__file__).resolve().parents[1]
LOG = ROOT.parent / "shared" / "data" / "carmen" / "intel-corrected.log.gz"
AOGM = str(Path(sys.executable).with_name("aogm"))
MODES = ("standard", "em", "adaptive")
TARGETS = {"adaptive": 15.0, "em": 30.0, "calibration": 30.0}


def aogm(*args: str) -> None:
    """Run ``aogm ARGS``, quietly; on failure its error and exit status 2."""
    done = subprocess.run([AOGM, *args], capture_output=True, text=True)
    if done.returncode != 0:
        sys.stderr.write(done.stderr)
        raise SystemExit(2)


def prepared(workdir: Path) -> tuple[Path, Path, Path]:
    """(the log, its params file, its model file) in ``workdir``: the log imported once, the model
    calibrated by this run (one a run of older code made would be stale)."""
    workdir.mkdir(parents=True, exist_ok=True)
    log, params, model = workdir / "intel.h5", workdir / "params.yaml", workdir / "intel_model.h5"
    params.write_text("resolution: 0.1\n")
    if not log.exists():
        aogm("import", "carmen", str(LOG), "-o", str(log), "--max-range", "30")
    aogm("calibrate", str(log), "--params", str(params), "-o", str(model))
    return log, params, model


def timed(log: Path, model: Path, runs: int) -> dict[str, dict]:
    """Per mode the best runtime_s and the best of each phase over ``runs`` rounds (the model given),
    and the em map calibrating on the log ("calibrating")."""
    params = params_from({"resolution": 0.1})
    made: dict[str, list] = {mode: [] for mode in (*MODES, "calibrating")}
    for _ in range(runs):
        for mode in MODES:
            made[mode].append(map_file(log, mode, params, model=model))
        made["calibrating"].append(map_file(log, "em", params))
    out = {}
    for mode, maps in made.items():
        phases = maps[0].stats["phase_seconds"]
        out[mode] = {"runtime_s": min(m.runtime_s for m in maps),
                     "phases": {k: min(m.stats["phase_seconds"][k] for m in maps) for k in phases},
                     "cluster_share": (maps[0].stats["cells_in_clusters"] / maps[0].stats["observed_cells"]
                                       if maps[0].stats.get("observed_cells") else None)}
    return out


def held_out(log: Path, params: Path, model: Path, workdir: Path) -> dict[str, float]:
    """Each mode's held-out band AUC (``aogm compare --holdout 0.1 --seed 1``, the model given)."""
    out = workdir / "compare.json"
    aogm("compare", str(log), "--params", str(params), "--forward-model", str(model), "--holdout", "0.1", "--seed", "1",
         "--json", str(out), "-q")
    return {r["mode"]: r["metrics"]["holdout_auc_band"] for r in json.loads(out.read_text())["results"]}


def verdict(ok: bool) -> str:
    return "held" if ok else "NOT held"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--workdir", default="out/bench-intel")
    args = ap.parse_args()
    if not LOG.exists():
        print(f"{LOG}: not found (the intel log of ../shared/data)", file=sys.stderr)
        return 2
    workdir = Path(args.workdir)
    log, params, model = prepared(workdir)
    rows = timed(log, model, args.runs)
    auc = held_out(log, params, model, workdir)
    std = rows["standard"]["runtime_s"]
    print(f"intel log at 0.1 m, its model given ({model}); best of {args.runs}")
    print(f"  {'mode':<12} {'best s':>8} {'x std':>7} {'clusters':>9} {'AUC band':>9}  phases (best s)")
    for mode, r in rows.items():
        clusters = "" if r["cluster_share"] is None else f"{r['cluster_share']:.1%}"
        band = f"{auc[mode]:.4f}" if mode in auc else ""
        phases = ", ".join(f"{k} {v:.3f}" for k, v in r["phases"].items())
        print(f"  {mode:<12} {r['runtime_s']:>8.3f} {r['runtime_s'] / std:>7.1f} {clusters:>9} {band:>9}  {phases}")
    calibration = rows["calibrating"]["phases"]["calibration"]
    ratios = {"adaptive": rows["adaptive"]["runtime_s"] / std, "em": rows["em"]["runtime_s"] / std,
              "calibration": calibration / std}
    for key, ratio in ratios.items():
        print(f"  {key} / standard: x{ratio:.1f} (target <= {TARGETS[key]:g}: {verdict(ratio <= TARGETS[key])})")
    for mode in ("em", "adaptive"):
        ok = auc[mode] >= auc["standard"]
        print(f"  {mode} held-out band AUC {auc[mode]:.4f} against the standard map's {auc['standard']:.4f} "
              f"(target >=: {verdict(ok)})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
