"""trust_av_common.ros.raw_inputs reads what rclpy's own deserialisation reads.

The oracle is rclpy (rosidl's typesupport): random messages serialised by
``rclpy.serialization.serialize_message`` read to the same field values, bit for bit,
through the raw readers; big-endian CDR (another vendor's byte order) is built by hand;
broken bytes are one error naming the type; encodings other than plain CDR go to rclpy.
"""

from __future__ import annotations

import random
import struct
from typing import Any

import pytest
from builtin_interfaces.msg import Duration
from geometry_msgs.msg import Vector3Stamped
from nav_msgs.msg import Odometry
from rclpy.serialization import serialize_message
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from trust_av_common.ros.raw_inputs import READERS, subscribe, type_name


def _text(rng: random.Random) -> str:
    return ''.join(rng.choice('abc_/xyzé0') for _ in range(rng.randrange(0, 12)))


def _header(msg: Any, rng: random.Random) -> None:
    msg.header.stamp.sec = rng.randrange(-2**31, 2**31)
    msg.header.stamp.nanosec = rng.randrange(0, 10**9)
    msg.header.frame_id = _text(rng)


def _f(rng: random.Random) -> float:
    return rng.choice([0.0, -0.0, 1e308, -5e-324, rng.uniform(-1e6, 1e6)])


def random_odometry(rng: random.Random) -> Odometry:
    msg = Odometry()
    _header(msg, rng)
    msg.child_frame_id = _text(rng)
    p = msg.pose.pose
    p.position.x, p.position.y, p.position.z = _f(rng), _f(rng), _f(rng)
    p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w = (
        _f(rng), _f(rng), _f(rng), _f(rng))
    msg.pose.covariance = [_f(rng) for _ in range(36)]
    t = msg.twist.twist
    t.linear.x, t.linear.y, t.linear.z = _f(rng), _f(rng), _f(rng)
    t.angular.x, t.angular.y, t.angular.z = _f(rng), _f(rng), _f(rng)
    msg.twist.covariance = [_f(rng) for _ in range(36)]
    return msg


def random_trajectory(rng: random.Random) -> JointTrajectory:
    msg = JointTrajectory()
    _header(msg, rng)
    msg.joint_names = [_text(rng) for _ in range(rng.randrange(0, 3))]
    for _ in range(rng.randrange(0, 12)):
        point = JointTrajectoryPoint()
        point.positions, point.velocities, point.accelerations, point.effort = (
            [_f(rng) for _ in range(rng.randrange(0, 3))] for _ in range(4))
        point.time_from_start = Duration(sec=rng.randrange(-2**31, 2**31),
                                         nanosec=rng.randrange(0, 10**9))
        msg.points.append(point)
    return msg


def random_vector3(rng: random.Random) -> Vector3Stamped:
    msg = Vector3Stamped()
    _header(msg, rng)
    msg.vector.x, msg.vector.y, msg.vector.z = _f(rng), _f(rng), _f(rng)
    return msg


def random_accel(rng: random.Random) -> Any:
    from geometry_msgs.msg import AccelStamped
    msg = AccelStamped()
    _header(msg, rng)
    a = msg.accel
    a.linear.x, a.linear.y, a.linear.z = _f(rng), _f(rng), _f(rng)
    a.angular.x, a.angular.y, a.angular.z = _f(rng), _f(rng), _f(rng)
    return msg


FIELDS = {
    'geometry_msgs/msg/AccelStamped': (random_accel, [
        'header.stamp.sec', 'header.stamp.nanosec', 'header.frame_id', 'accel.linear.x',
        'accel.linear.y', 'accel.linear.z', 'accel.angular.x', 'accel.angular.y',
        'accel.angular.z']),
    'nav_msgs/msg/Odometry': (random_odometry, [
        'header.stamp.sec', 'header.stamp.nanosec', 'header.frame_id', 'child_frame_id',
        'pose.pose.position.x', 'pose.pose.position.y', 'pose.pose.position.z',
        'pose.pose.orientation.x', 'pose.pose.orientation.y', 'pose.pose.orientation.z',
        'pose.pose.orientation.w', 'twist.twist.linear.x', 'twist.twist.linear.y',
        'twist.twist.linear.z', 'twist.twist.angular.x', 'twist.twist.angular.y',
        'twist.twist.angular.z']),
    'trajectory_msgs/msg/JointTrajectory': (random_trajectory, [
        'header.stamp.sec', 'header.stamp.nanosec', 'header.frame_id']),
    'geometry_msgs/msg/Vector3Stamped': (random_vector3, [
        'header.stamp.sec', 'header.stamp.nanosec', 'header.frame_id', 'vector.x',
        'vector.y', 'vector.z']),
}


def field(msg: Any, path: str) -> Any:
    for name in path.split('.'):
        msg = getattr(msg, name)
    return msg


def same(a: Any, b: Any) -> bool:
    """Equal, floats bit for bit (-0.0 is not 0.0)."""
    if isinstance(b, float):
        return struct.pack('<d', a) == struct.pack('<d', b)
    return bool(a == b)


@pytest.mark.parametrize('name', sorted(FIELDS))
def test_random_messages_read_as_rclpy_reads_them(name: str) -> None:
    make, paths = FIELDS[name]
    rng = random.Random(7)
    for _ in range(300):
        msg = make(rng)
        assert type_name(type(msg)) == name
        read = READERS[name](serialize_message(msg))
        for path in paths:
            assert same(field(read, path), field(msg, path)), path
        if name == 'trajectory_msgs/msg/JointTrajectory':
            assert read.joint_names == list(msg.joint_names)
            assert len(read.points) == len(msg.points)
            for r, m in zip(read.points, msg.points, strict=True):
                for seq in ('positions', 'velocities', 'accelerations', 'effort'):
                    assert len(getattr(r, seq)) == len(getattr(m, seq))
                    assert all(same(x, y) for x, y in zip(getattr(r, seq), getattr(m, seq),
                                                          strict=True))
                assert (r.time_from_start.sec, r.time_from_start.nanosec) == (
                    m.time_from_start.sec, m.time_from_start.nanosec)


def test_big_endian_cdr_reads_the_same() -> None:
    """CDR_BE (encapsulation 00 00), as a big-endian writer sends it: stamp, 'map\\0'
    (aligned: 4 + 4 + 4 + 4 bytes), then the vector from an 8-aligned offset."""
    data = (b'\x00\x00\x00\x00' + struct.pack('>iI', -3, 7) + struct.pack('>I', 4) + b'map\x00'
            + struct.pack('>ddd', 1.5, -2.25, 1e-300))
    read = READERS['geometry_msgs/msg/Vector3Stamped'](data)
    assert (read.header.stamp.sec, read.header.stamp.nanosec, read.header.frame_id) == (
        -3, 7, 'map')
    assert (read.vector.x, read.vector.y, read.vector.z) == (1.5, -2.25, 1e-300)


class FakeNode:
    """What subscribe() asks of a node: create_subscription and a logger (no rclpy context
    needed)."""

    def __init__(self) -> None:
        self.calls: list[tuple[Any, ...]] = []
        self.warnings: list[str] = []

    def create_subscription(self, cls: Any, topic: str, callback: Any, qos: Any,
                            **options: Any) -> str:
        self.calls.append((cls, topic, callback, qos, options))
        return 'subscription'

    def get_logger(self) -> Any:
        node = self

        class Logger:
            def warning(self, text: str, **_: Any) -> None:
                node.warnings.append(text)
        return Logger()


def test_subscribe_takes_bytes_and_drops_a_broken_message() -> None:
    """A broken message is dropped (never raised into the executor), counted in the node's
    ``dropped`` and logged naming the type and the topic; the next good one is read."""
    node = FakeNode()
    got: list[Any] = []
    subscribe(node, Odometry, 'ego/odom', got.append, 10)  # type: ignore[arg-type]
    cls, topic, on_bytes, qos, options = node.calls[0]
    events = options.pop('event_callbacks')   # publishers of another type are named
    assert (cls, topic, qos, options) == (Odometry, 'ego/odom', 10, {'raw': True})
    assert events.incompatible_type is not None
    msg = random_odometry(random.Random(1))
    data = serialize_message(msg)
    on_bytes(data)
    assert got[0].twist.twist.linear.x == msg.twist.twist.linear.x
    for broken in (data[:40], data[:3], data[:-1]):
        on_bytes(broken)
    assert len(got) == 1 and node.dropped == 3  # type: ignore[attr-defined]
    assert all('nav_msgs/msg/Odometry on ego/odom: ' in w for w in node.warnings)
    on_bytes(data)
    assert len(got) == 2
    # Not plain CDR (an XCDR2 encapsulation id): not read here but by rclpy, by its rules
    # (the payload is XCDR1, so its values are not the message's; the type says who read it).
    on_bytes(b'\x00\x07' + data[2:])
    assert isinstance(got[-1], Odometry)


def test_without_readers_rclpy_decodes() -> None:
    """``readers=False`` (the vehicle path) and types without a reader: taken as bytes and
    decoded by rclpy's ``deserialize_message`` into the rclpy message."""
    from diagnostic_msgs.msg import DiagnosticArray
    for cls, msg in ((Odometry, random_odometry(random.Random(2))),
                     (DiagnosticArray, DiagnosticArray())):
        node, got = FakeNode(), []
        subscribe(node, cls, 'topic', got.append, 10, readers=False)  # type: ignore[arg-type]
        assert sorted(node.calls[0][4]) == ['event_callbacks', 'raw'] and node.calls[0][4]['raw']
        node.calls[0][2](serialize_message(msg))
        assert got == [msg] and isinstance(got[0], cls)


INPUT_TYPES = ('nav_msgs/msg/Odometry', 'trajectory_msgs/msg/JointTrajectory',
               'geometry_msgs/msg/Vector3Stamped', 'geometry_msgs/msg/AccelStamped')
"""Every type a node of the graph subscribes through subscribe() (planner, monitor, ego
plant, driver, traffic): each input of each node is one of these."""


@pytest.mark.parametrize('readers', [True, False], ids=['raw_readers', 'rclpy'])
@pytest.mark.parametrize('name', INPUT_TYPES)
def test_fuzz_malformed_bytes_are_dropped_counted_and_reported(name: str,
                                                               readers: bool) -> None:
    """Random bytes, truncations and corruptions of a valid message, on every input type,
    through both decoders: each either decodes (then the callback gets it) or is dropped and
    counted with a warning; nothing raises. Seeded (the same bytes every run)."""
    from trust_av_common.ros.messages import message_class
    cls = message_class(name)
    rng = random.Random(name)
    valid = serialize_message(FIELDS[name][0](rng))
    node, got = FakeNode(), []
    subscribe(node, cls, 'input', got.append, 10, readers=readers)  # type: ignore[arg-type]
    on_bytes = node.calls[0][2]
    sent = 0
    for k in range(600):
        kind = k % 4
        if kind == 0:
            data = bytes(rng.randrange(256) for _ in range(rng.randrange(0, 300)))
        elif kind == 1:
            data = valid[:rng.randrange(len(valid))]
        elif kind == 2:
            flipped = bytearray(valid)
            for _ in range(rng.randrange(1, 6)):
                flipped[rng.randrange(len(flipped))] = rng.randrange(256)
            data = bytes(flipped)
        else:   # a plain CDR header, then noise
            data = b'\x00\x01\x00\x00' + bytes(rng.randrange(256)
                                               for _ in range(rng.randrange(0, 300)))
        on_bytes(data)
        sent += 1
    dropped = getattr(node, 'dropped', 0)
    assert len(got) + dropped == sent
    assert dropped >= 150 and len(node.warnings) == dropped   # every truncation at least
    assert all(w.startswith('dropped a malformed message') and f'{name} on input: ' in w
               for w in node.warnings)
    on_bytes(valid)
    assert len(got) + dropped == sent + 1


class _CdrWriter:
    """Little-endian plain CDR written by hand, each string either as rclpy writes it
    (length with the NUL) or with length 0 and no bytes (as other CDR writers may send
    ''), so the readers meet bytes rclpy's serialiser never produces."""

    def __init__(self, rng: random.Random) -> None:
        self.rng = rng
        self.data = bytearray(b'\x00\x01\x00\x00')

    def _align(self, size: int) -> None:
        self.data += b'\x00' * (-(len(self.data) - 4) % size)

    def put(self, code: str, *values: Any) -> None:
        size = struct.calcsize(code)
        self._align(size)
        self.data += struct.pack(f'<{len(values)}{code}', *values)

    def string(self, text: str) -> None:
        raw = text.encode()
        if not raw and self.rng.random() < 0.5:
            self.put('I', 0)
            return
        self.put('I', len(raw) + 1)
        self.data += raw + b'\x00'

    def header(self, msg: Any) -> None:
        self.put('i', msg.header.stamp.sec)
        self.put('I', msg.header.stamp.nanosec)
        self.string(msg.header.frame_id)


def _hand_serialised(name: str, msg: Any, rng: random.Random) -> bytes:
    out = _CdrWriter(rng)
    out.header(msg)
    if name == 'nav_msgs/msg/Odometry':
        out.string(msg.child_frame_id)
        p = msg.pose.pose
        out.put('d', p.position.x, p.position.y, p.position.z, p.orientation.x,
                p.orientation.y, p.orientation.z, p.orientation.w)
        out.put('d', *msg.pose.covariance)
        t = msg.twist.twist
        out.put('d', t.linear.x, t.linear.y, t.linear.z, t.angular.x, t.angular.y,
                t.angular.z)
        out.put('d', *msg.twist.covariance)
    elif name == 'trajectory_msgs/msg/JointTrajectory':
        out.put('I', len(msg.joint_names))
        for joint in msg.joint_names:
            out.string(joint)
        out.put('I', len(msg.points))
        for point in msg.points:
            for values in (point.positions, point.velocities, point.accelerations,
                           point.effort):
                out.put('I', len(values))
                if len(values):
                    out.put('d', *values)
            out.put('i', point.time_from_start.sec)
            out.put('I', point.time_from_start.nanosec)
    elif name == 'geometry_msgs/msg/Vector3Stamped':
        out.put('d', msg.vector.x, msg.vector.y, msg.vector.z)
    else:
        a = msg.accel
        out.put('d', a.linear.x, a.linear.y, a.linear.z, a.angular.x, a.angular.y,
                a.angular.z)
    return bytes(out.data)


@pytest.mark.parametrize('name', sorted(FIELDS))
def test_zero_length_strings_and_empty_sequences_read_as_rclpy_reads_them(name: str) -> None:
    """Fuzzed against rclpy's deserialize_message: strings of length 0 (no NUL), empty
    strings, empty joint-name and point sequences, empty value sequences -- every field
    the reader returns equals rclpy's."""
    from rclpy.serialization import deserialize_message

    from trust_av_common.ros.messages import message_class

    make, paths = FIELDS[name]
    rng = random.Random(7)
    zero_length_seen = 0
    for _ in range(300):
        msg = make(rng)
        if rng.random() < 0.6:
            msg.header.frame_id = ''
        if name == 'nav_msgs/msg/Odometry' and rng.random() < 0.6:
            msg.child_frame_id = ''
        if name == 'trajectory_msgs/msg/JointTrajectory':
            msg.joint_names = [rng.choice(['', 'j']) for _ in range(rng.randrange(0, 3))]
        data = _hand_serialised(name, msg, rng)
        zero_length_seen += b'\x00\x00\x00\x00' in data[12:16]
        theirs = deserialize_message(data, message_class(name))
        mine = READERS[name](data)
        for path in paths:
            assert same(field(mine, path), field(theirs, path)), (path, data.hex())
        if name == 'trajectory_msgs/msg/JointTrajectory':
            assert mine.joint_names == list(theirs.joint_names)
            assert len(mine.points) == len(theirs.points)
            for a, b in zip(mine.points, theirs.points, strict=True):
                for part in ('positions', 'velocities', 'accelerations', 'effort'):
                    assert list(getattr(a, part)) == list(getattr(b, part))
                assert (a.time_from_start.sec, a.time_from_start.nanosec) == (
                    b.time_from_start.sec, b.time_from_start.nanosec)
    assert zero_length_seen > 50   # the case this test is for did occur
