"""Robot frame -> world frame: where each sensor is, and where it points, at each scan. A pose is
(x, y, yaw), yaw counter-clockwise from +x (REP-103); a mount is a sensor's (x, y, yaw) on the robot."""

from __future__ import annotations

import numpy as np


def sensor_poses(pose: np.ndarray, mount: np.ndarray) -> np.ndarray:
    """(T, S, 3) world poses of S sensors mounted at ``mount`` (S, 3) on robot poses (T, 3)."""
    pose = np.asarray(pose, dtype=np.float64)
    mount = np.asarray(mount, dtype=np.float64)
    c = np.cos(pose[:, 2])[:, None]
    s = np.sin(pose[:, 2])[:, None]
    out = np.empty((pose.shape[0], mount.shape[0], 3))
    out[:, :, 0] = pose[:, 0, None] + c * mount[None, :, 0] - s * mount[None, :, 1]
    out[:, :, 1] = pose[:, 1, None] + s * mount[None, :, 0] + c * mount[None, :, 1]
    out[:, :, 2] = pose[:, 2, None] + mount[None, :, 2]
    return out
