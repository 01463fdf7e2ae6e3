"""Message builders and readers shared by the nodes: stamps, headers, odometry with its
``tf`` transform, one-joint longitudinal trajectories, diagnostics and the vehicles' markers
(the only conversions between messages and the core's floats).

Frames follow :mod:`trust_av_common.topics` (REP-105): odometry in ``odom`` with the
vehicle's body frame as child, trajectories and commands in the body frame of the vehicle
they belong to. Odometry, tf and markers are serialised once (:class:`SerializedTemplate`)
and published as bytes with only their stamp and values written in.
"""

from __future__ import annotations

import importlib
import struct
from collections.abc import Sequence
from typing import Any

from builtin_interfaces.msg import Duration, Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import AccelStamped, TransformStamped, Vector3Stamped
from nav_msgs.msg import Odometry
from std_msgs.msg import ColorRGBA, Header
from tf2_msgs.msg import TFMessage
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint
from visualization_msgs.msg import Marker, MarkerArray

from trust_av_common.lockstep import split_ns
from trust_av_common.topics import JOINT_NAME, NO_FRAME, ODOM_FRAME

__all__ = ['SerializedTemplate', 'TrajectoryBytes', 'VehicleMarkers', 'VehicleOdometry',
           'accel_command_bytes', 'diagnostic_values', 'diagnostics', 'header', 'message_class',
           'msg_ns', 'odometry', 'status_gap_m', 'time_msg', 'trajectory', 'trajectory_times',
           'trajectory_values', 'vector3_bytes', 'vehicle_markers']


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


class SerializedTemplate:
    """A message serialised once (CDR): :meth:`render` writes a stamp into every marked
    ``builtin_interfaces/Time`` and values into marked float64 fields of the bytes, so a
    message whose strings and sequences never change is published as bytes, without rclpy's
    field-by-field conversion of the Python message (a ``MarkerArray`` of six markers: about
    30 instead of 300 us per publish).

    The slots are found by serialising sentinel values and locating them; each must occur
    exactly once (a stamp sentinel exactly ``len(stamps)`` times).

    Args:
        msg: the message, complete except the marked stamps and fields.
        stamps: the ``Time`` objects inside ``msg`` that every render sets.
        fields: (object inside ``msg``, attribute name) of the float64 fields to set, in the
            order :meth:`render` takes their values (a ``float64[]`` field holds one value).

    Raises:
        ValueError: a sentinel was not found exactly as often as marked.
    """

    _SEC, _NANOSEC = 0x5EC0_5EC0, 0x3ADE_C0DE

    def __init__(self, msg: Any, stamps: Sequence[Time],
                 fields: Sequence[tuple[Any, str]] = ()) -> None:
        from rclpy.serialization import serialize_message

        for stamp in stamps:
            stamp.sec, stamp.nanosec = self._SEC, self._NANOSEC
        sentinels = [-1.2345678901234567e300 * (index + 1) for index in range(len(fields))]
        for (owner, name), value in zip(fields, sentinels, strict=True):
            is_array = not isinstance(getattr(owner, name), float)  # float64[] of one value
            setattr(owner, name, [value] if is_array else value)
        data = _exact(serialize_message(msg), type(msg))
        order = '<' if data[1] == 1 else '>'  # encapsulation: CDR little or big endian
        self._time = struct.Struct(order + 'iI')
        self._double = struct.Struct(order + 'd')
        self._stamp_at = _find(data, self._time.pack(self._SEC, self._NANOSEC), len(stamps))
        self._field_at = [_find(data, self._double.pack(value), 1)[0] for value in sentinels]
        self._data = bytearray(data)

    def render(self, ns: int, *values: float) -> bytes:
        """The message stamped ``ns`` (integer ns), with ``values`` in the marked fields."""
        sec, nanosec = split_ns(ns)
        for offset in self._stamp_at:
            self._time.pack_into(self._data, offset, sec, nanosec)
        for offset, value in zip(self._field_at, values, strict=True):
            self._double.pack_into(self._data, offset, value)
        return bytes(self._data)


def _exact(data: bytes, msg_type: Any) -> bytes:
    """``data`` cut to the message's CDR length. rmw_fastrtps' ``rmw_serialize`` (behind
    ``serialize_message``) returns its size *estimate* as the length: for a message with
    sequences the bytes end in a few unwritten ones, which a publisher would then send and a
    strict reader (rosbags: "CDR message size mismatch") refuses; a published Python
    message has its exact length. The exact length is the shortest prefix that deserialises:
    every field read, the last one up to its end."""
    from rclpy._rclpy_pybind11 import RMWError
    from rclpy.serialization import deserialize_message

    def reads(length: int) -> bool:
        try:
            deserialize_message(data[:length], msg_type)
        except RMWError:            # Fast CDR: not enough bytes for the next field
            return False
        return True

    if not reads(len(data)):
        raise ValueError(f'{msg_type.__name__}: the serialised bytes do not deserialise')
    length = len(data)
    while length > 4 and reads(length - 1):
        length -= 1
    return data[:length]


def _find(data: bytes, pattern: bytes, count: int) -> list[int]:
    offsets, at = [], data.find(pattern)
    while at >= 0:
        offsets.append(at)
        at = data.find(pattern, at + 1)
    if len(offsets) != count:
        raise ValueError(f'sentinel found {len(offsets)} times in the serialised message, '
                         f'expected {count}')
    return offsets


class VehicleOdometry:
    """One vehicle's odometry and its ``odom`` -> body transform (``tf``), serialised once.

    :meth:`update` gives both messages as bytes with the stamp, position and speed written
    in; the node publishes them as they are (:class:`SerializedTemplate`).

    Args:
        child_frame_id: the vehicle's body frame.
    """

    def __init__(self, child_frame_id: str) -> None:
        odom = odometry(0, 0.0, 0.0, child_frame_id)
        transform = TransformStamped(header=header(0, ODOM_FRAME),
                                     child_frame_id=child_frame_id)
        transform.transform.rotation.w = 1.0
        self._odometry = SerializedTemplate(
            odom, [odom.header.stamp],
            [(odom.pose.pose.position, 'x'), (odom.twist.twist.linear, 'x')])
        self._tf = SerializedTemplate(TFMessage(transforms=[transform]),
                                      [transform.header.stamp],
                                      [(transform.transform.translation, 'x')])

    def update(self, ns: int, position_m: float, speed_mps: float) -> tuple[bytes, bytes]:
        """Odometry and tf (serialised) stamped ``ns`` (integer ns), position (m along the
        road) and speed (m/s)."""
        return (self._odometry.render(ns, position_m, speed_mps),
                self._tf.render(ns, position_m))


MARKER_WIDTH_M = 1.8
MARKER_HEIGHT_M = 1.5
VEHICLE_LABELS = {'preceding_vehicle': 'preceding vehicle', 'ego': 'AV (ego)',
                  'human': 'human driver'}
_COLOURS = {'preceding_vehicle': (0.6, 0.6, 0.6), 'ego': (0.1, 0.5, 0.9),
            'human': (0.95, 0.55, 0.1)}


def vehicle_markers(vehicle_length_m: float) -> MarkerArray:
    """The three vehicles as markers: per vehicle a box (x from -length to 0 in its body
    frame: the frame origin is the front bumper) and a text label above it, each frame-locked
    in its vehicle's frame (a 3D view places them through ``tf``); stamps 0.

    Args:
        vehicle_length_m: box length, m.
    """
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
    return MarkerArray(markers=markers)


class VehicleMarkers:
    """:func:`vehicle_markers` serialised once; only the stamp changes from message to
    message (:meth:`update`).

    Args:
        vehicle_length_m: box length, m.
    """

    def __init__(self, vehicle_length_m: float) -> None:
        msg = vehicle_markers(vehicle_length_m)
        self._template = SerializedTemplate(msg, [marker.header.stamp for marker in msg.markers])

    def update(self, ns: int) -> bytes:
        """The array (serialised) stamped ``ns`` (integer ns)."""
        return self._template.render(ns)


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


class TrajectoryBytes:
    """Serialised :func:`trajectory` messages of one field and frame: one
    :class:`SerializedTemplate` per (number of points, step), made on first use, so a plan is
    published as bytes without building the message (they decode to exactly the message
    :func:`trajectory` builds; only CDR padding bytes may differ)."""

    def __init__(self, field: str, frame_id: str) -> None:
        if field not in ('accelerations', 'velocities'):
            raise ValueError(f'field must be accelerations or velocities, got {field!r}')
        self.field = field
        self.frame_id = frame_id
        self._templates: dict[tuple[int, float], SerializedTemplate] = {}

    def render(self, ns: int, dt_s: float, values: Sequence[float]) -> bytes:
        """The trajectory of ``values`` on the grid ``k * dt_s``, stamped ``ns``."""
        key = (len(values), dt_s)
        template = self._templates.get(key)
        if template is None:
            msg = trajectory(0, dt_s, frame_id=self.frame_id,
                             **{self.field: [0.0] * len(values)})
            template = SerializedTemplate(msg, [msg.header.stamp],
                                          [(point, self.field) for point in msg.points])
            self._templates[key] = template
        return template.render(ns, *values)


def accel_command_bytes(frame_id: str) -> SerializedTemplate:
    """``AccelStamped`` in ``frame_id``: ``render(ns, accel_x_mps2)``."""
    msg = AccelStamped(header=header(0, frame_id))
    return SerializedTemplate(msg, [msg.header.stamp], [(msg.accel.linear, 'x')])


def vector3_bytes(frame_id: str) -> SerializedTemplate:
    """``Vector3Stamped`` in ``frame_id``: ``render(ns, x, y, z)``."""
    msg = Vector3Stamped(header=header(0, frame_id))
    return SerializedTemplate(msg, [msg.header.stamp],
                              [(msg.vector, 'x'), (msg.vector, 'y'), (msg.vector, 'z')])


def trajectory_values(msg: JointTrajectory, field: str) -> list[float]:
    """The joint's ``accelerations`` or ``velocities`` over the points (the nodes check a
    message first: :func:`trust_av_common.envelope.trajectory_problem`).

    Raises:
        ValueError: a point without a value in ``field`` (one line naming it).
    """
    try:
        return [float(getattr(p, field)[0]) for p in msg.points]
    except IndexError:
        empty = next(k for k, p in enumerate(msg.points) if len(getattr(p, field)) == 0)
        raise ValueError(f'points[{empty}] has no {field}') from None


def trajectory_times(msg: JointTrajectory) -> list[float]:
    """The points' ``time_from_start``, s (a plan's own grid)."""
    return [p.time_from_start.sec + p.time_from_start.nanosec / 1e9 for p in msg.points]


HARDWARE_ID = 'none'
"""``DiagnosticStatus.hardware_id`` of every status here: no device (diagnostic_updater's
``none``; it warns about an empty one)."""


def diagnostics(ns: int, name: str, level_ok: bool, message: str,
                values: dict[str, str], error: bool = False) -> DiagnosticArray:
    """One DiagnosticStatus with key/values (floats as repr: exact round trip), level OK,
    WARN if not ``level_ok``, ERROR if ``error``; no frame (``frame_id`` empty: nothing
    spatial); ``hardware_id`` ``none``, diagnostic_updater's word for a status of no device."""
    level = (DiagnosticStatus.ERROR if error else DiagnosticStatus.OK if level_ok
             else DiagnosticStatus.WARN)
    status = DiagnosticStatus(level=level, name=name, message=message, hardware_id=HARDWARE_ID)
    status.values = [KeyValue(key=k, value=v) for k, v in values.items()]
    return DiagnosticArray(header=header(ns, NO_FRAME), status=[status])


def diagnostic_values(msg: DiagnosticArray) -> dict[str, str]:
    """Key/values of the first status."""
    return {kv.key: kv.value for kv in msg.status[0].values}


def status_gap_m(msg: DiagnosticArray) -> float | None:
    """The ``gap_m`` a step status (``ego/planner_status``, ``human/driver_status``) carries,
    or None when it carries none (a follower that reports no gap)."""
    gap = diagnostic_values(msg).get('gap_m') if msg.status else None
    return None if gap is None else float(gap)
