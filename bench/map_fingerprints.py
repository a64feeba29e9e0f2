"""Fingerprints of every map of every bundled world in every mode: one line per array.

Simulates each world (seed 1), maps it with ``aogm map`` in each mode and prints the sha256 of
every dataset of the map file, so that two checkouts can be compared with ``diff`` (runtimes
and other attributes aside). Usage: ``python bench/map_fingerprints.py [OUT_DIR] > prints.txt``.
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


def fingerprints(path: Path) -> list[tuple[str, str]]:
    out = []
    with h5py.File(path, "r") as f:
        def visit(name, obj):
            if isinstance(obj, h5py.Dataset):
                out.append((name, hashlib.sha256(obj[()].tobytes()).hexdigest()[:16]))
        f.visititems(visit)
    return sorted(out)


def main() -> None:
    work = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(tempfile.mkdtemp())
    work.mkdir(parents=True, exist_ok=True)
    aogm = [sys.executable, "-m", "aogm_cli"]
    for world in sorted((ROOT / "worlds").glob("*.yaml")):
        log = work / f"{world.stem}.h5"
        subprocess.run([*aogm, "simulate", str(world), "-o", str(log), "--seed", "1", "--quiet"], check=True)
        for name, digest in fingerprints(log):
            print(f"{world.stem} log {name} {digest}")
        for mode in MODES:
            out = work / f"{world.stem}-{mode}.h5"
            subprocess.run([*aogm, "map", str(log), "--mode", mode, "-o", str(out), "--quiet"], check=True)
            for name, digest in fingerprints(out):
                print(f"{world.stem} {mode} {name} {digest}")


if __name__ == "__main__":
    main()
