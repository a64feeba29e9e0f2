"""The ring's firing schedule (world key ``errors.firing``): which firing of each sonar a scan holds,
how long before the scan it was taken, and which earlier scan already holds it."""

from __future__ import annotations

import numpy as np

from aogm_cli.world.config import Firing

# Scan times and firing times are sums of rounded products: a firing this close before a scan
# (relative to the cycle) counts as at the scan, not a whole cycle earlier.
TIME_TOLERANCE = 1e-9


def slots(firing: Firing, n_sensors: int) -> np.ndarray:
    """Each sonar's slot in the cycle (S,): the configured ones, or 0, 1, ... in mount order."""
    return np.asarray(firing.slots or range(n_sensors), dtype=np.int64)


# Sonars fire in a fixed cycle, slot after slot ``interval`` seconds apart, from time 0 on (and
# before: the robot stands at its first pose until the log starts); a scan at time t holds each
# sonar's latest firing at or before t, as a robot's driver reports the newest reading of every
# sonar with the robot's current pose.
def schedule(firing: Firing, time: np.ndarray, n_sensors: int) -> tuple[np.ndarray, np.ndarray]:
    """Ages (T, S) and sources (T, S) of the readings of scans at ``time`` (T,).

    ``ages[t, k]`` >= 0 is how many seconds before scan t sonar k last fired; ``source[t, k]``
    is the first scan that holds that same firing (t itself when it is new), whose reading
    scan t repeats.
    """
    slot = slots(firing, n_sensors)
    cycle = (int(slot.max()) + 1) * firing.interval
    offset = slot * firing.interval  # (S,) first firing of each sonar in a cycle
    since = np.asarray(time, dtype=np.float64)[:, None] - offset[None, :]
    count = np.floor(since / cycle + TIME_TOLERANCE)  # which firing of each sonar: (T, S)
    ages = np.maximum(since - count * cycle, 0.0)
    new = np.ones(count.shape, dtype=bool)
    new[1:] = count[1:] != count[:-1]
    index = np.arange(count.shape[0])[:, None]
    source = np.maximum.accumulate(np.where(new, index, 0), axis=0)
    return ages, source
