"""Does the detection lobe learned from a log (``sensor_models.lobe.learn_lobe``) give back the simulator's
beam pattern? Each bundled world is simulated with Kuc & Siegel's pattern of width theta0 (``errors.echo_strength:
{min_strength: 0.01, beam_deg: theta0}``, random readings 5%) and as it is (every echo of the cone heard), seed 1;
each log's lobe is learned at its thinned standard map (``beam_model.lobe_walls``):

    python bench/lobe_study.py [--out /tmp/lf] [--worlds corridor_door ...] [--thetas 8 12]
    python bench/lobe_study.py --logs LOG.h5 ... --resolution 0.1      # logs as they are (a real robot's)
    python bench/lobe_study.py --worlds corridor_door --thetas 8 12 --objective   # and each fit's objective

Per log: theta0 and R0 learned (their intervals: the candidates explaining within 1% as many echoes), the
angle a surface met head-on at 1 and 4 m is heard out to, the echoes the lobe and the whole cone explain, the
effective opening the log learns today (``beam_model.opening_record``, half of it), and the seconds of one
standard map, of the walls (occupied evidence and the exact model's pass) and of the lobe's fit itself.
Target: theta0 within 3 degrees of the simulator's; the worlds as they are: the full cone.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import yaml

import aogm_cli
from aogm_cli.mapping import beam_model as B
from aogm_cli.mapping.modes import planned, resolved_params, warm_up
from aogm_cli.mapping.params import MapParams
from aogm_cli.mapping.runner import run_stages
from aogm_cli.world.beam_pattern import with_beam_pattern

ROOT = Path(__file__).resolve().parents[1]
WORLDS = ("corridor_door", "office_doors", "cluttered_lab", "furnished_room", "t_junction", "corridor_specular")


def world_variant(name: str, theta0: float | None, out: Path, sub_rays: int | None = None) -> Path:
    """The bundled world ``name`` with the beam pattern theta0 (None: as it is) and ``sub_rays`` sub-rays
    a cone (None: the world's, 11 by default: 3 degrees apart), written to ``out``."""
    text = (ROOT / "worlds" / f"{name}.yaml").read_text()
    world = yaml.safe_load(text) if theta0 is None else with_beam_pattern(text, theta0)
    if sub_rays is not None:
        world.setdefault("sonar", {})["sub_rays"] = sub_rays
    tail = "" if sub_rays is None else f"_{sub_rays}rays"
    path = out / f"{name}_{'default' if theta0 is None else f'{theta0:g}'}{tail}.yaml"
    path.write_text(yaml.safe_dump(world, sort_keys=False))
    return path


def simulated(world: Path, reuse: bool) -> Path:
    """``aogm simulate world --seed 1`` beside the world file (kept from an earlier run with ``reuse``)."""
    log = world.with_suffix(".h5")
    if not (reuse and log.exists()):
        subprocess.run([sys.executable, "-m", "aogm_cli", "simulate", str(world), "--seed", "1", "-o", str(log), "-q"],
                       check=True)
    return log


def measured(path: Path, resolution: float | None) -> dict:
    """The lobe learned from the log at ``path``, the opening it learns today, and what each step cost."""
    log = aogm_cli.load_log(path)
    params = resolved_params(log, MapParams() if resolution is None else MapParams(resolution=resolution))
    warm_up(log.sensor, params, "em")
    stages, state = planned(log, "em", params)
    names = [s.name for s in stages]
    s, phases = run_stages(stages[: names.index("standard") + 1], state)
    t0 = time.perf_counter()
    walls, _ = B.lobe_walls(s.whole, s.readings, params, s.standard.log_odds, s.standard.observed)
    t1 = time.perf_counter()
    B.lobe_record(s.readings, params, walls)  # its kernels compiled (or loaded): the next call is timed
    t1b = time.perf_counter()
    lobe = B.lobe_record(s.readings, params, walls)
    t2 = time.perf_counter() - t1b + t1
    opening = B.opening_record(s.whole, s.readings, params, s.standard.log_odds, s.standard.observed)
    return {"lobe": lobe, "half_opening": 0.5 * opening["opening_deg"], "standard_s": phases["standard"],
            "walls_s": t1 - t0, "lobe_s": t2 - t1}


def row(name: str, simulated_deg: str, m: dict) -> str:
    lobe = m["lobe"]
    if lobe.full_cone:
        learned = "full cone | - | - | -"
    else:
        (t_lo, t_hi), (r_lo, r_hi) = lobe.theta0_interval_deg, lobe.r0_interval_m
        learned = (f"{lobe.theta0_deg:g} ({t_lo:g}-{t_hi:g}) | {lobe.r0_m:.1f} ({r_lo:.1f}-{r_hi:.1f}) | "
                   f"{lobe.heard_deg(1.0):.1f} / {lobe.heard_deg(4.0):.1f}")
    return (f"| {name} | {simulated_deg} | {learned} | {lobe.explained_best} / {lobe.explained_cone} / {lobe.echoes} | "
            f"{m['half_opening']:g} | {m['standard_s']:.3f} | {m['walls_s']:.3f} | {m['lobe_s']:.3f} |")


def objective(lobe) -> str:
    """The fit's objective (``Lobe.explained``): per theta0 from 4 to 20 degrees, the echoes the best R0 explains
    and those R0 = 10 m (the simulator's head-on reach) explains."""
    from aogm_cli.sensor_models.lobe import R0_GRID_M, THETA0_GRID_DEG

    at10 = int(np.argmin(np.abs(R0_GRID_M - 10.0)))
    return "\n".join(f"    theta0 {t:4.1f}: best R0 {lobe.explained[i].max():6.0f}, R0 10 m {lobe.explained[i, at10]:6.0f}"
                     for i, t in enumerate(THETA0_GRID_DEG) if 4.0 <= t <= 20.0 and t == int(t))


HEADER = ("| log | simulated theta0 | learned theta0 (interval) | R0 m (interval) | heard at 1 m / 4 m (deg) | "
          "explained: lobe / cone / echoes | half opening (deg) | standard map s | walls s | lobe s |\n"
          "|---|---|---|---|---|---|---|---|---|---|")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", type=Path, default=Path("/tmp/lobe_study"))
    ap.add_argument("--worlds", nargs="*", default=list(WORLDS))
    ap.add_argument("--thetas", nargs="*", type=float, default=[8.0, 12.0])
    ap.add_argument("--logs", nargs="*", type=Path, default=[], help="logs as they are (no simulation)")
    ap.add_argument("--resolution", type=float, default=None, help="the grid of --logs")
    ap.add_argument("--reuse", action="store_true", help="keep logs simulated by an earlier run")
    ap.add_argument("--sub-rays", type=int, default=None, help="sub-rays a cone in the simulator (default: 11)")
    ap.add_argument("--objective", action="store_true", help="print each fit's objective by theta0 under its row")
    a = ap.parse_args()
    print(HEADER)
    if a.logs:
        for path in a.logs:
            m = measured(path, a.resolution)
            print(row(str(path), "?", m) + (f"\n{objective(m['lobe'])}" if a.objective else ""), flush=True)
        return
    a.out.mkdir(parents=True, exist_ok=True)
    for theta0 in [*a.thetas, None]:
        for name in a.worlds:
            log = simulated(world_variant(name, theta0, a.out, a.sub_rays), a.reuse)
            m = measured(log, None)
            print(row(name, "cone (default)" if theta0 is None else f"{theta0:g}", m)
                  + (f"\n{objective(m['lobe'])}" if a.objective else ""), flush=True)


if __name__ == "__main__":
    np.set_printoptions(linewidth=200)
    main()
