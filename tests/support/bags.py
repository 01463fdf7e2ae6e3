"""Bags written directly with the bag writer: two odometry topics, steps that fail to commit
(a failing disk)."""

from __future__ import annotations

import errno
import os

import numpy as np
import pytest
from rosbags.typesys import Stores, get_typestore

from trust_av.graph import mcap_steps
from trust_av.graph.bag_writer import BagWriter, qos_profile

TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
QOS = qos_profile(reliable=True, transient_local=True, depth=1000)


def odometry(stamp_ns: int, speed: float) -> bytes:
    types = TYPESTORE.types
    msg = types['nav_msgs/msg/Odometry'](
        header=types['std_msgs/msg/Header'](
            stamp=types['builtin_interfaces/msg/Time'](sec=stamp_ns // 10**9,
                                                      nanosec=stamp_ns % 10**9),
            frame_id='odom'),
        child_frame_id='ego',
        pose=types['geometry_msgs/msg/PoseWithCovariance'](
            pose=types['geometry_msgs/msg/Pose'](
                position=types['geometry_msgs/msg/Point'](x=speed, y=0.0, z=0.0),
                orientation=types['geometry_msgs/msg/Quaternion'](x=0.0, y=0.0, z=0.0,
                                                                  w=1.0)),
            covariance=np.zeros(36)),
        twist=types['geometry_msgs/msg/TwistWithCovariance'](
            twist=types['geometry_msgs/msg/Twist'](
                linear=types['geometry_msgs/msg/Vector3'](x=speed, y=0.0, z=0.0),
                angular=types['geometry_msgs/msg/Vector3'](x=0.0, y=0.0, z=0.0)),
            covariance=np.zeros(36)))
    return bytes(TYPESTORE.serialize_cdr(msg, 'nav_msgs/msg/Odometry'))


def fail_commit(monkeypatch: pytest.MonkeyPatch, number: int) -> None:
    """The ``number``-th chunk write (a step's commit) fails with EIO, as a failing disk."""
    commit = mcap_steps.WholeWrites.commit
    commits = []

    def failing(handle: mcap_steps.WholeWrites) -> None:
        commits.append(1)
        if len(commits) == number:
            raise OSError(errno.EIO, os.strerror(errno.EIO))
        commit(handle)

    monkeypatch.setattr(mcap_steps.WholeWrites, 'commit', failing)


def record(writer: BagWriter, steps: int, topics: tuple[str, ...] = ('/a/odom', '/b/odom'),
           *, finish: bool = True) -> None:
    for topic in topics:
        writer.add_topic(topic, 'nav_msgs/msg/Odometry', QOS)
    for step in range(steps):
        for topic in topics:
            writer.write(topic, odometry((100 + step) * 10**9, float(step)))
        if not writer.end_step():
            return
    if finish:
        writer.finish()
