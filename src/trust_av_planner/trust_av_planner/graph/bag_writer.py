"""Crash-safe rosbag2 bag directories: the graph's recordings.

A recording is a rosbag2 bag directory (``metadata.yaml`` + one MCAP file) written by
rosbags' ``Writer`` (version 9, MCAP storage, typestore ``ROS2_JAZZY``): the metadata, the
MCAP's own ``rosbag2`` record, the channels' ``offered_qos_profiles`` and the type hashes
are rosbags' (the format owner's reader rules are checked by ``tests/rosbag2_rules.py``).
On top of it, :class:`BagWriter` adds what a recording that must survive any end needs:

- **a chunk per step**: :meth:`BagWriter.end_step` closes the MCAP chunk and writes it
  through to the file (unbuffered), so a killed process leaves every step up to the kill
  on disk; :func:`~trust_av_planner.graph.bag_repair.repair_bag` turns such a directory
  into a complete bag.
- **a full disk**: a reserve file inside the bag directory holds, at all times, room for
  the MCAP summary and ``metadata.yaml``; when a write fails with ``ENOSPC`` the partial
  step is cut off, the reserve is released, the bag is finished with every complete step,
  and :class:`DiskFullError` says so. The reserve never outlives the writer.

Messages are raw CDR as they came over DDS; log time = publish time = the header stamp
(sim time in lock-step, wall time in wall mode).
"""

from __future__ import annotations

import errno
import os
import resource
import shutil
import signal
import struct
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from rosbags.interfaces import (
    Qos,
    QosDurability,
    QosHistory,
    QosLiveliness,
    QosReliability,
    QosTime,
)
from rosbags.rosbag2 import StoragePlugin, Writer, WriterError
from rosbags.typesys import Stores, get_typestore

from trust_av_planner.errors import TrustAvPlannerError
from trust_av_planner.graph.mcap_steps import StepStorage, StepWriter

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
CHUNK_OVERHEAD_BYTES = 4096
"""Room a step's chunk record may need beyond twice its messages' bytes (record headers,
message indexes), for the file-size limit check."""
EXIT_DISK_FULL = 3
"""Exit code of a recorder that stopped because the disk was full (the bag is finished)."""
MAX_INFINITE = QosTime(2147483647, 4294967295)
"""rmw's "infinite" duration as rosbag2 writes it in offered_qos_profiles."""


class BagWriteError(TrustAvPlannerError):
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


@dataclass
class _Topic:
    connection: Any
    count: int = 0
    step_count: int = 0


class BagWriter:
    """A rosbag2 bag directory being recorded, one MCAP chunk per step (context manager).

    Args:
        path: the bag directory to create (it must not exist).
        copy_of: for a repaired copy of another tool's recording (its log times are not
            header stamps): that tool's MCAP ``library``; the copy is then not marked as
            this project's recording (:data:`~trust_av_planner.graph.mcap_steps.RECORDER_LIBRARY`,
            ``trust_av.recorder``).

    Raises:
        BagWriteError: the directory exists or cannot be created.
    """

    def __init__(self, path: Path, *, copy_of: str | None = None) -> None:
        self.path = Path(path)
        if threading.current_thread() is threading.main_thread():
            # past a file-size limit a write fails with EFBIG instead of killing the process
            signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        existed = os.path.lexists(self.path)
        storage: type[StepStorage] = StepStorage
        if copy_of is not None:
            storage = type('_CopyStorage', (StepStorage,),
                           {'library': f'trust_av.bag_repair of {copy_of or "unknown"}'})
        try:
            writer: type[StepWriter] = StepWriter
            if storage is not StepStorage:
                writer = type('_CopyWriter', (StepWriter,), {'STORAGE_PLUGINS': {
                    **Writer.STORAGE_PLUGINS, StoragePlugin.MCAP: storage}})
            self._writer = writer(self.path, version=9, storage_plugin=StoragePlugin.MCAP)
            if copy_of is None:
                self._writer.set_custom_data('trust_av.recorder', 'one MCAP chunk per step')
            else:
                self._writer.set_custom_data('trust_av.repaired_copy_of', copy_of or 'unknown')
            self._writer.open()
        except (WriterError, OSError) as err:
            if not existed:                 # what this call created: an empty .mcap at most
                shutil.rmtree(self.path, ignore_errors=True)
            if isinstance(err, OSError) and err.errno in (errno.ENOSPC, errno.EDQUOT):
                raise DiskFullError(f'{self.path}: no room to start a recording '
                                    f'({os.strerror(err.errno)})') from err
            raise BagWriteError(f'{self.path}: cannot create the bag directory ({err})') from err
        self._topics: dict[str, _Topic] = {}
        self._storage_write = self._storage.write
        self._offsets: dict[str, int] = {}
        self._reserve = self.path / RESERVE_NAME
        self._reserved = 0
        self._chunks = 0
        self._step_first, self._step_last = 2**63 - 1, -1
        self._times = (2**63 - 1, 0)
        self.finished = False
        self.disk_full: str = ''
        self.steps = 0
        try:
            self._grow_reserve()
        except OSError as err:
            self._writer.abort()
            shutil.rmtree(self.path, ignore_errors=True)
            raise DiskFullError(f'{self.path}: no room to start a recording '
                                f'({os.strerror(err.errno or errno.ENOSPC)})') from err

    @property
    def counts(self) -> dict[str, int]:
        """Messages per topic written so far (complete steps and the pending one)."""
        return {name: t.count + t.step_count for name, t in self._topics.items()}

    def count(self, topic: str) -> int:
        """Messages of ``topic`` written so far (complete steps and the pending one)."""
        entry = self._topics[topic]
        return entry.count + entry.step_count

    def set_custom_data(self, key: str, value: str) -> None:
        """Set one ``custom_data`` entry of ``metadata.yaml`` (written when finished)."""
        self._writer.set_custom_data(key, value)

    def add_topic(self, topic: str, msgtype: str, qos: Qos | list[Qos]) -> None:
        """Register a topic with its type and the QoS its publishers offer: one profile per
        publisher, as ``ros2 bag record`` writes them (a profile alone: one publisher)."""
        profiles = qos if isinstance(qos, list) else [qos]
        connection = self._writer.add_connection(topic, msgtype, typestore=TYPESTORE,
                                                 offered_qos_profiles=profiles)
        self._topics[topic] = _Topic(connection)
        self._offsets[topic] = 8 if msgtype in STAMP_IN_FIRST_ELEMENT else 4

    def write(self, topic: str, data: bytes | memoryview, log_time_ns: int | None = None) -> int:
        """Append one raw CDR message to the current step; returns its log time (ns).

        Args:
            topic: a topic added with :meth:`add_topic`.
            data: the message, CDR with its 4-byte encapsulation header.
            log_time_ns: its log time, ns (default: the stamp of its header, which the
                graph's messages carry first).

        Raises:
            BagWriteError: the bag is finished (after :meth:`finish`, or once
                :meth:`end_step` returned False for a full disk)."""
        if self.finished:
            raise BagWriteError(f'{self.path}: written to after the bag was finished'
                                + (f' ({self.disk_full})' if self.disk_full else ''))
        entry = self._topics[topic]
        stamp = (header_stamp_ns(data, self._offsets[topic]) if log_time_ns is None
                 else log_time_ns)
        self._storage_write(entry.connection, stamp, data)
        entry.step_count += 1
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
        if limit is not None and (self._storage.bio.tell() + 2 * self._storage.chunk.bio.tell()
                                  + CHUNK_OVERHEAD_BYTES + self._needed_reserve() > limit):
            # the step and the summary would not fit under the limit: end before it does
            self._drop_pending_step()
            self._finish_after_write_error(OSError(errno.EFBIG, os.strerror(errno.EFBIG)),
                                           f'file-size limit of {limit} bytes (RLIMIT_FSIZE)')
            return False
        try:
            self._storage.close_step_chunk()
        except OSError as err:
            self._drop_pending_step()
            self._finish_after_write_error(err)
            return False
        self._chunks += 1
        for entry in self._topics.values():
            entry.count += entry.step_count
            entry.step_count = 0
        if self._step_last >= 0:
            self._times = (min(self._times[0], self._step_first),
                           max(self._times[1], self._step_last))
        self._step_first, self._step_last = 2**63 - 1, -1
        self.steps += 1
        if self._reserved < self._needed_reserve():
            try:
                self._grow_reserve()
            except OSError as err:
                self._finish_after_write_error(err)
                return False
        return True

    def _drop_pending_step(self) -> None:
        for entry in self._topics.values():
            entry.step_count = 0
        self._step_first, self._step_last = 2**63 - 1, -1
        self._storage.discard_chunk()

    def finish(self) -> None:
        """Write the pending step, the MCAP summary and metadata.yaml; remove the reserve."""
        if self.finished:
            return
        if any(entry.step_count for entry in self._topics.values()) and not self.end_step():
            return  # the disk filled up: end_step finished the bag
        try:
            self._storage.close_step_chunk()   # topics added after the last message
        except OSError as err:
            if err.errno not in (errno.ENOSPC, errno.EDQUOT):
                raise
            self._storage.discard_chunk()
        self._close()

    def __enter__(self) -> BagWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.finish()

    @property
    def _storage(self) -> StepStorage:
        storage = self._writer.storage
        assert isinstance(storage, StepStorage)
        return storage

    def _needed_reserve(self) -> int:
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

    def _finish_after_write_error(self, err: OSError, what: str = '') -> None:
        """Finish on the reserve with the complete steps; say why in :attr:`disk_full`
        (``disk full`` for ENOSPC and EDQUOT, else the error or ``what``)."""
        reason = os.strerror(err.errno) if err.errno else str(err)
        if err.errno in (errno.ENOSPC, errno.EDQUOT):
            what = f'disk full ({reason})'
        self.disk_full = (f'{self.path}: {what or f"cannot write ({reason})"} after '
                          f'{self.steps} complete steps; the bag holds them and is finished')
        self._close()

    def _close(self) -> None:
        """Finish the MCAP and write metadata.yaml with the complete steps' counts."""
        self.finished = True
        self._reserve.unlink(missing_ok=True)
        writer = self._writer
        storage = self._storage
        for entry in self._topics.values():
            writer.counts[entry.connection.id] = entry.count
            storage.channel_stats[entry.connection.id] = entry.count
        if self.steps:
            writer.min_timestamp, writer.max_timestamp = self._times
            storage.message_start_time, storage.message_end_time = self._times
        else:
            writer.min_timestamp = writer.max_timestamp = 0
            storage.message_start_time = storage.message_end_time = 0
        try:
            writer.close()
        except OSError as err:
            raise BagWriteError(f'{self.path}: cannot finish the bag ({err.strerror})') from err
