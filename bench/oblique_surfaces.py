"""What incidence in EM's heard test might give (docs/algorithms.md, "The lobe that hears"), emulated after the
fact: surface cells an em map shows free although none of its readings passed them in the lobe's heard region
within ANGLE degrees of their normal are shown as the standard map has them, and the map scored again.

    python bench/oblique_surfaces.py [--params P.yaml] [--angle A ...] LOG.h5 EM_MAP.h5 [LOG.h5 EM_MAP.h5 ...]

Per log: the em mode's stages up to ``sweeps`` with ``--params`` (the map's own readings, lobe, deflections and
standard map, as ``aogm map --mode em`` made them with the same parameters), the surfaces of ``beam_model.surfaces``
and, per angle, the cells given back: a surface (a normal), a wall in the standard map (log-odds > 0), free in
the em map, and no heard pass met it within the angle of its normal (``surface.hidden``), ``MARGIN`` before the
reading's range or deflection. Prints leak and block (``planner_metrics``, a 0.2 m disk) as is and with them.
An emulation, not the model: EM with incidence would weigh those cells' head-on readings itself.
"""

from __future__ import annotations

import argparse

import numba
import numpy as np

from aogm_cli.evaluation.planner import ROBOT_RADIUS, planner_metrics
from aogm_cli.io.logfile import LogReader
from aogm_cli.io.mapfile import read_map_file
from aogm_cli.map_files import resolve_params, sensor_model
from aogm_cli.mapping import beam_model as B
from aogm_cli.mapping.modes import resolved_params, state_before
from aogm_cli.mapping.standard import probability_from_log_odds
from aogm_cli.sensor_models.cone import flat_offsets, unheard
from aogm_cli.sensor_models.surface import cone_walk, cos2_of, hidden

MARGIN = 0.1  # m: a pass ends this far before the reading's range (``surface.head_on_passes``)


@numba.njit
def heard_head_on(tpl, flat, shape, readings, ends, normal, cos2, out):
    """out[c] += 1 for every reading whose heard cells up to ends[t] hold surface cell c within the angle."""
    rows, cols, bins = readings
    n_cells = shape[0] * shape[1]
    ib = np.empty(int(np.max(np.diff(tpl.offsets))), dtype=np.int32)
    for t in range(ends.shape[0]):
        if not ends[t] > 0.0:
            continue
        m, _ = cone_walk(tpl, flat, shape, rows[t], cols[t], bins[t], ends[t], False, ib)
        s0 = tpl.offsets[tpl.base_bin[bins[t]]]
        for j in range(m):
            c = np.int64(ib[j])
            if c < n_cells and not unheard(tpl, s0 + j) and normal[0, c] == normal[0, c] \
                    and not hidden(normal, cos2, c, rows[t], cols[t], shape[1]):
                out[c] += 1.0


def emulate(log_path: str, map_path: str, params_file: str | None, angles: list[float]) -> list[str]:
    with LogReader(log_path) as reader:
        log = reader.read()
    params = resolved_params(log, resolve_params(params_file))
    s = state_before(log, "em", params, "sweeps", given=sensor_model("em", params, log, log_path))
    run, grid = s.readings, s.grid
    normals = B.surfaces(run, s.in_use, s.standard.log_odds)
    z = np.where(np.isnan(run.z), -np.inf, np.minimum(run.z - MARGIN, run.sensor.max_range))
    ends = z if run.shadow is None else np.minimum(z, run.shadow)
    cones = tuple(np.ascontiguousarray(a, dtype=np.int64).reshape(-1) for a in (run.rows, run.cols, run.bins))
    m = read_map_file(map_path)
    standard = probability_from_log_odds(s.standard.log_odds).reshape(-1)
    lines = []
    for angle in angles:
        passes = np.zeros(grid.height * grid.width)
        heard_head_on(run.templates.kernel_arrays, flat_offsets(run.templates, grid.width), grid.shape, cones,
                      np.ascontiguousarray(ends, dtype=np.float64).reshape(-1), normals, cos2_of(angle), passes)
        p = m.probability.reshape(-1)
        back = (normals[0] == normals[0]) & (s.standard.log_odds.reshape(-1) > 0) & (p < 0.5) & (passes == 0)
        shown = np.where(back, standard, p).reshape(grid.shape)
        observed = m.observed | back.reshape(grid.shape)
        before = planner_metrics(grid, m.probability, m.observed, log.truth.occupancy, log.poses(), ROBOT_RADIUS)
        after = planner_metrics(grid, shown, observed, log.truth.occupancy, log.poses(), ROBOT_RADIUS)
        lines.append(f"{map_path}: angle {angle:g}: leak {before['leak']:.3f} -> {after['leak']:.3f}, block "
                     f"{before['block']:.3f} -> {after['block']:.3f}; {int(back.sum())} of "
                     f"{int(np.sum(normals[0] == normals[0]))} surface cells given back")
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("pairs", nargs="+", help="LOG.h5 EM_MAP.h5 pairs")
    parser.add_argument("--params", default=None, help="the --params the em maps were made with")
    parser.add_argument("--angle", type=float, action="append", help="degrees off the normal (repeatable; 30)")
    args = parser.parse_args()
    if len(args.pairs) % 2:
        parser.error("expected LOG.h5 EM_MAP.h5 pairs")
    for log_path, map_path in zip(args.pairs[::2], args.pairs[1::2], strict=True):
        print("\n".join(emulate(log_path, map_path, args.params, args.angle or [30.0])))


if __name__ == "__main__":
    main()
