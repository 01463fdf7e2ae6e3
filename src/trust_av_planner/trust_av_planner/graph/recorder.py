"""MCAP writing for the ``recorder`` node (:mod:`trust_av_planner.graph.recorder_node`): every
topic of the graph into a rosbag2-compatible MCAP.

The file has profile ``ros2``, ``ros2msg`` schemas (full definitions from the rosbags type
store), ``cdr`` messages as they came over DDS (raw subscriptions, no re-serialisation),
channel QoS metadata (``offered_qos_profiles``) and a ``rosbag2`` metadata record. Log time
and publish time are the message's header stamp, i.e. sim time (every recorded type starts
with a Header or a Time). The writer flushes a chunk at every new ``/clock``, so a run that
is killed leaves every step up to the kill on disk; :func:`repair_mcap` rewrites such a
truncated file into a complete one. The recorder ends by itself once it holds every message
of ``expected_steps`` steps.
"""

from __future__ import annotations

import logging
import struct
from pathlib import Path
from typing import IO

from mcap.exceptions import McapError
from mcap.records import Channel, Message, Schema
from mcap.stream_reader import StreamReader
from mcap.writer import CompressionType, Writer
from rosbags.typesys import Stores, get_typestore

LOG = logging.getLogger(__name__)
ROS_DISTRO = 'jazzy'
TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
_INFINITE = '{sec: 2147483647, nsec: 4294967295}'


def _qos_yaml(depth: int, durability: int) -> str:
    return (f'- history: 1\n  depth: {depth}\n  reliability: 1\n  durability: {durability}\n'
            f'  deadline: {_INFINITE}\n  lifespan: {_INFINITE}\n  liveliness: 1\n'
            f'  liveliness_lease_duration: {_INFINITE}\n'
            '  avoid_ros_namespace_conventions: false\n')


QOS_YAML = {'STEP': _qos_yaml(1000, 1), 'CLOCK': _qos_yaml(1000, 1)}
"""rosbag2's ``offered_qos_profiles`` (rmw enums: history 1 keep-last, reliability 1
reliable, durability 1 transient-local), matching :mod:`trust_monitor.ros.qos`."""


STAMP_IN_FIRST_ELEMENT = frozenset({'tf2_msgs/msg/TFMessage',
                                    'visualization_msgs/msg/MarkerArray'})
"""Types that start with a sequence of stamped messages: the stamp is the first
element's (after the uint32 sequence length)."""


def header_stamp_ns(data: bytes, offset: int = 4) -> int:
    """Stamp of a CDR message that starts with a Time or a Header at ``offset`` (4: after
    the 4-byte encapsulation header; 8: in the first element of a leading sequence): int32
    sec, uint32 nanosec, little or big endian."""
    little = data[1] == 1
    sec, nanosec = struct.unpack('<iI' if little else '>iI', data[offset:offset + 8])
    return sec * 1_000_000_000 + nanosec


class McapBag:
    """A rosbag2-style MCAP writer for raw CDR messages (a context manager)."""

    def __init__(self, path: Path) -> None:
        self.path = path
        path.parent.mkdir(parents=True, exist_ok=True)
        self._stream: IO[bytes] = path.open('wb')
        self._writer = Writer(self._stream, compression=CompressionType.ZSTD)
        self._writer.start(profile='ros2', library='trust_av_planner recorder')
        self._channels: dict[str, int] = {}
        self._offsets: dict[str, int] = {}
        self._schemas: dict[str, int] = {}
        self.counts: dict[str, int] = {}
        self._first_ns: int | None = None
        self._last_ns = 0
        self._finished = False

    def add_topic(self, topic: str, msgtype: str, qos: str) -> None:
        """Register a topic (its schema once per type)."""
        if msgtype not in self._schemas:
            text, _ = TYPESTORE.generate_msgdef(msgtype, ros_version=2)
            self._schemas[msgtype] = self._writer.register_schema(
                name=msgtype, encoding='ros2msg', data=text.encode())
        self._channels[topic] = self._writer.register_channel(
            topic=topic, message_encoding='cdr', schema_id=self._schemas[msgtype],
            metadata={'offered_qos_profiles': QOS_YAML[qos]})
        self._offsets[topic] = 8 if msgtype in STAMP_IN_FIRST_ELEMENT else 4
        self.counts[topic] = 0

    def write(self, topic: str, data: bytes) -> int:
        """Write one raw message, log time = its stamp; returns the stamp."""
        ns = header_stamp_ns(data, self._offsets[topic])
        self._writer.add_message(self._channels[topic], log_time=ns, data=data,
                                 publish_time=ns, sequence=self.counts[topic])
        self.counts[topic] += 1
        self._first_ns = ns if self._first_ns is None else min(self._first_ns, ns)
        self._last_ns = max(self._last_ns, ns)
        return ns

    def flush(self) -> None:
        """Close the current chunk and push it to the file."""
        self._writer.flush()

    def finish(self) -> None:
        """Write the rosbag2 metadata record, the summary and the footer; close the file."""
        if self._finished:
            return
        self._finished = True
        first = self._first_ns or 0
        topics = ''.join(f'    - topic_metadata: {{name: {t}}}\n      message_count: {n}\n'
                         for t, n in self.counts.items())
        metadata = (f'rosbag2_bagfile_information:\n  version: 9\n  storage_identifier: mcap\n'
                    f'  duration: {{nanoseconds: {self._last_ns - first}}}\n'
                    f'  starting_time: {{nanoseconds_since_epoch: {first}}}\n'
                    f'  message_count: {sum(self.counts.values())}\n'
                    f'  topics_with_message_count:\n{topics}')
        self._writer.add_metadata('rosbag2', {'serialized_metadata': metadata,
                                              'ROS_DISTRO': ROS_DISTRO})
        self._writer.finish()
        self._stream.close()

    def __enter__(self) -> McapBag:
        return self

    def __exit__(self, *exc: object) -> None:
        self.finish()


def repair_mcap(path: Path) -> int:
    """Rewrite a truncated MCAP (a killed recorder) into a complete file, in place.

    Reads records in order until the truncation and writes every complete message again.

    Returns:
        The number of messages kept.
    """
    schemas: dict[int, Schema] = {}
    channels: dict[int, Channel] = {}
    messages: list[Message] = []
    try:
        with path.open('rb') as handle:
            for record in StreamReader(handle).records:
                if isinstance(record, Schema):
                    schemas[record.id] = record
                elif isinstance(record, Channel):
                    channels[record.id] = record
                elif isinstance(record, Message):
                    messages.append(record)
    except (McapError, struct.error, EOFError, ValueError) as err:
        # Expected: the stream ends inside the record the writer was writing when killed.
        LOG.warning('%s: recording ends in a truncated record (%s); keeping the %d complete '
                    'messages before it', path, err, len(messages))
    tmp = path.with_suffix('.mcap.tmp')
    with tmp.open('wb') as out:
        writer = Writer(out, compression=CompressionType.ZSTD)
        writer.start(profile='ros2', library='trust_av_planner repair_mcap')
        schema_ids = {sid: writer.register_schema(s.name, s.encoding, s.data)
                      for sid, s in schemas.items()}
        channel_ids = {cid: writer.register_channel(c.topic, c.message_encoding,
                                                    schema_ids[c.schema_id], c.metadata)
                       for cid, c in channels.items() if c.schema_id in schema_ids}
        kept = 0
        for m in messages:
            if m.channel_id in channel_ids:
                writer.add_message(channel_ids[m.channel_id], m.log_time, m.data,
                                   m.publish_time, m.sequence)
                kept += 1
        writer.add_metadata('rosbag2', {'ROS_DISTRO': ROS_DISTRO,
                                        'repaired': 'truncated recording'})
        writer.finish()
    tmp.replace(path)
    return kept
