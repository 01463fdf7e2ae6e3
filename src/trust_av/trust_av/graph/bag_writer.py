"""Crash-safe rosbag2 bag directories: the graph's recordings.

A recording is a rosbag2 bag directory (``metadata.yaml`` + its MCAP files), written through
public library API only: the MCAP file by the ``mcap`` library's ``mcap.writer.Writer``
(:mod:`~trust_av.graph.mcap_steps`), ``metadata.yaml`` and the MCAP's ``rosbag2``
metadata record by :mod:`~trust_av.graph.bag_metadata` (PyYAML), the types'
definitions and RIHS01 hashes by the public ``Typestore.generate_msgdef`` and
``Typestore.hash_rihs01`` of rosbags' ``ROS2_JAZZY`` typestore, QoS profiles as
``rosbags.interfaces.Qos``. No private attribute and no internal module of a library is
used. What rosbag2 Jazzy writes is kept: version-9 metadata; schemas ``ros2msg``; every
channel's metadata holds ``offered_qos_profiles`` (one profile per publisher) and
``topic_type_hash`` (``rosbag2_storage_mcap`` ``mcap_storage.cpp`` ``create_topic``, jazzy
L933-938); the format owner's reader rules are checked by ``tests/support/rosbag2_rules.py``.
On top of it, :class:`BagWriter` adds what a recording that must survive any end needs:

- **a chunk per step**: :meth:`BagWriter.end_step` closes the MCAP chunk and writes it
  through to the file (unbuffered), so a killed process leaves every step up to the kill
  on disk; :func:`~trust_av.graph.bag_repair.repair_bag` turns such a directory
  into a complete bag.
- **split files**: after :data:`MAX_CHUNKS_PER_FILE` chunks (steps) the MCAP file is
  finished (summary, footer) and recording goes on in the next, ``<bag>_1.mcap``,
  ``<bag>_2.mcap``, ... (rosbag2's split: ``metadata.yaml`` lists the files in order, with
  each one's messages and time span). The MCAP writer keeps an index entry per chunk until
  its file's summary is written (1.4-2.3 kB each, measured), so a file's chunks bound the
  recorder's memory: without the split it grew by about 80 MB an hour at 10 Hz.
- **a full disk**: a reserve file inside the bag directory holds, at all times, room for
  the MCAP summary and ``metadata.yaml``; when a write fails with ``ENOSPC`` the partial
  step is cut off, the reserve is released, the bag is finished with every complete step,
  and :class:`DiskFullError` says so. The reserve never outlives the writer. As the MCAP
  writer cannot take back a step, the writer that finishes the bag is rebuilt from the
  complete steps in the file (:func:`~trust_av.graph.mcap_steps.replay`).

Messages are raw CDR as they came over DDS; in lock-step log time = publish time = the
header stamp (sim time); in wall mode, as ``ros2 bag record`` writes them, log time = the
time the recorder received the message and publish time = its header stamp (the
publisher's), both wall time (``receive_time_ns`` of :meth:`BagWriter.write`).
"""

from __future__ import annotations

import errno
import os
import resource
import shutil
import signal
import struct
import threading
from collections.abc import Mapping
from pathlib import Path

from mcap.writer import Writer as McapWriter
from rosbags.interfaces import (
    Qos,
    QosDurability,
    QosHistory,
    QosLiveliness,
    QosReliability,
    QosTime,
)
from rosbags.typesys import Stores, get_typestore

from trust_av.errors import TrustAvAppError
from trust_av.graph.bag_metadata import BagInfo, FileInfo, TopicInfo, qos_text
from trust_av.graph.mcap_steps import (
    RECORDER_LIBRARY,
    REPAIR_LIBRARY,
    WholeWrites,
    new_writer,
    replay,
)

__all__ = ['EXIT_DISK_FULL', 'MAX_CHUNKS_PER_FILE', 'RESERVE_BASE_BYTES', 'RESERVE_NAME',
           'RESERVE_PER_CHUNK_BYTES', 'RESERVE_STEP_CHUNKS', 'STAMP_IN_FIRST_ELEMENT', 'TYPESTORE',
           'BagWriteError', 'BagWriter', 'DiskFullError', 'header_stamp_ns', 'qos_profile']

TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
RESERVE_BASE_BYTES = 48 * 1024
"""Room kept for finishing a bag besides the chunk indexes: the rosbag2 metadata record,
schemas, channels with their QoS, statistics, footer and metadata.yaml (measured: about
30 kB for the graph's 12 recorded topics)."""
RESERVE_PER_CHUNK_BYTES = 256
"""Summary bytes per chunk written (a chunk index: about 70 bytes + 10 per channel in it)."""
RESERVE_STEP_CHUNKS = 64
"""The reserve grows by this many chunks' worth at a time (one fallocate per 64 steps)."""
RESERVE_NAME = '.reserve'
MESSAGE_RECORD_BYTES = 31
"""An MCAP Message record's bytes besides its data (opcode, length, channel, sequence,
log and publish time)."""
CHUNK_OVERHEAD_BYTES = 4096
"""Room a step's chunk record may need beyond twice its messages' bytes (record headers,
message indexes), for the file-size limit check."""
EXIT_DISK_FULL = 3
MAX_CHUNKS_PER_FILE = 10_000
"""Chunks (steps) per MCAP file before the recording goes on in the next file: above the
longest shipped cycle (about 8,500 steps at 10 Hz), so a run on one is one file; an hour at
10 Hz is four. One file's chunk index is held in memory until the file is finished (about
14-23 MB at this size)."""
"""Exit code of a recorder that stopped because the disk was full (the bag is finished)."""
MAX_INFINITE = QosTime(2147483647, 4294967295)
"""rmw's "infinite" duration as rosbag2 writes it in offered_qos_profiles."""


class BagWriteError(TrustAvAppError):
    """A recording cannot be written or read back; the message names the bag."""


class DiskFullError(BagWriteError):
    """The disk filled up while recording; the bag was finished with the complete steps
    (or, at the start, there was no room for a recording: nothing is left)."""

    exit_code = EXIT_DISK_FULL
    """What a node process that raised it exits with (its one line may not fit on the disk
    either; the orchestrator knows the code)."""


STAMP_IN_FIRST_ELEMENT = frozenset({'tf2_msgs/msg/TFMessage',
                                    'visualization_msgs/msg/MarkerArray'})
"""Types that start with a sequence of stamped messages: the stamp is the first element's
(after the uint32 sequence length)."""


def header_stamp_ns(data: bytes | memoryview, offset: int = 4) -> int:
    """Stamp of a CDR message that starts with a Time or a Header at ``offset`` (4: after
    the 4-byte encapsulation header; 8: in the first element of a leading sequence): int32
    sec, uint32 nanosec, little or big endian."""
    little = data[1] == 1
    sec, nanosec = struct.unpack_from('<iI' if little else '>iI', data, offset)
    return int(sec) * 1_000_000_000 + int(nanosec)


def qos_profile(*, reliable: bool, transient_local: bool, depth: int,
                deadline_ns: int = 0) -> Qos:
    """An offered QoS profile as rosbag2 stores it (keep-last history, automatic
    liveliness, infinite lifespan; ``deadline_ns`` 0 = infinite)."""
    deadline = (MAX_INFINITE if deadline_ns <= 0
                else QosTime(deadline_ns // 1_000_000_000, deadline_ns % 1_000_000_000))
    return Qos(QosHistory.KEEP_LAST, depth,
               QosReliability.RELIABLE if reliable else QosReliability.BEST_EFFORT,
               QosDurability.TRANSIENT_LOCAL if transient_local else QosDurability.VOLATILE,
               deadline, MAX_INFINITE, QosLiveliness.AUTOMATIC, MAX_INFINITE, False)


def _file_size_limit() -> int | None:
    """This process's file-size limit (soft ``RLIMIT_FSIZE``), bytes; ``None`` if none."""
    soft, _ = resource.getrlimit(resource.RLIMIT_FSIZE)
    return None if soft == resource.RLIM_INFINITY else int(soft)


class BagWriter:
    """A rosbag2 bag directory being recorded, one MCAP chunk per step (context manager).

    Args:
        path: the bag directory to create (it must not exist).
        copy_of: for a repaired copy of another tool's recording (its log times are not
            header stamps): that tool's MCAP ``library``; the copy is then not marked as
            this project's recording (:data:`~trust_av.graph.mcap_steps.RECORDER_LIBRARY`,
            ``trust_av.recorder``).
        custom_data: ``custom_data`` entries of ``metadata.yaml`` (the run's record).
        max_chunks_per_file: chunks (steps) per MCAP file before the next file starts.

    Raises:
        BagWriteError: the directory exists or cannot be created.
        DiskFullError: there is no room to start a recording (nothing is left).
    """

    def __init__(self, path: Path, *, copy_of: str | None = None,
                 custom_data: Mapping[str, str] | None = None,
                 max_chunks_per_file: int = MAX_CHUNKS_PER_FILE) -> None:
        if max_chunks_per_file < 1:
            raise ValueError(f'max_chunks_per_file must be at least 1, got {max_chunks_per_file}')
        self.path = Path(path)
        self._max_chunks = max_chunks_per_file
        if threading.current_thread() is threading.main_thread():
            # past a file-size limit a write fails with EFBIG instead of killing the process
            signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        self._library = (RECORDER_LIBRARY if copy_of is None
                         else f'{REPAIR_LIBRARY} of {copy_of or "unknown"}')
        self._file = FileInfo(f'{self.path.name}.mcap')
        self._info = BagInfo([self._file])
        if copy_of is None:
            self._info.custom_data['trust_av.recorder'] = 'one MCAP chunk per step'
        else:
            self._info.custom_data['trust_av.repaired_copy_of'] = copy_of or 'unknown'
        self._info.custom_data.update(custom_data or {})   # the run's record (run_record)
        self._topics: dict[str, TopicInfo] = {}
        self._channels: dict[str, int] = {}
        self._schemas: dict[str, int] = {}
        self._schema_records: list[tuple[str, str, bytes]] = []
        self._channel_records: list[tuple[str, str, int, dict[str, str]]] = []
        self._pending: dict[str, int] = {}
        self._step_bytes = 0
        self._offsets: dict[str, int] = {}
        self._reserve = self.path / RESERVE_NAME
        self._reserved = 0
        self._chunks = 0     # of the current file
        self._step_first, self._step_last = 2**63 - 1, -1
        self._times = (2**63 - 1, 0)
        self.finished = False
        self.disk_full: str = ''
        self.steps = 0
        if os.path.lexists(self.path):
            raise BagWriteError(f'{self.path}: cannot create the bag directory ({self.path} '
                                'exists already, not overwriting)')
        stream: WholeWrites | None = None
        try:
            self.path.mkdir(mode=0o755, parents=True)
        except OSError as err:
            raise self._start_error(err) from err
        try:       # all or nothing: an error or a stop signal part-way leaves no directory
            try:
                stream = WholeWrites(self._mcap_path)
                self._mcap = new_writer(stream, self._library)
            except OSError as err:
                raise self._start_error(err) from err
            self._stream = stream
            try:
                self._grow_reserve()
            except OSError as err:
                raise DiskFullError(f'{self.path}: no room to start a recording '
                                    f'({os.strerror(err.errno or errno.ENOSPC)})') from err
        except BaseException:
            if stream is not None:
                stream.close()
            shutil.rmtree(self.path, ignore_errors=True)
            raise

    @property
    def _mcap_path(self) -> Path:
        """The MCAP file being written."""
        return self.path / self._file.path

    @property
    def files(self) -> list[str]:
        """The bag's MCAP files so far, in order (names in the bag directory)."""
        return [file.path for file in self._info.files]

    def _start_error(self, err: OSError) -> BagWriteError:
        """The error of a start that failed."""
        if err.errno in (errno.ENOSPC, errno.EDQUOT):
            return DiskFullError(f'{self.path}: no room to start a recording '
                                 f'({os.strerror(err.errno)})')
        return BagWriteError(f'{self.path}: cannot create the bag directory ({err})')

    @property
    def counts(self) -> dict[str, int]:
        """Messages per topic written so far (complete steps and the pending one)."""
        return {name: t.count + self._pending[name] for name, t in self._topics.items()}

    def count(self, topic: str) -> int:
        """Messages of ``topic`` written so far (complete steps and the pending one)."""
        return self._topics[topic].count + self._pending[topic]

    def set_custom_data(self, key: str, value: str) -> None:
        """Set one ``custom_data`` entry of ``metadata.yaml`` (written when finished)."""
        self._info.custom_data[key] = value

    def add_topic(self, topic: str, msgtype: str, qos: Qos | list[Qos]) -> None:
        """Register a topic with its type and the QoS its publishers offer: one profile per
        publisher, as ``ros2 bag record`` writes them (a profile alone: one publisher).

        Raises:
            BagWriteError: the topic was added already.
        """
        if topic in self._topics:
            raise BagWriteError(f'{self.path}: topic {topic!r} added twice')
        profiles = list(qos) if isinstance(qos, list) else [qos]
        type_hash = TYPESTORE.hash_rihs01(msgtype)
        if msgtype not in self._schemas:
            msgdef, _ = TYPESTORE.generate_msgdef(msgtype, ros_version=2)
            encoding = 'ros2idl' if msgdef.startswith('=' * 80 + '\nIDL: ') else 'ros2msg'
            self._schema_records.append((msgtype, encoding, msgdef.encode()))
            self._schemas[msgtype] = self._mcap.register_schema(msgtype, encoding,
                                                                msgdef.encode())
        metadata = {'offered_qos_profiles': qos_text(profiles), 'topic_type_hash': type_hash}
        self._channel_records.append((topic, 'cdr', self._schemas[msgtype], metadata))
        self._channels[topic] = self._mcap.register_channel(topic, 'cdr', self._schemas[msgtype],
                                                            metadata)
        self._topics[topic] = TopicInfo(topic, msgtype, profiles, type_hash)
        self._info.topics.append(self._topics[topic])
        self._pending[topic] = 0
        self._offsets[topic] = 8 if msgtype in STAMP_IN_FIRST_ELEMENT else 4

    def add_attachment(self, name: str, media_type: str, data: bytes, *, log_time_ns: int,
                       create_time_ns: int) -> None:
        """Write an MCAP attachment record (a file kept with the recording, indexed in the
        summary), e.g. one kept from a repaired recording; before the first message."""
        self._mcap.add_attachment(create_time_ns, log_time_ns, name, media_type, data)

    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        """Write an MCAP metadata record (indexed in the summary); before the first message."""
        self._mcap.add_metadata(name, data)

    def add_schema(self, name: str, encoding: str, data: bytes) -> None:
        """Register a schema no topic of the bag uses (kept from a repaired recording: it is
        in the summary)."""
        self._schema_records.append((name, encoding, data))   # in every file, in this order
        self._mcap.register_schema(name, encoding, data)

    def write(self, topic: str, data: bytes | memoryview, log_time_ns: int | None = None, *,
              receive_time_ns: int | None = None) -> int:
        """Append one raw CDR message to the current step; returns its log time (ns).

        Args:
            topic: a topic added with :meth:`add_topic`.
            data: the message, CDR with its 4-byte encapsulation header.
            log_time_ns: its log time and publish time, ns (default: the stamp of its
                header, which the graph's messages carry first).
            receive_time_ns: wall mode, as ``ros2 bag record``: the log time is this
                receive time, the publish time the header's stamp (the publisher's).

        Raises:
            BagWriteError: the bag is finished (after :meth:`finish`, or once
                :meth:`end_step` returned False for a full disk)."""
        if self.finished:
            raise BagWriteError(f'{self.path}: written to after the bag was finished'
                                + (f' ({self.disk_full})' if self.disk_full else ''))
        published = (header_stamp_ns(data, self._offsets[topic]) if log_time_ns is None
                     else log_time_ns)
        stamp = published if receive_time_ns is None else receive_time_ns
        self._mcap.add_message(self._channels[topic], stamp,
                               data if isinstance(data, bytes) else bytes(data), published)
        self._pending[topic] += 1
        self._step_bytes += len(data) + MESSAGE_RECORD_BYTES
        if stamp < self._step_first:
            self._step_first = stamp
        if stamp > self._step_last:
            self._step_last = stamp
        return stamp

    def end_step(self) -> bool:
        """Write the current step to disk as one chunk.

        Returns:
            True while recording goes on; False once the bag cannot grow (a full disk, the
            file-size limit ``RLIMIT_FSIZE``, or any other write error): the partial step
            (if any) was cut off and the bag was finished with every complete step (see
            :attr:`disk_full`).
        """
        if self.finished:
            return False
        limit = _file_size_limit()
        start = self._stream.tell()
        if limit is not None and (start + 2 * self._step_bytes + CHUNK_OVERHEAD_BYTES
                                  + self._needed_reserve() > limit):
            # the step and the summary would not fit under the limit: end before it does
            self._finish_after_write_error(start, OSError(errno.EFBIG, os.strerror(errno.EFBIG)),
                                           f'file-size limit of {limit} bytes (RLIMIT_FSIZE)')
            return False
        if self._step_bytes:
            try:
                self._stream.gather()
                self._mcap.flush()  # type: ignore[no-untyped-call]  # the step's chunk
                self._stream.commit()
            except OSError as err:
                self._finish_after_write_error(start, err)
                return False
            self._chunks += 1
        if self._step_last >= 0:
            self._file.start_ns = (min(self._file.start_ns, self._step_first) if self._file.count
                                   else self._step_first)
            self._file.end_ns = max(self._file.end_ns, self._step_last)
            self._times = (min(self._times[0], self._step_first),
                           max(self._times[1], self._step_last))
        for name, entry in self._topics.items():
            entry.count += self._pending[name]
            self._file.count += self._pending[name]
            self._pending[name] = 0
        self._step_bytes = 0
        self._step_first, self._step_last = 2**63 - 1, -1
        self.steps += 1
        if self._chunks >= self._max_chunks:
            return self._next_file()
        if self._reserved < RESERVE_BASE_BYTES + RESERVE_PER_CHUNK_BYTES * self._chunks:
            try:   # the reserve no longer pays for the summary: room for 64 more chunks
                self._grow_reserve()
            except OSError as err:
                self._finish_after_write_error(self._stream.tell(), err)
                return False
        return True

    def finish(self) -> None:
        """Write the pending step, the MCAP summary and metadata.yaml; remove the reserve.

        Raises:
            BagWriteError: the summary or metadata.yaml cannot be written (the bag is left
                for ``trust-av repair-bag``).
        """
        if self.finished:
            return
        if self._step_bytes and not self.end_step():
            return  # the disk filled up: end_step finished the bag
        self._close()

    def __enter__(self) -> BagWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.finish()

    def _next_file(self) -> bool:
        """Finish the current MCAP file and go on in the next, ``<bag>_<n>.mcap``: the same
        header, schemas and channels (same ids), in the same order; its reserve grown.

        Returns:
            True; False if the next file cannot be started (a full disk): it is removed,
            and the bag is finished with the files before it (see :attr:`disk_full`).

        Raises:
            BagWriteError: the current file or ``metadata.yaml`` cannot be finished (the bag
                is left for ``trust-av repair-bag``).
        """
        try:
            self._finish_file()
        except BagWriteError:
            self.finished = True
            raise
        following = FileInfo(f'{self.path.name}_{len(self._info.files)}.mcap')
        stream: WholeWrites | None = None
        try:
            stream = WholeWrites(self.path / following.path)
            writer = new_writer(stream, self._library)
            for schema in self._schema_records:
                writer.register_schema(*schema)
            for channel in self._channel_records:
                writer.register_channel(*channel)
            self._stream, self._mcap, self._file, self._chunks = stream, writer, following, 0
            self._info.files.append(following)
            self._grow_reserve()
        except OSError as err:
            if self._info.files[-1] is following:
                self._info.files.pop()
            if stream is not None:
                stream.close()
            (self.path / following.path).unlink(missing_ok=True)
            self._reserve.unlink(missing_ok=True)
            reason = os.strerror(err.errno) if err.errno else str(err)
            self.disk_full = (f'{self.path}: cannot start its next file {following.path} '
                              f'({reason}) after {self.steps} complete steps; the bag holds '
                              'them and is finished')
            self.finished = True
            try:
                self._info.write(self.path)
            except OSError as error:
                raise BagWriteError(f'{self.path}: cannot finish the bag ({error.strerror})'
                                    ) from error
            return False
        return True

    def _needed_reserve(self) -> int:
        """The reserve's size when grown: the summary of the chunks so far and of
        :data:`RESERVE_STEP_CHUNKS` more, and metadata.yaml (bytes)."""
        return RESERVE_BASE_BYTES + RESERVE_PER_CHUNK_BYTES * (self._chunks + RESERVE_STEP_CHUNKS)

    def _grow_reserve(self) -> None:
        size = self._needed_reserve()
        fd = os.open(self._reserve, os.O_WRONLY | os.O_CREAT | os.O_CLOEXEC | os.O_NOFOLLOW,
                     0o600)
        try:
            os.posix_fallocate(fd, 0, size)
        finally:
            os.close(fd)
        self._reserved = size

    def _finish_after_write_error(self, end: int, err: OSError, what: str = '') -> None:
        """Cut the file back to ``end`` (the end of the complete steps), finish on the
        reserve with the complete steps; say why in :attr:`disk_full` (``disk full`` for
        ENOSPC and EDQUOT, else the error or ``what``).

        Raises:
            BagWriteError: the complete steps cannot be finished as a bag (it is left for
                ``trust-av repair-bag``).
        """
        reason = os.strerror(err.errno) if err.errno else str(err)
        if err.errno in (errno.ENOSPC, errno.EDQUOT):
            what = f'disk full ({reason})'
        self.disk_full = (f'{self.path}: {what or f"cannot write ({reason})"} after '
                          f'{self.steps} complete steps; the bag holds them and is finished')
        self.finished = True
        for name in self._topics:
            self._pending[name] = 0
        self._step_bytes = 0
        try:
            self._stream.truncate(end)
            self._mcap = self._rebuilt_writer(end)
        except (OSError, ValueError) as error:
            self._reserve.unlink(missing_ok=True)
            self._stream.close()
            raise BagWriteError(f'{self.path}: cannot finish the bag after {what or reason} '
                                f'({error}); trust-av repair-bag keeps its complete '
                                'steps') from error
        self._close()

    def _rebuilt_writer(self, end: int) -> McapWriter:
        """An MCAP writer holding the complete steps only (the failed step's messages are
        in the old one): rebuilt from the file, given the schemas and channels that are
        not in the file (registered since its last chunk), writing on from ``end``.

        Raises:
            ValueError: the file does not rebuild to ``end`` bytes.
            OSError: the file cannot be read.
        """
        rebuilt = replay(self._mcap_path, end, self._library)
        for schema in self._schema_records[rebuilt.schemas:]:
            rebuilt.writer.register_schema(*schema)
        for channel in self._channel_records[rebuilt.channels:]:
            rebuilt.writer.register_channel(*channel)
        rebuilt.stream.sink = self._stream
        return rebuilt.writer

    def _close(self) -> None:
        """Finish the current MCAP file and write metadata.yaml with the complete steps'
        counts.

        Raises:
            BagWriteError: it cannot be written.
        """
        self.finished = True
        if self._chunks == 0 and len(self._info.files) > 1:
            self._drop_empty_file()   # begun at the last split, nothing written to it since
        else:
            self._finish_file()
        try:
            self._info.write(self.path)
        except OSError as err:
            raise BagWriteError(f'{self.path}: cannot finish the bag ({err.strerror})') from err

    def _drop_empty_file(self) -> None:
        """Remove the current MCAP file, which holds no chunk (only its header)."""
        self._reserve.unlink(missing_ok=True)
        self._stream.close()
        (self.path / self._info.files.pop().path).unlink()

    def _finish_file(self) -> None:
        """Finish the current MCAP file (the ``rosbag2`` metadata record: the bag as it is
        so far; summary, footer) on the room of the reserve, fsync and close it.

        Raises:
            BagWriteError: it cannot be written.
        """
        self._reserve.unlink(missing_ok=True)
        if self._times[1] >= self._times[0]:
            self._info.start_ns, self._info.end_ns = self._times
        try:
            try:
                self._mcap.add_metadata('rosbag2',
                                        {'serialized_metadata': self._info.serialized()})
                self._mcap.finish()  # type: ignore[no-untyped-call]
                self._stream.sync()
            finally:
                self._stream.close()
        except OSError as err:
            raise BagWriteError(f'{self.path}: cannot finish the bag ({err.strerror})') from err
