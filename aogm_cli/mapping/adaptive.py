"""The paper's adaptive mode's clusters: the bands the detector's flagged readings sweep near their
ranges (``find_clusters``), and EM's problem over the cluster cells with every other cell held at the
thresholded standard map (``cluster_problems``); ``view.joined_view`` draws the map."""

from __future__ import annotations

import numpy as np

from aogm_cli.core.log import Log
from aogm_cli.mapping.cluster import grown, label_clusters, near_occupied, readings_near_clusters
from aogm_cli.mapping.em import EMProblem, ProblemFor, em_problem, em_readings, find_root
from aogm_cli.mapping.params import EMConfig, MapParams
from aogm_cli.mapping.plan import CONE, Plan
from aogm_cli.mapping.standard import occupied_evidence
from aogm_cli.sensor_models.readings import LaidOutReadings, cone_bands

BAND_BELOW = 0.2  # m: a flagged reading's band starts this far before its range
NEAR_OCCUPIED = 0  # cells (8-connected) from a cell the standard map holds occupied that a band may mark


def cluster_problem(run: LaidOutReadings, clusters: np.ndarray, occupied: np.ndarray, config: EMConfig,
                    subset: np.ndarray | None = None) -> EMProblem:
    """EM's problem inside ``clusters`` (ids, 0 outside): the readings whose cones could reach a
    cluster cell (``cluster.readings_near_clusters``; of those ``subset`` marks, if given), under
    the flat map ``occupied``, with which clusters share a reading."""
    near = readings_near_clusters(clusters, run.rows, run.cols, run.z, run.grid, run.sensor.max_range, config.forward)
    if subset is not None:
        near = near[subset[near]]
    rd = em_readings(run.cones, run.templates, run.grid, run.sensor.max_range,
                     config.forward, select=near, shadow=run.shadow)
    return em_problem(rd, run.templates, run.grid.shape, occupied, config, labels=clusters.reshape(-1))


def coupled_groups(problem: EMProblem, n_clusters: int) -> int:
    """How many groups of coupled clusters (clusters joined through a reading whose cone holds
    cells of both): independent problems, which one EM run over every cluster solves at once."""
    parent = problem.parent
    roots = {int(find_root(parent, k)) for k in range(1, n_clusters + 1)}
    return len(roots)


def contested_cells(log: Log, grid, params: MapParams, log_odds: np.ndarray,
                    shadow: np.ndarray | None = None) -> np.ndarray:
    """Cells (H, W) whose occupied evidence alone reaches ``adaptive.contested`` log-odds but
    which the standard map holds free: where the readings disagree and the standard
    map cannot explain them (walls that specular or multipath readings, too long, cleared).
    One more standard pass, with the inverse model's free evidence set to nothing (and the
    deflected beams, ``shadow``, stopped: they hit nothing)."""
    cuts = None if shadow is None else shadow.reshape(np.shape(log.ranges))
    return (occupied_evidence(log, grid, params, cuts) >= params.adaptive.contested) & (log_odds <= 0)


def find_clusters(run: LaidOutReadings, flags: np.ndarray, standard, params: MapParams, plan: Plan,
                  log: Log | None = None) -> tuple[np.ndarray, int]:
    """(cluster ids (H, W), count): a flagged cone's band near its range, z - BAND_BELOW ..
    z + alpha, where the map ``standard`` (``state.StandardMap``) holds cells occupied (the
    walls EM may thin or open, a doorway), and as ``plan.outside`` says:

    * "thinned" (the thinned map outside, its free cells no reading holds free unknown): the cells
      the thinned map holds free but the exact inverse model holds occupied by ``adaptive.contested``
      log-odds or more (walls that too-long specular or multipath readings cleared), from the exact
      model's evidence the thinning computed; then every cluster grown by one cell into the wall
      layers the thinning removed (Elfes' map holds them occupied, and EM starts there from it:
      ``stages.start``);
    * "elfes" (Elfes' map outside the clusters): the ``contested`` cells (``contested_cells``,
      one more standard pass over ``log``) and the ``weak`` ones, whose log-odds lie within
      ``adaptive.weak`` of the prior (space behind a wall that one random reading crossed), all
      grown by ``adaptive.grow`` cells (8-connected; sonar cones only: growing cost the intel laser
      log's held-out AUC, docs/algorithms.md)."""
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
        if config.contested > 0:
            region |= contested_cells(log, run.grid, params, log_odds, run.shadow) & observed
        if config.weak > 0:
            region |= observed & (np.abs(log_odds - params.inverse_model.l0) < config.weak)
        grow = config.grow if plan.sensor == CONE else 0
    return label_clusters(observed & grown(region, grow))


def cluster_problems(run: LaidOutReadings, clusters: np.ndarray) -> ProblemFor:
    """The adaptive mode's problems: EM over every cluster cell at once (``cluster_problem``),
    every other cell held at the map it is given; with ``em.start`` "empty", the cluster cells
    start free. Clusters that share no reading are independent (as the paper has them): one run
    gives each its own result."""
    cells = np.flatnonzero(clusters.reshape(-1) > 0)

    def problem_for(config: EMConfig, occ: np.ndarray, subset: np.ndarray | None):
        if config.start == "empty":
            occ[cells] = False
        return cluster_problem(run, clusters, occ, config, subset), cells

    return problem_for


def near_clusters(run: LaidOutReadings, clusters: np.ndarray, forward) -> np.ndarray:
    """Bool mask of the readings whose cones reach a cluster: those the model is fitted on, the
    ones EM explains (outside the clusters the thresholded standard map stands, and readings
    crossing its thick walls look random)."""
    near = np.zeros(run.z.size, dtype=bool)
    near[readings_near_clusters(clusters, run.rows, run.cols, run.z, run.grid, run.sensor.max_range, forward)] = True
    return near
