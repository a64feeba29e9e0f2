"""Benchmark: EM's set-up and each sweep against one standard pass (same run), with memory.

Run as ``python bench/bench_em.py``. Simulates corridor_door and corridor_specular (seed 1),
compiles every kernel first, then times (best of three): one standard pass over all readings
(the ceiling the paper compares with), laying out EM's readings, their likelihood state
(one walk of every cone), and each sweep; per sweep it prints the flips, the candidates
scored, the window pairs generated and the time. EM holds no (reading, cell) pair array:
the tiles' scratch at its largest is printed beside the readings' own arrays.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from seed_logs import em_inputs, for_each_seed_log, standard_pass

from aogm_cli.io.logfile import LogReader
from aogm_cli.map_files import resolve_params
from aogm_cli.mapping import em as E


def one_run(inputs):
    run, config, log_odds = inputs.readings, inputs.params.em, inputs.log_odds
    keep = ~np.isnan(run.z)
    t0 = time.perf_counter()
    rd = E.em_readings(tuple(a[keep] for a in run.cones), run.templates, run.grid, run.sensor.max_range, config.forward)
    t_readings = time.perf_counter() - t0
    occupied = np.ascontiguousarray((log_odds > 0).reshape(-1))
    t0 = time.perf_counter()
    problem = E.em_problem(rd, run.templates, run.grid.shape, occupied, config)
    t_state = time.perf_counter() - t0
    stamps = [time.perf_counter()]
    result = E.run_em(problem, occupied, np.flatnonzero(problem.seen), config,
                      lambda *_: stamps.append(time.perf_counter()))
    t_total = time.perf_counter() - stamps[0]
    return rd, t_readings, t_state, np.diff(stamps), t_total, result


def bench(world_name: str, log_path: Path) -> None:
    inputs = em_inputs(log_path, resolve_params())
    with LogReader(log_path) as reader:  # the standard pass's own clock: mapping work, no I/O
        t_std = min(standard_pass(reader, inputs.readings.grid, inputs.params)[2] for _ in range(5))
    runs = [one_run(inputs) for _ in range(3)]
    rd, _, _, _, _, result = runs[0]
    t_readings = min(r[1] for r in runs)
    t_state = min(r[2] for r in runs)
    sweeps = np.min([r[3] for r in runs], axis=0)
    t_total = min(r[4] for r in runs)
    # the readings' two tables (their state included) and the orders they enter and leave the tiles by
    readings_bytes = rd.ints.nbytes + rd.floats.nbytes + rd.enter.nbytes + rd.leave.nbytes + rd.window_leave.nbytes
    print(f"\n{world_name}: {rd.z.size} readings, {result.candidates.size} candidate cells")
    print(f"  standard pass (ceiling)    {t_std * 1e3:8.2f} ms")
    print(f"  EM's readings              {t_readings * 1e3:8.2f} ms")
    print(f"  likelihood state           {t_state * 1e3:8.2f} ms  = {t_state / t_std:5.1f} x standard pass")
    for k, seconds in enumerate(sweeps):
        print(f"  sweep {k + 1:2d}  {seconds * 1e3:8.2f} ms  = {seconds / t_std:5.1f} x standard  "
              f"flips {result.flips[k]:6d}  scored {result.scored[k]:7d}  window pairs {result.pairs[k]:8d}")
    total = t_std + t_readings + t_state + t_total
    print(f"  EM total                   {total * 1e3:8.2f} ms  = {total / t_std:5.1f} x standard pass")
    print(f"  memory: readings and state {readings_bytes / rd.z.size:6.0f} B per reading; tiles' scratch at "
          f"most {result.scratch_bytes / 1e6:.1f} MB")


def main() -> None:
    print("EM mapping benchmark (the ceiling is one standard pass over the same readings, same run)")
    for_each_seed_log(bench)


if __name__ == "__main__":
    main()
