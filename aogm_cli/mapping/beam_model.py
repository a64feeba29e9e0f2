"""What the log says of its beam before EM: its detection lobe (``lobe_record``, ``heard_run``) and the angle of
incidence: the echoes' surfaces and the beams deflected beyond ``em.specular_deg`` (``surfaces``, ``deflected_run``)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from aogm_cli.core.log import Log
from aogm_cli.mapping.params import MapParams
from aogm_cli.mapping.standard import ExactPass, echo_walls, exact_pass, thin_pass
from aogm_cli.sensor_models.cone import flat_offsets
from aogm_cli.sensor_models.forward_model import ForwardModelConfig
from aogm_cli.sensor_models.heard import heard_templates
from aogm_cli.sensor_models.lobe import Lobe, learn_lobe
from aogm_cli.sensor_models.readings import LaidOutReadings, forward_templates
from aogm_cli.sensor_models.surface import reading_shadows, surface_normals

# the scans the lobe's walls are made of (``lobe_walls``): its two passes cost 1.6 s of a 13 s adaptive map of the
# office at 20,000 scans (``make bench-scale``); the bundled and real sonar logs have at most 651
LOBE_SCANS = 2000


def surfaces(run: LaidOutReadings, log_odds: np.ndarray) -> np.ndarray:
    """The surfaces the echoes came from (``surface.surface_normals``) among the standard map's walls."""
    grid = run.grid
    believed = np.asarray(log_odds).reshape(grid.shape) > 0
    return surface_normals(run.templates.kernel_arrays, flat_offsets(run.templates, grid.width), grid.shape,
                           run.cones, run.sensor.max_range, grid.resolution, believed)


def deflected_run(run: LaidOutReadings, normals: np.ndarray, params: MapParams) -> LaidOutReadings | None:
    """``run`` with beams that met a surface beyond the specular angle stopped there (None: no such beam)."""
    shadow = reading_shadows(run, normals, params.em.forward, params.surface.core)
    if not np.isfinite(shadow).any():
        return None
    return dataclasses.replace(run, shadow=shadow)


def lobe_walls(whole: Log, run: LaidOutReadings, params: MapParams, log_odds: np.ndarray,
               observed: np.ndarray, walls: np.ndarray | None = None,
               exact: ExactPass | None = None) -> tuple[np.ndarray, ExactPass | None]:
    """(H * W) bool: the walls the lobe is learned at: the standard map's ``log_odds`` and the cells occupied
    evidence alone makes walls (``standard.echo_walls``; ``walls``: those of the whole log, made already),
    thinned by the exact inverse model (``exact``: its pass of the whole log, made already); the evidence and
    the thinning of at most ``LOBE_SCANS`` scans spread over the log (every scan of the bundled and real logs).
    And the exact pass of the whole log it made or took (None: it took fewer scans)."""
    cuts = run.cuts
    every = max(1, math.ceil(whole.n_scans / LOBE_SCANS))
    if every > 1:
        whole = dataclasses.replace(whole, time=whole.time[::every], pose=whole.pose[::every],
                                    ranges=whole.ranges[::every])
        cuts = None if cuts is None else cuts[::every]
        walls = exact = None
    log_odds = echo_walls(whole, run.grid, params, log_odds, cuts) if walls is None else walls
    if exact is None or not exact.made_with(params, whole, cuts):
        exact = exact_pass(whole, run.grid, params, cuts)
    thinned = thin_pass(whole, run.grid, params, log_odds, observed, cuts, exact=exact).log_odds > 0
    return thinned.reshape(-1), exact if every == 1 else None


def lobe_record(run: LaidOutReadings, params: MapParams, walls: np.ndarray) -> Lobe:
    """The detection lobe (``lobe.learn_lobe``) of ``run``'s readings at ``walls`` (``lobe_walls``), an echo
    within EM's window (``window`` sigmas) of a wall cell explained by it."""
    forward = params.em.forward
    return learn_lobe(run.templates, run.grid, run.cones, walls, float(run.sensor.max_range),
                      float(forward.window * forward.sigma))


def heard_run(run: LaidOutReadings, forward: ForwardModelConfig) -> LaidOutReadings:
    """``run`` with its cones' unheard cells marked (``heard.heard_templates``) for EM and calibration, from the
    whole cones (a lobe learned replaces one configured; the whole cone learned undoes it)."""
    templates = heard_templates(forward_templates(run.grid, run.sensor), forward.lobe_deg, forward.lobe_range)
    return run if templates is run.templates else dataclasses.replace(run, templates=templates)
