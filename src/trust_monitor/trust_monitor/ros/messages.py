"""Message builders and readers shared by the nodes: stamps, headers, odometry with its
``tf`` transform, one-joint longitudinal trajectories, diagnostics and the vehicles' markers
(the only conversions between messages and the core's floats).

Frames follow :mod:`trust_monitor.common.topics` (REP-105): odometry in ``odom`` with the
vehicle's body frame as child, trajectories and commands in the body frame of the vehicle
they belong to. Messages published every step are built once (:class:`VehicleOdometry`,
:class:`VehicleMarkers`) and only their stamp and values change.
"""

from __future__ import annotations

import importlib
from collections.abc import Sequence
from typing import Any

from builtin_interfaces.msg import Duration, Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import TransformStamped
from nav_msgs.msg import Odometry
from std_msgs.msg import ColorRGBA, Header
from tf2_msgs.msg import TFMessage
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint
from visualization_msgs.msg import Marker, MarkerArray

from trust_monitor.common.lockstep import split_ns
from trust_monitor.common.topics import JOINT_NAME, NO_FRAME, ODOM_FRAME


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
    """Longitudinal odometry in ``odom``: x along the road (the front bumper), speed in
    twist.linear.x (expressed in the child frame, the vehicle's body frame)."""
    msg = Odometry(header=header(ns, ODOM_FRAME), child_frame_id=child_frame_id)
    msg.pose.pose.position.x = float(position_m)
    msg.pose.pose.orientation.w = 1.0
    msg.twist.twist.linear.x = float(speed_mps)
    return msg


class VehicleOdometry:
    """One vehicle's odometry and its ``odom`` -> body transform (``tf``), built once.

    :meth:`update` writes the stamp, position and speed into both messages; the node then
    publishes :attr:`odometry` and :attr:`tf` (rclpy serialises on ``publish``, so the
    messages may be changed again right after).

    Args:
        child_frame_id: the vehicle's body frame.
    """

    def __init__(self, child_frame_id: str) -> None:
        self.odometry = odometry(0, 0.0, 0.0, child_frame_id)
        self._transform = TransformStamped(header=header(0, ODOM_FRAME),
                                           child_frame_id=child_frame_id)
        self._transform.transform.rotation.w = 1.0
        self.tf = TFMessage(transforms=[self._transform])

    def update(self, ns: int, position_m: float, speed_mps: float) -> None:
        """Stamp ``ns`` (integer ns), position (m along the road) and speed (m/s)."""
        sec, nanosec = split_ns(ns)
        for stamp in (self.odometry.header.stamp, self._transform.header.stamp):
            stamp.sec, stamp.nanosec = sec, nanosec
        self.odometry.pose.pose.position.x = float(position_m)
        self.odometry.twist.twist.linear.x = float(speed_mps)
        self._transform.transform.translation.x = float(position_m)


MARKER_WIDTH_M = 1.8
MARKER_HEIGHT_M = 1.5
VEHICLE_LABELS = {'preceding_vehicle': 'preceding vehicle', 'ego': 'AV (ego)',
                  'human': 'human driver'}
_COLOURS = {'preceding_vehicle': (0.6, 0.6, 0.6), 'ego': (0.1, 0.5, 0.9),
            'human': (0.95, 0.55, 0.1)}


class VehicleMarkers:
    """A ``MarkerArray`` of the three vehicles, built once: per vehicle a box (x from
    -length to 0 in its body frame: the frame origin is the front bumper) and a text label
    above it. Every marker is frame-locked in its vehicle's frame, so only the stamp changes
    from message to message (:meth:`update`); a 3D view places them through ``tf``.

    Args:
        vehicle_length_m: box length, m.
    """

    def __init__(self, vehicle_length_m: float) -> None:
        markers = []
        for index, (frame, label) in enumerate(VEHICLE_LABELS.items()):
            red, green, blue = _COLOURS[frame]
            box = Marker(header=header(0, frame), ns='vehicles', id=index, type=Marker.CUBE,
                         action=Marker.ADD, frame_locked=True,
                         color=ColorRGBA(r=red, g=green, b=blue, a=0.9))
            box.pose.position.x = -0.5 * vehicle_length_m
            box.pose.position.z = 0.5 * MARKER_HEIGHT_M
            box.pose.orientation.w = 1.0
            box.scale.x, box.scale.y, box.scale.z = (float(vehicle_length_m), MARKER_WIDTH_M,
                                                     MARKER_HEIGHT_M)
            text = Marker(header=header(0, frame), ns='labels', id=index,
                          type=Marker.TEXT_VIEW_FACING, action=Marker.ADD, frame_locked=True,
                          text=label, color=ColorRGBA(r=1.0, g=1.0, b=1.0, a=1.0))
            text.pose.position.x = -0.5 * vehicle_length_m
            text.pose.position.z = MARKER_HEIGHT_M + 0.8
            text.pose.orientation.w = 1.0
            text.scale.z = 0.8
            markers += [box, text]
        self.msg = MarkerArray(markers=markers)
        self._stamps = [marker.header.stamp for marker in self.msg.markers]

    def update(self, ns: int) -> MarkerArray:
        """The array stamped ``ns`` (integer ns)."""
        sec, nanosec = split_ns(ns)
        for stamp in self._stamps:
            stamp.sec, stamp.nanosec = sec, nanosec
        return self.msg


def trajectory(ns: int, dt_s: float, *, frame_id: str,
               accelerations: Sequence[float] | None = None,
               velocities: Sequence[float] | None = None) -> JointTrajectory:
    """One-joint longitudinal trajectory, one point per step (time_from_start k*dt), in
    ``frame_id`` (the body frame of the vehicle whose plan or speeds it holds)."""
    values = accelerations if accelerations is not None else velocities
    assert values is not None
    msg = JointTrajectory(header=header(ns, frame_id), joint_names=[JOINT_NAME])
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


def diagnostics(ns: int, name: str, level_ok: bool, message: str,
                values: dict[str, str]) -> DiagnosticArray:
    """One DiagnosticStatus with key/values (floats as repr: exact round trip); no frame
    (``frame_id`` empty: nothing spatial)."""
    status = DiagnosticStatus(level=DiagnosticStatus.OK if level_ok else DiagnosticStatus.WARN,
                              name=name, message=message, hardware_id='sim')
    status.values = [KeyValue(key=k, value=v) for k, v in values.items()]
    return DiagnosticArray(header=header(ns, NO_FRAME), status=[status])


def diagnostic_values(msg: DiagnosticArray) -> dict[str, str]:
    """Key/values of the first status."""
    return {kv.key: kv.value for kv in msg.status[0].values}
