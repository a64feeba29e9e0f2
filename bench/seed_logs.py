"""The benchmarks' inputs: the paper's two seed worlds simulated with seed 1 into a temporary folder."""

from __future__ import annotations

import sys
import tempfile
from collections.abc import Callable
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from aogm_cli.io.logfile import write_log
from aogm_cli.simulation.sonar import simulate  # noqa: E402
from aogm_cli.world.loader import load_world  # noqa: E402

SEED_WORLDS = ("corridor_door", "corridor_specular")


def for_each_seed_log(bench: Callable[[str, Path], None]) -> None:
    """Call ``bench(world_name, log_path)`` for each seed world's simulated log."""
    with tempfile.TemporaryDirectory() as folder:
        for world in SEED_WORLDS:
            log_path = Path(folder) / f"{world}.h5"
            write_log(log_path, simulate(load_world(ROOT / "worlds" / f"{world}.yaml"), seed=1))
            bench(world, log_path)
