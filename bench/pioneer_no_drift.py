"""The ``*_pioneer`` worlds without odometry drift, as ``aogm compare`` scores them (worlds/README.md, "The lobe,
and the leak without drift").

    python bench/pioneer_no_drift.py [--params P.yaml] [--detector all] [--seed 1] [--keep DIR]

Writes each ``worlds/*_pioneer.yaml`` with its ``errors.odometry`` taken out (named ``<world>_nodrift``),
simulates it (``aogm simulate --seed``), compares the logs with ``aogm compare --modes standard,em,adaptive``
(``--params`` and ``--detector`` passed on) and prints each map's leak, block, accuracy and checks, and for adaptive the share
of the observed cells its clusters hold (``stats``: cells_in_clusters / observed_cells). Worlds, logs and
maps go to a temporary folder unless ``--keep DIR``.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import yaml

from aogm_cli.io.mapfile import read_map_file

ROOT = Path(__file__).resolve().parents[1]


def no_drift(world: Path, out: Path) -> Path:
    """``world`` with its odometry errors taken out, written to ``out``."""
    raw = yaml.safe_load(world.read_text())
    (raw.get("errors") or {}).pop("odometry", None)
    raw["name"] = f"{raw['name']}_nodrift"
    path = out / f"{raw['name']}.yaml"
    path.write_text(yaml.safe_dump(raw, sort_keys=False))
    return path


def aogm(*args: str) -> None:
    subprocess.run([sys.executable, "-m", "aogm_cli", *args], check=True, stdout=subprocess.DEVNULL)


def run(out: Path, seed: int, params: str | None, detector: str | None) -> None:
    logs = []
    for world in sorted((ROOT / "worlds").glob("*_pioneer.yaml")):
        path = no_drift(world, out)
        logs.append(out / f"{path.stem}.h5")
        aogm("simulate", str(path), "-o", str(logs[-1]), "--seed", str(seed), "-q")
    report, maps = out / "compare.json", out / "maps"
    aogm("compare", *map(str, logs), "--modes", "standard,em,adaptive", "--json", str(report),
         "--maps-dir", str(maps), "--quiet", *(["--params", params] if params else []),
         *(["--detector", detector] if detector else []))
    print(f"{'world':<36} {'mode':<9} {'leak':>6} {'block':>6} {'accuracy':>8} {'checks':>6} {'clusters':>8}")
    for r in json.loads(report.read_text())["results"]:
        m = r["metrics"]
        checks = f"{sum(c['passed'] for c in m['checks'])}/{len(m['checks'])}"
        share = ""
        if r["mode"] == "adaptive":
            stats = read_map_file(maps / f"{r['world']}_adaptive.h5").stats
            share = f"{stats['cells_in_clusters'] / stats['observed_cells']:.2f}"
        print(f"{r['world']:<36} {r['mode']:<9} {m['leak']:6.3f} {m['block']:6.3f} {m['accuracy']:8.4f} "
              f"{checks:>6} {share:>8}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--params", help="a --params file for aogm compare")
    parser.add_argument("--detector", help="aogm compare's --detector (default: the packaged one)")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--keep", type=Path, help="keep worlds, logs and maps here")
    args = parser.parse_args()
    if args.keep:
        args.keep.mkdir(parents=True, exist_ok=True)
        run(args.keep, args.seed, args.params, args.detector)
        return
    with tempfile.TemporaryDirectory() as tmp:
        run(Path(tmp), args.seed, args.params, args.detector)


if __name__ == "__main__":
    main()
