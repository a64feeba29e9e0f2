"""Compile aogm's numba kernels into their on-disk cache before the test workers start (``make test``).

Run as ``python tests/warm_kernels.py em DIR`` and ``python tests/warm_kernels.py rest DIR`` at
once (``make kernels``): two processes compile two disjoint halves (EM's kernels and
calibration's; the simulator's, which writes corridor_door's log into DIR for the other to map
with EM, the laser's, the exact model's, the held-out scores' and the consistency's),
where every pytest worker would otherwise compile nearly all of them itself on a clean clone, both
cores compiling the same kernels. Nothing is asserted: a test that needs a kernel compiles it
anyway if this did not.
"""

from __future__ import annotations

import dataclasses
import math
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def sonar():
    """Two sonars at right angles."""
    from aogm_cli.core.log import SensorSpec

    return SensorSpec(mount=np.array([[0.1, 0.0, 0.0], [0.0, 0.1, math.pi / 2]]))


def warm_em(folder: str) -> None:
    from aogm_cli.io.logfile import LogReader
    from aogm_cli.map_files import resolve_params
    from aogm_cli.mapping.modes import map_in_mode, warm_up

    warm_up(sonar(), resolve_params(), "adaptive")
    path = handed(folder, "corridor_door")  # simulated by the other process (the simulator compiled once)
    # calibrated on the log (the detector carries a model for this ring: with it the log would not calibrate)
    with LogReader(path) as reader:
        map_in_mode(reader, "em", resolve_params(None, {"calibration": {"carried": False}}))


def warm_standard(path: Path) -> None:
    """The thinned standard map (the exact model's kernel), held-out scores and the map's
    consistency with the log, on the log at ``path``."""
    from aogm_cli.evaluation.consistency import map_consistency
    from aogm_cli.evaluation.holdout import HoldoutSplit, holdout_scores, split_log
    from aogm_cli.io.logfile import LogReader
    from aogm_cli.map_files import resolve_params
    from aogm_cli.mapping.modes import map_source

    params = resolve_params()
    thin = dataclasses.replace(params, exact=dataclasses.replace(params.exact, thin=True))
    with LogReader(path) as reader:
        m = map_source(reader, "standard", thin)
        split = HoldoutSplit(0.1, 1)
        kept, _ = split_log(reader, split)
        holdout_scores(reader, map_source(kept, "standard", params), split)
    map_consistency(str(path), m)


def simulated(folder: str, world: str) -> Path:
    """The log of ``world`` at seed 1 in ``folder``, written whole before it appears there."""
    from aogm_cli.io.logfile import write_log
    from aogm_cli.simulation.sonar import simulate
    from aogm_cli.world.loader import load_world

    path = Path(folder) / f"{world}.h5"
    part = path.with_suffix(".part")
    write_log(part, simulate(load_world(ROOT / "worlds" / f"{world}.yaml"), seed=1))
    part.replace(path)
    return path


def handed(folder: str, world: str, wait: float = 600.0) -> Path:
    """``simulated(folder, world)`` as the other process writes it (simulated here if it does not
    appear within ``wait`` seconds)."""
    path = Path(folder) / f"{world}.h5"
    deadline = time.monotonic() + wait
    while not path.exists() and time.monotonic() < deadline:
        time.sleep(0.2)
    return path if path.exists() else simulated(folder, world)


def warm_rest(folder: str) -> None:
    from aogm_cli.core.log import SensorSpec
    from aogm_cli.map_files import resolve_params
    from aogm_cli.mapping.modes import map_in_mode, tiny_log

    door = simulated(folder, "corridor_door")  # first: the other process maps it with EM
    params = resolve_params()
    laser = SensorSpec(mount=np.array([[0.0, 0.0, 0.0]]), kind="laser", beam_width=math.radians(0.5), min_range=0.0,
                       max_range=8.0, noise_sigma=0.01)
    map_in_mode(tiny_log(laser), "standard", params)
    warm_standard(door)
    for world in ("corridor_door_real", "cluttered_lab_real", "cluttered_lab_pioneer"):
        simulated(folder, world)  # the simulator with errors, side lobes and sequential firing


if __name__ == "__main__":
    from aogm_cli.cli import keep_cone_templates

    keep_cone_templates()  # the templates built here are kept on disk for the test workers, as a command keeps them
    if len(sys.argv) > 2:  # the folder both processes share (make kernels)
        {"em": warm_em, "rest": warm_rest}[sys.argv[1]](sys.argv[2])
    else:
        with tempfile.TemporaryDirectory() as shared:
            {"em": warm_em, "rest": warm_rest}[sys.argv[1]](shared)
