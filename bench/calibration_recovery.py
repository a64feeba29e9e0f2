"""Does calibration give back a simulator's noise and random-reading rate? A world is simulated
at several (noise_sigma, random_rate) settings, none equal to the forward model's defaults, and
mapped in em mode calibrating on the log (``calibration.carried: false``: the packaged detector's model of
the simulated ring is not taken); the learned sigma and p_rand are printed beside the simulator's, with the
fit at the true map for reference (the estimator without map errors).

    python bench/calibration_recovery.py [--world worlds/corridor_door.yaml] [--seed 1] [--params P.yaml]

``--params`` changes the other mapping parameters (as ``aogm map --params``); calibration's own constants
(``mapping.calibration.TUNING``: the broad start, the subsampling) are changed by editing them.

Targets: sigma within 20% of the simulator's, p_rand within 0.03 (the script exits 1 when one is missed).
"""

from __future__ import annotations

import argparse
import re
import sys
import tempfile
from pathlib import Path

import numpy as np

from aogm_cli.io.logfile import LogReader, write_log
from aogm_cli.map_files import map_file, resolve_params
from aogm_cli.mapping import calibration as C
from aogm_cli.mapping.params import MapParams
from aogm_cli.mapping.pipeline import log_grid
from aogm_cli.sensor_models.readings import lay_out_readings
from aogm_cli.simulation.sonar import simulate
from aogm_cli.world.loader import load_world

ROOT = Path(__file__).resolve().parents[1]
SETTINGS = ((0.05, 0.10), (0.08, 0.02), (0.12, 0.15))  # (noise_sigma m, random_rate)


def world_with(text: str, noise: float, rate: float) -> str:
    text = re.sub(r"noise_sigma: [0-9.]+", f"noise_sigma: {noise}", text)
    return re.sub(r"random_rate: [0-9.]+", f"random_rate: {rate}", text)


def fit_at_truth(log_path: Path, params: MapParams) -> C.Fit:
    """The fit at the log's true map, from the configured model."""
    with LogReader(log_path) as reader:
        log = reader.read()
        grid = log_grid(reader, params.resolution)
    laid = lay_out_readings(log.pose, log.ranges, log.sensor, grid)
    occupied = np.ascontiguousarray(log.truth.occupancy.reshape(-1).astype(bool))
    return C.fit_at_map(laid, C.sample_readings(laid, C.TUNING.max_readings), occupied, params.em.forward,
                        params.calibration)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--world", default=str(ROOT / "worlds" / "corridor_door.yaml"))
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--params", help="a --params YAML for the maps (default: the defaults)")
    args = ap.parse_args()
    params = resolve_params(args.params, {"calibration": {"carried": False}})
    text = Path(args.world).read_text()
    print(f"{Path(args.world).name}, seed {args.seed}: em mode, calibrating on each log (calibration.carried: false)")
    print("| simulator sigma | simulator random rate | random share (truth) | learned sigma | error | learned p_rand |"
          " error | p_hit | p_max | rounds | at the true map: sigma, p_rand | targets met |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    failed = 0
    with tempfile.TemporaryDirectory() as folder:
        for noise, rate in SETTINGS:
            world = Path(folder) / "world.yaml"
            world.write_text(world_with(text, noise, rate))
            log_path = Path(folder) / "log.h5"
            log = simulate(load_world(world), seed=args.seed)
            write_log(log_path, log)
            m = map_file(log_path, "em", params)
            final = m.stats["calibration"]["final"]
            truth = fit_at_truth(log_path, params)
            ok = abs(final["sigma"] - noise) <= 0.2 * noise and abs(final["p_rand"] - rate) <= 0.03
            failed += not ok
            print(f"| {noise} | {rate} | {(log.truth.cause == 2).mean():.3f} | {final['sigma']:.4f} |"
                  f" {100 * (final['sigma'] - noise) / noise:+.0f}% | {final['p_rand']:.4f} | {final['p_rand'] - rate:+.4f} |"
                  f" {final['p_hit']:.3f} | {final['p_max']:.3f} | {len(m.stats['calibration']['rounds']) - 1} |"
                  f" {truth.forward.sigma:.4f}, {truth.forward.p_rand:.4f} | {'yes' if ok else 'NO'} |")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
