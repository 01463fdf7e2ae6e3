"""Speed traces to and from rosbag2 bags (MCAP or sqlite3), read and written with rosbags.

Reading: the preceding vehicle's speed comes from one topic of a recorded bag, as
``nav_msgs/msg/Odometry`` (``twist.twist.linear.x``) or ``geometry_msgs/msg/TwistStamped``
(``twist.linear.x``), timed by the message header stamps (which may start at 0, as in a
simulation on sim time); only a topic whose header stamps are all zero is timed by the
recording's log times. The samples go through the same validation and resampling as a CSV
trace (:func:`preceding_traffic.traces.read_samples` rules), so irregular sampling and
short holes are interpolated and a hole longer than ``max_sample_gap_s`` is rejected with
its time. The preview is the recorded future.

Writing: :func:`write_trace_bag` turns a ``time_s,speed_mps`` trace into a rosbag2 MCAP bag
of Odometry messages (position integrated from speed, header stamps at the recorded times,
holes kept as they are).

This module is I/O, not a model: it imports rosbags (pure Python), never rclpy.
"""

from __future__ import annotations

import os
import shutil
import struct
import tempfile
from collections.abc import Iterator
from pathlib import Path

import numpy as np
from rosbags.highlevel import AnyReader, AnyReaderError
from rosbags.rosbag2 import ReaderError, StoragePlugin, Writer, WriterError
from rosbags.typesys import Stores, get_typestore

from preceding_traffic.traces import (
    SpeedTrace,
    TraceConfig,
    TraceError,
    check_accelerations,
    check_sample,
    resample,
)
from trust_av_common.input_files import not_regular

__all__ = ['ODOMETRY', 'TWIST_STAMPED', 'TYPESTORE', 'BagError', 'load_bag_trace',
           'odometry_messages', 'read_bag_samples', 'write_trace_bag']

ODOMETRY = 'nav_msgs/msg/Odometry'
TWIST_STAMPED = 'geometry_msgs/msg/TwistStamped'
SPEED_TYPES = (ODOMETRY, TWIST_STAMPED)
"""Message types a speed can be read from."""

TYPESTORE = get_typestore(Stores.ROS2_JAZZY)

DAMAGED = (ReaderError, UnicodeDecodeError, struct.error, KeyError, IndexError, OverflowError,
           ValueError, OSError, MemoryError)
"""What rosbags' readers raise on a damaged file (a corrupt chunk index, record length,
string or schema encoding) besides their own errors: read as "cannot read the bag". A damaged
record length can make them ask for GiBs (``MemoryError``) before any byte is read."""


class BagError(TraceError):
    """A bag is unusable as a speed source; the message names the bag and the problem."""


def _speed(msg: object, msgtype: str) -> float:
    if msgtype == ODOMETRY:
        return float(msg.twist.twist.linear.x)  # type: ignore[attr-defined]
    return float(msg.twist.linear.x)  # type: ignore[attr-defined]


def _stamp_ns(msg: object) -> int:
    stamp = msg.header.stamp  # type: ignore[attr-defined]
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def read_bag_samples(path: Path, topic: str, msgtype: str,
                     config: TraceConfig) -> tuple[np.ndarray, np.ndarray]:
    """Raw ``(time_s, speed_mps)`` samples of one topic of a rosbag2 bag, validated.

    Args:
        path: bag directory (with ``metadata.yaml``) or a single ``.mcap``/``.db3`` file.
        topic: topic holding the preceding vehicle's state.
        msgtype: expected message type, one of :data:`SPEED_TYPES`.
        config: validation settings (``max_sample_gap_s``).

    Raises:
        BagError: unreadable or truncated bag, unsupported storage, missing topic, wrong
            message type, no messages, or samples that fail the trace rules.
    """
    if msgtype not in SPEED_TYPES:
        raise BagError(f'{path}: cannot read a speed from {msgtype}; use one of '
                       f'{", ".join(SPEED_TYPES)}')
    if not path.exists():
        raise BagError(f'{path}: no such bag')
    try:
        inputs = sorted(p for p in path.iterdir() if p.suffix in ('.mcap', '.db3', '.yaml')) \
            if path.is_dir() else [path]
    except OSError as err:
        raise BagError(f'{path}: cannot read the bag ({err.strerror})') from err
    for item in inputs:                  # checked before opening: a FIFO blocks the open
        kind = not_regular(item)
        if kind is not None:
            raise BagError(f'{item}: not a regular file ({kind}; expected a rosbag2 bag)')
    times: list[float] = []
    speeds: list[float] = []
    try:
        with AnyReader([path], default_typestore=TYPESTORE) as reader:
            connections = [c for c in reader.connections if c.topic == topic]
            if not connections:
                available = ', '.join(sorted({f'{c.topic} ({c.msgtype})'
                                              for c in reader.connections})) or 'none'
                raise BagError(f'{path}: no topic {topic}; the bag has: {available}')
            wrong = [c.msgtype for c in connections if c.msgtype != msgtype]
            if wrong:
                raise BagError(f'{path}: topic {topic} has type {wrong[0]}, expected {msgtype}')
            _check_definition(path, topic, msgtype, reader.typestore)
            stamps: list[int] = []
            log_times: list[int] = []
            for connection, log_time, raw in reader.messages(connections=connections):
                msg = reader.deserialize(raw, connection.msgtype)
                stamps.append(_stamp_ns(msg))
                log_times.append(log_time)
                speeds.append(_speed(msg, connection.msgtype))
    except BagError:
        raise
    except (AnyReaderError, WriterError) as err:
        raise BagError(f'{path}: cannot read bag ({err})') from err
    except DAMAGED as err:
        raise BagError(f'{path}: cannot read bag (damaged: {type(err).__name__}: '
                       f'{str(err)[:200]})') from err
    if not speeds:
        raise BagError(f'{path}: topic {topic} has no messages')
    # Header stamps are the time base when the messages carry them (a simulation's stamps
    # start at 0); only a topic whose stamps are all zero is timed by its log times.
    times = [ns * 1e-9 for ns in (stamps if any(stamps) else log_times)]
    return _validated(path, topic, times, speeds, config)


def _check_definition(path: Path, topic: str, msgtype: str, bag_types: object) -> None:
    """The bag's definition of ``msgtype`` (its schema) must be ROS 2 Jazzy's: another
    tool's message under the same name has other fields, and reading a speed from it
    would be a guess."""
    ours = TYPESTORE.generate_msgdef(msgtype)[1]
    try:
        theirs = bag_types.generate_msgdef(msgtype)[1]  # type: ignore[attr-defined]
    except Exception as err:
        theirs = f'unreadable ({type(err).__name__})'
    if theirs != ours:
        raise BagError(f'{path}: topic {topic} is named {msgtype}, but the bag defines it '
                       "differently from ROS 2 Jazzy (another tool's message); no speed can be "
                       'read from it')


def _validated(path: Path, topic: str, times: list[float], speeds: list[float],
               config: TraceConfig) -> tuple[np.ndarray, np.ndarray]:
    for i, (t, v) in enumerate(zip(times, speeds, strict=True)):
        where = f'{path}: {topic} message {i} at t = {t:.3f} s'
        try:
            check_sample(where, t, v, times[i - 1] if i else None, config)
        except TraceError as err:
            raise BagError(str(err)) from err
    if len(times) < 2:
        raise BagError(f'{path}: topic {topic} needs at least 2 messages, got {len(times)}')
    return np.asarray(times), np.asarray(speeds)


def load_bag_trace(path: str | Path, topic: str, msgtype: str, dt_s: float,
                   config: TraceConfig) -> SpeedTrace:
    """A bag's speed topic on the control grid, as a :class:`SpeedTrace`."""
    path = Path(path)
    times, speeds = read_bag_samples(path, topic, msgtype, config)
    try:
        check_accelerations(f'{path}: {topic}', times, speeds, config)
        grid = resample(times, speeds, dt_s, f'{path}: {topic}')
    except TraceError as err:
        raise BagError(str(err)) from err
    return SpeedTrace(name=path.stem, dt_s=dt_s, speeds_mps=grid,
                      t0_s=float(times[0]), source=str(path))


def odometry_messages(times_s: np.ndarray, speeds_mps: np.ndarray,
                      frame_id: str, child_frame_id: str) -> Iterator[tuple[int, object]]:
    """``(stamp_ns, Odometry)`` per sample; position integrated with the trapezoid rule."""
    types = TYPESTORE.types
    position = 0.0
    for i, (t, v) in enumerate(zip(times_s, speeds_mps, strict=True)):
        if i:
            position += 0.5 * (v + speeds_mps[i - 1]) * (t - times_s[i - 1])
        ns = round(t * 1e9)
        header = types['std_msgs/msg/Header'](
            stamp=types['builtin_interfaces/msg/Time'](sec=ns // 1_000_000_000,
                                                        nanosec=ns % 1_000_000_000),
            frame_id=frame_id)
        point = types['geometry_msgs/msg/Point'](x=position, y=0.0, z=0.0)
        identity = types['geometry_msgs/msg/Quaternion'](x=0.0, y=0.0, z=0.0, w=1.0)
        pose = types['geometry_msgs/msg/PoseWithCovariance'](
            pose=types['geometry_msgs/msg/Pose'](position=point, orientation=identity),
            covariance=np.zeros(36))
        vector = types['geometry_msgs/msg/Vector3']
        twist = types['geometry_msgs/msg/TwistWithCovariance'](
            twist=types['geometry_msgs/msg/Twist'](linear=vector(x=float(v), y=0.0, z=0.0),
                                                   angular=vector(x=0.0, y=0.0, z=0.0)),
            covariance=np.zeros(36))
        yield ns, types[ODOMETRY](header=header, child_frame_id=child_frame_id, pose=pose,
                                  twist=twist)


def write_trace_bag(times_s: np.ndarray, speeds_mps: np.ndarray, path: Path, topic: str, *,
                    frame_id: str = 'odom', child_frame_id: str = 'preceding_vehicle') -> int:
    """Write samples as a rosbag2 MCAP bag of ``nav_msgs/msg/Odometry``; log time = stamp.
    Missing parent folders of ``path`` are created.

    Returns:
        The number of messages written.

    Raises:
        BagError: the bag directory exists already, is a symbolic link or cannot be
            written (then nothing of it is left).
    """
    if path.is_symlink():           # a dangling link would be written through
        raise BagError(f'{path}: a symbolic link; give a real path for the bag directory')
    if path.exists():
        raise BagError(f'{path}: exists already; remove it or choose another name')
    ancestor = path.parent
    while not ancestor.exists() and ancestor != ancestor.parent:
        ancestor = ancestor.parent
    if not ancestor.is_dir():
        raise BagError(f'{path}: cannot write bag ({ancestor} is not a folder)')
    count = 0
    # written in a temporary directory beside it and renamed when finished: a stop or a
    # full disk half-way leaves no bag (rosbags' Writer would close a shorter one that looks
    # finished)
    staging: Path | None = None
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        staging = Path(tempfile.mkdtemp(dir=path.parent, prefix=f'.{path.name}.'))
        with Writer(staging / path.name, version=9,
                    storage_plugin=StoragePlugin.MCAP) as writer:
            connection = writer.add_connection(topic, ODOMETRY, typestore=TYPESTORE)
            for ns, msg in odometry_messages(times_s, speeds_mps, frame_id, child_frame_id):
                writer.write(connection, ns, TYPESTORE.serialize_cdr(msg, ODOMETRY))
                count += 1
        os.rename(staging / path.name, path)
    except (WriterError, OSError) as err:
        reason = err.strerror if isinstance(err, OSError) and err.strerror else err
        raise BagError(f'{path}: cannot write bag ({reason})') from err
    finally:
        if staging is not None:
            shutil.rmtree(staging, ignore_errors=True)
    return count
