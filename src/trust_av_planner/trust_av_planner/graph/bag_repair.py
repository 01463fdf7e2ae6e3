"""Repair of a recording whose writer did not finish (a killed recorder, a machine crash):
every message of every complete MCAP chunk is kept (the graph writes one chunk per step,
:mod:`~trust_av_planner.graph.bag_writer`), rewritten into a complete rosbag2 directory that
replaces the recording only once it is whole."""

from __future__ import annotations

import shutil
import struct
from pathlib import Path

from mcap.exceptions import McapError
from mcap.records import Channel, Message, Schema
from mcap.stream_reader import StreamReader
from rosbags.interfaces import Qos
from rosbags.rosbag2.metadata import parse_qos

from trust_av_planner.graph.bag_writer import BagWriteError, BagWriter, qos_profile
from trust_monitor.common.output_files import stop_signals_held


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
    return files[0]


def _complete_records(path: Path) -> tuple[dict[int, Schema], dict[int, Channel],
                                           list[Message], str]:
    schemas: dict[int, Schema] = {}
    channels: dict[int, Channel] = {}
    messages: list[Message] = []
    problem = ''
    try:
        with path.open('rb') as handle:
            for record in StreamReader(handle, skip_magic=False).records:
                if isinstance(record, Schema):
                    schemas[record.id] = record
                elif isinstance(record, Channel):
                    channels[record.id] = record
                elif isinstance(record, Message):
                    messages.append(record)
    except (McapError, struct.error, EOFError, ValueError) as err:
        problem = str(err) or type(err).__name__
    return schemas, channels, messages, problem


def _offered_qos(channel: Channel) -> list[Qos]:
    text = channel.metadata.get('offered_qos_profiles', '')
    return parse_qos(text) if text else []


def repair_bag(path: Path) -> int:
    """Rewrite a recording left unfinished (a killed recorder, a machine crash) into a
    complete bag directory, in place: every message of every complete chunk is kept.

    Works on a bag directory (with or without ``metadata.yaml``) or a lone ``.mcap`` file
    (which becomes a bag directory of the same stem beside it).

    Returns:
        The number of messages kept.

    Raises:
        BagWriteError: nothing at ``path``, no readable MCAP records, the bag directory of
            a lone ``.mcap`` exists already, an earlier repair was killed before it finished
            (its recording is named), or the new bag cannot be written or put in place (the
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
    schemas, channels, messages, problem = _complete_records(source)
    if not channels:
        raise BagWriteError(f'{source}: no readable MCAP channels ({problem or "empty"})')
    if target != path and target.exists():
        raise BagWriteError(f'{target} exists already and the repaired bag of {path} would '
                            'replace it; move it away first')
    shutil.rmtree(workspace, ignore_errors=True)
    workspace.mkdir()
    staging = workspace / target.name
    kept = 0
    try:
        writer = BagWriter(staging)
        by_id: dict[int, str] = {}
        for cid, channel in sorted(channels.items()):
            schema = schemas.get(channel.schema_id)
            if schema is None or channel.topic in by_id.values():
                continue
            qos = _offered_qos(channel)
            writer.add_topic(channel.topic, schema.name,
                             qos or qos_profile(reliable=True, transient_local=False, depth=10))
            by_id[cid] = channel.topic
        step_time = None
        for message in sorted(messages, key=lambda m: m.log_time):
            topic = by_id.get(message.channel_id)
            if topic is None:
                continue
            if step_time is not None and message.log_time != step_time:
                writer.end_step()
            writer.write(topic, message.data)
            step_time = message.log_time
            kept += 1
        writer.finish()
        if writer.disk_full:
            raise BagWriteError(f'{target}: no room to repair the bag')
        _swap_into_place(path, staging, target, workspace / 'old')
    finally:
        if not (workspace / 'old').exists():   # never delete the only copy of a recording
            shutil.rmtree(workspace, ignore_errors=True)
    return kept


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
