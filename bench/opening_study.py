"""The beam's opening each log learns, and what it does to em and adaptive (docs/algorithms.md, "The
beam's opening"):

    python bench/opening_study.py LOG.h5 ... [--resolution 0.1]

    python bench/opening_study.py LOG.h5 ... --maps [--against REF.h5]

Per log: the echoes the thinned standard map explains with the whole cone as a share of the best
opening's, and the opening learned (``calibration.learn`` with ``opening_deg``). With ``--maps``,
each log's em and adaptive maps with the cone and with the learned opening, scored as a planner
sees them: against the truth (accuracy, leak, block, checks) when the log has one, else walls kept
and leak against the standard map of REF (default: the log itself; another import of the same
robot's log at another beam width, for example).
"""

from __future__ import annotations

import argparse

import aogm_cli
from aogm_cli.evaluation.planner import against_standard

LEARN = "sigma,p_rand,p_hit,p_max,specular_deg,opening_deg"


def scores(m, log, ref, robot_radius: float) -> str:
    """A map's scores as a planner sees it: against the truth when the log has one, else against
    the standard map ``ref`` = (its log, the map)."""
    if log.truth is not None:
        e = aogm_cli.evaluate(m, log, robot_radius)
        checks = f"{sum(c['passed'] for c in e['checks'])}/{len(e['checks'])}"
        return f"accuracy {e['accuracy']:.4f}, leak {e['leak']:.4f}, block {e['block']:.4f}, checks {checks}"
    ref_log, std = ref
    s = against_standard(std.grid, m.probability, m.observed, std.probability, std.observed, ref_log.pose, robot_radius)
    return (f"walls kept {s['walls_kept']:.3f}, leak vs standard {s['leak_vs_standard']:.3f}, "
            f"far leak {s['far_leak']:.3f}")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("logs", nargs="+")
    ap.add_argument("--resolution", type=float, default=None)
    ap.add_argument("--maps", action="store_true",
                    help="also score em and adaptive with the cone and with the learned opening")
    ap.add_argument("--against", default=None,
                    help="score a log without truth against this log's standard map (default: its own)")
    ap.add_argument("--robot-radius", type=float, default=0.2)
    a = ap.parse_args()
    grid = {} if a.resolution is None else {"resolution": a.resolution}
    print("| log | the cone's share of the best opening's echoes | learned opening (deg) |"
          + (" mode | with the cone | with the learned opening |" if a.maps else "")
          + "\n|---|---|---|" + ("---|---|---|" if a.maps else ""))
    for path in a.logs:
        log = aogm_cli.load_log(path)
        learned = {"em": aogm_cli.map_log(log, "em", calibration={"learn": LEARN}, **grid)}
        record = learned["em"].stats["calibration"]["opening"]
        explained = record["explained"]
        row = f"| {path} | {explained[-1] / max(max(explained), 1):.3f} | {record['opening_deg']:g} |"
        if not a.maps:
            print(row)
            continue
        ref_log = aogm_cli.load_log(a.against) if a.against else log
        ref = (ref_log, aogm_cli.map_log(ref_log, "standard", **grid))
        learned["adaptive"] = aogm_cli.map_log(log, "adaptive", calibration={"learn": LEARN}, **grid)
        for mode in ("em", "adaptive"):
            cone = aogm_cli.map_log(log, mode, **grid)
            print(f"{row} {mode} | {scores(cone, log, ref, a.robot_radius)} | "
                  f"{scores(learned[mode], log, ref, a.robot_radius)} |")


if __name__ == "__main__":
    main()
