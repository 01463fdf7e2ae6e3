"""Message builders and readers shared by the nodes: stamps, headers, odometry, one-joint
longitudinal trajectories and diagnostics (the only conversions between messages and the
core's floats)."""

from __future__ import annotations

import importlib
from collections.abc import Sequence
from typing import Any

from builtin_interfaces.msg import Duration, Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from nav_msgs.msg import Odometry
from std_msgs.msg import Header
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from trust_monitor.common.lockstep import split_ns
from trust_monitor.common.topics import JOINT_NAME


def message_class(msgtype: str) -> Any:
    """The Python class of ``pkg/msg/Name``."""
    package, _, name = msgtype.split('/')
    return getattr(importlib.import_module(f'{package}.msg'), name)


def time_msg(ns: int) -> Time:
    """``builtin_interfaces/Time`` of integer nanoseconds."""
    sec, nanosec = split_ns(ns)
    return Time(sec=sec, nanosec=nanosec)


def msg_ns(stamp: Time) -> int:
    """Integer nanoseconds of a ``builtin_interfaces/Time``."""
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def header(ns: int, frame_id: str) -> Header:
    """A header stamped ``ns``."""
    return Header(stamp=time_msg(ns), frame_id=frame_id)


def odometry(ns: int, position_m: float, speed_mps: float, child_frame_id: str) -> Odometry:
    """Longitudinal odometry: x along the road, speed in twist.linear.x."""
    msg = Odometry(header=header(ns, 'odom'), child_frame_id=child_frame_id)
    msg.pose.pose.position.x = float(position_m)
    msg.pose.pose.orientation.w = 1.0
    msg.twist.twist.linear.x = float(speed_mps)
    return msg


def trajectory(ns: int, dt_s: float, *, accelerations: Sequence[float] | None = None,
               velocities: Sequence[float] | None = None) -> JointTrajectory:
    """One-joint longitudinal trajectory, one point per step (time_from_start k*dt)."""
    values = accelerations if accelerations is not None else velocities
    assert values is not None
    msg = JointTrajectory(header=header(ns, 'odom'), joint_names=[JOINT_NAME])
    for k, value in enumerate(values):
        point = JointTrajectoryPoint()
        if accelerations is not None:
            point.accelerations = [float(value)]
        else:
            point.velocities = [float(value)]
        total = round(k * dt_s * 1e9)
        point.time_from_start = Duration(sec=total // 1_000_000_000,
                                         nanosec=total % 1_000_000_000)
        msg.points.append(point)
    return msg


def trajectory_values(msg: JointTrajectory, field: str) -> list[float]:
    """The joint's ``accelerations`` or ``velocities`` over the points."""
    return [float(getattr(p, field)[0]) for p in msg.points]


def trajectory_times(msg: JointTrajectory) -> list[float]:
    """The points' ``time_from_start``, s (a plan's own grid)."""
    return [p.time_from_start.sec + p.time_from_start.nanosec / 1e9 for p in msg.points]


def diagnostics(ns: int, name: str, level_ok: bool, message: str,
                values: dict[str, str]) -> DiagnosticArray:
    """One DiagnosticStatus with key/values (floats as repr: exact round trip)."""
    status = DiagnosticStatus(level=DiagnosticStatus.OK if level_ok else DiagnosticStatus.WARN,
                              name=name, message=message, hardware_id='sim')
    status.values = [KeyValue(key=k, value=v) for k, v in values.items()]
    return DiagnosticArray(header=header(ns, ''), status=[status])


def diagnostic_values(msg: DiagnosticArray) -> dict[str, str]:
    """Key/values of the first status."""
    return {kv.key: kv.value for kv in msg.status[0].values}
