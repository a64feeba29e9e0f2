"""Study: would a lobe fitted on every n-th scan check a carried lobe at a fraction of the fit's cost?

    python bench/lobe_check_study.py 2,3,4 LOG.h5 [LOG.h5 ...]

For each log (simulated, of the packaged detector's ring) the state of an em map just before its lobe stage,
the packaged detector's model taken without a lobe; then the lobe fit (``beam_model.lobe_walls`` and
``lobe.learn_lobe``) on every scan and on every n-th scan (walls and echoes of those scans only): each fit's
decision (the whole cone or theta0), the echoes the best lobe and the whole cone explain, and its time.
"""

from __future__ import annotations

import dataclasses
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from cone_views import state_before  # noqa: E402

import aogm_cli.mapping.beam_model as B  # noqa: E402
from aogm_cli.io.logfile import LogReader  # noqa: E402
from aogm_cli.map_files import resolve_params, sensor_model  # noqa: E402
from aogm_cli.mapping.modes import resolved_params  # noqa: E402
from aogm_cli.sensor_models.lobe import learn_lobe  # noqa: E402


def main() -> None:
    every_list = [int(x) for x in sys.argv[1].split(",")]
    for path in sys.argv[2:]:
        with LogReader(path) as reader:
            log = reader.read()
            given = sensor_model("em", resolve_params(), reader, path)
        if given is not None:
            given = dataclasses.replace(given, lobe_deg=None, lobe_range=None)
        s = state_before(log, "em", resolved_params(log, resolve_params()), "lobe", given)
        forward = s.in_use.em.forward
        out = []
        for every in [1, *every_list]:
            whole, cuts, walls = s.whole, s.readings.cuts, s.echo_walls
            if every > 1:
                whole = dataclasses.replace(whole, time=whole.time[::every], pose=whole.pose[::every],
                                            ranges=whole.ranges[::every])
                cuts, walls = None if cuts is None else cuts[::every], None
            t0 = time.perf_counter()
            at, _ = B.lobe_walls(whole, s.readings, s.in_use, s.standard.log_odds, s.standard.observed, walls, None)
            n, width = s.whole.ranges.shape
            keep = np.repeat(np.arange(n) % every == 0, width)
            cones = tuple(np.ascontiguousarray(a).reshape(-1)[keep] for a in s.readings.cones)
            lobe = learn_lobe(s.readings.templates, s.readings.grid, cones, at, float(s.readings.sensor.max_range),
                              float(forward.window * forward.sigma))
            seconds = time.perf_counter() - t0
            shape = "cone" if lobe.full_cone else f"{lobe.theta0_deg:g} deg"
            out.append(f"1/{every}: {shape}, best {lobe.explained_best}, cone {lobe.explained_cone} of {lobe.echoes} "
                       f"({seconds * 1e3:.1f} ms)")
        print(Path(path).name, " | ".join(out), flush=True)


if __name__ == "__main__":
    main()
