"""Compile aogm's numba kernels into their on-disk cache before the test workers start (``make test``).

Run as ``python tests/warm_kernels.py em`` and ``python tests/warm_kernels.py rest`` at once: two
processes compile two disjoint halves (EM's kernels; the simulator's, the standard, laser and
exact mappers' and the scores'), where every pytest worker would otherwise compile nearly all of
them itself on a clean clone, both cores compiling the same kernels. Nothing is asserted: a test
that needs a kernel compiles it anyway if this did not.
"""

from __future__ import annotations

import dataclasses
import math
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def sonar():
    """Two sonars at right angles."""
    from aogm_cli.core.log import SensorSpec

    return SensorSpec(mount=np.array([[0.1, 0.0, 0.0], [0.0, 0.1, math.pi / 2]]))


def warm_em() -> None:
    from aogm_cli.io.logfile import LogReader
    from aogm_cli.mapping.modes import map_in_mode, warm_up
    from aogm_cli.report.map_run import resolve_params

    warm_up(sonar(), resolve_params(), "adaptive", single=False)  # the other process compiles the single reading's
    with tempfile.TemporaryDirectory() as folder:  # learning the beam's opening and the specular angle at walls
        learn = {"calibration": {"learn": "sigma,p_rand,p_hit,p_max,specular_deg,opening_deg", "rounds": 1}}
        with LogReader(simulated(folder, "corridor_door")) as reader:
            map_in_mode(reader, "em", resolve_params(None, learn))


def simulated(folder: str, world: str) -> Path:
    from aogm_cli.io.logfile import write_log
    from aogm_cli.simulation.sonar import simulate
    from aogm_cli.world.loader import load_world

    path = Path(folder) / f"{world}.h5"
    write_log(path, simulate(load_world(ROOT / "worlds" / f"{world}.yaml"), seed=1))
    return path


def warm_rest() -> None:
    from aogm_cli.core.log import SensorSpec
    from aogm_cli.evaluation.consistency import map_consistency
    from aogm_cli.evaluation.holdout import HoldoutSplit, holdout_scores, split_log
    from aogm_cli.io.logfile import LogReader
    from aogm_cli.mapping.modes import map_in_mode, map_source, tiny_log, warm_single
    from aogm_cli.report.map_run import resolve_params

    params = resolve_params()
    warm_single(sonar(), params)  # EM's kernels for one reading, while the other process compiles them for many
    thin = dataclasses.replace(params, exact=dataclasses.replace(params.exact, thin=True))
    laser = SensorSpec(mount=np.array([[0.0, 0.0, 0.0]]), kind="laser", beam_width=math.radians(0.5), min_range=0.0,
                       max_range=8.0, noise_sigma=0.01)
    map_in_mode(tiny_log(laser), "standard", params)
    with tempfile.TemporaryDirectory() as folder:
        path = simulated(folder, "corridor_door")
        for world in ("corridor_door_real", "cluttered_lab_real", "cluttered_lab_pioneer"):  # the simulator with errors, side lobes and sequential firing
            simulated(folder, world)
        with LogReader(path) as reader:
            m = map_source(reader, "standard", thin)
            split = HoldoutSplit(0.1, 1)
            kept, _ = split_log(reader, split)
            holdout_scores(reader, map_source(kept, "standard", params), split)
        map_consistency(str(path), m)


if __name__ == "__main__":
    from aogm_cli.cli import keep_cone_templates

    keep_cone_templates()  # the templates built here are kept on disk for the test workers, as a command keeps them
    {"em": warm_em, "rest": warm_rest}[sys.argv[1]]()
