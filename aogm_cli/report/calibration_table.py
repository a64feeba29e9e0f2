"""The record of a calibration (``mapping.calibration.calibration_rounds``, in a map's
``stats["calibration"]``) as ``aogm calibrate`` and ``aogm info`` print it: one line per round, then
what was learned and from how many readings; the lobe that hears (``lobe_line``); and the one line
``aogm map`` prints of what a map learned from its log (``learned_line``)."""

from __future__ import annotations

from aogm_cli.core.occupancy_map import OccupancyMap
from aogm_cli.mapping.learned import FROM_LOG, SENSOR_KEYS


def calibration_table(record: dict) -> str:
    """The record of ``calibration_rounds`` (and the final map) as a plain-text table, one line per round, then the model."""
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
    lines.append(f"learned from {record['readings_used']} readings: "
                 + ", ".join(f"{k} {final[k]:.4g}" for k in SENSOR_KEYS if k in final))
    return "\n".join(lines)


def lobe_line(record: dict) -> str:
    """The lobe a map learned (``sensor_models.lobe.Lobe.as_dict``, the map's ``learned["lobe"]``) as one line: the
    echo rate by angle off the axis at the walls (2-degree bins), the echoes the whole cone and the lobe explain,
    and the lobe."""
    chances = [sum(row) for row in record["chances"]]
    hits = [sum(row) for row in record["hits"]]
    pairs = [(sum(hits[a:a + 2]), sum(chances[a:a + 2])) for a in range(0, len(chances), 2)]
    rates = " ".join(f"{h / c:.2f}" if c else "-" for h, c in pairs)
    return (f"the lobe: echo rate by angle off the axis at the thinned walls (2-degree bins): {rates}; of "
            f"{record['echoes']} echoes the whole cone explains {record['explained_cone']}, the best lobe "
            f"{record['explained_best']} -> {_lobe_words(record)}")


def _in_place(params: dict) -> str:
    """What a lobe learned from the log says of a lobe the map's ``params`` configured: it takes that one's place
    (``Learned.model``), and how to keep it."""
    configured = float((params.get("em") or {}).get("lobe_deg") or 0.0)
    if configured <= 0.0:
        return ""
    return (f" (in place of the configured theta0 {configured:g} deg: calibration.learn without lobe_deg "
            f"keeps that one)")


def _carried_lobe(learned: dict) -> dict:
    """The lobe a map took with its sensor's model (its ``learned`` record's lobe_deg, lobe_range) as ``_lobe_words``
    takes a fit's record."""
    return {"full_cone": learned["lobe_deg"] == 0.0, "theta0_deg": learned["lobe_deg"], "r0_m": learned["lobe_range"]}


def _lobe_words(record: dict) -> str:
    """The lobe of a ``Lobe.as_dict`` record in words."""
    if record["full_cone"]:
        return "the whole cone"
    return f"theta0 {record['theta0_deg']:g} deg, heard out to {record['r0_m']:.3g} m on the axis"


def learned_line(path, m: OccupancyMap) -> str | None:
    """The one line that says what a map learned from its log and where the rest of its model came from (None:
    a standard map, or nothing learned)."""
    learned = m.learned or {}
    if m.mode == "standard" or not learned:
        return None
    parts = [] if learned.get("lobe") is None else [f"lobe: {_lobe_words(learned['lobe'])}{_in_place(m.params)}"]
    sensor = learned.get("sensor") or {}
    rates = learned.get("rates") or {}
    from_log = learned.get("origin") == FROM_LOG
    parts += [f"{k} {rates.get(k, sensor.get(k)):.3g}" for k in ("sigma", "p_rand", "p_hit", "p_max")
              if k in rates or (from_log and k in sensor)]
    if not parts:
        return None
    carried_lobe = "" if learned.get("lobe") is not None or learned.get("lobe_deg") is None else (
        f" and its lobe ({_lobe_words(_carried_lobe(learned))})")
    rest = f"; the sensor's model{carried_lobe} {learned.get('origin', 'configured')}" if sensor and not from_log else ""
    return f"{path}: learned from this log: {', '.join(parts)}{rest}"
