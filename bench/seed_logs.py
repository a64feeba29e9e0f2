"""The benchmarks' inputs: the paper's two seed worlds simulated with seed 1 into a temporary
folder, and a log's readings laid out as EM and adaptive mapping take them (``em_inputs``)."""

from __future__ import annotations

import tempfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from aogm_cli.io.logfile import LogReader, write_log
from aogm_cli.mapping.em import pair_index
from aogm_cli.mapping.em_kernels import EMModel, PairIndex, SweepStamps
from aogm_cli.mapping.modes import resolved_params, warm_up
from aogm_cli.mapping.params import EMConfig, MapParams
from aogm_cli.mapping.pipeline import Readings, forward_templates, lay_out_readings, log_grid
from aogm_cli.mapping.sensor_models.forward_model import ForwardIndex
from aogm_cli.mapping.standard import standard_pass
from aogm_cli.simulation.sonar import simulate
from aogm_cli.world.loader import load_world

ROOT = Path(__file__).resolve().parents[1]
SEED_WORLDS = ("corridor_door", "corridor_specular")


def for_each_seed_log(bench: Callable[[str, Path], None]) -> None:
    """Call ``bench(world_name, log_path)`` for each seed world's simulated log."""
    with tempfile.TemporaryDirectory() as folder:
        for world in SEED_WORLDS:
            log_path = Path(folder) / f"{world}.h5"
            write_log(log_path, simulate(load_world(ROOT / "worlds" / f"{world}.yaml"), seed=1))
            bench(world, log_path)


@dataclass
class EMInputs:
    """What EM and adaptive mapping hold before their own work starts (as ``mapping.em.map_em``)."""

    params: MapParams  # as ``modes.map_file`` resolves them for the log
    readings: Readings
    log_odds: np.ndarray
    observed: np.ndarray
    t_standard: float  # the standard pass's own clock


def em_inputs(log_path: Path, params: MapParams) -> EMInputs:
    """Compile every kernel of the em mode, run its (timed) standard pass over the whole log held
    in memory and lay out every reading (``pipeline.lay_out_readings``), as ``map_em`` does."""
    with LogReader(log_path) as reader:
        params = resolved_params(reader, params)
        sensor = reader.sensor
        warm_up(sensor, params, "em")
        grid = log_grid(reader, params.resolution)
        whole = reader.read()
        log_odds, observed, t_standard = standard_pass(reader, grid, params,
                                                       chunks=[(0, whole.time, whole.pose, whole.ranges)])
    forward_templates(grid, sensor)  # one-time set-up, cached
    readings = lay_out_readings(whole.pose, whole.ranges, sensor, grid)
    return EMInputs(params, readings, log_odds, observed, t_standard)


def em_kernel_inputs(index: ForwardIndex, candidates: np.ndarray, config: EMConfig) -> tuple[PairIndex, EMModel]:
    """The cell -> readings index of ``candidates`` and the model's constants, as ``em.run_em``
    builds them for its kernels (``em_kernels``)."""
    p_hit = float(config.forward.p_hit)
    max_entries = int(np.max(np.diff(index.ptr))) if index.n_readings else 0
    model = EMModel(p_hit, float(config.l_prior), (1.0 - p_hit) ** np.arange(max_entries + 1, dtype=np.float64))
    return pair_index(index, candidates), model


def sweep_stamps(index: ForwardIndex, pairs: PairIndex) -> SweepStamps:
    """Fresh bookkeeping for the sweeps, as ``em.run_em`` starts them."""
    n_cand = pairs.cand_cell.shape[0]
    return SweepStamps(np.zeros(index.n_readings, dtype=np.int64), np.full(n_cand, -1, dtype=np.int64),
                       np.zeros(1, dtype=np.int64), np.zeros(n_cand, dtype=np.float64))
