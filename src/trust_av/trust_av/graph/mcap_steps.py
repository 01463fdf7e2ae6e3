"""The MCAP file under :class:`~trust_av.graph.bag_writer.BagWriter`, through the
public API of the ``mcap`` library: ``mcap.writer.Writer`` (``start``, ``register_schema``,
``register_channel``, ``add_message``, ``flush``, ``add_metadata``, ``finish``) writing to
an unbuffered file, and ``mcap.stream_reader.StreamReader`` to rebuild a writer's state
from the file after a step failed to be written.

A step is one chunk: the writer's automatic chunking is off (a chunk size it never
reaches) and ``Writer.flush`` closes the chunk at the end of each step (it writes no chunk
without messages, so the first chunk always has a message index, as rosbag2's time-ordered
read needs: ``tests/support/rosbag2_rules.py`` ``time_ordered_read``). Chunks are uncompressed."""

from __future__ import annotations

import os
import struct
from dataclasses import dataclass
from pathlib import Path
from typing import IO, cast

from mcap.exceptions import EndOfFile, McapError
from mcap.records import Channel, Header, Message, MessageIndex, Schema
from mcap.stream_reader import StreamReader
from mcap.writer import LIBRARY_IDENTIFIER, CompressionType, Writer

__all__ = ['RECORDER_LIBRARY', 'REPAIR_LIBRARY', 'WholeWrites', 'new_writer', 'replay']

RECORDER_LIBRARY = 'trust_av.bag_writer'
"""What the MCAP header's ``library`` field of a bag this project wrote starts with (followed
by `` (mcap-python/VERSION)``): how :mod:`~trust_av.graph.bag_repair` tells its own
recordings, whose log time is the header stamp, from another tool's."""
REPAIR_LIBRARY = 'trust_av.bag_repair'
"""The ``library`` field of a repaired copy: ``trust_av.bag_repair of`` the original's."""
PROFILE = 'ros2'
"""The MCAP header's ``profile`` (rosbag2's MCAP plugin writes and expects ``ros2``)."""
NO_AUTOMATIC_CHUNKS = 2**62
"""The writer's ``chunk_size``: never reached, so a chunk ends only at ``flush`` (a step)."""


def library_name(library: str) -> str:
    """The MCAP header's ``library``: ``library`` and the mcap writer's own identifier."""
    return f'{library} ({LIBRARY_IDENTIFIER})'


class WholeWrites:
    """An unbuffered file whose ``write`` writes everything or raises ``OSError`` (no silent
    short writes). Between :meth:`gather` and :meth:`commit` writes are collected and go to
    the file in one ``os.write`` loop (a chunk and its small index records: one system
    call, not one per record).

    Args:
        path: the MCAP file to create (it must not exist).

    Raises:
        OSError: it cannot be created.
    """

    def __init__(self, path: Path) -> None:
        self.fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_CLOEXEC, 0o644)
        self.position = 0
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

    def flush(self) -> None:
        """Nothing is buffered (``mcap.writer.Writer.flush`` calls it)."""

    def truncate(self, size: int) -> None:
        """Cut the file at ``size`` and continue writing there (collected writes are
        dropped)."""
        self.gathered = None
        os.ftruncate(self.fd, size)
        os.lseek(self.fd, size, os.SEEK_SET)
        self.position = size

    def sync(self) -> None:
        """fsync the file."""
        os.fsync(self.fd)

    def close(self) -> None:
        os.close(self.fd)


class Redirect:
    """A stream that counts and drops what is written until :attr:`sink` is set, then
    writes through to it: the writer rebuilt by :func:`replay` goes over the bytes that are
    in the file already, then writes the rest of the file."""

    def __init__(self) -> None:
        self.position = 0
        self.sink: WholeWrites | None = None

    def write(self, data: bytes | bytearray | memoryview) -> int:
        if self.sink is not None:
            return self.sink.write(data)
        self.position += len(data)
        return len(data)

    def tell(self) -> int:
        return self.sink.tell() if self.sink is not None else self.position

    def flush(self) -> None:
        """Nothing is buffered."""


def new_writer(stream: WholeWrites | Redirect, library: str) -> Writer:
    """An MCAP writer on ``stream`` that has written its magic and header (profile
    ``ros2``, ``library`` as :func:`library_name`), one chunk per ``flush``, uncompressed."""
    writer = Writer(cast('IO[bytes]', stream), chunk_size=NO_AUTOMATIC_CHUNKS,
                    compression=CompressionType.NONE)
    writer.start(profile=PROFILE, library=library_name(library))
    return writer


@dataclass
class Replayed:
    """A writer rebuilt from a file's complete chunks, and what it found."""

    writer: Writer
    stream: Redirect
    schemas: int
    channels: int


def replay(path: Path, end: int, library: str) -> Replayed:
    """A new writer in the state the writer of ``path`` had when its first ``end`` bytes
    were written: every schema, channel and message of the file read with
    ``StreamReader`` and given to it in file order, a ``flush`` after each chunk (its
    message indexes follow it), the bytes it writes counted, not written.

    The MCAP writer is deterministic, so the rebuilt writer writes the same bytes; it is
    checked: its count must be ``end``. Set ``stream.sink`` to go on writing the file.

    Raises:
        ValueError: the file does not replay to ``end`` bytes (the bag is then left as it
            is, for ``trust-av repair-bag``).
        OSError: the file cannot be read.
    """
    stream = Redirect()
    writer = new_writer(stream, library)
    schemas = channels = 0
    with path.open('rb') as handle:
        try:
            for record in StreamReader(handle, skip_magic=False,
                                       record_size_limit=max(end, 1)).records:
                schemas, channels = _give(writer, library, record, schemas, channels)
        except EndOfFile:          # the end of the complete steps: the file ends there
            if handle.tell() != end:
                raise ValueError(f'it ends at byte {handle.tell()}, not {end}') from None
        except (McapError, struct.error) as err:   # a record cut off or damaged
            raise ValueError(f'it cannot be read to byte {end} ({err})') from err
    if stream.position != end:
        raise ValueError(f'its complete steps replay to {stream.position} bytes, not {end}')
    return Replayed(writer, stream, schemas, channels)


def _give(writer: Writer, library: str, record: object, schemas: int,
          channels: int) -> tuple[int, int]:
    """Give one record read from the file to the rebuilt writer; the schemas and channels
    seen so far."""
    if isinstance(record, Header):
        if record.library != library_name(library) or record.profile != PROFILE:
            raise ValueError(f'its header names {record.library!r}')
    elif isinstance(record, Schema):
        schemas += 1
        if writer.register_schema(record.name, record.encoding, record.data) != record.id:
            raise ValueError(f'schema {record.id} is out of order')
    elif isinstance(record, Channel):
        channels += 1
        if writer.register_channel(record.topic, record.message_encoding, record.schema_id,
                                   record.metadata) != record.id:
            raise ValueError(f'channel {record.id} is out of order')
    elif isinstance(record, Message):
        writer.add_message(record.channel_id, record.log_time, record.data,
                           record.publish_time, record.sequence)
    elif isinstance(record, MessageIndex):
        writer.flush()  # type: ignore[no-untyped-call]
    return schemas, channels
