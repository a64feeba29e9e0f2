"""Study: can a map fit the forward model's building part (p_hit, p_max) or a new robot's sensor part
(sigma, p_rand) in one E-step pass at a map made before EM, instead of calibration rounds?

Run as ``python bench/building_fit_study.py LOG.h5 ...``. For each log (em mode's stages up to ``rates``:
the lobe learned, the packaged detector's carried model if any), fits at the lobe's walls
(``beam_model.lobe_walls``: the thinned standard map with echo evidence) on 1000 and 4000 readings, and
prints the fits beside the model in use; then the calibration rounds' model (``calibration.carried``
false), the values EM's maps are made with. docs/algorithms.md, "The building's part of the model".
"""

from __future__ import annotations

import argparse
import dataclasses

import numpy as np

from aogm_cli.io.logfile import LogReader
from aogm_cli.map_files import carried_model, map_file, resolve_detector, resolve_params
from aogm_cli.mapping import beam_model as B
from aogm_cli.mapping.calibration import fit_at_map, sample_readings
from aogm_cli.mapping.modes import Flagger, planned, resolved_params
from aogm_cli.mapping.runner import run_stages
from aogm_cli.mapping.stages import RATES_START

KEYS = ("sigma", "p_rand", "p_hit", "p_max")


def fits(path: str) -> list[str]:
    with LogReader(path) as reader:
        log = reader.read()
    params = resolved_params(log, resolve_params())
    detector, record = resolve_detector(None)
    given = carried_model(None, log.sensor, log.truth is not None, detector)
    stages, state = planned(log, "em", params, Flagger(detector, record), None, given)
    names = [s.name for s in stages]
    state, _ = run_stages(stages[:names.index("rates") if "rates" in names else names.index("region")], state)
    walls, _ = B.lobe_walls(state.whole, state.readings, state.in_use, state.standard.log_odds, state.standard.observed)
    forward = state.in_use.em.forward
    lines = [f"in use ({state.learned.origin}): " + " ".join(f"{k} {getattr(forward, k):.3f}" for k in KEYS)]
    for n in (1000, 4000):
        for learn in ("p_hit,p_max", "sigma,p_rand,p_hit,p_max"):
            config = dataclasses.replace(params.calibration, learn=learn)
            start = dataclasses.replace(forward, p_max=max(forward.p_max, RATES_START))
            fit = fit_at_map(state.readings, sample_readings(state.readings, n), np.ascontiguousarray(walls), start,
                             config, loglik=False).forward
            lines.append(f"one pass at the walls, {n} readings, {learn}: "
                         + " ".join(f"{k} {getattr(fit, k):.3f}" for k in KEYS))
    rounds = map_file(path, "em", dataclasses.replace(params, calibration=dataclasses.replace(params.calibration,
                                                                                              carried=False)))
    lines.append("calibration rounds: " + " ".join(f"{k} {rounds.learned['sensor'][k]:.3f}" for k in KEYS))
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("logs", nargs="+")
    for path in parser.parse_args().logs:
        print(path)
        for line in fits(path):
            print("   ", line)


if __name__ == "__main__":
    main()
