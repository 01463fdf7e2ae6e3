"""Repair of a recording whose writer did not finish (a killed recorder, a machine crash):
every message of every complete MCAP chunk is kept (the graph writes one chunk per step,
:mod:`~trust_av.graph.bag_writer`), rewritten into a complete rosbag2 directory that
replaces the recording only once it is whole. A recording split into several MCAP files
(rosbag2's split; the graph's after ``MAX_CHUNKS_PER_FILE`` steps) is read file after file,
in ``metadata.yaml``'s order or, without it, by the files' numbers (``<bag>.mcap``, then
``<bag>_1.mcap``, ...; rosbag2's ``<bag>_0.mcap``, ``<bag>_1.mcap``, ...).

A complete recording is never rewritten. Complete is MCAP's own rule (the specification,
https://mcap.dev/spec: a file is the magic, the header, the data section, the optional summary
and summary-offset sections, the footer and the magic again): the ``mcap`` library's
``StreamReader`` with CRC validation reads it from the leading magic through every record to
the footer and the closing magic (:func:`complete_mcap`). Of a file it repairs nothing is
dropped: the attachments and metadata records are copied with the ``mcap`` library's writer,
channels without messages become topics without messages and schemas no channel uses are
registered again; the ``rosbag2`` metadata record, which describes the bag, is written anew
for the repaired one. The copy replaces the recording only once it reads back with the
``mcap`` reader (through its summary) and with rosbags, every message the same bytes on its
topic at its log time, with every attachment and metadata record."""

from __future__ import annotations

import os
import re
import shutil
import struct
from dataclasses import dataclass, field, replace
from pathlib import Path

import yaml
from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap.records import Attachment, Channel, Footer, Header, Message, Metadata, Schema
from mcap.stream_reader import StreamReader
from rosbags.interfaces import Qos
from rosbags.rosbag2 import Reader as Rosbag2Reader
from rosbags.rosbag2.errors import ReaderError
from rosbags.rosbag2.metadata import parse_qos

from trust_av.graph.bag_writer import TYPESTORE, BagWriteError, BagWriter, qos_profile
from trust_av.graph.mcap_steps import RECORDER_LIBRARY
from trust_av_common.errors import one_line
from trust_av_common.output_files import stop_signals_held

__all__ = ['complete_mcap', 'finished', 'mcap_files', 'repair', 'repair_bag', 'written_here']

FOREIGN_CHUNK_MESSAGES = 1000
"""Messages per chunk in the repaired copy of another tool's bag (it has no steps)."""


def mcap_files(path: Path) -> list[Path]:
    """The MCAP files of a bag directory in the order they were written (or ``path`` itself
    if it is a file): ``metadata.yaml``'s ``relative_file_paths`` if it lists exactly the
    files there, else by their numbers after the directory's name (none first).

    Raises:
        BagWriteError: no bag at ``path``, or files whose order cannot be told.
    """
    if path.is_file():
        return [path]
    files = sorted(path.glob('*.mcap')) if path.is_dir() else []
    if not files:
        raise BagWriteError(f'{path}: not a bag directory with an MCAP file (0 found)')
    for file in files:
        if not file.is_file():          # a FIFO would block the read
            raise BagWriteError(f'{file}: not a regular file')
    listed = _listed_files(path)
    if sorted(listed) == [file.name for file in files]:
        return [path / name for name in listed]
    numbered = re.compile(re.escape(path.name) + r'(?:_(\d+))?\.mcap')
    numbers = [numbered.fullmatch(file.name) for file in files]
    if len(files) > 1 and not all(numbers):
        raise BagWriteError(f'{path}: cannot tell the order of its {len(files)} MCAP files '
                            f'(not all named {path.name}_<n>.mcap, and metadata.yaml does not '
                            'list them); nothing was changed')

    def number(file: Path) -> int:
        match = numbered.fullmatch(file.name)
        return int(match[1]) if match and match[1] else -1

    return sorted(files, key=number)


def _listed_files(bag: Path) -> list[str]:
    """The ``relative_file_paths`` of the bag's ``metadata.yaml`` ([] if none can be read)."""
    metadata = bag / 'metadata.yaml'
    try:
        document = yaml.safe_load(metadata.read_text(errors='replace'))
    except (OSError, yaml.YAMLError):
        return []
    info = document.get('rosbag2_bagfile_information') if isinstance(document, dict) else None
    names = info.get('relative_file_paths') if isinstance(info, dict) else None
    return ([name for name in names if isinstance(name, str)]
            if isinstance(names, list) else [])


@dataclass
class _Records:
    """What a linear read of an MCAP file found before its first unreadable byte."""

    schemas: dict[int, Schema] = field(default_factory=dict)
    channels: dict[int, Channel] = field(default_factory=dict)
    messages: list[Message] = field(default_factory=list)
    attachments: list[Attachment] = field(default_factory=list)
    metadata: list[Metadata] = field(default_factory=list)
    library: str = ''
    complete: bool = False     # read to its footer without a problem
    problem: str = ''


def _complete_records(path: Path) -> _Records:
    found = _Records()
    try:
        with path.open('rb') as handle:
            # no record is longer than the file: a damaged length is an error, not an
            # allocation of up to 4 GiB
            size = max(os.fstat(handle.fileno()).st_size, 1)
            for record in StreamReader(handle, skip_magic=False,
                                       record_size_limit=size).records:
                if isinstance(record, Schema):
                    found.schemas[record.id] = record
                elif isinstance(record, Channel):
                    found.channels[record.id] = record
                elif isinstance(record, Message):
                    found.messages.append(record)
                elif isinstance(record, Attachment):
                    found.attachments.append(record)
                elif isinstance(record, Metadata):
                    found.metadata.append(record)
                elif isinstance(record, Header):
                    found.library = record.library
                elif isinstance(record, Footer):
                    found.complete = True
    except (McapError, struct.error, EOFError, ValueError, OSError, MemoryError) as err:
        # MemoryError: a damaged chunk whose stated uncompressed size cannot be allocated
        found.problem = str(err) or type(err).__name__
        found.complete = False
    return found


def _merged(parts: list[_Records]) -> _Records:
    """The records of a recording's files as one: schemas and channels by their content (each
    file registers them again; another tool's ids may differ from file to file), numbered in
    the order first seen, the messages pointed at them, everything in file order."""
    if len(parts) == 1:
        return parts[0]
    merged = _Records(library=parts[0].library, complete=all(part.complete for part in parts),
                      problem=next((part.problem for part in parts if part.problem), ''))
    schema_ids: dict[tuple[str, str, bytes], int] = {}
    channel_ids: dict[tuple[str, str, int, tuple[tuple[str, str], ...]], int] = {}
    for part in parts:
        schemas: dict[int, int] = {}
        for sid, schema in part.schemas.items():
            key = (schema.name, schema.encoding, bytes(schema.data))
            if key not in schema_ids:
                schema_ids[key] = len(merged.schemas) + 1
                merged.schemas[schema_ids[key]] = replace(schema, id=schema_ids[key])
            schemas[sid] = schema_ids[key]
        channels: dict[int, int] = {}
        for cid, channel in part.channels.items():
            schema_id = schemas.get(channel.schema_id, 0)   # 0: none (or one not in the file)
            ckey = (channel.topic, channel.message_encoding, schema_id,
                    tuple(sorted(channel.metadata.items())))
            if ckey not in channel_ids:
                channel_ids[ckey] = len(merged.channels) + 1
                merged.channels[channel_ids[ckey]] = replace(channel, id=channel_ids[ckey],
                                                             schema_id=schema_id)
            channels[cid] = channel_ids[ckey]
        # a message on a channel its file does not have stays on none (it cannot be kept)
        merged.messages.extend(replace(message, channel_id=channels.get(message.channel_id, 0))
                               for message in part.messages)
        merged.attachments.extend(part.attachments)
        merged.metadata.extend(part.metadata)
    return merged


def complete_mcap(path: Path) -> bool:
    """Whether the MCAP file is complete by MCAP's rules: the ``mcap`` library's
    ``StreamReader``, validating every CRC that is set (chunks, the data section), reads it
    from the leading magic through every record to the footer and the closing magic."""
    try:
        with path.open('rb') as handle:
            size = max(os.fstat(handle.fileno()).st_size, 1)
            return any(isinstance(record, Footer) for record in StreamReader(
                handle, skip_magic=False, validate_crcs=True, record_size_limit=size).records)
    except (McapError, struct.error, EOFError, ValueError, OSError, MemoryError):
        return False


def finished(path: Path) -> bool:
    """Whether the bag directory at ``path`` is finished as its writer finishes one: a
    ``metadata.yaml`` that lists exactly its MCAP files, each complete
    (:func:`complete_mcap`). A recorder stopped after it finished its bag (a stop signal
    racing the end of its exit) leaves one: there is nothing to repair. A bag cut at a
    split is not finished: the file begun after the split has no footer."""
    if not path.is_dir() or not (path / 'metadata.yaml').is_file():
        return False
    try:
        files = mcap_files(path)
    except BagWriteError:
        return False
    return (sorted(_listed_files(path)) == sorted(file.name for file in files)
            and all(complete_mcap(file) for file in files))


@dataclass(frozen=True)
class Repaired:
    """What a repair kept (every one of it is in the repaired bag)."""

    messages: int
    topics: int
    quiet_channels: int
    """channels without messages, kept as topics without messages"""
    unused_schemas: int
    attachments: int
    metadata: int

    def __str__(self) -> str:
        parts = [f'{self.messages} messages kept on {self.topics} '
                 f'topic{"s" if self.topics != 1 else ""}']
        for count, one, many in (
                (self.quiet_channels, 'topic without messages', 'topics without messages'),
                (self.unused_schemas, 'schema no channel uses', 'schemas no channel uses'),
                (self.attachments, 'attachment', 'attachments'),
                (self.metadata, 'metadata record', 'metadata records')):
            if count:
                parts.append(f'{count} {one if count == 1 else many}')
        return ', '.join(parts)


def _offered_qos(source: Path, channel: Channel) -> list[Qos]:
    """The QoS profiles a channel's publishers offered (rosbag2's YAML in its metadata).

    Raises:
        BagWriteError: the YAML is damaged (nothing is changed: the repair refuses rather
            than invent a profile).
    """
    text = channel.metadata.get('offered_qos_profiles', '')
    try:
        profiles = parse_qos(text) if text else []
        for profile in profiles:     # a policy rmw has no name for (rosbag2 would refuse it)
            for policy in ('history', 'reliability', 'durability', 'liveliness'):
                if getattr(profile, policy).name == 'UNKNOWN':
                    raise ValueError(f'{policy} is not a policy rmw knows')
    except (ReaderError, LookupError, TypeError, ValueError, AttributeError) as err:
        raise BagWriteError(f'{source}: cannot repair topic {channel.topic!r} (its '
                            f'offered_qos_profiles cannot be read: {one_line(err)}); nothing '
                            'was changed') from err
    return profiles


def written_here(bag: Path, library: str) -> bool:
    """Whether this project's recorder wrote the recording: its MCAP header names
    :data:`~trust_av.graph.mcap_steps.RECORDER_LIBRARY`, or its ``metadata.yaml``
    carries the ``trust_av.recorder`` custom data the writer sets. Its log times are then
    the messages' header stamps; another tool's are kept as they are."""
    if library.startswith(RECORDER_LIBRARY):
        return True
    metadata = bag / 'metadata.yaml' if bag.is_dir() else None
    if metadata is None or not metadata.is_file():
        return False
    try:
        document = yaml.safe_load(metadata.read_text(errors='replace'))
    except yaml.YAMLError:
        return False
    info = document.get('rosbag2_bagfile_information') if isinstance(document, dict) else None
    custom = info.get('custom_data') if isinstance(info, dict) else None
    return isinstance(custom, dict) and 'trust_av.recorder' in custom


def _topics(source: Path, found: _Records) -> dict[int, tuple[str, str, list[Qos]]]:
    """Channel id -> (topic, type, offered QoS) for every channel, with messages or not.

    Raises:
        BagWriteError: a channel cannot be written again (no schema, not CDR, a type outside
            ROS 2 Jazzy's, a topic on two channels): nothing would be kept of it.
    """
    topics: dict[int, tuple[str, str, list[Qos]]] = {}
    for cid, channel in sorted(found.channels.items()):
        schema = found.schemas.get(channel.schema_id)
        why = ('it has no schema' if schema is None
               else f'its encoding is {channel.message_encoding!r}, not cdr'
               if channel.message_encoding != 'cdr'
               else f'its type {schema.name} is not a ROS 2 Jazzy type'
               if schema.name not in TYPESTORE.types
               else 'the topic is on two channels'
               if any(t[0] == channel.topic for t in topics.values()) else '')
        if why:
            raise BagWriteError(f'{source}: cannot repair topic {channel.topic!r} ({why}); '
                                'nothing was changed')
        assert schema is not None
        topics[cid] = (channel.topic, schema.name, _offered_qos(source, channel))
    return topics


def _verify(staging: Path, expected: list[tuple[str, int, bytes]], source: _Records) -> None:
    """The repaired bag reads back whole: linearly, through its summary with the ``mcap``
    reader and with rosbags, every kept message the same bytes on its topic at its log
    time; every attachment and metadata record of ``source`` (but its ``rosbag2`` record)
    and every topic there.

    Raises:
        BagWriteError: it does not (the recording is then kept as it was).
    """
    files = mcap_files(staging)
    parts = [_complete_records(file) for file in files]
    want = sorted(expected)
    readers: dict[str, list[tuple[str, int, bytes]]] = {'a linear read': sorted(
        (part.channels[m.channel_id].topic if m.channel_id in part.channels else '',
         m.log_time, bytes(m.data)) for part in parts for m in part.messages)}
    problem = next((f'{file.name}: {part.problem or "incomplete"}'
                    for file, part in zip(files, parts, strict=True) if not part.complete), '')
    readers['the mcap reader'] = []
    summary_attachments: list[tuple[str, str, int, bytes]] = []
    summary_metadata: list[tuple[str, list[tuple[str, str]]]] = []
    try:
        for file in files:
            with file.open('rb') as handle:
                reader = make_reader(handle)
                readers['the mcap reader'].extend(
                    (channel.topic, message.log_time, bytes(message.data))
                    for _, channel, message in reader.iter_messages(log_time_order=False))
                summary_attachments.extend((a.name, a.media_type, a.log_time, bytes(a.data))
                                           for a in reader.iter_attachments())
                summary_metadata.extend((m.name, sorted(m.metadata.items()))
                                        for m in reader.iter_metadata() if m.name != 'rosbag2')
        readers['the mcap reader'].sort()
        summary_attachments.sort()
        summary_metadata.sort()
        with Rosbag2Reader(staging) as bag:
            readers['rosbags'] = sorted((connection.topic, time, bytes(data))
                                        for connection, time, data in bag.messages())
            topics = {connection.topic for connection in bag.connections}
    except (McapError, ReaderError, struct.error, EOFError, ValueError, OSError) as err:
        problem = problem or one_line(err)
        summary_attachments, summary_metadata, topics = [], [], set()
    wrong = [name for name, got in readers.items() if got != want]
    if not problem and wrong:
        problem = f'{wrong[0]} finds {len(readers[wrong[0]])} of {len(want)} messages'
    if not problem and summary_attachments != sorted(
            (a.name, a.media_type, a.log_time, bytes(a.data)) for a in source.attachments):
        problem = 'its attachments differ'
    if not problem and summary_metadata != sorted(
            (m.name, sorted(m.metadata.items())) for m in source.metadata
            if m.name != 'rosbag2'):
        problem = 'its metadata records differ'
    if not problem and topics != {c.topic for c in source.channels.values()}:
        problem = 'its topics differ'
    if problem:
        raise BagWriteError(f'{staging}: the repaired bag does not read back whole '
                            f'({problem}); nothing was changed')


def repair_bag(path: Path) -> int:
    """:func:`repair`; returns the number of messages kept."""
    return repair(path).messages


def _write_copy(staging: Path, target: Path, found: _Records,
                topics: dict[int, tuple[str, str, list[Qos]]], kept_messages: list[Message],
                unused_schemas: list[Schema], ours: bool) -> list[tuple[str, int, bytes]]:
    """Write the repaired bag at ``staging``: every topic, unused schema, attachment and
    metadata record, and the kept messages (a recording of ours re-cut into one chunk per
    step, another tool's keeping its log times); what was written, (topic, log time, data)
    per message, for :func:`_verify`.

    Raises:
        BagWriteError: no room on the disk for it (the recording is not changed).
    """
    expected: list[tuple[str, int, bytes]] = []
    writer = BagWriter(staging, copy_of=None if ours else found.library)
    for topic, msgtype, qos in topics.values():
        # every publisher's offered profile, as recorded (rosbag2 writes one per publisher)
        writer.add_topic(topic, msgtype,
                         qos or qos_profile(reliable=True, transient_local=False, depth=10))
    for schema in unused_schemas:
        writer.add_schema(schema.name, schema.encoding, schema.data)
    for attachment in found.attachments:
        writer.add_attachment(attachment.name, attachment.media_type, attachment.data,
                              log_time_ns=attachment.log_time,
                              create_time_ns=attachment.create_time)
    for record in found.metadata:
        if record.name != 'rosbag2':     # the bag's own: written anew for the copy
            writer.add_metadata(record.name, dict(record.metadata))
    step_time = None
    in_chunk = 0
    for message in sorted(kept_messages, key=lambda m: m.log_time):
        topic = topics[message.channel_id][0]
        if ours and step_time is not None and message.log_time != step_time:
            writer.end_step()
        elif not ours and in_chunk >= FOREIGN_CHUNK_MESSAGES:
            writer.end_step()
            in_chunk = 0
        log_time = writer.write(topic, message.data,
                                None if ours else message.log_time)
        expected.append((topic, log_time, bytes(message.data)))
        step_time = message.log_time
        in_chunk += 1
    writer.finish()
    if writer.disk_full:
        raise BagWriteError(f'{target}: no room to repair the bag ({writer.disk_full}); '
                            'nothing was changed')
    return expected


def repair(path: Path) -> Repaired:
    """Rewrite a recording left unfinished (a killed recorder, a machine crash) into a
    complete bag directory, in place: every message of every complete chunk is kept.

    Works on a bag directory (with or without ``metadata.yaml``) or a lone ``.mcap`` file
    (which becomes a bag directory of the same stem beside it). A recording this project
    wrote (:func:`written_here`) is re-cut into one chunk per step, its log times being the
    header stamps; another tool's keeps its log times (publish time = log time in the
    repaired bag). Attachments, metadata records, channels without messages and schemas
    no channel uses are kept. The recording is replaced only once the repaired bag is
    complete and read back whole (:func:`_verify`).

    Returns:
        What was kept (at least one message).

    Raises:
        BagWriteError: nothing at ``path``; no readable MCAP channels or no complete
            message (nothing is changed); a complete MCAP file (:func:`complete_mcap`:
            never rewritten, whoever wrote it); a topic that cannot be written again; the
            bag directory of a lone ``.mcap`` exists already; an earlier repair was killed
            before it finished (its recording is named); or the new bag cannot be written,
            read back or put in place (the recording is then kept).
    """
    path = Path(path)
    lone = path.suffix == '.mcap' and not path.is_dir()
    target = path.with_suffix('') if lone else path
    workspace = target.with_name(f'.{target.name}.repairing')
    if (workspace / 'old').exists():
        raise BagWriteError(f'{workspace / "old"}: the recording of an earlier repair that '
                            f'did not finish; move it back to {path} (or away) first')
    sources = mcap_files(path)
    for link in (path, *sources):
        if link.is_symlink():           # the swap would move the link, not the recording
            raise BagWriteError(f'{link}: a symbolic link; repair-bag rewrites a recording in '
                                'place, never through a link: give the real path')
    source = sources[0] if len(sources) == 1 else path
    found = _merged([_complete_records(file) for file in sources])
    if not found.channels:
        raise BagWriteError(f'{source}: no readable MCAP channels '
                            f'({found.problem or "empty"})')
    ours = written_here(path, found.library)
    if found.complete and all(complete_mcap(file) for file in sources):
        hint = ('' if lone or (path / 'metadata.yaml').is_file() else
                "; its bag directory lacks metadata.yaml: 'ros2 bag reindex' writes one")
        raise BagWriteError(f'{path}: a complete bag written by '
                            f'{found.library or "another tool"} (MCAP footer, summary and '
                            'closing magic read, every CRC valid); nothing to repair, '
                            f'repair-bag never rewrites a complete recording{hint}')
    topics = _topics(source, found)
    kept_messages = [m for m in found.messages if m.channel_id in topics]
    if not kept_messages:
        raise BagWriteError(f'{source}: no complete message to keep '
                            f'({found.problem or "the recording has none"}); nothing was '
                            'changed')
    if target != path and target.exists():
        raise BagWriteError(f'{target} exists already and the repaired bag of {path} would '
                            'replace it; move it away first')
    shutil.rmtree(workspace, ignore_errors=True)
    workspace.mkdir()
    staging = workspace / target.name
    used_schemas = {channel.schema_id for channel in found.channels.values()}
    unused_schemas = [schema for sid, schema in sorted(found.schemas.items())
                      if sid not in used_schemas]
    try:
        expected = _write_copy(staging, target, found, topics, kept_messages,
                               unused_schemas, ours)
        _verify(staging, expected, found)
        _swap_into_place(path, staging, target, workspace / 'old')
    finally:
        if not (workspace / 'old').exists():   # never delete the only copy of a recording
            shutil.rmtree(workspace, ignore_errors=True)
    with_messages = {topics[m.channel_id][0] for m in kept_messages}
    return Repaired(len(expected), len(with_messages), len(topics) - len(with_messages),
                    len(unused_schemas), len(found.attachments),
                    sum(record.name != 'rosbag2' for record in found.metadata))


def _swap_into_place(path: Path, staging: Path, target: Path, old: Path) -> None:
    """The repaired bag replaces the recording (moved to ``old`` first, and deleted only
    once the new one is in place; back at ``path`` if that fails), with stop signals held
    between the two renames."""
    with stop_signals_held():
        if path.exists():
            path.rename(old)
        try:
            staging.rename(target)
        except OSError as err:
            if old.exists():
                old.rename(path)
            raise BagWriteError(f'{target}: cannot put the repaired bag there '
                                f'({err.strerror})') from err
    if old.is_dir():
        shutil.rmtree(old)
    elif old.exists():
        old.unlink()
