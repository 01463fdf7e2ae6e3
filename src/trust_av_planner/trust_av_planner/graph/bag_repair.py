"""Repair of a recording whose writer did not finish (a killed recorder, a machine crash):
every message of every complete MCAP chunk is kept (the graph writes one chunk per step,
:mod:`~trust_av_planner.graph.bag_writer`), rewritten into a complete rosbag2 directory that
replaces the recording only once it is whole."""

from __future__ import annotations

import os
import shutil
import struct
from dataclasses import dataclass, field
from pathlib import Path

import yaml
from mcap.exceptions import McapError
from mcap.records import Channel, Footer, Header, Message, Schema
from mcap.stream_reader import StreamReader
from rosbags.interfaces import Qos
from rosbags.rosbag2.errors import ReaderError
from rosbags.rosbag2.metadata import parse_qos

from trust_av_planner.graph.bag_writer import TYPESTORE, BagWriteError, BagWriter, qos_profile
from trust_av_planner.graph.mcap_steps import RECORDER_LIBRARY
from trust_monitor.common.output_files import stop_signals_held
from trust_monitor.errors import one_line

FOREIGN_CHUNK_MESSAGES = 1000
"""Messages per chunk in the repaired copy of another tool's bag (it has no steps)."""


def mcap_file(path: Path) -> Path:
    """The MCAP file of a bag directory (or ``path`` itself if it is a file).

    Raises:
        BagWriteError: no bag at ``path``.
    """
    if path.is_file():
        return path
    files = sorted(path.glob('*.mcap')) if path.is_dir() else []
    if len(files) != 1:
        raise BagWriteError(f'{path}: not a bag directory with one MCAP file '
                            f'({len(files)} found)')
    if not files[0].is_file():          # a FIFO would block the read
        raise BagWriteError(f'{files[0]}: not a regular file')
    return files[0]


@dataclass
class _Records:
    """What a linear read of an MCAP file found before its first unreadable byte."""

    schemas: dict[int, Schema] = field(default_factory=dict)
    channels: dict[int, Channel] = field(default_factory=dict)
    messages: list[Message] = field(default_factory=list)
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
                elif isinstance(record, Header):
                    found.library = record.library
                elif isinstance(record, Footer):
                    found.complete = True
    except (McapError, struct.error, EOFError, ValueError, OSError, MemoryError) as err:
        # MemoryError: a damaged chunk whose stated uncompressed size cannot be allocated
        found.problem = str(err) or type(err).__name__
        found.complete = False
    return found


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
    :data:`~trust_av_planner.graph.mcap_steps.RECORDER_LIBRARY`, or its ``metadata.yaml``
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
    """Channel id -> (topic, type, offered QoS) for every channel that has messages.

    Raises:
        BagWriteError: a channel with messages cannot be written again (no schema, not CDR,
            a type outside ROS 2 Jazzy's, a topic on two channels): nothing would be kept of it.
    """
    used = {message.channel_id for message in found.messages}
    topics: dict[int, tuple[str, str, list[Qos]]] = {}
    for cid, channel in sorted(found.channels.items()):
        if cid not in used:
            continue
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


def _verify(staging: Path, expected: list[tuple[str, int]]) -> None:
    """The repaired bag holds every kept message, on its topic at its log time.

    Raises:
        BagWriteError: it does not (the recording is then kept as it was).
    """
    found = _complete_records(mcap_file(staging))
    names = {cid: channel.topic for cid, channel in found.channels.items()}
    got = sorted((names.get(m.channel_id, ''), m.log_time) for m in found.messages)
    if not found.complete or got != sorted(expected):
        raise BagWriteError(f'{staging}: the repaired bag does not read back whole '
                            f'({len(got)} of {len(expected)} messages'
                            f'{", " + found.problem if found.problem else ""}); nothing '
                            'was changed')


def repair_bag(path: Path) -> int:
    """Rewrite a recording left unfinished (a killed recorder, a machine crash) into a
    complete bag directory, in place: every message of every complete chunk is kept.

    Works on a bag directory (with or without ``metadata.yaml``) or a lone ``.mcap`` file
    (which becomes a bag directory of the same stem beside it). A recording this project
    wrote (:func:`written_here`) is re-cut into one chunk per step, its log times being the
    header stamps; another tool's keeps its log times (publish time = log time in the
    repaired bag). The recording is replaced only once the repaired bag is complete and
    read back whole.

    Returns:
        The number of messages kept (at least one).

    Raises:
        BagWriteError: nothing at ``path``; no readable MCAP channels or no complete
            message (nothing is changed); another tool's bag that is complete already; a
            topic that cannot be written again; the bag directory of a lone ``.mcap``
            exists already; an earlier repair was killed before it finished (its recording
            is named); or the new bag cannot be written, read back or put in place (the
            recording is then kept).
    """
    path = Path(path)
    lone = path.suffix == '.mcap' and not path.is_dir()
    target = path.with_suffix('') if lone else path
    workspace = target.with_name(f'.{target.name}.repairing')
    if (workspace / 'old').exists():
        raise BagWriteError(f'{workspace / "old"}: the recording of an earlier repair that '
                            f'did not finish; move it back to {path} (or away) first')
    source = mcap_file(path)
    found = _complete_records(source)
    if not found.channels:
        raise BagWriteError(f'{source}: no readable MCAP channels '
                            f'({found.problem or "empty"})')
    ours = written_here(path, found.library)
    if not ours and found.complete and (path / 'metadata.yaml').is_file():
        raise BagWriteError(f'{path}: a complete bag written by {found.library or "another tool"}'
                            '; nothing to repair')
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
    expected: list[tuple[str, int]] = []
    try:
        writer = BagWriter(staging, copy_of=None if ours else found.library)
        for topic, msgtype, qos in topics.values():
            # every publisher's offered profile, as recorded (rosbag2 writes one per publisher)
            writer.add_topic(topic, msgtype,
                             qos or qos_profile(reliable=True, transient_local=False, depth=10))
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
            expected.append((topic, log_time))
            step_time = message.log_time
            in_chunk += 1
        writer.finish()
        if writer.disk_full:
            raise BagWriteError(f'{target}: no room to repair the bag ({writer.disk_full}); '
                                'nothing was changed')
        _verify(staging, expected)
        _swap_into_place(path, staging, target, workspace / 'old')
    finally:
        if not (workspace / 'old').exists():   # never delete the only copy of a recording
            shutil.rmtree(workspace, ignore_errors=True)
    return len(expected)


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
