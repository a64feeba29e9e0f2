"""What the tests read of cone templates and of a map's stages: a heading bin's yaw and cells, one reading's
cells on a grid (through the compiled ``cone.cone_cells``), and the state of a map before a stage."""

from __future__ import annotations

import numpy as np

from aogm_cli.sensor_models.cone import TWO_PI, ConeTemplates, cone_cells


def bin_heading(tpl: ConeTemplates, k):
    """Central yaw (rad, in [0, 2 pi)) of heading bin(s) ``k``."""
    return np.asarray(k, dtype=np.float64) * (TWO_PI / tpl.n_bins)


def cells(tpl: ConeTemplates, k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(drow, dcol, range, bearing) of every cell of heading bin ``k``'s cone, in range order."""
    k = int(k) % tpl.n_bins
    b = int(tpl.base_bin[k])
    a, bb, c, d = (int(v) for v in tpl.transform[k])
    s, e = int(tpl.offsets[b]), int(tpl.offsets[b + 1])
    dc, dr = tpl.dcol[s:e].astype(np.int64), tpl.drow[s:e].astype(np.int64)
    det = a * d - bb * c
    return (c * dc + d * dr, a * dc + bb * dr, tpl.ranges[s:e].copy(), det * tpl.bearings[s:e])


def reading_cells(tpl: ConeTemplates, grid, row: int, col: int, k: int, limit: float):
    """Cells (flat index, range) of one reading's cone inside ``grid``, up to ``limit`` metres."""
    if grid.resolution != tpl.resolution:
        raise ValueError(f"templates are for resolution {tpl.resolution}, grid has {grid.resolution}")
    k = int(k) % tpl.n_bins
    b = int(tpl.base_bin[k])
    size = int(tpl.offsets[b + 1] - tpl.offsets[b])
    out_index = np.empty(size, dtype=np.int64)
    out_range = np.empty(size, dtype=np.float64)
    n = cone_cells(tpl.kernel_arrays, grid.height, grid.width, int(row), int(col), k, float(limit), out_index,
                   out_range, -1.0)
    return out_index[:n], out_range[:n]


def state_before(log, mode: str, params, stage: str, given=None):
    """The state of a ``mode`` map of ``log`` just before its first stage named ``stage``."""
    from aogm_cli.mapping.modes import planned
    from aogm_cli.mapping.runner import run_stages

    stages, state = planned(log, mode, params, given=given)
    names = [s.name for s in stages]
    return run_stages(stages[:names.index(stage)], state)[0]
