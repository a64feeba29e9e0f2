"""tf in a bag -> 2D: the robot's poses along a chain of frames interpolated in time, and each
sensor's mount (its frame in the robot's base frame) from the static transforms.

Frames are a tree (each child has one parent); a leading "/" of a ROS 1 frame name is ignored.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from aogm_cli.core.errors import InputError
from aogm_cli.io.importers import interpolate_poses, wrap_angle


def frame_name(name: str) -> str:
    """A frame id as tf2 compares it: without a leading '/'."""
    return name.lstrip("/")


def rotation_matrix(x: float, y: float, z: float, w: float) -> np.ndarray:
    """The rotation (3, 3) of a quaternion (normalised here; a zero quaternion is the identity)."""
    n = math.sqrt(x * x + y * y + z * z + w * w)
    if not n or not math.isfinite(n):
        return np.eye(3)
    x, y, z, w = x / n, y / n, z / n, w / n
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def yaw_of(x: float, y: float, z: float, w: float) -> float:
    """The heading of a quaternion: the angle of its rotated x axis in the x-y plane."""
    r = rotation_matrix(x, y, z, w)
    return math.atan2(r[1, 0], r[0, 0])


def pose_of(position, orientation) -> tuple[float, float, float]:
    """(x, y, yaw) of a geometry_msgs Point/Vector3 and Quaternion."""
    o = orientation
    return float(position.x), float(position.y), yaw_of(o.x, o.y, o.z, o.w)


def compose(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """2D poses a ∘ b (each (N, 3) or (3,)): b given in a's frame -> in a's parent frame."""
    a, b = np.atleast_2d(a), np.atleast_2d(b)
    c, s = np.cos(a[:, 2]), np.sin(a[:, 2])
    return np.column_stack([a[:, 0] + c * b[:, 0] - s * b[:, 1], a[:, 1] + s * b[:, 0] + c * b[:, 1],
                            wrap_angle(a[:, 2] + b[:, 2])])


def invert(a: np.ndarray) -> np.ndarray:
    """The inverse of 2D poses (N, 3)."""
    a = np.atleast_2d(a)
    c, s = np.cos(a[:, 2]), np.sin(a[:, 2])
    return np.column_stack([-c * a[:, 0] - s * a[:, 1], s * a[:, 0] - c * a[:, 1], wrap_angle(-a[:, 2])])


@dataclass
class PoseSeries:
    """Poses (x, y, yaw) of one thing over time (a tf edge, an odometry topic), sampled at ``time``."""

    name: str  # what errors call it: "map -> odom", "/odom"
    time: list[float] = field(default_factory=list)
    pose: list[tuple[float, float, float]] = field(default_factory=list)
    not_finite: int = 0  # samples left out: a NaN or infinite time or pose

    def add(self, t: float, pose: tuple[float, float, float]) -> None:
        if not (math.isfinite(t) and all(math.isfinite(v) for v in pose)):
            self.not_finite += 1
            return
        self.time.append(t)
        self.pose.append(pose)

    def at(self, time: np.ndarray, max_gap: float) -> tuple[np.ndarray, np.ndarray]:
        """(poses (T, 3), covered (T,)) at ``time``: linear in x, y and along the shorter arc in yaw;
        covered means inside the samples' span, with the two samples around it at most ``max_gap`` s
        apart (an exact sample always counts)."""
        st = np.asarray(self.time, dtype=np.float64)
        pose, inside = interpolate_poses(st, np.asarray(self.pose, dtype=np.float64), time)
        if st.size:
            st = np.sort(st)
            j = np.clip(np.searchsorted(st, time, side="left"), 1, max(1, st.size - 1))
            gap = st[j] - st[j - 1] if st.size > 1 else np.zeros(time.shape)
            exact = st[np.clip(np.searchsorted(st, time), 0, st.size - 1)] == time
            inside &= (gap <= max_gap) | exact
        return pose, inside



def stamp(msg) -> float:
    """A stamped message's (or transform's) header time, in seconds."""
    s = msg.header.stamp
    return s.sec + s.nanosec / 1e9

class TfTree:
    """The transforms of /tf (dynamic, interpolated) and /tf_static of a bag, child -> parent."""

    def __init__(self) -> None:
        self.parent: dict[str, str] = {}
        self.static: dict[str, tuple[np.ndarray, np.ndarray]] = {}  # child -> (translation (3,), rotation (3, 3))
        self.dynamic: dict[str, PoseSeries] = {}  # child -> its poses in its parent's frame
        self.reparented = 0  # transforms naming a second parent for a child (ignored, as tf2 refuses them)

    def add(self, message, static: bool) -> None:
        """Add every transform of a tf2_msgs/TFMessage, each at its own stamp."""
        for tr in message.transforms:
            parent, child = frame_name(tr.header.frame_id), frame_name(tr.child_frame_id)
            if self.parent.setdefault(child, parent) != parent:
                self.reparented += 1
                continue
            v, q = tr.transform.translation, tr.transform.rotation
            if static:
                self.static[child] = (np.array([v.x, v.y, v.z], dtype=np.float64), rotation_matrix(q.x, q.y, q.z, q.w))
            else:
                series = self.dynamic.setdefault(child, PoseSeries(f"{parent} -> {child}"))
                series.add(stamp(tr), pose_of(v, q))

    def frames(self) -> set[str]:
        return set(self.parent) | set(self.parent.values())

    def _ancestors(self, frame: str) -> list[str]:
        """``frame`` and its parents up to the root."""
        out = [frame]
        while out[-1] in self.parent and len(out) <= len(self.parent):
            out.append(self.parent[out[-1]])
        return out

    def _path(self, parent: str, child: str, key: str) -> tuple[list[str], list[str]]:
        """The frames from the common ancestor down to ``parent`` and to ``child`` (each list
        excludes the ancestor); an error naming the frame that is missing or not connected."""
        for f in (parent, child):
            if f not in self.frames():
                known = ", ".join(sorted(self.frames())) or "none"
                raise InputError(f"no transform names frame {f!r} (frames in tf: {known})", key=key)
        up_p, up_c = self._ancestors(parent), self._ancestors(child)
        common = next((f for f in up_c if f in up_p), None)
        if common is None:
            raise InputError(f"frames {parent!r} and {child!r} are not connected by tf "
                             f"(their roots are {up_p[-1]!r} and {up_c[-1]!r})", key=key)
        return up_p[: up_p.index(common)][::-1], up_c[: up_c.index(common)][::-1]

    def poses(self, parent: str, child: str, time: np.ndarray, max_gap: float, key: str
              ) -> tuple[np.ndarray, np.ndarray, str | None]:
        """(2D poses (T, 3) of ``child`` in ``parent`` at ``time``, covered (T,), the first edge that
        does not cover some time, or None). Static edges hold at all times."""
        time = np.asarray(time, dtype=np.float64)
        covered = np.ones(time.shape, dtype=bool)
        gap_edge = None

        def down(frames: list[str]) -> np.ndarray:
            nonlocal covered, gap_edge
            pose = np.zeros((time.size, 3))
            for f in frames:
                if f in self.dynamic:
                    edge, ok = self.dynamic[f].at(time, max_gap)
                    if gap_edge is None and not ok.all():
                        gap_edge = self.dynamic[f].name
                    covered &= ok
                else:
                    t, r = self.static[f]
                    edge = np.broadcast_to([t[0], t[1], math.atan2(r[1, 0], r[0, 0])], (time.size, 3))
                pose = compose(pose, edge)
            return pose

        to_parent, to_child = self._path(parent, child, key)
        return compose(invert(down(to_parent)), down(to_child)), covered, gap_edge

    def static_transform(self, base: str, frame: str, key: str) -> tuple[np.ndarray, np.ndarray]:
        """(translation (3,), rotation (3, 3)) of ``frame`` in ``base`` from static transforms only."""
        try:
            up_b, up_f = self._path(base, frame, key)
        except InputError as exc:
            raise InputError(f"no static transform from {base!r} to {frame!r} in /tf_static ({exc.message}); "
                             "publish one or give --mounts FILE", key=key) from None
        dynamic = [f for f in up_b + up_f if f not in self.static]
        if dynamic:
            raise InputError(f"the transform from {base!r} to {frame!r} goes through {dynamic[0]!r}, which is only "
                             "in /tf (moving); mounts are read from /tf_static, or give --mounts FILE", key=key)

        def down(frames: list[str]) -> tuple[np.ndarray, np.ndarray]:
            t, r = np.zeros(3), np.eye(3)
            for f in frames:
                ft, fr = self.static[f]
                t, r = t + r @ ft, r @ fr
            return t, r

        tb, rb = down(up_b)
        tf_, rf = down(up_f)
        return rb.T @ (tf_ - tb), rb.T @ rf


def planar_mounts(translation: np.ndarray, rotation: np.ndarray, bearings: np.ndarray, tolerance: float,
                  key: str) -> np.ndarray:
    """Mounts (n, 3) in the base frame of beams at ``bearings`` (rad, about the sensor frame's z axis)
    of a sensor at (translation, rotation); an error naming ``key`` when a beam points more than
    ``tolerance`` (rad) out of the base frame's x-y plane (a tilted mount). Upside-down sensors
    (rolled by pi) come out mirrored, as they are."""
    beams = np.column_stack([np.cos(bearings), np.sin(bearings), np.zeros(bearings.size)]) @ rotation.T
    tilt = np.arcsin(np.clip(np.abs(beams[:, 2]), 0.0, 1.0))
    if tilt.max(initial=0.0) > tolerance:
        raise InputError(f"the sensor is tilted {math.degrees(tilt.max()):.1f} deg out of the base frame's plane "
                         f"(tolerance {math.degrees(tolerance):g} deg); a 2D map needs a level sensor "
                         "(--tilt-tolerance)", key=key)
    yaw = np.arctan2(beams[:, 1], beams[:, 0])
    return np.column_stack([np.full(bearings.size, translation[0]), np.full(bearings.size, translation[1]), yaw])
