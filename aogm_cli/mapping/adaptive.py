"""The adaptive mode's clusters (``find_clusters``: the bands the detector's flagged readings sweep near their
ranges) and EM's problem over them, every other cell held at the thresholded standard map (``cluster_problems``)."""

from __future__ import annotations

import numpy as np

from aogm_cli.core.log import Log
from aogm_cli.mapping.cluster import grown, label_clusters, near_occupied, readings_near_clusters
from aogm_cli.mapping.em import EMProblem, ProblemFor, run_problem
from aogm_cli.mapping.em_kernels.likelihood import _find
from aogm_cli.mapping.params import EMConfig, MapParams
from aogm_cli.mapping.plan import CONE, Plan
from aogm_cli.mapping.standard import occupied_evidence
from aogm_cli.sensor_models.readings import LaidOutReadings, cone_bands

BAND_BELOW = 0.2  # m: a flagged reading's band starts this far before its range
NEAR_OCCUPIED = 0  # cells (8-connected) from a cell the standard map holds occupied that a band may mark


def coupled_groups(problem: EMProblem, n_clusters: int) -> int:
    """How many groups of clusters coupled through shared readings (union-find roots): the independent problems."""
    return len({_find(problem.parent, k) for k in range(1, n_clusters + 1)})


def find_clusters(run: LaidOutReadings, flags: np.ndarray, standard, params: MapParams, plan: Plan,
                  log: Log | None = None) -> tuple[np.ndarray, int]:
    """(cluster ids (H, W), count): a flagged cone's band z - BAND_BELOW .. z + alpha where ``standard``
    holds cells occupied (the walls EM may thin or open), and as ``plan.outside`` says: "thinned", the
    cells the exact model's evidence holds occupied by ``adaptive.contested`` but the thinned map free,
    then one cell into the wall layers thinning removed (EM starts there from Elfes' map); "elfes", the
    contested cells the standard map holds free and the ``weak`` ones near the prior (space behind a wall one random reading
    crossed), grown by ``adaptive.grow`` (cones only: it cost the intel laser log's AUC, docs/algorithms.md)."""
    log_odds, observed, config = standard.log_odds, standard.observed, params.adaptive
    region, _ = cone_bands(run.grid, run.templates, tuple(a[flags] for a in run.cones),
                           BAND_BELOW, params.inverse_model.alpha)
    region &= observed & (log_odds > params.inverse_model.clamp_min)
    region &= near_occupied(log_odds, NEAR_OCCUPIED)
    grow = 0
    if plan.outside == "thinned":
        if config.contested > 0 and standard.evidence is not None:
            region |= observed & (log_odds <= 0) & (standard.evidence >= config.contested)
        if standard.elfes is not None:  # the inner layers: EM, not the exact model, thins a wall it works on
            region |= grown(region, 1) & observed & (standard.elfes > 0) & (log_odds <= 0)
    else:
        if config.contested > 0:  # cleared walls: occupied evidence by ``contested`` the standard map holds free
            cuts = None if run.shadow is None else run.shadow.reshape(np.shape(log.ranges))
            region |= (occupied_evidence(log, run.grid, params, cuts) >= config.contested) & (log_odds <= 0) & observed
        if config.weak > 0:
            region |= observed & (np.abs(log_odds - params.inverse_model.l0) < config.weak)
        grow = config.grow if plan.sensor == CONE else 0
    return label_clusters(observed & grown(region, grow))


def cluster_problems(run: LaidOutReadings, clusters: np.ndarray) -> ProblemFor:
    """EM over every cluster cell at once, the others held; clusters sharing no reading are independent results."""
    cells = np.flatnonzero(clusters.reshape(-1) > 0)
    def problem_for(config: EMConfig, occ: np.ndarray, subset: np.ndarray | None):
        """EM's problem inside ``clusters`` over the readings whose cones could reach them, under ``occ``."""
        near = readings_near_clusters(clusters, run.rows, run.cols, run.z, run.grid, run.sensor.max_range,
                                      config.forward)
        if subset is not None:
            near = near[subset[near]]
        return run_problem(run, config, near, occ, labels=clusters.reshape(-1)), cells
    return problem_for


def near_clusters(run: LaidOutReadings, clusters: np.ndarray, forward) -> np.ndarray:
    """Bool mask of the readings whose cones reach a cluster, the ones the model is fitted on (readings
    crossing the thick walls outside look random)."""
    near = np.zeros(run.z.size, dtype=bool)
    near[readings_near_clusters(clusters, run.rows, run.cols, run.z, run.grid, run.sensor.max_range, forward)] = True
    return near
