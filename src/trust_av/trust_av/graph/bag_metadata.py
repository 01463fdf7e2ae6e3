"""A bag directory's ``metadata.yaml`` and the YAML a bag's MCAP keeps of it, as rosbag2
Jazzy reads them (version 9).

Written with PyYAML's ``safe_dump`` (block style, keys sorted), field for field as rosbags'
``Writer.close`` wrote them before (``rosbags/rosbag2/writer.py``, rosbags 0.11.9; the only
difference in the text: a long value, the type hash, is no longer folded onto the next
line), which is what rosbag2's
``rosbag2_storage/src/rosbag2_storage/metadata_io.cpp`` (jazzy) reads: the fields are
checked against that reader's rules by ``tests/support/rosbag2_rules.py``. An offered QoS
profile is written as rosbag2's ``rosbag2_storage/src/rosbag2_storage/qos.cpp`` (jazzy) encodes a
``Rosbag2QoS`` for version 9: history, depth, reliability, durability, deadline, lifespan,
liveliness, liveliness_lease_duration and avoid_ros_namespace_conventions, the durations as
``sec``/``nsec``.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml
from rosbags.interfaces import Qos

__all__ = ['BagInfo', 'FileInfo', 'TopicInfo', 'qos_text']

METADATA_VERSION = 9
"""rosbag2 metadata version written (Jazzy's)."""
ROS_DISTRO = 'jazzy'
"""``ros_distro`` of the metadata: what rosbag2 on Jazzy writes there (the ``ROS_DISTRO``
environment variable: ros2/rosbag2 ``rosbag2_cpp/src/rosbag2_cpp/writers/sequential_writer.cpp``
``open``); rosbag2 reads the field as information only."""


def dump_yaml(document: Any) -> str:
    """``document`` as block-style YAML, keys sorted (as rosbags wrote it)."""
    return str(yaml.safe_dump(document, default_flow_style=False, sort_keys=True))


def qos_document(profiles: list[Qos]) -> list[dict[str, Any]]:
    """Offered QoS profiles as version-9 metadata holds them (one mapping per publisher)."""
    return [{'history': q.history.name.lower(), 'depth': q.depth,
             'reliability': q.reliability.name.lower(),
             'durability': q.durability.name.lower(),
             'deadline': {'sec': q.deadline.sec, 'nsec': q.deadline.nsec},
             'lifespan': {'sec': q.lifespan.sec, 'nsec': q.lifespan.nsec},
             'liveliness': q.liveliness.name.lower(),
             'liveliness_lease_duration': {'sec': q.liveliness_lease_duration.sec,
                                           'nsec': q.liveliness_lease_duration.nsec},
             'avoid_ros_namespace_conventions': q.avoid_ros_namespace_conventions}
            for q in profiles]


def qos_text(profiles: list[Qos]) -> str:
    """The ``offered_qos_profiles`` string of a topic's MCAP channel metadata (the same
    YAML, as one string; rosbag2_storage_mcap ``mcap_storage.cpp`` ``create_topic``)."""
    return dump_yaml(qos_document(profiles)).strip()


@dataclass
class TopicInfo:
    """One topic of a bag: what ``topics_with_message_count`` says of it."""

    name: str
    msgtype: str
    qos: list[Qos]
    type_hash: str
    """RIHS01 hash of the type (``type_description_hash``)."""
    count: int = 0


@dataclass
class FileInfo:
    """One MCAP file of a bag: what its ``files`` entry says (rosbag2's ``FileInformation``:
    ``metadata_io.cpp`` ``convert<FileInformation>``)."""

    path: str
    """its name, relative to the bag directory"""
    start_ns: int = 0
    end_ns: int = 0
    count: int = 0

    def document(self) -> dict[str, Any]:
        """The ``files[]`` mapping."""
        return {'path': self.path,
                'starting_time': {'nanoseconds_since_epoch': self.start_ns},
                'duration': {'nanoseconds': max(0, self.end_ns - self.start_ns)},
                'message_count': self.count}


@dataclass
class BagInfo:
    """What ``metadata.yaml`` says of a finished bag: its files in order (rosbag2 reads them
    one after the other), its topics, its time span and ``custom_data``."""

    files: list[FileInfo]
    topics: list[TopicInfo] = field(default_factory=list)
    start_ns: int = 0
    end_ns: int = 0
    custom_data: dict[str, str] = field(default_factory=dict)

    def document(self) -> dict[str, Any]:
        """The ``rosbag2_bagfile_information`` mapping."""
        duration = max(0, self.end_ns - self.start_ns)
        count = sum(topic.count for topic in self.topics)
        return {
            'version': METADATA_VERSION,
            'storage_identifier': 'mcap',
            'relative_file_paths': [file.path for file in self.files],
            'duration': {'nanoseconds': duration},
            'starting_time': {'nanoseconds_since_epoch': self.start_ns},
            'message_count': count,
            'topics_with_message_count': [
                {'topic_metadata': {'name': topic.name, 'type': topic.msgtype,
                                    'serialization_format': 'cdr',
                                    'offered_qos_profiles': qos_document(topic.qos),
                                    'type_description_hash': topic.type_hash},
                 'message_count': topic.count}
                for topic in self.topics],
            'compression_format': '',
            'compression_mode': '',
            'files': [file.document() for file in self.files],
            'custom_data': dict(self.custom_data) or None,
            'ros_distro': ROS_DISTRO,
        }

    def serialized(self) -> str:
        """The YAML the MCAP's ``rosbag2`` metadata record holds (``serialized_metadata``:
        the mapping without its top-level key; ``mcap_storage.cpp`` ``read_metadata``)."""
        return dump_yaml(self.document()).strip()

    def write(self, directory: Path) -> None:
        """Write ``directory/metadata.yaml``: a temporary file, fsync, rename, fsync of the
        directory (a crash leaves the old state or the whole new file).

        Raises:
            OSError: it cannot be written (the temporary file is removed).
        """
        text = dump_yaml({'rosbag2_bagfile_information': self.document()}).encode()
        target = directory / 'metadata.yaml'
        temporary = directory / 'metadata.yaml.tmp'
        try:
            fd = os.open(temporary, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | os.O_CLOEXEC
                         | os.O_NOFOLLOW, 0o644)
            try:
                view = memoryview(text)
                while view:
                    view = view[os.write(fd, view):]
                os.fsync(fd)
            finally:
                os.close(fd)
            os.replace(temporary, target)
        except OSError:
            temporary.unlink(missing_ok=True)
            raise
        fsync_directory(directory)


def fsync_directory(directory: Path) -> None:
    """Make the directory's entries (a created or renamed file) durable."""
    fd = os.open(directory, os.O_RDONLY | os.O_DIRECTORY | os.O_CLOEXEC)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)
