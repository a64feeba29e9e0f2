"""Odometry drift: the pose estimate a robot's dead reckoning logs while it drives the true path
(``dead_reckoning``)."""

from __future__ import annotations

import math

import numpy as np

from aogm_cli.world.config import Odometry


def _wrap(angle: np.ndarray) -> np.ndarray:
    """Angles (rad) wrapped into [-pi, pi)."""
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


def relative_motion(pose: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(rot1, trans, rot2), each (T-1,), of the motion between consecutive poses (T, 3).

    rot1 turns the heading towards the next position, trans drives there (negative when the
    robot backs up: the position lies more than 90 degrees off its heading), rot2 turns to the
    next heading. A step in place (no translation) is all rot2.
    """
    d = np.diff(pose[:, :2], axis=0)
    trans = np.hypot(d[:, 0], d[:, 1])
    moved = trans > 0.0
    rot1 = np.where(moved, _wrap(np.arctan2(d[:, 1], d[:, 0]) - pose[:-1, 2]), 0.0)
    back = np.abs(rot1) > math.pi / 2
    rot1 = np.where(back, _wrap(rot1 + math.pi), rot1)
    trans = np.where(back, -trans, trans)
    rot2 = _wrap(np.diff(pose[:, 2]) - rot1)
    return rot1, trans, rot2


# The true relative motion between consecutive scans is split into (rot1, trans, rot2) and each part
# drawn with Gaussian error, as in the odometry motion model of Probabilistic Robotics (Thrun, Burgard
# & Fox 2005, table 5.6), with UMBmark's systematic errors (Borenstein & Feng 1996: unequal wheel
# diameters, a wrong wheelbase) as a bias on each turn, then integrated from the true first pose.
def dead_reckoning(pose: np.ndarray, odometry: Odometry, rng: np.random.Generator) -> np.ndarray:
    """The drifting pose estimate (T, 3) of a robot driving the true ``pose`` (T, 3).

    The first pose is known; each later step's (rot1, trans, rot2) gets Gaussian errors of
    std ``translation |trans|`` and ``sqrt((rotation rot)^2 + rotation_per_metre^2 trans^2 / 2)``
    (Probabilistic Robotics' alpha1 = rotation^2, alpha2 = rotation_per_metre^2 / 2,
    alpha3 = translation^2, alpha4 = 0: a metre driven adds ``rotation_per_metre`` rad of
    heading std, split between the two turns). ``rng`` gives one (T-1, 3) standard normal draw,
    drawn only when one of these random errors is on. The systematic errors draw nothing: each
    turn gets ``turn_bias * rot`` and ``heading_bias_per_metre * trans / 2`` (trans signed: backing
    up turns the other way, as unequal wheels do). With every error zero the true poses come
    back unchanged. Yaw is wrapped into [-pi, pi).
    """
    pose = np.asarray(pose, dtype=np.float64)
    if odometry.off or pose.shape[0] < 2:
        return pose.copy()
    rot1, trans, rot2 = relative_motion(pose)
    if not odometry.random_off:
        z = rng.standard_normal((pose.shape[0] - 1, 3))
        turn_per_metre = odometry.rotation_per_metre**2 * trans**2 / 2.0
        rot1, trans, rot2 = (
            rot1 + np.sqrt((odometry.rotation * rot1) ** 2 + turn_per_metre) * z[:, 0],
            trans + odometry.translation * np.abs(trans) * z[:, 1],
            rot2 + np.sqrt((odometry.rotation * rot2) ** 2 + turn_per_metre) * z[:, 2],
        )
    if odometry.heading_bias_per_metre != 0.0 or odometry.turn_bias != 0.0:
        half_arc = odometry.heading_bias_per_metre * trans / 2.0
        rot1 = rot1 * (1.0 + odometry.turn_bias) + half_arc
        rot2 = rot2 * (1.0 + odometry.turn_bias) + half_arc
    yaw = pose[0, 2] + np.concatenate([[0.0], np.cumsum(rot1 + rot2)])
    heading = yaw[:-1] + rot1
    x = pose[0, 0] + np.concatenate([[0.0], np.cumsum(trans * np.cos(heading))])
    y = pose[0, 1] + np.concatenate([[0.0], np.cumsum(trans * np.sin(heading))])
    return np.column_stack([x, y, _wrap(yaw)])
