"""Benchmark: EM's problem set-up (the ``index`` phase) on the two seed worlds, on one thread.

Run as ``python bench/bench_em_index.py [--calls 60]``. For corridor_door and corridor_specular (seed
1) it times, best and median of ``--calls`` calls each: ``em.em_readings`` over every reading,
``em.em_problem`` under an empty map (one walk of every cone, ``em_kernels.likelihood._init_state``),
the same with cluster labels (every 7th cell a cluster: the union-find and the narrowed extents), and
``_init_state`` alone over every reading. Compare two checkouts by running it in each, alternately.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from seed_logs import em_inputs, for_each_seed_log

from aogm_cli.core.budget import Limits, using
from aogm_cli.map_files import resolve_params
from aogm_cli.mapping import em as E
from aogm_cli.mapping.em_kernels.likelihood import _init_state
from aogm_cli.sensor_models.cone import flat_offsets


def timed(call, calls: int) -> str:
    seconds = []
    for _ in range(calls):
        t0 = time.perf_counter()
        call()
        seconds.append(time.perf_counter() - t0)
    return f"best {min(seconds) * 1e3:7.3f} ms, median {np.median(seconds) * 1e3:7.3f} ms"


def bench_world(world: str, log_path, calls: int) -> None:
    inputs = em_inputs(log_path, resolve_params())
    run, config = inputs.readings, inputs.params.em
    grid = run.grid
    keep = ~np.isnan(run.z)
    empty = np.zeros(grid.height * grid.width, dtype=bool)
    labels = (np.arange(grid.height * grid.width) % 7 == 0).astype(np.int64)

    def readings():
        return E.em_readings(run.cones, run.templates, grid, run.sensor.max_range, config.forward, select=keep)

    rd = readings()
    problem = E.em_problem(rd, run.templates, grid.shape, empty.copy(), config)
    n = rd.ints.shape[0]
    marks = (np.zeros(grid.height * grid.width, dtype=bool), np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64),
             np.zeros((0, 4), dtype=np.int32))
    flat = flat_offsets(run.templates, grid.width)
    rows = (("em_readings", readings),
            ("em_problem", lambda: E.em_problem(rd, run.templates, grid.shape, empty.copy(), config)),
            ("em_problem, clusters", lambda: E.em_problem(rd, run.templates, grid.shape, empty.copy(), config,
                                                          labels=labels)),
            ("_init_state", lambda: _init_state(run.templates.kernel_arrays, flat, rd, problem.model, empty, grid.shape,
                                                marks, (0, n))))
    print(f"{world} ({n} readings, one thread)")
    with using(Limits(threads=1)):
        for name, call in rows:
            print(f"  {name:22s} {timed(call, calls)}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--calls", type=int, default=60, help="calls timed per row (default 60)")
    args = parser.parse_args()
    for_each_seed_log(lambda world, path: bench_world(world, path, args.calls))


if __name__ == "__main__":
    main()
