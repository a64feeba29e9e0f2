"""Fingerprints of every map of every bundled world in every mode: one line per array.

Simulates each world (seed 1), imports the real 8-sonar ring and intel laser logs of ../shared/data,
maps each log with ``aogm map`` in each mode (the real logs at 0.1 m) and prints the sha256 of every
dataset of the map file, so that two checkouts can be compared with ``diff`` (runtimes and other
attributes aside). Usage: ``python bench/map_fingerprints.py [OUT_DIR] > prints.txt``.
"""

from __future__ import annotations

import hashlib
import subprocess
import sys
import tempfile
from pathlib import Path

import h5py

ROOT = Path(__file__).resolve().parent.parent
MODES = ("standard", "em", "adaptive")
DATA = ROOT.parent / "shared" / "data"
SONAR = DATA / "sonar" / "udacity_8sonar"
REAL_LOGS = {  # the import commands of .ci/run and docs/your-robot.md
    "udacity_8sonar": [
        "import", "text", "--ranges", str(SONAR / "measurement.txt"), "--poses", str(SONAR / "poses.txt"),
        "--range-time-column", "1", "--range-columns", "2-9", "--pose-time-column", "1",
        "--pose-columns", "2,3,4", "--time-unit", "ms", "--range-unit", "mm", "--position-unit", "mm",
        "--angle-unit", "ddeg", "--no-echo", "5110", "--bearings=-90,-37.5,-22.5,-7.5,7.5,22.5,37.5,90",
        "--max-range", "5.0", "--beam-width", "20"],
    "intel": ["import", "carmen", str(DATA / "carmen" / "intel-corrected.log.gz"), "--max-range", "30"],
}


def fingerprints(path: Path) -> list[tuple[str, str]]:
    out = []
    with h5py.File(path, "r") as f:
        def visit(name, obj):
            if isinstance(obj, h5py.Dataset):
                out.append((name, hashlib.sha256(obj[()].tobytes()).hexdigest()[:16]))
        f.visititems(visit)
    return sorted(out)


def print_maps(aogm: list[str], log: Path, name: str, extra: list[str]) -> None:
    for digest_name, digest in fingerprints(log):
        print(f"{name} log {digest_name} {digest}", flush=True)
    for mode in MODES:
        out = log.with_name(f"{name}-{mode}.h5")
        subprocess.run([*aogm, "map", str(log), "--mode", mode, "-o", str(out), "--quiet", *extra], check=True)
        for digest_name, digest in fingerprints(out):
            print(f"{name} {mode} {digest_name} {digest}", flush=True)


def main() -> None:
    work = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(tempfile.mkdtemp())
    work.mkdir(parents=True, exist_ok=True)
    aogm = [sys.executable, "-m", "aogm_cli"]
    for world in sorted((ROOT / "worlds").glob("*.yaml")):
        log = work / f"{world.stem}.h5"
        subprocess.run([*aogm, "simulate", str(world), "-o", str(log), "--seed", "1", "--quiet"], check=True)
        print_maps(aogm, log, world.stem, [])
    params = work / "real.yaml"
    params.write_text("resolution: 0.1\n")
    for name, command in REAL_LOGS.items():
        log = work / f"{name}.h5"
        subprocess.run([*aogm, *command, "-o", str(log), "-q"], check=True)
        print_maps(aogm, log, name, ["--params", str(params)])


if __name__ == "__main__":
    main()
