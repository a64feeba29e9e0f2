"""Bags written with rosbags' own writers for the importer tests (test_import_rosbag, test_rosaria):
``Bag``, a ROS 1, ROS 2 sqlite3 or MCAP bag being written message by message, and ``T0``."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from rosbags.rosbag1 import Writer as Writer1
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Writer2
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from aogm_cli.io.importers.rosbag_messages import SONAR_ARRAY, SONAR_ARRAY_MSG

T0 = 1000.0  # s: the bag's stamps are the log's times plus this


class Bag:
    """A bag being written: ``kind`` ros1, sqlite3 or mcap; ``write(topic, type, t, **fields)``."""

    def __init__(self, path: Path, kind: str):
        self.ros1 = kind == "ros1"
        self.ts = get_typestore(Stores.ROS1_NOETIC if self.ros1 else Stores.ROS2_HUMBLE)
        extra = get_types_from_msg(SONAR_ARRAY_MSG, SONAR_ARRAY)
        if "tf2_msgs/msg/TFMessage" not in self.ts.fielddefs:
            extra.update(get_types_from_msg("geometry_msgs/TransformStamped[] transforms", "tf2_msgs/msg/TFMessage"))
        self.ts.register(extra)
        plugin = StoragePlugin.MCAP if kind == "mcap" else StoragePlugin.SQLITE3
        self.writer = Writer1(path) if self.ros1 else Writer2(path, version=9, storage_plugin=plugin)
        self.connections: dict[str, object] = {}

    def __enter__(self):
        self.writer.open()
        return self

    def __exit__(self, *exc):
        self.writer.close()

    def msg(self, msgtype: str, /, **fields):
        return self.ts.types[msgtype](**fields)

    def header(self, t: float, frame: str):
        sec = int(t)
        stamp = self.msg("builtin_interfaces/msg/Time", sec=sec, nanosec=round((t - sec) * 1e9))
        extra = {"seq": 0} if self.ros1 else {}
        return self.msg("std_msgs/msg/Header", stamp=stamp, frame_id=frame, **extra)

    def pose(self, p):
        point = self.msg("geometry_msgs/msg/Point", x=float(p[0]), y=float(p[1]), z=0.0)
        return self.msg("geometry_msgs/msg/Pose", position=point, orientation=self.quaternion(p[2]))

    def quaternion(self, yaw: float):
        return self.msg("geometry_msgs/msg/Quaternion", x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2))

    def transform(self, t: float, parent: str, child: str, p, z: float = 0.0, rotation=None):
        v = self.msg("geometry_msgs/msg/Vector3", x=float(p[0]), y=float(p[1]), z=z)
        tr = self.msg("geometry_msgs/msg/Transform", translation=v, rotation=rotation or self.quaternion(p[2]))
        return self.msg("geometry_msgs/msg/TransformStamped", header=self.header(t, parent), child_frame_id=child,
                        transform=tr)

    def write(self, topic: str, msgtype: str, t: float, message) -> None:
        if topic not in self.connections:
            self.connections[topic] = self.writer.add_connection(topic, msgtype, typestore=self.ts)
        data = self.ts.serialize_ros1(message, msgtype) if self.ros1 else self.ts.serialize_cdr(message, msgtype)
        self.writer.write(self.connections[topic], round(t * 1e9), data)

    def odometry(self, t: float, pose):
        """A nav_msgs/Odometry of ``pose`` at ``t`` (odom -> base_link, standing still)."""
        cov = self.msg("geometry_msgs/msg/PoseWithCovariance", pose=self.pose(pose), covariance=np.zeros(36))
        zero = self.msg("geometry_msgs/msg/Vector3", x=0.0, y=0.0, z=0.0)
        twist = self.msg("geometry_msgs/msg/TwistWithCovariance",
                         twist=self.msg("geometry_msgs/msg/Twist", linear=zero, angular=zero), covariance=np.zeros(36))
        return self.msg("nav_msgs/msg/Odometry", header=self.header(t, "odom"), child_frame_id="base_link", pose=cov,
                        twist=twist)

    def tf(self, topic: str, t: float, transforms) -> None:
        self.write(topic, "tf2_msgs/msg/TFMessage", t, self.msg("tf2_msgs/msg/TFMessage", transforms=transforms))
