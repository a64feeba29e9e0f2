"""The forward model learned from the log it maps (Thrun 2003's "learning"): closed-form updates
of p_rand, p_max, p_hit and sigma from the expectations of every reading's cause at a binary map,
alternated with EM's map until the parameters settle (``calibrated_em``), bounded and recorded.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from aogm_cli.mapping.params import CalibrationConfig, EMConfig, MapParams
from aogm_cli.sensor_models import forward_model as F
from aogm_cli.sensor_models.cone import flat_offsets
from aogm_cli.sensor_models.lobe import LOBE_BIN_DEG, cone_deg, learned_opening, lobe_bins, opening_matches
from aogm_cli.sensor_models.readings import LaidOutReadings
from aogm_cli.sensor_models.surface import INCIDENCE_BINS, incidence_counts, specular_angle

LEARNED = ("sigma", "p_rand", "p_hit", "p_max")  # the forward model's parameters calibration sets
ONCE = ("specular_deg", "opening_deg")  # and those it learns once, before EM (``incidence_at``, ``opening_at``)
CAL_BLOCKS = 4  # a long log's calibration maps this many runs of consecutive scans (``_scan_blocks``)


def sample_readings(run: LaidOutReadings, max_readings: int, select: np.ndarray | None = None) -> F.ExpectationReadings:
    """The readings the parameters are fitted on: every valid reading of ``run`` (NaN left out;
    with ``select``, a bool mask, only those it marks), or every n-th of them when there are
    more than ``max_readings`` (deterministic, spread over the whole log); deflected beams
    (``run.shadow``) as the forward model takes them (``forward_model.deflect``)."""
    valid = ~np.isnan(run.z)
    keep = np.flatnonzero(valid if select is None else valid & select)
    if keep.size > max_readings:
        keep = keep[:: -(-keep.size // max_readings)]
    z, limit = F.deflect(run.z[keep].astype(np.float64), None if run.shadow is None else run.shadow[keep],
                         run.sensor.max_range)
    return F.ExpectationReadings(run.rows[keep].astype(np.int64), run.cols[keep].astype(np.int64),
                                 run.bins[keep].astype(np.int64), z, limit)


def expectations(run: LaidOutReadings, readings: F.ExpectationReadings, occupied: np.ndarray,
                 forward: F.ForwardModelConfig, obstacles: F.Obstacles | None = None) -> tuple[np.ndarray, F.Obstacles]:
    """The summed expectations (``forward_model.expectation_sums``, E_SIZE,) of ``readings``
    under the flat binary map ``occupied`` and the model ``forward``, and the cones' obstacles
    they were taken from (pass them back while the map stands: ``fit_at_map``)."""
    out = np.zeros(F.E_SIZE)
    templates = run.templates
    model = (float(forward.p_rand), float(forward.p_max), float(forward.p_hit), float(forward.sigma),
             float(forward.window), float(run.sensor.max_range))
    obstacles = F.expectation_sums(templates.kernel_arrays, flat_offsets(templates, run.grid.width), run.grid.shape,
                                   readings, np.ascontiguousarray(occupied, dtype=np.bool_), model, out, obstacles)
    return out, obstacles


def m_step(sums: np.ndarray, forward: F.ForwardModelConfig, config: CalibrationConfig) -> F.ForwardModelConfig:
    """The parameters that maximise the expected log-likelihood given the summed expectations,
    each clipped to its bounds (``CalibrationConfig``). A component that got no weight (p_max
    0 from the start, no detection, no obstacle examined) keeps its value."""
    n = sums[F.E_READINGS]
    if n <= 0:
        return forward
    p_rand = float(np.clip(sums[F.E_RANDOM] / n, config.p_rand_min, config.p_rand_max))
    p_max = float(np.clip(sums[F.E_DROPOUT] / n, 0.0, config.p_max_max)) if forward.p_max > 0 else 0.0
    if p_rand + p_max > config.p_rand_max + config.p_max_max:
        scale = (config.p_rand_max + config.p_max_max) / (p_rand + p_max)
        p_rand, p_max = p_rand * scale, p_max * scale
    p_hit = forward.p_hit
    if sums[F.E_EXAMINED] > 0 and sums[F.E_DETECTED] > 0:
        p_hit = float(np.clip(sums[F.E_DETECTED] / sums[F.E_EXAMINED], config.p_hit_min, config.p_hit_max))
    sigma = forward.sigma
    if sums[F.E_DETECTED] > 0:
        sigma = float(np.clip(math.sqrt(sums[F.E_SQUARED] / sums[F.E_DETECTED]), config.sigma_min, config.sigma_max))
    learned = {"sigma": sigma, "p_rand": p_rand, "p_hit": p_hit, "p_max": p_max}
    return dataclasses.replace(forward, **{k: v for k, v in learned.items() if k in config.learned})


def settled(a: F.ForwardModelConfig, b: F.ForwardModelConfig, tolerance: float) -> bool:
    """True when no learned parameter moved by more than ``tolerance``: sigma relative to its
    value, the probabilities in absolute terms."""
    if abs(a.sigma - b.sigma) > tolerance * max(a.sigma, b.sigma):
        return False
    return all(abs(getattr(a, k) - getattr(b, k)) <= tolerance for k in LEARNED if k != "sigma")


@dataclass
class Fit:
    """The parameters fitted at one map, and how the fit went."""

    forward: F.ForwardModelConfig
    iterations: int
    loglik_per_reading: float  # mean log p(z | m) of the sample under ``forward`` at the map


def fit_at_map(run: LaidOutReadings, readings: F.ExpectationReadings, occupied: np.ndarray, forward: F.ForwardModelConfig,
               config: CalibrationConfig) -> Fit:
    """EM over the parameters alone at a fixed map: expectations, then ``m_step``, until the
    parameters settle (``config.tolerance`` / 10) or ``config.fit_iterations``."""
    iterations = 0
    # the cones' obstacles found once, at twice the starting sigma, serve every iteration whose
    # sigma stays below (found again if it grows beyond): the same sums, one cone walk
    templates = run.templates
    obstacles = F.find_obstacles(templates.kernel_arrays, flat_offsets(templates, run.grid.width), run.grid.shape,
                                 readings, np.ascontiguousarray(occupied, dtype=np.bool_),
                                 min(2.0 * forward.sigma, config.sigma_max), float(forward.window),
                                 float(run.sensor.max_range))
    while iterations < config.fit_iterations:
        iterations += 1
        sums, obstacles = expectations(run, readings, occupied, forward, obstacles)
        new = m_step(sums, forward, config)
        done = settled(new, forward, config.tolerance / 10)
        forward = new
        if done:
            break
    sums, _ = expectations(run, readings, occupied, forward, obstacles)
    n = max(sums[F.E_READINGS], 1.0)
    return Fit(forward, iterations, float(sums[F.E_LOGLIK] / n))


def incidence_at(run: LaidOutReadings, readings: F.ExpectationReadings, occupied: np.ndarray,
                 forward: F.ForwardModelConfig, config: CalibrationConfig, normals: np.ndarray) -> dict:
    """The specular angle learned from ``readings`` at the flat binary map ``occupied`` (the
    standard map's, which keeps the walls that grazing passes would make EM erase): per 10-degree
    bin of incidence the readings that echoed from a surface cell and those that passed one
    (``surface.incidence_counts``, surfaces ``normals``), and where the echo rate falls to half
    (``specular_angle``)."""
    counts = np.zeros((2, INCIDENCE_BINS))
    templates = run.templates
    incidence_counts(templates.kernel_arrays, flat_offsets(templates, run.grid.width), run.grid.shape,
                     (readings.rows, readings.cols, readings.bins, readings.z),
                     np.ascontiguousarray(occupied, dtype=np.bool_), normals,
                     (float(forward.sigma), float(forward.window), float(run.sensor.max_range), config.pass_margin), counts)
    return {"echoes": counts[0].astype(int).tolist(), "passes": counts[1].astype(int).tolist(),
            "specular_deg": specular_angle(counts, config.specular_rate)}


def opening_at(run: LaidOutReadings, readings: F.ExpectationReadings, occupied: np.ndarray,
               forward: F.ForwardModelConfig) -> dict:
    """The beam's effective opening learned from ``readings`` at the flat binary map ``occupied``
    (the thinned standard map: Elfes' map smears each echo over the whole cone, and its smear
    would make every opening wider than the axis look wrong): how many echoes the map explains
    (the nearest occupied cell within the opening lies within the Gaussian window of the range)
    for each opening, per degree off the axis (``lobe.opening_matches``), and the opening
    learned from that curve (``lobe.learned_opening``)."""
    templates = run.templates
    matches = np.zeros(lobe_bins(run.sensor.beam_width))
    z_max = float(run.sensor.max_range)
    opening_matches(templates.kernel_arrays, flat_offsets(templates, run.grid.width), templates.bearings,
                    run.grid.shape, (readings.rows, readings.cols, readings.bins, readings.z),
                    np.ascontiguousarray(occupied, dtype=np.bool_),
                    (float(forward.window * forward.sigma), z_max, math.radians(LOBE_BIN_DEG)), matches)
    echoes = int(np.sum(readings.z < z_max))
    return {"echoes": echoes, "explained": matches.astype(int).tolist(), "bin_deg": LOBE_BIN_DEG,
            "cone_deg": cone_deg(run.sensor.beam_width),
            "opening_deg": learned_opening(matches, echoes, run.sensor.beam_width)}


def model_values(forward: F.ForwardModelConfig) -> dict:
    """The learned parameters' values (LEARNED, and those learned once, ONCE)."""
    return {k: float(getattr(forward, k)) for k in (*LEARNED, *ONCE)}


# (config, flat occupied updated in place, a bool mask of the readings to map or None for all) ->
# (EM's objective after its last sweep, its sweeps, what the caller keeps)
EMStep = Callable[[EMConfig, np.ndarray, np.ndarray | None], tuple[float, int, object]]


def em_with_model(run: LaidOutReadings, occupied: np.ndarray, params: MapParams, em_step: EMStep,
                  select: np.ndarray | None = None) -> tuple[EMConfig, object, dict | None]:
    """EM with the configured forward model, or calibrated (``calibrated_em``, fitted on the
    readings ``select`` marks, default all) when ``params.calibration.enabled``: (the EM config
    used, ``em_step``'s last result, the record or None)."""
    if not params.calibration.enabled:
        return params.em, em_step(params.em, occupied, None)[2], None
    return calibrated_em(run, occupied, params.em, params.calibration, em_step, select)


def calibrated_em(run: LaidOutReadings, occupied: np.ndarray, em: EMConfig, config: CalibrationConfig,
                  em_step: EMStep, select: np.ndarray | None = None) -> tuple[EMConfig, object, dict]:
    """Alternate EM maps of part of the log with fits of the forward model at them
    (``fit_at_map``, on every reading), then map every scan once with the last fit. Round 0
    maps every ``config.start_subsample``-th scan with the configured model made at least
    ``config.start_sigma`` broad, in at most ``config.start_sweeps`` sweeps (its map only serves
    the first fit: a broad model puts each wall at the readings' mean); each later round fits
    the parameters at the last map and, until they settle (``config.tolerance``) or
    ``config.rounds``, maps every ``config.subsample``-th scan with them (at most ``fit_sweeps``
    sweeps). Every EM run starts from the flat binary map ``occupied`` as given (updated in place
    to the final map): a warm start from a broad or half-made map keeps walls thick
    (corridor_door 0.970 against 0.974 on a development version that started warm).

    Returns (the EM config the final map was made with, the last EM result, the record: the
    starting values, per round the fitted values, the mean log-likelihood of the sample at the
    fit and EM's objective and sweeps, and the final map's EM objective and sweeps)."""
    blocks = _scan_blocks(run, config.max_scans)
    if blocks is not None:  # a long log: the rounds map (and fit on) blocks of its scans only
        select = blocks if select is None else select & blocks
    readings = sample_readings(run, config.max_readings, select)
    scans, first_scans = (_and(_every_nth_scan(run, n), blocks) for n in (config.subsample, config.start_subsample))
    start = occupied.copy()
    record = {"initial": model_values(em.forward), "readings_used": int(readings.z.shape[0]),
              "fitted_at": f"1 scan in {config.start_subsample}, then 1 in {config.subsample}"
              + ("" if blocks is None else f", of {CAL_BLOCKS} runs of {config.max_scans // CAL_BLOCKS} consecutive scans"),
              "rounds": []}
    used = dataclasses.replace(em, forward=dataclasses.replace(em.forward, sigma=max(em.forward.sigma, config.start_sigma)))
    step = dataclasses.replace(used, max_sweeps=min(em.max_sweeps, config.start_sweeps))
    entry = {"round": 0, **model_values(used.forward)}
    record["rounds"].append(entry)
    for round_no in range(1, config.rounds + 1):
        objective, sweeps, _ = em_step(step, occupied, first_scans if round_no == 1 else scans)
        entry.update(em_objective=float(objective), em_sweeps=int(sweeps))
        # fitted on every reading (not only those the map was made from, which it explains too
        # well: sigma 0.046 against 0.058 at the simulator's 0.05, 0.088 against 0.118 at 0.12)
        fit = fit_at_map(run, readings, occupied, used.forward, config)
        occupied[:] = start
        entry = {"round": round_no, **model_values(fit.forward), "fit_iterations": fit.iterations,
                 "loglik_per_reading": fit.loglik_per_reading}
        record["rounds"].append(entry)
        settled_now = settled(fit.forward, used.forward, config.tolerance)
        used = dataclasses.replace(em, forward=fit.forward)
        step = dataclasses.replace(used, max_sweeps=min(em.max_sweeps, config.fit_sweeps))
        if settled_now:
            break
    objective, sweeps, result = em_step(used, occupied, None)
    record["final"] = model_values(used.forward)
    record["final_em"] = {"em_objective": float(objective), "em_sweeps": int(sweeps)}
    return used, result, record


def _scan_blocks(run: LaidOutReadings, max_scans: int) -> np.ndarray | None:
    """A bool mask over ``run``'s readings marking ``max_scans`` of its scans in ``CAL_BLOCKS``
    runs of consecutive scans spread evenly over the log (None: the log has no more scans than
    that). Consecutive scans keep the readings' density where the blocks are, so that the fits
    see the walls as every scan draws them (every n-th scan instead broadens sigma)."""
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


def calibration_table(record: dict) -> str:
    """The record of ``calibrated_em`` as a plain-text table, one line per round, then the model."""
    lines = [f"{'round':>5} {'sigma':>8} {'p_rand':>8} {'p_hit':>8} {'p_max':>8} {'loglik/rd':>10} {'EM objective':>14}"
             f" {'sweeps':>6}"]
    for r in record["rounds"]:
        loglik = f"{r['loglik_per_reading']:10.4f}" if "loglik_per_reading" in r else f"{'-':>10}"
        objective = f"{r['em_objective']:14.2f}" if "em_objective" in r else f"{'(final map)':>14}"
        sweeps = f"{r['em_sweeps']:6d}" if "em_sweeps" in r else f"{'-':>6}"
        lines.append(f"{r['round']:>5} {r['sigma']:8.4f} {r['p_rand']:8.4f} {r['p_hit']:8.4f} {r['p_max']:8.4f}"
                     f" {loglik} {objective} {sweeps}")
    final = record["final"]
    if "final_em" in record:
        lines.append(f"final map, every scan with the last fit: EM objective {record['final_em']['em_objective']:.2f}, "
                     f"{record['final_em']['em_sweeps']} sweeps (the rounds' maps: {record['fitted_at']})")
    if "incidence" in record:
        inc = record["incidence"]
        lines.append("echo rate by angle of incidence at the standard map's surfaces (10-degree bins): "
                     + " ".join(f"{e / (e + p):.2f}" if e + p else "-" for e, p in zip(inc["echoes"], inc["passes"],
                                                                                      strict=True))
                     + f" -> specular_deg {inc['specular_deg']:.1f}")
    if "opening" in record:
        op = record["opening"]
        lines.append(f"echoes the thinned standard map explains by the beam's opening ({op['echoes']} echoes; "
                     f"{2 * op['bin_deg']:g}, {4 * op['bin_deg']:g}, ... {op['cone_deg']:.0f} degrees): "
                     + " ".join(f"{e / max(op['echoes'], 1):.2f}" for e in op["explained"])
                     + f" -> opening_deg {op['opening_deg']:.1f}")
    lines.append(f"learned from {record['readings_used']} readings: "
                 + ", ".join(f"{k} {final[k]:.4g}" for k in (*LEARNED, *ONCE) if k in final))
    return "\n".join(lines)


def learned_params_yaml(record: dict, source: str) -> str:
    """A ``--params`` file holding the learned model (calibration off, so it is used as it is)."""
    final = record["final"]
    body = "\n".join(f"  {k}: {final[k]!r}" for k in (*LEARNED, *ONCE) if k in final)
    return f"# forward model learned by aogm calibrate from {source}\nem:\n{body}\ncalibration:\n  enabled: false\n"
