"""Inputs taken as serialised bytes and read without building rclpy message objects.

rclpy turns every message it takes into nested Python objects: an ``Odometry`` is 14 of
them (54 us here), a ten-point ``JointTrajectory`` 33 (92 us), while a node reads a stamp
and one or two numbers. For the types the graph's nodes take on every step, a subscription
made with :func:`subscribe` takes the bytes (``raw=True``) and :data:`READERS` reads them
into light objects with the same attribute paths as the message (``msg.header.stamp.sec``,
``msg.pose.pose.position.x``, ``msg.points[k].accelerations``), so node code is unchanged.
Other types, and every input of a wall-mode (vehicle) node, are decoded by rclpy's own
``deserialize_message`` (:func:`subscribe`); a message that does not decode either way is
dropped, counted and logged, never raised into the executor.

The bytes are CDR as ROS 2 serialises them (rmw_fastrtps: XCDR1 with a 4-byte
encapsulation header, little- or big-endian by its second byte; primitives aligned to their
size from the end of that header; a string is a uint32 length including the NUL, then the
bytes -- or a length of 0 and no bytes, which rclpy reads as ''; a sequence a uint32
count, then the elements, none for a count of 0; fixed arrays have no count). Every
field of these types is read (covariances are skipped by their fixed size), so a message
from any publisher -- the graph's own serialised templates, another DDS vendor, a real
vehicle -- reads to the same values as rclpy's own deserialisation (tests/graph/test_raw_inputs.py
compares both on random messages, and reads a hand-built big-endian one). Bytes in another
encoding (XCDR2, parameter lists) are left to rclpy; a truncated or malformed message
raises :class:`RawInputError` in a reader, and :func:`subscribe` drops it.
"""

from __future__ import annotations

import os
import struct
from collections.abc import Callable
from typing import Any

from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.node import Node
from rclpy.qos import QoSProfile
from rclpy.serialization import deserialize_message

from trust_av_common.errors import TrustAvError

__all__ = ['INPUTS_ENV', 'READERS', 'check_input_types', 'subscribe', 'type_name',
           'wrong_type_publishers']

INPUTS_ENV = 'TRUST_AV_INPUTS'
"""Set to ``rclpy`` to take every input as an rclpy message instead (how
``benchmarks/bench_graph.py --rclpy-inputs`` measures what the readers save)."""
ENCAPSULATION_BYTES = 4
BYTE_ORDER = {b'\x00\x01': '<', b'\x00\x00': '>'}
"""Encapsulation kind (plain CDR: CDR_LE, CDR_BE) -> struct byte order. Other kinds
(XCDR2, parameter lists) are left to rclpy's deserialisation."""


class RawInputError(TrustAvError):
    """A message's bytes are not a valid serialisation of its type."""


class OtherEncodingError(Exception):
    """Not plain CDR: read with rclpy instead."""


class _Fields:
    """A message, or a part of one, read from bytes: its fields as attributes."""

    def __init__(self, **fields: Any) -> None:
        self.__dict__.update(fields)

    def __repr__(self) -> str:
        return f'{type(self).__name__}({self.__dict__})'


class Time:
    """``builtin_interfaces`` Time or Duration read from bytes."""

    __slots__ = ('nanosec', 'sec')

    def __init__(self, sec: int, nanosec: int) -> None:
        self.sec = sec
        self.nanosec = nanosec


class Header:
    """``std_msgs/msg/Header`` read from bytes."""

    __slots__ = ('frame_id', 'stamp')

    def __init__(self, stamp: Time, frame_id: str) -> None:
        self.stamp = stamp
        self.frame_id = frame_id


class _Cursor:
    """Reads CDR primitives from ``data`` in its byte order, aligned from the payload."""

    __slots__ = ('at', 'data', 'order')

    def __init__(self, data: bytes) -> None:
        if len(data) < ENCAPSULATION_BYTES:
            raise RawInputError('shorter than its encapsulation header')
        order = BYTE_ORDER.get(bytes(data[:2]))
        if order is None:
            raise OtherEncodingError(bytes(data[:2]).hex())
        self.data = data
        self.order = order
        self.at = ENCAPSULATION_BYTES

    def _align(self, size: int) -> None:
        self.at += -(self.at - ENCAPSULATION_BYTES) % size

    def unpack(self, code: str, size: int, count: int = 1) -> tuple[Any, ...]:
        self._align(size)
        end = self.at + size * count
        if end > len(self.data):
            raise RawInputError(f'ends at byte {len(self.data)}, needs {end}')
        values = struct.unpack_from(f'{self.order}{count}{code}', self.data, self.at)
        self.at = end
        return values

    def uint32(self) -> int:
        value: int = self.unpack('I', 4)[0]
        return value

    def skip_doubles(self, count: int) -> None:
        self._align(8)
        self.at += 8 * count
        if self.at > len(self.data):
            raise RawInputError(f'ends at byte {len(self.data)}, needs {self.at}')

    def string(self) -> str:
        """A CDR string: a uint32 length counting the NUL, then the bytes. A length of 0
        (no bytes at all, as some CDR writers send an empty string) reads as '' as in
        rclpy's deserialisation (Fast CDR ``deserialize(std::string&)``)."""
        length = self.uint32()
        if length == 0:
            return ''
        end = self.at + length
        if end > len(self.data) or self.data[end - 1] != 0:
            raise RawInputError(f'bad string of length {length} at byte {self.at}')
        text = bytes(self.data[self.at:end - 1]).decode('utf-8')
        self.at = end
        return text

    def header(self) -> Header:
        sec = self.unpack('i', 4)[0]
        nanosec = self.uint32()
        return Header(Time(sec, nanosec), self.string())

    def vector3(self) -> _Fields:
        x, y, z = self.unpack('d', 8, 3)
        return _Fields(x=x, y=y, z=z)


def read_odometry(data: bytes) -> _Fields:
    """``nav_msgs/msg/Odometry``: header, child_frame_id, pose (position, orientation),
    twist (linear, angular); the covariances are skipped."""
    cur = _Cursor(data)
    header = cur.header()
    child = cur.string()
    px, py, pz, qx, qy, qz, qw = cur.unpack('d', 8, 7)
    cur.skip_doubles(36)
    linear, angular = cur.vector3(), cur.vector3()
    cur.skip_doubles(36)
    return _Fields(header=header, child_frame_id=child,
                   pose=_Fields(pose=_Fields(position=_Fields(x=px, y=py, z=pz),
                                             orientation=_Fields(x=qx, y=qy, z=qz, w=qw))),
                   twist=_Fields(twist=_Fields(linear=linear, angular=angular)))


class _Point:
    """One ``JointTrajectoryPoint`` read from bytes."""

    __slots__ = ('accelerations', 'effort', 'positions', 'time_from_start', 'velocities')

    def __init__(self, positions: list[float], velocities: list[float],
                 accelerations: list[float], effort: list[float], time_from_start: Time
                 ) -> None:
        self.positions = positions
        self.velocities = velocities
        self.accelerations = accelerations
        self.effort = effort
        self.time_from_start = time_from_start


def read_joint_trajectory(data: bytes) -> _Fields:
    """``trajectory_msgs/msg/JointTrajectory``: header, joint names, every point's
    positions, velocities, accelerations, effort and time_from_start (a plan is read on
    every step by three nodes: the loop over points is written out)."""
    cur = _Cursor(data)
    header = cur.header()
    names = [cur.string() for _ in range(cur.uint32())]
    count = cur.uint32()
    order, at, size = cur.order, cur.at, len(data)
    uint32, duration = struct.Struct(order + 'I').unpack_from, struct.Struct(order + 'iI')
    points = []
    for _ in range(count):
        seqs = []
        for _ in range(4):
            at += -(at - ENCAPSULATION_BYTES) % 4
            n = uint32(data, at)[0]
            at += 4
            if n:
                at += -(at - ENCAPSULATION_BYTES) % 8
                if at + 8 * n > size:
                    raise RawInputError(f'ends at byte {size}, needs {at + 8 * n}')
                seqs.append(list(struct.unpack_from(f'{order}{n}d', data, at)))
                at += 8 * n
            else:
                seqs.append([])
        at += -(at - ENCAPSULATION_BYTES) % 4
        sec, nanosec = duration.unpack_from(data, at)
        at += 8
        points.append(_Point(seqs[0], seqs[1], seqs[2], seqs[3], Time(sec, nanosec)))
    return _Fields(header=header, joint_names=names, points=points)


def read_vector3_stamped(data: bytes) -> _Fields:
    """``geometry_msgs/msg/Vector3Stamped``: header, vector."""
    cur = _Cursor(data)
    return _Fields(header=cur.header(), vector=cur.vector3())


def read_accel_stamped(data: bytes) -> _Fields:
    """``geometry_msgs/msg/AccelStamped``: header, accel (linear, angular)."""
    cur = _Cursor(data)
    header = cur.header()
    return _Fields(header=header, accel=_Fields(linear=cur.vector3(), angular=cur.vector3()))


READERS: dict[str, Callable[[bytes], _Fields]] = {
    'nav_msgs/msg/Odometry': read_odometry,
    'trajectory_msgs/msg/JointTrajectory': read_joint_trajectory,
    'geometry_msgs/msg/Vector3Stamped': read_vector3_stamped,
    'geometry_msgs/msg/AccelStamped': read_accel_stamped,
}
"""Message type name -> reader of its bytes."""


def type_name(msg_class: Any) -> str:
    """``pkg/msg/Name`` of an rclpy message class."""
    module = msg_class.__module__.split('.')[0]
    return f'{module}/msg/{msg_class.__name__}'


DECODE_ERRORS = (RawInputError, struct.error, UnicodeDecodeError, RuntimeError, ValueError,
                 TypeError, OverflowError, MemoryError)
"""What a message's decoding raises for bytes that are not a serialisation of its type: the
readers' own errors, and rclpy's ``deserialize_message``: ``RMWError`` (a ``RuntimeError``),
"failed to deserialize ROS message: Fast CDR exception ..." from ``rmw_deserialize``, seen for
every kind of bytes tests/graph/test_raw_inputs.py's fuzz test sends; the others for the
conversions of decoded fields to Python."""


def subscribe(node: Node, msg_class: Any, topic: str, callback: Callable[[Any], None],
              qos: QoSProfile | int, *, readers: bool = True, **options: Any) -> Any:
    """``node.create_subscription`` taking the bytes, decoded before ``callback`` sees them:
    with :data:`READERS` when ``readers`` is true and the type has one (the callback gets
    the light object; bytes in another encoding than plain CDR go to rclpy), else with
    rclpy's own ``deserialize_message`` (the callback gets the rclpy message: what the
    vehicle path uses, ``readers=False``). ``options`` go to ``create_subscription`` (e.g.
    event callbacks).

    A publisher of another type on the topic never matches (DDS matches endpoints by topic
    and type name), so none of its messages arrives to be dropped: :func:`check_input_types`
    names it (rclpy's incompatible-type event, ``SubscriptionEventCallbacks(incompatible_type
    =...)``, where the rmw raises it, and the graph).

    A message that does not decode (:data:`DECODE_ERRORS`) is dropped, counted in the node's
    ``dropped`` attribute (reported on ``/diagnostics``) and logged as a warning naming the
    type, the topic and the error (at most one line a second); it never reaches
    ``callback`` and never raises into the executor. An exception of ``callback`` itself is
    not caught here.
    """
    name = type_name(msg_class)
    reader = READERS.get(name) if readers and os.environ.get(INPUTS_ENV) != 'rclpy' else None

    def on_bytes(data: bytes) -> None:
        try:
            if reader is None:
                msg = deserialize_message(data, msg_class)
            else:
                try:
                    msg = reader(data)
                except OtherEncodingError:
                    msg = deserialize_message(data, msg_class)
        except DECODE_ERRORS as err:
            dropped(node, f'{name} on {topic}: {type(err).__name__}: {err}')
            return
        callback(msg)

    events = options.pop('event_callbacks', None) or SubscriptionEventCallbacks()
    if events.incompatible_type is None:
        events.incompatible_type = lambda _info: _incompatible_type(node)
    subscription = node.create_subscription(msg_class, topic, on_bytes, qos, raw=True,
                                            event_callbacks=events, **options)
    node.__dict__.setdefault('typed_inputs', []).append((subscription, name))
    return subscription


def wrong_type_publishers(node: Node, topic: str, name: str) -> str:
    """The publishers on ``topic`` (resolved) whose type is not ``name``, from the graph:
    ``std_msgs/msg/String (/talker)``, several joined by ``, ``; '' when there is none."""
    found = sorted({f'{info.topic_type} ({info.node_namespace.rstrip("/")}/{info.node_name})'
                    for info in node.get_publishers_info_by_topic(topic)
                    if info.topic_type != name})
    return ', '.join(found)


def check_input_types(node: Node) -> bool:
    """Name the publishers of another type on the inputs :func:`subscribe` made: one error
    line when they appear or change, one line when they are gone; kept in the node's
    ``wrong_types`` (topic -> :func:`wrong_type_publishers`) for ``/diagnostics``.

    Called by the incompatible-type event, and by a managed node's ``/diagnostics`` report
    (once a second, ``ManagedNode.diagnose``): rmw_fastrtps_cpp 8.4.3 with Fast DDS 2.14
    (the Jazzy wheels) does not raise that event (its ``on_inconsistent_topic`` never
    comes), so the graph is what finds them here.

    Returns:
        Whether ``wrong_types`` changed (``/diagnostics`` is then due at once).
    """
    known: dict[str, str] = node.__dict__.setdefault('wrong_types', {})
    changed = False
    for subscription, name in node.__dict__.get('typed_inputs', []):
        topic = subscription.topic_name
        wrong = wrong_type_publishers(node, topic, name)
        if wrong == known.get(topic, ''):
            continue
        changed = True
        if wrong:
            known[topic] = wrong
            node.get_logger().error(f'input {topic} takes {name}; not connected (another '
                                    f'type): {wrong}')
        else:
            del known[topic]
            node.get_logger().info(f'input {topic}: no publisher of another type any more')
    return changed


def _incompatible_type(node: Node) -> None:
    """The incompatible-type event: :func:`check_input_types`, ``/diagnostics`` at once."""
    diagnostics = getattr(node, 'diagnostics', None)
    if check_input_types(node) and diagnostics is not None:
        diagnostics.changed()


def dropped(node: Node, what: str) -> None:
    """Count and log one dropped malformed message (``node.dropped``, made 0 if absent)."""
    node.dropped = getattr(node, 'dropped', 0) + 1  # type: ignore[attr-defined]
    node.get_logger().warning(f'dropped a malformed message ({node.dropped} so far): '  # type: ignore[attr-defined]
                              f'{what}', throttle_duration_sec=1.0)
