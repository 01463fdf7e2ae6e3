"""The MCAP storage under :class:`~trust_av_planner.graph.bag_writer.BagWriter`: rosbags'
MCAP writer writing through an unbuffered file, one chunk per step, with the channel metadata
rosbag2 Jazzy writes and a header naming this project's writer."""

from __future__ import annotations

import os
from collections import defaultdict
from importlib.metadata import version
from io import BytesIO
from pathlib import Path
from typing import Any

from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.rosbag2.storage_mcap import (
    Channel,
    McapWriter,
    PendingChunk,
    write_channel,
    write_record,
    write_string,
)

RECORDER_LIBRARY = 'trust_av.bag_writer'
"""What the MCAP header's ``library`` field of a bag this project wrote starts with (followed
by `` (rosbags-VERSION)``): how :mod:`~trust_av_planner.graph.bag_repair` tells its own
recordings, whose log time is the header stamp, from another tool's."""

class WholeWrites:
    """An unbuffered file whose ``write`` writes everything or raises ``OSError`` (no silent
    short writes: rosbags' writer ignores ``write``'s return value). Between
    :meth:`gather` and :meth:`commit` writes are collected and go to the file in one
    ``os.write`` loop (a chunk and its ~45 small index records: one system call, not 45)."""

    def __init__(self, path: Path, offset: int) -> None:
        self.fd = os.open(path, os.O_WRONLY | os.O_CLOEXEC)
        os.lseek(self.fd, offset, os.SEEK_SET)
        self.position = offset
        self.gathered: list[bytes] | None = None

    def write(self, data: bytes | bytearray | memoryview) -> int:
        if self.gathered is not None:
            self.gathered.append(bytes(data))
            self.position += len(data)
            return len(data)
        view = memoryview(data)
        while view:
            written = os.write(self.fd, view)
            self.position += written
            view = view[written:]
        return len(data)

    def gather(self) -> None:
        """Collect writes from now on (``tell`` counts them) until :meth:`commit`."""
        self.gathered = []

    def commit(self) -> None:
        """Write what was collected; ``OSError`` if it does not all fit."""
        view, self.gathered = memoryview(b''.join(self.gathered or ())), None
        while view:   # ``position`` already counts these bytes
            view = view[os.write(self.fd, view):]

    def tell(self) -> int:
        return self.position

    def truncate(self, size: int) -> None:
        """Cut the file at ``size`` and continue writing there (collected writes are
        dropped)."""
        self.gathered = None
        os.ftruncate(self.fd, size)
        os.lseek(self.fd, size, os.SEEK_SET)
        self.position = size

    def close(self) -> None:
        os.close(self.fd)


class StepStorage(McapWriter):
    """rosbags' MCAP storage, writing through an unbuffered file (so a closed chunk is on
    disk) and able to cut off a chunk that failed half-written."""

    library = RECORDER_LIBRARY
    """The MCAP header's ``library`` (followed by `` (rosbags-VERSION)``)."""

    def __init__(self, path: Path, compression: Any) -> None:
        super().__init__(path, compression)
        self.bio.seek(0)                    # the same magic and header, naming this writer
        self.bio.truncate(0)
        self.bio.write(b'\x89MCAP\x30\r\n')
        header = BytesIO()
        write_string(header, 'ros2')
        write_string(header, f'{self.library} (rosbags-{version("rosbags")})')
        write_record(self.bio, 0x01, header)
        self.bio.flush()
        offset = self.bio.tell()
        self.bio.close()
        self.bio = WholeWrites(self.path, offset)

    def add_connection(self, connection: Any, offered_qos_profiles: str) -> None:
        """A channel with the metadata rosbag2 Jazzy's MCAP plugin writes: the offered QoS
        profiles and the type hash (``topic_type_hash``: the RIHS01 hash of the type, as
        in metadata.yaml's ``type_description_hash``; ``rosbag2_storage_mcap``
        ``mcap_storage.cpp`` ``create_topic``, jazzy L933-938). rosbags writes the first
        only."""
        metadata = BytesIO()
        for key, value in (('offered_qos_profiles', offered_qos_profiles),
                           ('topic_type_hash', connection.digest)):
            write_string(metadata, key)
            write_string(metadata, value)
        self.channels.append(Channel(connection.id, connection.msgtype, connection.topic,
                                     connection.ext.serialization_format,
                                     metadata.getvalue()))
        self.channel_stats[connection.id] = 0
        write_channel(self.chunk.bio, self.channels[-1], self.schemas)

    def discard_chunk(self) -> None:
        """Start a new, empty pending chunk (what was pending is dropped)."""
        self.chunk = PendingChunk(2**63 - 1, 0, BytesIO(), defaultdict(list))

    def close_step_chunk(self) -> None:
        """Write the pending chunk to the file; on an error cut the file back to where the
        chunk began, drop the chunk and re-raise.

        A pending chunk without messages (only the schema and channel records of topics
        added since the last chunk) is written as those records, outside any chunk: the
        mcap C++ reader that rosbag2 Jazzy uses refuses a time-ordered read of a file whose
        first chunk has no message index (``reader.inl`` of ``foxglove/mcap``
        ``releases/cpp/v1.3.0``, ``IndexedMessageReader``), and rosbag2 reads in time order.
        """
        if not self.chunk.bio.tell():
            return
        start, indexed = self.bio.tell(), len(self.chunks)
        self.bio.gather()
        try:
            if self.chunk.msgs:
                self.close_chunk()
            else:
                self.bio.write(self.chunk.bio.getbuffer())
                self.discard_chunk()
            self.bio.commit()
        except OSError:
            self.bio.truncate(start)
            del self.chunks[indexed:]   # close_chunk indexed the chunk the file lacks
            raise


class StepWriter(Writer):
    """rosbags' Writer with :class:`StepStorage` as its MCAP storage plugin."""

    STORAGE_PLUGINS = {**Writer.STORAGE_PLUGINS, StoragePlugin.MCAP: StepStorage}  # noqa: RUF012
