"""Benchmark: maps of worlds whose sonar has a real beam pattern, as a planner sees them, and the beam each map learns.

    python bench/bench_beam.py [--worlds corridor_door,...] [--beam-deg 8,12] [--seed 1] [--modes em,adaptive]
                               [--params P.yaml] [--json OUT] [--keep DIR]

For each bundled world and each theta0 of ``--beam-deg`` (degrees; ``default`` for the world's own
pattern, which in the bundled clean worlds hears every echo) writes the variant of the world with
``errors.echo_strength: {min_strength: 0.01, beam_deg: THETA0}`` merged in and ``sonar.random_rate: 0.05``
(``world.beam_pattern.with_beam_pattern``; ``default`` sets the random rate only), simulates it, and
maps the log in this process (``map_files.map_file``) in the standard mode (for reference) and each
of ``--modes``, with ``--params`` (default: the defaults). Every map is scored as ``aogm compare``
scores it: accuracy and the world's checks (``evaluation.metrics.evaluate``), and leak and block for a
robot of radius 0.2 m (``evaluation.planner.planner_metrics``, ``ROBOT_RADIUS``); and what it learned
of the beam (its ``learned`` record, ``mapping.learned.Learned``: the lobe, theta0/R0 or the whole cone,
and the forward model's p_hit, p_max, sigma, p_rand and specular angle, with where they came from). Each mode's map is made on its own (``aogm compare`` lets the em map take
what the adaptive map learned). Worlds and logs go to a temporary folder unless ``--keep DIR``.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

import numpy as np
import yaml

from aogm_cli.core.errors import InputError
from aogm_cli.core.log import CAUSE_ECHO, CAUSE_NO_ECHO, CAUSE_SPECULAR
from aogm_cli.evaluation.metrics import evaluate
from aogm_cli.evaluation.planner import ROBOT_RADIUS, planner_metrics
from aogm_cli.io.logfile import LogReader, write_log
from aogm_cli.map_files import map_file, resolve_params
from aogm_cli.simulation.sonar import simulate
from aogm_cli.world.beam_pattern import MIN_STRENGTH, RANDOM_RATE, with_beam_pattern
from aogm_cli.world.loader import load_world

ROOT = Path(__file__).resolve().parents[1]
WORLDS = ("corridor_door", "office_doors", "cluttered_lab", "furnished_room", "t_junction", "corridor_specular")
MODES = ("standard", "em", "adaptive")
DEFAULT = "default"  # --beam-deg's name for the world's own pattern
HEADER = (f"{'world':<18} {'theta0':>7} {'mode':<9} {'leak':>6} {'block':>6} {'accuracy':>8} {'checks':>6} "
          f"{'lobe':>9} {'p_hit':>6} {'p_max':>6} {'sigma':>6} {'p_rand':>6} {'spec.':>5} {'s':>6}  model from")


def beam_list(text: str) -> list[str]:
    """--beam-deg's values: ``default`` or a number of degrees (the loader checks its range)."""
    out = []
    for item in (t.strip() for t in text.split(",") if t.strip()):
        if item != DEFAULT:
            try:
                float(item)
            except ValueError:
                raise argparse.ArgumentTypeError(f"expected numbers of degrees or {DEFAULT!r}, got {item!r}") from None
        out.append(item)
    return out


def variant(world: str, theta0: str, folder: Path) -> Path:
    """The world file of ``world`` with the beam pattern ``theta0``, written in ``folder``."""
    beam = None if theta0 == DEFAULT else float(theta0)
    raw = with_beam_pattern((ROOT / "worlds" / f"{world}.yaml").read_text(), beam)
    raw["name"] = f"{world}_beam{theta0}"
    path = folder / f"{raw['name']}.yaml"
    path.write_text(f"# {world}.yaml with the beam pattern theta0 = {theta0} (bench/bench_beam.py)\n"
                    + yaml.safe_dump(raw, sort_keys=False))
    return path


def causes(cause: np.ndarray) -> dict[str, float]:
    """The share of the log's readings of each cause (``/truth/cause``)."""
    return {name: float(np.mean(cause == c)) for name, c in
            (("echo", CAUSE_ECHO), ("no_echo", CAUSE_NO_ECHO), ("specular", CAUSE_SPECULAR))}


def beam_learned(m) -> dict:
    """What map ``m`` learned of the beam: its ``learned`` record flattened."""
    learned = m.learned or {}
    sensor = learned.get("sensor") or {}
    return {"origin": learned.get("origin"), "lobe_deg": learned.get("lobe_deg"), "lobe_range": learned.get("lobe_range"),
            "specular_deg": learned.get("specular_deg"),
            **{k: sensor.get(k) for k in ("p_hit", "p_max", "sigma", "p_rand")}, "learned": learned}


def scored(log_path: Path, modes: list[str], params) -> list[dict]:
    """Per mode: the map of the log scored as ``aogm compare`` scores it, and what it learned."""
    with LogReader(log_path) as reader:
        truth, poses = reader.truth(), reader.poses()
    rows = []
    for mode in modes:
        m = map_file(log_path, mode, params)
        metrics = evaluate(m, truth)
        planner = planner_metrics(m.grid, m.probability, m.observed, truth.occupancy, poses, ROBOT_RADIUS)
        rows.append({"mode": mode, "leak": planner["leak"], "block": planner["block"],
                     "surface_recall": planner["surface_recall"], "accuracy": metrics["accuracy"],
                     "occupied_f1": metrics["occupied_f1"],
                     "checks": {c["name"]: c["passed"] for c in metrics["checks"]},
                     "runtime_s": m.runtime_s, **beam_learned(m)})
    return rows


def number(value, fmt: str) -> str:
    return "-" if value is None else format(value, fmt)


def line(world: str, theta0: str, r: dict) -> str:
    checks = f"{sum(r['checks'].values())}/{len(r['checks'])}"
    lobe = "-" if r["lobe_deg"] is None else "cone" if r["lobe_deg"] == 0 else f"{r['lobe_deg']:g}/{r['lobe_range']:.2g}"
    return (f"{world:<18} {theta0:>7} {r['mode']:<9} {r['leak']:>6.3f} {r['block']:>6.3f} {r['accuracy']:>8.4f} "
            f"{checks:>6} {lobe:>9} {number(r['p_hit'], '.3f'):>6} {number(r['p_max'], '.3f'):>6} "
            f"{number(r['sigma'], '.3f'):>6} {number(r['p_rand'], '.3f'):>6} {number(r['specular_deg'], '.0f'):>5} "
            f"{r['runtime_s']:>6.1f}  {r['origin'] or '-'}")


def run(args, folder: Path) -> list[dict]:
    params = resolve_params(args.params)
    modes = list(dict.fromkeys(["standard", *args.modes]))
    print(f"Seed {args.seed}; variants with echo_strength {{min_strength: {MIN_STRENGTH}, beam_deg: THETA0}} and "
          f"random_rate {RANDOM_RATE}; params: {args.params or 'defaults'}; leak/block at robot radius {ROBOT_RADIUS} m")
    print("lobe: theta0/R0 of the detection lobe the map's forward model uses, or cone (the whole cone); "
          "no echo: the log's readings without an echo")
    print(HEADER)
    doc = []
    for world in args.worlds:
        for theta0 in args.beam_deg:
            path = variant(world, theta0, folder)
            log = simulate(load_world(path), seed=args.seed)
            log_path = folder / f"{path.stem}.h5"
            write_log(log_path, log)
            share = causes(log.truth.cause)
            print(f"{world:<18} {theta0:>7} (log: {log.ranges.size} readings, no echo {share['no_echo']:.1%}, "
                  f"specular/multipath {share['specular']:.1%})")
            rows = scored(log_path, modes, params)
            for r in rows:
                print(line(world, theta0, r), flush=True)
            doc.append({"world": world, "theta0": theta0, "variant": path.name, "log": log_path.name,
                        "causes": share, "modes": rows})
    return doc


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--worlds", default=",".join(WORLDS), help="bundled worlds, comma-separated (default: six)")
    parser.add_argument("--beam-deg", type=beam_list, default=beam_list("8,12"),
                        help="theta0 of each variant in degrees, comma-separated; 'default': the world's own (default 8,12)")
    parser.add_argument("--seed", type=int, default=1, help="the simulator's seed (default 1)")
    parser.add_argument("--modes", default="em,adaptive", help="modes besides standard, comma-separated (default em,adaptive)")
    parser.add_argument("--params", help="a --params YAML every map is made with")
    parser.add_argument("--json", type=Path, help="write every number as JSON")
    parser.add_argument("--keep", type=Path, help="write the worlds and logs here (default: a temporary folder)")
    args = parser.parse_args()
    args.worlds = [w.strip() for w in args.worlds.split(",") if w.strip()]
    args.modes = [m.strip() for m in args.modes.split(",") if m.strip()]
    if unknown := [m for m in args.modes if m not in MODES]:
        parser.error(f"--modes: expected some of {', '.join(MODES)}, got {', '.join(unknown)}")
    if missing := [w for w in args.worlds if not (ROOT / "worlds" / f"{w}.yaml").is_file()]:
        parser.error(f"--worlds: no bundled world {', '.join(missing)} (worlds/*.yaml)")
    try:
        if args.keep:
            args.keep.mkdir(parents=True, exist_ok=True)
            doc = run(args, args.keep)
        else:
            with tempfile.TemporaryDirectory() as folder:
                doc = run(args, Path(folder))
    except InputError as exc:
        sys.exit(f"bench_beam: {exc}")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        out = {"seed": args.seed, "params": args.params, "min_strength": MIN_STRENGTH, "random_rate": RANDOM_RATE,
               "robot_radius": ROBOT_RADIUS, "kept": None if args.keep is None else str(args.keep), "runs": doc}
        args.json.write_text(json.dumps(out, indent=1) + "\n")
        print(f"JSON: {args.json}")


if __name__ == "__main__":
    main()
