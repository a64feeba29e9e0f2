"""The forward model learned from the log it maps (Thrun 2003): closed-form updates of p_rand, p_max, p_hit and
sigma from each reading's expected cause at a binary map, alternated with EM's map (``calibration_rounds``)."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from aogm_cli.mapping.learned import SENSOR_KEYS
from aogm_cli.mapping.params import CalibrationConfig, EMConfig
from aogm_cli.sensor_models import forward_model as F
from aogm_cli.sensor_models.cone import flat_offsets
from aogm_cli.sensor_models.readings import LaidOutReadings

CAL_BLOCKS = 4  # a long log's calibration maps this many runs of consecutive scans (``_scan_blocks``)


@dataclass(frozen=True)
class Tuning:
    """How calibration works inside, fixed by measurement (docs/algorithms.md, "Where the defaults come from"):
    not a user's setting. ``TUNING`` is what every map uses; tests make their own."""

    rounds: int = 4  # rounds of an EM map and a fit at it, at most (``calibration_rounds``)
    tolerance: float = 0.02  # the rounds stop once no parameter moves by more (sigma relative; ``settled``)
    fit_iterations: int = 30  # updates of the parameters at one map (``fit_at_map``)
    max_readings: int = 200_000  # the readings fitted on (every n-th beyond: ``sample_readings``)
    start_sigma: float = 0.1  # the first EM map's sigma is at least this broad (m)
    start_sweeps: int = 3  # the first (broad) EM run's sweep limit: its map only serves the first fit
    fit_sweeps: int = 4  # the sweep limit of the later maps made for a fit (the final map: em.max_sweeps)
    subsample: int = 2  # the rounds' maps are made from every n-th scan
    start_subsample: int = 4  # and the broad first map from every n-th
    max_scans: int = 2000  # a longer log calibrates on this many scans, in CAL_BLOCKS runs
    # and on at most this many readings (a sensor of more than 32 beams: a laser's 180 a scan, 355 scans)
    max_mapped_readings: int = 64_000
    # bounds: sigma from a tenth of a 5 cm cell to half a metre; p_rand, p_max below one half (a model
    # calling most readings random or dropped explains nothing); p_hit away from 0 and 1 (EM needs
    # 1 - p_hit > 0; a wall every reading misses is no wall)
    sigma_min: float = 0.005
    sigma_max: float = 0.5
    p_rand_min: float = 0.001
    p_rand_max: float = 0.5
    p_max_max: float = 0.4
    p_hit_min: float = 0.05
    p_hit_max: float = 0.95


TUNING = Tuning()


def sample_readings(run: LaidOutReadings, max_readings: int, select: np.ndarray | None = None) -> F.ExpectationReadings:
    """The readings the parameters are fitted on: the valid ones of ``run`` (those ``select`` marks), every
    n-th beyond ``max_readings`` (spread over the log), deflected beams as ``forward_model.deflect`` has them."""
    valid = ~np.isnan(run.z)
    keep = np.flatnonzero(valid if select is None else valid & select)
    if keep.size > max_readings:
        keep = keep[:: -(-keep.size // max_readings)]
    z, limit = F.deflect(run.z[keep].astype(np.float64), None if run.shadow is None else run.shadow[keep],
                         run.sensor.max_range)
    return F.ExpectationReadings(run.rows[keep].astype(np.int64), run.cols[keep].astype(np.int64),
                                 run.bins[keep].astype(np.int64), z, limit)


def _cones(run: LaidOutReadings) -> tuple:
    """(kernel arrays, flat offsets, grid shape): ``run``'s cone templates as the kernels take them."""
    return run.templates.kernel_arrays, flat_offsets(run.templates, run.grid.width), run.grid.shape


def _flat_bool(occupied: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(occupied, dtype=np.bool_)


def expectations(run: LaidOutReadings, readings: F.ExpectationReadings, occupied: np.ndarray,
                 forward: F.ForwardModelConfig, obstacles: F.Obstacles | None = None,
                 uncounted: int = 0) -> tuple[np.ndarray, F.Obstacles]:
    """The summed expectations of ``readings`` under ``occupied`` and ``forward``, and the obstacles they came from;
    ``uncounted`` readings more, left out because they add nothing but their count to the sums asked for."""
    out = np.zeros(F.E_SIZE)
    out[F.E_READINGS] = uncounted
    obstacles = F.expectation_sums(*_cones(run), readings, _flat_bool(occupied), forward.kernel_model(run.sensor.max_range),
                                   out, obstacles)
    return out, obstacles


def m_step(sums: np.ndarray, forward: F.ForwardModelConfig, keys: tuple[str, ...],
           bounds: Tuning = TUNING) -> F.ForwardModelConfig:
    """The ``keys`` maximising the expected log-likelihood, clipped to ``bounds``; unweighted ones keep their value."""
    n = sums[F.E_READINGS]
    if n <= 0:
        return forward
    p_rand = float(np.clip(sums[F.E_RANDOM] / n, bounds.p_rand_min, bounds.p_rand_max))
    p_max = float(np.clip(sums[F.E_DROPOUT] / n, 0.0, bounds.p_max_max)) if forward.p_max > 0 else 0.0
    if p_rand + p_max > bounds.p_rand_max + bounds.p_max_max:
        scale = (bounds.p_rand_max + bounds.p_max_max) / (p_rand + p_max)
        p_rand, p_max = p_rand * scale, p_max * scale
    p_hit = forward.p_hit
    if sums[F.E_EXAMINED] > 0 and sums[F.E_DETECTED] > 0:
        p_hit = float(np.clip(sums[F.E_DETECTED] / sums[F.E_EXAMINED], bounds.p_hit_min, bounds.p_hit_max))
    sigma = forward.sigma
    if sums[F.E_DETECTED] > 0:
        sigma = float(np.clip(math.sqrt(sums[F.E_SQUARED] / sums[F.E_DETECTED]), bounds.sigma_min, bounds.sigma_max))
    learned = {"sigma": sigma, "p_rand": p_rand, "p_hit": p_hit, "p_max": p_max}
    return dataclasses.replace(forward, **{k: v for k, v in learned.items() if k in keys})


def settled(a: F.ForwardModelConfig, b: F.ForwardModelConfig, tolerance: float) -> bool:
    """True when no learned parameter moved by more than ``tolerance`` (sigma relative, the rest absolute)."""
    if abs(a.sigma - b.sigma) > tolerance * max(a.sigma, b.sigma):
        return False
    return all(abs(getattr(a, k) - getattr(b, k)) <= tolerance for k in SENSOR_KEYS if k != "sigma")


@dataclass
class Fit:
    """The parameters fitted at one map, and how the fit went."""

    forward: F.ForwardModelConfig
    iterations: int
    loglik_per_reading: float | None  # mean log p(z | m) of the sample under ``forward`` at the map (None: not asked)


def fit_at_map(run: LaidOutReadings, readings: F.ExpectationReadings, occupied: np.ndarray, forward: F.ForwardModelConfig,
               config: CalibrationConfig, tuning: Tuning = TUNING, loglik: bool = True) -> Fit:
    """EM over the parameters alone at a fixed map: expectations, then ``m_step``, until they settle
    (``tuning.tolerance`` / 10); with ``loglik``, one more pass for the sample's mean log-likelihood. A fit of
    p_max alone walks the cones of the readings a dropout may explain only (``dropout_readings``)."""
    uncounted = 0
    if config.learned == ("p_max",) and not loglik:
        readings, uncounted = dropout_readings(readings, forward.sigma, float(run.sensor.max_range))
    iterations = 0
    # obstacles found once at twice the starting sigma serve every iteration below it: one cone walk
    obstacles = F.find_obstacles(*_cones(run), readings, _flat_bool(occupied), min(2.0 * forward.sigma, tuning.sigma_max),
                                 float(forward.window), float(run.sensor.max_range))
    while iterations < tuning.fit_iterations:
        iterations += 1
        sums, obstacles = expectations(run, readings, occupied, forward, obstacles, uncounted)
        new = m_step(sums, forward, config.learned, tuning)
        done = settled(new, forward, tuning.tolerance / 10)
        forward = new
        if done:
            break
    if not loglik:
        return Fit(forward, iterations, None)
    sums, _ = expectations(run, readings, occupied, forward, obstacles)
    n = max(sums[F.E_READINGS], 1.0)
    return Fit(forward, iterations, float(sums[F.E_LOGLIK] / n))


# a reading this many sigmas short of the max range has N(z; z_max) = 0 exactly (exp underflows beyond ~38.6)
DROPOUT_SIGMAS = 40.0


def dropout_readings(readings: F.ExpectationReadings, sigma: float, z_max: float) -> tuple[F.ExpectationReadings, int]:
    """(the readings a dropout may explain, how many others): an echo more than ``DROPOUT_SIGMAS`` short of z_max
    has G0 = 0, so it adds 1 to E_READINGS and exactly 0 to E_DROPOUT, all that p_max's update reads (``m_step``:
    p_rand + p_max, each clipped, never exceeds their bounds' sum). Sums over the rest alone are the same, bit for
    bit: adding 0.0 changes no float."""
    keep = ~(readings.z < z_max - DROPOUT_SIGMAS * sigma)
    if keep.all():
        return readings, 0
    return F.ExpectationReadings(*(a[keep] for a in readings)), int(keep.size - np.count_nonzero(keep))


def model_values(forward: F.ForwardModelConfig) -> dict:
    """The learned parameters' values (``learned.SENSOR_KEYS``: those calibration sets)."""
    return {k: float(getattr(forward, k)) for k in SENSOR_KEYS}


# (config, flat occupied updated in place, reading mask or None) -> (EM's last objective, sweeps, the result)
EMStep = Callable[[EMConfig, np.ndarray, np.ndarray | None], tuple[float, int, object]]


def calibration_rounds(run: LaidOutReadings, occupied: np.ndarray, em: EMConfig, config: CalibrationConfig,
                       em_step: EMStep, select: np.ndarray | None = None,
                       tuning: Tuning = TUNING) -> tuple[EMConfig, dict]:
    """Alternate EM maps of part of the log with fits of the forward model at them (``fit_at_map``); the
    final map is the caller's. Round 0 maps with a broad model (a broad model puts each wall at the readings'
    mean), later rounds with the last fit, until it settles or ``tuning.rounds``. Every run starts from
    ``occupied`` as given, left as it was: a warm start from a broad or half-made map keeps walls thick
    (docs/algorithms.md, "Where the defaults come from"). Returns (the last fit's EM config, the record)."""
    max_scans = calibration_scans(run, tuning)
    blocks = _scan_blocks(run, max_scans)
    if blocks is not None:  # a long log: the rounds map (and fit on) blocks of its scans only
        select = blocks if select is None else select & blocks
    readings = sample_readings(run, tuning.max_readings, select)
    scans, first_scans = (_and(_every_nth_scan(run, n), blocks) for n in (tuning.subsample, tuning.start_subsample))
    start = occupied.copy()
    record = {"initial": model_values(em.forward), "readings_used": int(readings.z.shape[0]),
              "fitted_at": f"1 scan in {tuning.start_subsample}, then 1 in {tuning.subsample}"
              + ("" if blocks is None else f", of {CAL_BLOCKS} runs of {max_scans // CAL_BLOCKS} consecutive scans"),
              "rounds": []}
    used = dataclasses.replace(em, forward=dataclasses.replace(em.forward, sigma=max(em.forward.sigma, tuning.start_sigma)))
    step = dataclasses.replace(used, max_sweeps=min(em.max_sweeps, tuning.start_sweeps))
    entry = {"round": 0, **model_values(used.forward)}
    record["rounds"].append(entry)
    for round_no in range(1, tuning.rounds + 1):
        objective, sweeps, _ = em_step(step, occupied, first_scans if round_no == 1 else scans)
        entry.update(em_objective=float(objective), em_sweeps=int(sweeps))
        # fitted on every reading, not only those the map was made from, which it explains too well
        # round 0's broad sigma is no fit: a sigma not learned stays as configured
        kept = used.forward if "sigma" in config.learned else dataclasses.replace(used.forward, sigma=em.forward.sigma)
        fit = fit_at_map(run, readings, occupied, kept, config, tuning)
        occupied[:] = start
        entry = {"round": round_no, **model_values(fit.forward), "fit_iterations": fit.iterations,
                 "loglik_per_reading": fit.loglik_per_reading}
        record["rounds"].append(entry)
        settled_now = settled(fit.forward, used.forward, tuning.tolerance)
        used = dataclasses.replace(em, forward=fit.forward)
        step = dataclasses.replace(used, max_sweeps=min(em.max_sweeps, tuning.fit_sweeps))
        if settled_now:
            break
    record["final"] = model_values(used.forward)
    return used, record


def calibration_scans(run: LaidOutReadings, tuning: Tuning = TUNING) -> int:
    """Scans a long log calibrates on: ``tuning.max_scans``, fewer for wide scans (cost bounded in readings)."""
    width = run.ranges.shape[1]
    return max(CAL_BLOCKS, min(tuning.max_scans, tuning.max_mapped_readings // max(width, 1)))


def _scan_blocks(run: LaidOutReadings, max_scans: int) -> np.ndarray | None:
    """A reading mask of ``max_scans`` scans in ``CAL_BLOCKS`` runs of consecutive scans spread over the log
    (None: no more scans than that): the fits see walls as every scan draws them (every n-th broadens sigma)."""
    scans, width = run.ranges.shape
    if scans <= max_scans:
        return None
    size = max_scans // CAL_BLOCKS
    starts = np.linspace(0, scans - size, CAL_BLOCKS).astype(int)
    keep = np.zeros(scans, dtype=bool)
    for a in starts:
        keep[a : a + size] = True
    return np.repeat(keep, width)


def _and(a: np.ndarray | None, b: np.ndarray | None) -> np.ndarray | None:
    """Both masks (None: all)."""
    return b if a is None else a if b is None else a & b


def _every_nth_scan(run: LaidOutReadings, n: int) -> np.ndarray | None:
    """A bool mask over ``run``'s readings marking every ``n``-th scan's (None for n = 1)."""
    if n <= 1:
        return None
    scans, width = run.ranges.shape
    return np.repeat(np.arange(scans) % n == 0, width)
