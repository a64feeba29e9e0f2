"""Which detection lobe EM's own forward model prefers at the truth's map, or at EM's own map per lobe
(docs/algorithms.md, "The lobe that hears"): per simulated log, the log-likelihood of every reading, sum of
log p(z | m), for each lobe of a grid of theta0 and R0.

    python bench/lobe_likelihood.py [--own-map] [--incidence DEG] [--theta0 6,8,...] [--r0 5,6.3,...] LOG.h5 [...]

At the truth (the default): the readings, their deflections, surfaces and calibrated model are the em mode's up
to ``index`` (``aogm map --mode em`` with ``em.heard_incidence_deg`` DEG, 90: no heard test); each lobe makes its
heard templates (``heard.heard_templates``), EM's problem (``em.run_problem``) at the truth, and the sum of
log(C_t + w S_t). ``--own-map``: the likelihood profiled over the map, each lobe's at the em map ``aogm map`` makes
with that lobe configured (``em: {lobe_deg, lobe_range, heard_incidence_deg}``, ``calibration.learn`` without
``lobe_deg``): EM's final objective less its prior term. Prints the best lobes and how far each trails the first.
"""

from __future__ import annotations

import argparse
import dataclasses

import numpy as np

from aogm_cli.io.logfile import LogReader
from aogm_cli.map_files import resolve_params, sensor_model
from aogm_cli.mapping.em import run_problem
from aogm_cli.mapping.modes import resolved_params, state_before
from aogm_cli.mapping.params import CalibrationConfig
from aogm_cli.sensor_models.heard import heard_templates
from aogm_cli.sensor_models.readings import forward_templates

SHOWN = 6  # the best lobes printed per log


def likelihoods(log_path: str, incidence: float, thetas: list[float], reaches: list[float]) -> list[tuple]:
    """(log-likelihood, theta0, R0) of every lobe, best first."""
    with LogReader(log_path) as reader:
        log = reader.read()
    params = resolved_params(log, resolve_params(overrides={"em": {"heard_incidence_deg": incidence}}))
    s = state_before(log, "em", params, "index", given=sensor_model("em", params, log, log_path))
    run, config = s.readings, s.in_use.em
    truth = (np.asarray(log.truth.occupancy) != 0).reshape(-1)
    whole = forward_templates(run.grid, run.sensor)
    valid = ~np.isnan(run.z)
    out = []
    for theta0 in thetas:
        for r0 in reaches:
            lobe = dataclasses.replace(run, templates=heard_templates(whole, float(theta0), float(r0)))
            problem = run_problem(lobe, config, valid, truth.copy())
            const = problem.readings.floats["const"]
            out.append((float(np.sum(np.log(const + problem.model.w * problem.state.s))), theta0, r0))
    return sorted(out, reverse=True)


def own_map_likelihoods(log_path: str, incidence: float, thetas: list[float], reaches: list[float]) -> list[tuple]:
    """(log-likelihood at the em map made with the lobe, theta0, R0) of every lobe, best first."""
    with LogReader(log_path) as reader:
        log = reader.read()
    learn = ",".join(k for k in CalibrationConfig().learned if k != "lobe_deg")
    out = []
    for theta0 in thetas:
        for r0 in reaches:
            params = resolved_params(log, resolve_params(overrides={
                "em": {"lobe_deg": theta0, "lobe_range": r0, "heard_incidence_deg": incidence},
                "calibration": {"learn": learn}}))
            s = state_before(log, "em", params, "view", given=sensor_model("em", params, log, log_path))
            result = s.em.result
            prior = s.in_use.em.l_prior * int(np.count_nonzero(s.occupied[result.candidates]))
            out.append((float(result.objective[-1] - prior), theta0, r0))
    return sorted(out, reverse=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("logs", nargs="+")
    parser.add_argument("--own-map", action="store_true", help="at EM's own map per lobe, not the truth's")
    parser.add_argument("--incidence", type=float, default=35.0, help="em.heard_incidence_deg (90: no heard test)")
    parser.add_argument("--theta0", default="6,8,10,12,14,16", help="degrees, comma-separated")
    parser.add_argument("--r0", default="5,6.3,7.9,10,12.6,15.8", help="metres, comma-separated")
    args = parser.parse_args()
    thetas = [float(v) for v in args.theta0.split(",")]
    reaches = [float(v) for v in args.r0.split(",")]
    for path in args.logs:
        ranked = (own_map_likelihoods if args.own_map else likelihoods)(path, args.incidence, thetas, reaches)
        best = ranked[0][0]
        shown = ", ".join(f"{t:g} / {r:g} ({ll - best:+.1f})" for ll, t, r in ranked[:SHOWN])
        print(f"{path}: theta0 / R0 (log-likelihood against the best): {shown}")


if __name__ == "__main__":
    main()
