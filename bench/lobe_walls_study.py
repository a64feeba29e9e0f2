"""What the detection lobe is fitted at decides what it learns (docs/algorithms.md, "The lobe that hears"): per
simulated log, the lobe an em map fits (``beam_model.lobe_record``, the map's own rule, state and carried model) at the walls it fits
it at (``beam_model.lobe_walls``: the standard map with its echo walls, thinned) and at the truth's walls, and how
many of the thinned walls' cells lie more than a cell from any true wall. Two walls between the two tell which
of the thinned walls' faults moves the fit: the thinned cells within a cell of a true wall (the false ones left
out), and the true wall cells within a cell of a thinned one (the walls the map misses left out).

    python bench/lobe_walls_study.py LOG.h5 [LOG.h5 ...] [--maps-dir DIR] [--rows DIR] [--held-r0 R]

``--maps-dir DIR``: also fit at each EM map ``DIR/<log>_em.h5``'s own occupied cells (``/map/occupied``; the maps
``aogm compare --maps-dir`` writes). ``--rows DIR``: map each log with each lobe configured (``em.lobe_deg``,
``em.lobe_range``, ``calibration.learn`` without ``lobe_deg``; ``aogm compare --modes em,adaptive``, files in DIR)
and count the rows with leak <= 0.03 and block <= 0.08 per kind of walls. ``--held-r0 R``: also the theta0 the fit
learns at each kind of walls with R0 held at the candidate nearest R metres (``lobe.R0_GRID_M``).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import yaml
from scipy import ndimage

import aogm_cli
from aogm_cli.map_files import sensor_model
from aogm_cli.mapping import beam_model as B
from aogm_cli.mapping.modes import resolved_params, state_before
from aogm_cli.mapping.params import CalibrationConfig, MapParams
from aogm_cli.sensor_models.lobe import R0_GRID_M, THETA0_GRID_DEG

LEAK, BLOCK = 0.03, 0.08  # issue 47's targets


def fits(path: Path, maps_dir: Path | None, held_r0: float | None = None) -> tuple[dict, str]:
    """The lobe (theta0, R0; (0, 10): the whole cone; with ``held_r0`` also theta0 at that R0) fitted at each kind of
    walls, and a line on the thinned walls."""
    log = aogm_cli.load_log(path)
    params = resolved_params(log, MapParams())
    # the em map's state before its lobe, with the model ``aogm map`` gives it (the packaged detector's)
    s = state_before(log, "em", params, "lobe", given=sensor_model("em", params, log, str(path)))
    truth = np.asarray(log.truth.occupancy) != 0
    walls = {"thinned": B.lobe_walls(s.whole, s.readings, s.in_use, s.standard.log_odds, s.standard.observed,
                                     s.echo_walls, s.exact)[0],
             "truth": truth.reshape(-1)}
    thinned = walls["thinned"].reshape(truth.shape)
    walls["thinned near truth"] = (thinned & ndimage.binary_dilation(truth)).reshape(-1)
    walls["truth near thinned"] = (truth & ndimage.binary_dilation(thinned)).reshape(-1)
    if maps_dir is not None:
        with h5py.File(maps_dir / f"{path.stem}_em.h5", "r") as f:
            walls["em map"] = f["map/occupied"][...].astype(bool).reshape(-1)
    off = walls["thinned"].reshape(truth.shape) & ~ndimage.binary_dilation(truth)
    found = {}
    for kind, w in walls.items():
        lobe = B.lobe_record(s.readings, s.in_use, w)
        found[kind] = (0.0, 10.0) if lobe.full_cone else (lobe.theta0_deg, lobe.r0_m)
        if held_r0 is not None:
            j = int(np.argmin(np.abs(np.log(R0_GRID_M / held_r0))))
            found[f"{kind}, R0 held"] = (float(THETA0_GRID_DEG[np.argmax(lobe.explained[:, j])]), float(R0_GRID_M[j]))
    return found, f"thinned walls {int(walls['thinned'].sum())} cells, {int(off.sum())} more than a cell from a true wall"


def rows(path: Path, lobe: tuple[float, float], out: Path, kind: str) -> list[tuple[str, float, float]]:
    """(mode, leak, block) of ``path`` mapped with ``lobe`` configured."""
    learn = ",".join(k for k in CalibrationConfig().learned if k != "lobe_deg")
    params = out / f"{path.stem}_{kind.replace(' ', '_')}.yaml"
    params.write_text(yaml.safe_dump({"em": {"lobe_deg": lobe[0], "lobe_range": lobe[1]},
                                      "calibration": {"learn": learn}}))
    report = params.with_suffix(".json")
    subprocess.run([sys.executable, "-m", "aogm_cli", "compare", str(path), "--modes", "em,adaptive", "--params",
                    str(params), "--json", str(report), "--quiet"], check=True, stdout=subprocess.DEVNULL)
    return [(r["mode"], r["metrics"]["leak"], r["metrics"]["block"]) for r in json.loads(report.read_text())["results"]]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("logs", nargs="+", type=Path)
    parser.add_argument("--maps-dir", type=Path, help="fit at these EM maps' occupied cells too")
    parser.add_argument("--rows", type=Path, metavar="DIR", help="map with each lobe configured; count the rows")
    parser.add_argument("--held-r0", type=float, metavar="R", help="also theta0 with R0 held at R metres")
    args = parser.parse_args()
    met: dict[str, list[bool]] = {}
    for path in args.logs:
        found, line = fits(path, args.maps_dir, args.held_r0)
        print(f"{path.name}: {line}; lobe (theta0 deg / R0 m; 0: the whole cone) at " +
              ", ".join(f"{kind} {t:g} / {r:.3g}" for kind, (t, r) in found.items()), flush=True)
        if args.rows is not None:
            args.rows.mkdir(parents=True, exist_ok=True)
            for kind, lobe in found.items():
                for mode, leak, block in rows(path, lobe, args.rows, kind):
                    met.setdefault(kind, []).append(leak <= LEAK and block <= BLOCK)
                    print(f"    {kind:8s} {mode:9s} leak {leak:.3f} block {block:.3f}", flush=True)
    for kind, ok in met.items():
        print(f"lobes fitted at the {kind} walls: {sum(ok)} of {len(ok)} rows meet leak <= {LEAK} and block <= {BLOCK}")


if __name__ == "__main__":
    main()
