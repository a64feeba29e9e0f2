"""Which readings a sonar map deflects (docs/algorithms.md, "Why 15 degrees, and not learned"): per simulated log,
the readings whose beam core meets a surface beyond the specular angle before their echo, by what the simulator
says caused each reading, and how many of the points where they stop lie near a true wall.

    python bench/deflections.py [--params P.yaml] LOG.h5 [LOG.h5 ...]

Per log, the em mode's stages up to ``deflections`` (with the model the packaged detector carries, as ``aogm map``
takes it) and ``beam_model.deflected_run`` at the map's specular angle; the deflected readings counted by
``/truth/cause`` (0 echo of the nearest surface, 1 no echo, 2 random, 3 specular or multipath), beside every
reading's; and the deflection points (on the beam's axis at the range it stops) within one cell of a cell the
truth holds occupied.
"""

from __future__ import annotations

import argparse
import math

import numpy as np
from scipy.ndimage import binary_dilation

from aogm_cli.io.logfile import LogReader
from aogm_cli.map_files import resolve_params, sensor_model
from aogm_cli.mapping import beam_model as B
from aogm_cli.mapping.modes import resolved_params, state_before


def deflections(log_path: str, params_file: str | None) -> str:
    with LogReader(log_path) as reader:
        log = reader.read()
    params = resolved_params(log, resolve_params(params_file))
    s = state_before(log, "em", params, "deflections", given=sensor_model("em", params, log, log_path))
    run = B.deflected_run(s.readings, B.surfaces(s.readings, s.in_use, s.standard.log_odds), s.in_use)
    cause = np.asarray(log.truth.cause).reshape(-1)
    every = np.bincount(cause, minlength=4).tolist()
    if run is None:
        return f"{log_path}: {cause.size} readings, none deflected (specular angle {s.in_use.em.forward.specular_deg:g})"
    t = np.flatnonzero(np.isfinite(run.shadow))
    grid = s.grid
    heading = 2.0 * math.pi * run.bins.reshape(-1)[t] / run.templates.base_bin.shape[0]
    steps = run.shadow[t] / grid.resolution
    rows = np.clip(np.round(run.rows.reshape(-1)[t] + steps * np.sin(heading)).astype(np.int64), 0, grid.height - 1)
    cols = np.clip(np.round(run.cols.reshape(-1)[t] + steps * np.cos(heading)).astype(np.int64), 0, grid.width - 1)
    near_wall = binary_dilation(np.asarray(log.truth.occupancy) != 0)[rows, cols]
    return (f"{log_path}: {cause.size} readings, {t.size} deflected (specular angle "
            f"{s.in_use.em.forward.specular_deg:g}); by cause (echo, no echo, random, specular) "
            f"{np.bincount(cause[t], minlength=4).tolist()} of {every}; stopped within a cell of a true wall "
            f"{int(near_wall.sum())}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("logs", nargs="+")
    parser.add_argument("--params", help="a parameter file, as aogm map --params takes it")
    args = parser.parse_args()
    for path in args.logs:
        print(deflections(path, args.params))


if __name__ == "__main__":
    main()
