"""Test-side oracle: what rosbag2 Jazzy requires of a bag directory (metadata.yaml + MCAP).

:func:`check_bag_directory` returns every problem that would make rosbag2 Jazzy's reader
(``ros2 bag info`` / ``ros2 bag play``) refuse or misread a bag. Each rule names the source
it mirrors; line numbers are those of ``ros2/rosbag2`` branch ``jazzy`` at 64717ee (Oct 2024):

* ``Y`` = ``rosbag2_storage/include/rosbag2_storage/yaml.hpp`` (the YAML decoders),
* ``Q`` = ``rosbag2_storage/src/rosbag2_storage/qos.cpp`` (the QoS decoder),
* ``IO`` = ``rosbag2_storage/src/rosbag2_storage/metadata_io.cpp``,
* ``M`` = ``rosbag2_storage_mcap/src/mcap_storage.cpp`` (the MCAP storage plugin),
* ``R`` = ``rosbag2_cpp/src/rosbag2_cpp/readers/sequential_reader.cpp``,
* ``T`` = ``rosbag2_transport/src/rosbag2_transport/recorder.cpp`` (what the recorder writes).

The MCAP itself is read the way rosbag2's plugin reads it: through the mcap C++ library that
Jazzy's ``mcap_vendor/CMakeLists.txt`` pins (``foxglove/mcap`` tag ``releases/cpp/v1.3.0``),
always in log-time order: R sets its ``read_order_`` on the storage when it opens (L113),
whose default is ``ReadOrder{}`` (``rosbag2_cpp/readers/sequential_reader.hpp`` L215) =
``ReceivedTimestamp``, ascending (``rosbag2_storage/storage_interfaces/
base_read_interface.hpp`` L30-47); M ``set_read_order`` (L723-748) maps it to
``ReadMessageOptions::ReadOrder::LogTimeOrder`` and ``read_next`` (L634-667) reads with it.
``RI`` = ``cpp/mcap/include/mcap/reader.inl`` at that tag; see :func:`time_ordered_read`.

YAML values are decoded as yaml-cpp 0.8.0 (Jazzy's ``yaml_cpp_vendor`` on Ubuntu 24.04)
decodes them: ``as<std::string>()`` takes any scalar and turns a null into ``"null"``
(``node/impl.h as_if<std::string>``), integers are read by ``std::stringstream`` with the
base left open (``convert.h YAML_DEFINE_CONVERT_STREAMABLE``; unsigned refuses a leading
``-``), booleans are y/yes/true/on and n/no/false/off in lower, Upper or UPPER case
(``convert.cpp``), a plain ``~``/``null``/``Null``/``NULL``/empty scalar is a null node
(``singledocparser.cpp``), and a missing key throws ``InvalidNode``.
"""

from __future__ import annotations

import json
import re
import struct
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml
from mcap.exceptions import McapError
from mcap.reader import make_reader

_INT32 = (-(2**31), 2**31 - 1)
_UINT64 = (0, 2**64 - 1)
_NULL_WORDS = frozenset({'', '~', 'null', 'Null', 'NULL'})
_BOOL_WORDS = {'y': True, 'yes': True, 'true': True, 'on': True,
               'n': False, 'no': False, 'false': False, 'off': False}
# rmw 7.3 qos_string_conversions.c *_from_str (exact match) and types.h enum values.
HISTORY = {'system_default': 0, 'keep_last': 1, 'keep_all': 2}
RELIABILITY = {'system_default': 0, 'reliable': 1, 'best_effort': 2, 'best_available': 4}
DURABILITY = {'system_default': 0, 'transient_local': 1, 'volatile': 2, 'best_available': 4}
LIVELINESS = {'system_default': 0, 'automatic': 1, 'manual_by_topic': 3, 'best_available': 5}
_HISTORY_UNKNOWN = 3
# rosidl_runtime_c/src/type_hash.c rosidl_stringify_type_hash: "RIHS%02d_" + 64 x "%02x";
# T type_hash_to_string (L630-652) writes that for version 1, else "".
TYPE_HASH = re.compile(r'RIHS01_[0-9a-f]{64}')

REQUIRED_V9 = (
    'version', 'storage_identifier', 'duration.nanoseconds',
    'starting_time.nanoseconds_since_epoch', 'message_count', 'topics_with_message_count',
    'topics_with_message_count[].topic_metadata.name',
    'topics_with_message_count[].topic_metadata.type',
    'topics_with_message_count[].topic_metadata.serialization_format',
    'topics_with_message_count[].topic_metadata.offered_qos_profiles',
    'topics_with_message_count[].topic_metadata.type_description_hash',
    'topics_with_message_count[].message_count', 'relative_file_paths',
    'compression_format', 'compression_mode', 'files', 'files[].path',
    'files[].starting_time.nanoseconds_since_epoch', 'files[].duration.nanoseconds',
    'files[].message_count', 'custom_data', 'ros_distro',
)
"""Every field Y ``convert<BagMetadata>::decode`` reads for version 9 (L277-307, with
``TopicInformation`` L158-164, ``TopicMetadata`` L125-143, ``FileInformation`` L207-215,
``nanoseconds`` L228-232, ``time_point`` L245-251)."""


@dataclass
class YNode:
    """A YAML node as yaml-cpp sees it: ``null``, ``scalar``, ``seq`` or ``map``."""

    kind: str
    text: str = ''
    items: list[Any] = field(default_factory=list)
    line: int = 0


def compose(text: str) -> YNode:
    """The first document of ``text`` as yaml-cpp's ``YAML::Load`` builds it.

    Raises:
        yaml.YAMLError: not YAML.
    """
    anchors: dict[str, YNode] = {}
    stack: list[YNode] = []
    root: YNode | None = None
    pending_key: list[YNode | None] = []

    def attach(node: YNode) -> None:
        nonlocal root
        if not stack:
            root = node if root is None else root
            return
        parent = stack[-1]
        if parent.kind == 'seq':
            parent.items.append(node)
        elif pending_key[-1] is None:
            pending_key[-1] = node
        else:
            parent.items.append((pending_key[-1], node))
            pending_key[-1] = None

    for event in yaml.parse(text, Loader=getattr(yaml, 'CSafeLoader', yaml.SafeLoader)):
        line = event.start_mark.line + 1 if event.start_mark else 0
        if isinstance(event, yaml.DocumentEndEvent) and root is not None:
            break
        if isinstance(event, yaml.ScalarEvent):
            plain = event.style in (None, '')
            is_null = plain and event.tag is None and event.value in _NULL_WORDS
            node = YNode('null' if is_null else 'scalar', event.value, line=line)
            if event.anchor:
                anchors[event.anchor] = node
            attach(node)
        elif isinstance(event, yaml.AliasEvent):
            attach(anchors[event.anchor])
        elif isinstance(event, (yaml.SequenceStartEvent, yaml.MappingStartEvent)):
            node = YNode('seq' if isinstance(event, yaml.SequenceStartEvent) else 'map',
                         line=line)
            if event.anchor:
                anchors[event.anchor] = node
            attach(node)
            stack.append(node)
            pending_key.append(None)
        elif isinstance(event, (yaml.SequenceEndEvent, yaml.MappingEndEvent)):
            stack.pop()
            pending_key.pop()
    return root if root is not None else YNode('null')


class Decoder:
    """yaml-cpp conversions that record a problem instead of throwing."""

    def __init__(self, where: str) -> None:
        self.where = where
        self.problems: list[str] = []

    def fail(self, path: str, problem: str, cite: str) -> None:
        """Record one problem."""
        self.problems.append(f'{self.where}: {path}: {problem} ({cite})')

    def get(self, node: YNode | None, key: str, path: str, cite: str) -> YNode | None:
        """``node[key]`` on a const node; a missing key is a problem."""
        if node is None:
            return None
        full = f'{path}.{key}' if path else key
        if node.kind == 'map':
            for name, value in node.items:
                if name.kind == 'scalar' and name.text == key:
                    return value  # type: ignore[no-any-return]
        what = 'missing' if node.kind in ('map', 'null', 'seq') else 'parent is a scalar'
        self.fail(full, what, cite)
        return None

    def string(self, node: YNode | None, path: str, cite: str) -> str | None:
        """``as<std::string>()``: any scalar; a null reads as ``'null'``."""
        if node is None:
            return None
        if node.kind == 'null':
            return 'null'
        if node.kind != 'scalar':
            self.fail(path, f'expected a string, found a {node.kind}', cite)
            return None
        return node.text

    def integer(self, node: YNode | None, path: str, cite: str,
                bounds: tuple[int, int] = _UINT64) -> int | None:
        """``as<int>()`` / ``as<uint64_t>()`` via ``std::stringstream`` (base 0)."""
        if node is None:
            return None
        if node.kind != 'scalar':
            self.fail(path, f'expected an integer, found a {node.kind}', cite)
            return None
        text = node.text
        match = re.fullmatch(r'([+-]?)(0[xX][0-9a-fA-F]+|0[0-7]*|[1-9][0-9]*)\s*', text)
        if match is None or (bounds[0] >= 0 and text.startswith('-')):
            self.fail(path, 'expected an integer'
                      + (' >= 0' if bounds[0] >= 0 else ''), cite)
            return None
        digits = match.group(2)
        if digits[:2] in ('0x', '0X'):
            value = int(digits, 16)
        elif digits.startswith('0'):
            value = int(digits, 8)  # istream with the base left open: a leading 0 is octal
        else:
            value = int(digits, 10)
        value = -value if match.group(1) == '-' else value
        if not bounds[0] <= value <= bounds[1]:
            self.fail(path, f'integer out of range [{bounds[0]}, {bounds[1]}]', cite)
            return None
        return value

    def boolean(self, node: YNode | None, path: str, cite: str) -> bool | None:
        """``as<bool>()``: y/yes/true/on, n/no/false/off, in flexible case."""
        if node is None:
            return None
        text = node.text if node.kind == 'scalar' else None
        flexible = text is not None and (text == text.lower() or text == text.upper()
                                         or (text[:1].isupper() and text[1:] == text[1:].lower()))
        if text is None or not flexible or text.lower() not in _BOOL_WORDS:
            self.fail(path, 'expected true or false', cite)
            return None
        return _BOOL_WORDS[text.lower()]

    def sequence(self, node: YNode | None, path: str, cite: str) -> list[YNode] | None:
        """``IsSequence()`` (convert<std::vector>::decode)."""
        if node is None:
            return None
        if node.kind != 'seq':
            self.fail(path, f'expected a sequence, found a {node.kind}', cite)
            return None
        return node.items

    def nanoseconds(self, node: YNode | None, path: str, key: str, cite: str) -> int | None:
        """Y L228-232 / L245-251: ``{nanoseconds: uint64}`` or ``{nanoseconds_since_epoch}``."""
        return self.integer(self.get(node, key, path, cite), f'{path}.{key}', cite)


def decode_qos(dec: Decoder, node: YNode, path: str) -> dict[str, Any] | None:
    """Q ``convert<rclcpp::QoS>::decode`` (L167-213) for one profile.

    Returns:
        The profile as rmw enum values, or None if it does not decode.
    """
    cite = 'qos.cpp convert<rclcpp::QoS>::decode L167-213'
    before = len(dec.problems)
    history_node = dec.get(node, 'history', path, cite)
    history_int = None
    if history_node is not None and history_node.kind == 'scalar':
        probe = Decoder('')
        history_int = probe.integer(history_node, '', '', _INT32)
    profile: dict[str, Any] = {}
    if history_int is not None and 0 <= history_int <= _HISTORY_UNKNOWN:
        profile['history'] = history_int  # Q L176-181: numeric form of version <= 8
        for name in ('reliability', 'durability', 'liveliness'):
            profile[name] = dec.integer(dec.get(node, name, path, cite), f'{path}.{name}',
                                        cite, _INT32)
    else:
        text = dec.string(history_node, f'{path}.history', cite)
        profile['history'] = HISTORY.get(text, _HISTORY_UNKNOWN) if text is not None else None
        for name, table in (('reliability', RELIABILITY), ('durability', DURABILITY),
                            ('liveliness', LIVELINESS)):
            text = dec.string(dec.get(node, name, path, cite), f'{path}.{name}', cite)
            if text is not None and text not in table:
                dec.fail(f'{path}.{name}', 'not a policy name rmw knows (rmw '
                         'qos_string_conversions.c *_from_str gives UNKNOWN)', cite)
            profile[name] = table.get(text) if text is not None else None
    if profile['history'] == _HISTORY_UNKNOWN:
        dec.fail(f'{path}.history', 'not a history policy name rmw knows (UNKNOWN)', cite)
    if profile['history'] == HISTORY['keep_last']:  # Q L197-198: depth read for keep_last only
        profile['depth'] = dec.integer(dec.get(node, 'depth', path, cite), f'{path}.depth',
                                       cite, _INT32)
    for name in ('deadline', 'lifespan', 'liveliness_lease_duration'):
        time = dec.get(node, name, path, cite)  # Q L129-149 convert<rmw_time_t>::decode
        profile[name] = (dec.integer(dec.get(time, 'sec', f'{path}.{name}', cite),
                                     f'{path}.{name}.sec', cite),
                         dec.integer(dec.get(time, 'nsec', f'{path}.{name}', cite),
                                     f'{path}.{name}.nsec', cite))
    profile['avoid_ros_namespace_conventions'] = dec.boolean(
        dec.get(node, 'avoid_ros_namespace_conventions', path, cite),
        f'{path}.avoid_ros_namespace_conventions', cite)
    return profile if len(dec.problems) == before else None


def decode_qos_list(dec: Decoder, node: YNode | None, path: str) -> list[dict[str, Any]] | None:
    """Q ``convert<std::vector<rclcpp::QoS>>::decode`` (L260-275): a sequence of profiles."""
    items = dec.sequence(node, path, 'qos.cpp L260-275 (and yaml.hpp L130-132)')
    if items is None:
        return None
    profiles = [decode_qos(dec, item, f'{path}[{index}]') for index, item in enumerate(items)]
    return None if any(p is None for p in profiles) else profiles  # type: ignore[return-value]


def check_type_hash(dec: Decoder, value: str | None, msgtype: str | None, path: str) -> None:
    """The form T ``type_hash_to_string`` writes, and the Jazzy type's own hash if known."""
    if value is None or value == '':
        return
    if TYPE_HASH.fullmatch(value) is None:
        dec.fail(path, 'not the form rosbag2 writes (RIHS01_ and 64 lowercase hex digits, or '
                 'empty)', 'recorder.cpp type_hash_to_string L630-652; rosidl type_hash.c')
        return
    known = installed_type_hash(msgtype) if msgtype else None
    if known is not None and known != value:
        dec.fail(path, f'is not the RIHS01 hash of {msgtype} in this Jazzy install',
                 f'share/{msgtype}.json (rosidl type description)')


def installed_type_hash(msgtype: str) -> str | None:
    """The RIHS01 hash of a type from the installed Jazzy type description, if present."""
    parts = msgtype.split('/')
    if len(parts) != 3:
        return None
    description = Path(sys.prefix) / 'share' / parts[0] / parts[1] / f'{parts[2]}.json'
    if not description.is_file():
        return None
    data = json.loads(description.read_text())
    for entry in data.get('type_hashes', []):
        if entry.get('type_name') == msgtype:
            return str(entry.get('hash_string'))
    return None


@dataclass
class DecodedMetadata:
    """The fields of a decoded BagMetadata that the cross-checks need."""

    version: int | None = None
    storage_identifier: str | None = None
    duration_ns: int | None = None
    starting_ns: int | None = None
    message_count: int | None = None
    topics: list[dict[str, Any]] = field(default_factory=list)
    relative_file_paths: list[str] = field(default_factory=list)
    files: list[dict[str, Any]] = field(default_factory=list)


def decode_bag_metadata(dec: Decoder, node: YNode | None, path: str) -> DecodedMetadata:
    """Y ``convert<BagMetadata>::decode`` (L277-307), every field for the file's version."""
    out = DecodedMetadata()
    if node is None:
        return out
    if node.kind != 'map':
        dec.fail(path or '(top)', f'expected a mapping, found a {node.kind}', 'yaml.hpp L277')
        return out

    def y(line: str) -> str:
        return f'yaml.hpp {line}'

    out.version = dec.integer(dec.get(node, 'version', path, y('L279')), 'version', y('L279'),
                              _INT32)
    version = out.version if out.version is not None else 9
    out.storage_identifier = dec.string(dec.get(node, 'storage_identifier', path, y('L280')),
                                        'storage_identifier', y('L280'))
    out.duration_ns = dec.nanoseconds(dec.get(node, 'duration', path, y('L281')), 'duration',
                                      'nanoseconds', y('L281, L228-232'))
    out.starting_ns = dec.nanoseconds(dec.get(node, 'starting_time', path, y('L282-283')),
                                      'starting_time', 'nanoseconds_since_epoch',
                                      y('L282-283, L245-251'))
    out.message_count = dec.integer(dec.get(node, 'message_count', path, y('L284')),
                                    'message_count', y('L284'))
    topics = dec.sequence(dec.get(node, 'topics_with_message_count', path, y('L285-287')),
                          'topics_with_message_count', y('L179-191'))
    for index, item in enumerate(topics or []):
        where = f'topics_with_message_count[{index}]'
        meta = dec.get(item, 'topic_metadata', where, y('L160-161'))
        mpath = f'{where}.topic_metadata'
        if meta is not None and meta.kind != 'map':
            dec.fail(mpath, f'expected a mapping, found a {meta.kind}', y('L125-143'))
            meta = None
        topic: dict[str, Any] = {}
        for name, line in (('name', 'L127'), ('type', 'L128'),
                           ('serialization_format', 'L129')):
            topic[name] = dec.string(dec.get(meta, name, mpath, y(line)), f'{mpath}.{name}',
                                     y(line))
        if version >= 9:
            qos_node = dec.get(meta, 'offered_qos_profiles', mpath, y('L130-132'))
            topic['qos'] = decode_qos_list(dec, qos_node, f'{mpath}.offered_qos_profiles')
        elif version >= 4:
            text = dec.string(dec.get(meta, 'offered_qos_profiles', mpath, y('L133-135')),
                              f'{mpath}.offered_qos_profiles', y('L133-135'))
            topic['qos'] = decode_qos_string(dec, text, f'{mpath}.offered_qos_profiles')
        if version >= 7:
            value = dec.string(dec.get(meta, 'type_description_hash', mpath, y('L137-138')),
                               f'{mpath}.type_description_hash', y('L137-138'))
            check_type_hash(dec, value, topic['type'], f'{mpath}.type_description_hash')
            topic['type_description_hash'] = value
        topic['message_count'] = dec.integer(dec.get(item, 'message_count', where, y('L162')),
                                             f'{where}.message_count', y('L162'))
        out.topics.append(topic)
    paths = dec.sequence(dec.get(node, 'relative_file_paths', path, y('L289')),
                         'relative_file_paths', y('L289'))
    for index, item in enumerate(paths or []):
        text = dec.string(item, f'relative_file_paths[{index}]', y('L289'))
        if text is not None:
            out.relative_file_paths.append(text)
    if version >= 3:
        for name, line in (('compression_format', 'L292'), ('compression_mode', 'L293')):
            dec.string(dec.get(node, name, path, y(line)), name, y(line))
    if version >= 5:
        files = dec.sequence(dec.get(node, 'files', path, y('L296-297')), 'files',
                             y('L296-297'))
        for index, item in enumerate(files or []):
            where = f'files[{index}]'
            entry = {
                'path': dec.string(dec.get(item, 'path', where, y('L209')), f'{where}.path',
                                   y('L209')),
                'starting_ns': dec.nanoseconds(
                    dec.get(item, 'starting_time', where, y('L210-211')),
                    f'{where}.starting_time', 'nanoseconds_since_epoch', y('L210-211')),
                'duration_ns': dec.nanoseconds(dec.get(item, 'duration', where, y('L212')),
                                               f'{where}.duration', 'nanoseconds', y('L212')),
                'message_count': dec.integer(dec.get(item, 'message_count', where, y('L213')),
                                             f'{where}.message_count', y('L213')),
            }
            out.files.append(entry)
    if version >= 6:
        custom = dec.get(node, 'custom_data', path, y('L300-302'))
        if custom is not None and custom.kind == 'seq' and custom.items:
            dec.fail('custom_data', 'a non-empty sequence has no keys', y('L61-67'))
        elif custom is not None and custom.kind == 'map':
            for key, value in custom.items:
                for part in (key, value):
                    dec.string(part, f'custom_data.{key.text}', y('L61-67'))
    if version >= 8:
        dec.string(dec.get(node, 'ros_distro', path, y('L303-305')), 'ros_distro',
                   y('L303-305'))
    return out


def decode_qos_string(dec: Decoder, text: str | None, path: str) -> list[dict[str, Any]] | None:
    """Q ``to_rclcpp_qos_vector`` (L447-452): empty means none, else a YAML sequence."""
    if text is None:
        return None
    if text == '':
        return []
    try:
        node = compose(text)
    except yaml.YAMLError:
        dec.fail(path, 'not YAML', 'qos.cpp to_rclcpp_qos_vector L447-452')
        return None
    return decode_qos_list(dec, node, path)


def time_ordered_read(path: Path) -> tuple[int, str]:
    """The messages the pinned mcap C++ reader returns from ``path`` in log-time order.

    RI ``IndexedMessageReader::IndexedMessageReader`` (L1799-1846) takes the summary's chunk
    indexes, kept sorted by chunk start offset (RI ``CompareChunkIndexes`` L14-16, L458-470),
    and refuses the whole read ("cannot read MCAP in time order with no message indexes",
    L1814-1817) when there is none or the FIRST has ``message_index_length`` 0 -- as a chunk
    holding only schema and channel records does. It then queues each chunk whose message
    index offsets name a channel (L1825-1846) and reads, from the chunk start to the end of
    its message indexes, only Chunk and MessageIndex records (anything else is
    ``InvalidRecord``, L1903-1943), one message per message-index entry (L1944-1970).

    Returns:
        (messages read, the reader's refusal or '' if none).
    """
    from mcap.reader import make_reader as _make_reader

    data = path.read_bytes()
    with path.open('rb') as stream:
        summary = _make_reader(stream).get_summary()
    indexes = sorted(summary.chunk_indexes if summary else [],
                     key=lambda index: index.chunk_start_offset)
    if not indexes or indexes[0].message_index_length == 0:
        return 0, 'cannot read MCAP in time order with no message indexes'
    channels = set(summary.channels) if summary else set()
    read = 0
    for index in indexes:
        if not channels & set(index.message_index_offsets):
            continue
        records = b''
        pos = index.chunk_start_offset
        end = pos + index.chunk_length + index.message_index_length
        while pos < end:
            opcode, length = data[pos], struct.unpack_from('<Q', data, pos + 1)[0]
            body, pos = data[pos + 9:pos + 9 + length], pos + 9 + length
            if opcode == 0x06:                  # Chunk: times, sizes, crc, compression
                size = struct.unpack_from('<I', body, 28)[0]
                compression = body[32:32 + size].decode()
                if compression:
                    return read, f'compressed chunk ({compression}) not checked here'
                records = body[32 + size + 8:]
            elif opcode == 0x07:                # MessageIndex: channel, (time, offset)*
                channel = struct.unpack_from('<H', body, 0)[0]
                entries = struct.unpack_from('<I', body, 2)[0] // 16
                for number in range(entries):
                    stamp, offset = struct.unpack_from('<QQ', body, 6 + 16 * number)
                    if records[offset:offset + 1] != b'\x05' or \
                            struct.unpack_from('<HIQ', records, offset + 9)[::2] != \
                            (channel, stamp):
                        return read, 'a message index entry does not point at its message'
                    read += 1
            else:
                return read, ('expected only chunks and message indices, found opcode '
                              f'{opcode:#04x}')
    return read, ''


@dataclass
class McapFacts:
    """What rosbag2's MCAP plugin reads from one file (M ``read_metadata`` L414-504)."""

    message_count: int = 0
    start_ns: int = 0
    end_ns: int = 0
    topics: dict[str, dict[str, Any]] = field(default_factory=dict)


def check_mcap(path: Path, where: str, problems: list[str]) -> McapFacts | None:
    """The MCAP file as the plugin reads it: summary, channels, QoS, the rosbag2 record."""
    dec = Decoder(where)
    facts = McapFacts()
    try:
        with path.open('rb') as stream:
            reader = make_reader(stream)
            summary = reader.get_summary()
            if summary is None or summary.statistics is None:
                problems.append(f'{where}: no Statistics record in the summary (rosbag2 reads '
                                'message counts and times from it: mcap_storage.cpp L459-463)')
                return None
            stats = summary.statistics
            counts: dict[int, int] = {}
            first: int | None = None
            last = 0
            for _, channel, message in reader.iter_messages(log_time_order=False):
                counts[channel.id] = counts.get(channel.id, 0) + 1
                first = message.log_time if first is None else min(first, message.log_time)
                last = max(last, message.log_time)
            records = list(reader.iter_metadata())
    except (OSError, McapError, ValueError, EOFError) as err:
        problems.append(f'{where}: not a readable MCAP ({type(err).__name__}: {err}) '
                        '(mcap_storage.cpp open_impl L363-379)')
        return None
    cite_stats = 'MCAP Statistics record vs the messages; mcap_storage.cpp L459-463'
    if stats.message_count:
        read, refusal = time_ordered_read(path)
        if refusal or read != stats.message_count:
            dec.fail('time-ordered read', f'{read} of {stats.message_count} messages come '
                     f'back{f" ({refusal})" if refusal else ""}', 'mcap C++ v1.3.0 '
                     'reader.inl IndexedMessageReader L1799-1846, as mcap_storage.cpp '
                     'read_next L634-667 reads')
    if stats.message_count != sum(counts.values()):
        dec.fail('statistics.message_count', f'{stats.message_count} but the file holds '
                 f'{sum(counts.values())} messages', cite_stats)
    if counts and (stats.message_start_time, stats.message_end_time) != (first, last):
        dec.fail('statistics.message_start_time/end_time', "do not match the messages' log "
                 'times', cite_stats)
    for channel_id, channel in summary.channels.items():
        if stats.channel_message_counts.get(channel_id, 0) != counts.get(channel_id, 0):
            dec.fail(f'channel {channel.topic}', 'statistics count differs from the messages',
                     cite_stats)
        schema = summary.schemas.get(channel.schema_id)
        if schema is None:
            dec.fail(f'channel {channel.topic}', 'has no schema ("Could not find schema for '
                     'topic")', 'mcap_storage.cpp L471-474')
        qos = None
        if 'offered_qos_profiles' in channel.metadata:
            qos = decode_qos_string(dec, channel.metadata['offered_qos_profiles'],
                                    f'channel {channel.topic} offered_qos_profiles')
        if 'topic_type_hash' in channel.metadata:
            check_type_hash(dec, channel.metadata['topic_type_hash'],
                            schema.name if schema else None,
                            f'channel {channel.topic} topic_type_hash')
        topic = facts.topics.setdefault(channel.topic, {'message_count': 0, 'types': set(),
                                                        'formats': set(), 'qos': qos,
                                                        'hash': channel.metadata.get(
                                                            'topic_type_hash')})
        topic['message_count'] += stats.channel_message_counts.get(channel_id, 0)
        topic['types'].add(schema.name if schema else None)
        topic['formats'].add(channel.message_encoding)
    facts.message_count = stats.message_count
    facts.start_ns, facts.end_ns = stats.message_start_time, stats.message_end_time
    for record in records:
        if record.name != 'rosbag2':
            continue
        # M L414-453: the record's serialized_metadata is decoded as BagMetadata (no
        # rosbag2_bagfile_information wrapper: M update_metadata L956-969 writes encode()).
        text = record.metadata.get('serialized_metadata')
        if text is None:
            dec.fail('rosbag2 metadata record', 'has no serialized_metadata (rosbag2 warns and '
                     'assumes version 8): neither absent nor complete', 'mcap_storage.cpp '
                     'L433-439')
            continue
        if text == '':
            continue
        record_dec = Decoder(f'{where}: rosbag2 metadata record')
        try:
            node = compose(text)
        except yaml.YAMLError:
            record_dec.fail('serialized_metadata', 'not YAML', 'mcap_storage.cpp L440-442')
        else:
            decode_bag_metadata(record_dec, node, '')
        dec.problems.extend(record_dec.problems)
    problems.extend(dec.problems)
    return facts


def check_bag_directory(path: str | Path, expected_version: int = 9) -> list[str]:
    """Every problem rosbag2 Jazzy's reader would have with the bag at ``path``.

    Args:
        path: a bag directory (``metadata.yaml`` and its storage files).
        expected_version: the metadata version the bag must have.

    Returns:
        One line per problem; empty if the bag passes every rule.
    """
    path = Path(path)
    problems: list[str] = []
    if not path.is_dir():
        problems.append(f'{path}: not a bag directory; rosbag2 reads <dir>/metadata.yaml '
                        '(metadata_io.cpp read_metadata L26-42, info.cpp read_metadata)')
        if path.is_file():
            check_mcap(path, str(path), problems)
        return problems
    meta_path = path / 'metadata.yaml'
    if not meta_path.is_file():
        problems.append(f'{meta_path}: missing ("Could not find metadata in bag directory", '
                        'info.cpp; sequential_reader.cpp L95-120)')
        for mcap_file in sorted(path.glob('*.mcap')):
            check_mcap(mcap_file, str(mcap_file), problems)
        return problems
    dec = Decoder(str(meta_path))
    try:
        root = compose(meta_path.read_text())
    except (yaml.YAMLError, UnicodeDecodeError) as err:
        return [f'{meta_path}: not YAML ({type(err).__name__}) (metadata_io.cpp L29)']
    info = dec.get(root, 'rosbag2_bagfile_information', '', 'metadata_io.cpp L30')
    meta = decode_bag_metadata(dec, info, 'rosbag2_bagfile_information')
    problems.extend(dec.problems)
    where = str(meta_path)
    if meta.version is not None and meta.version != expected_version:
        problems.append(f'{where}: version: {meta.version}, expected {expected_version}')
    if meta.storage_identifier is not None and meta.storage_identifier != 'mcap':
        problems.append(f'{where}: storage_identifier: {meta.storage_identifier!r}, only '
                        "'mcap' is checked here (sequential_reader.cpp L97-99 picks the "
                        'plugin by it)')
    if not meta.relative_file_paths and not dec.problems:
        problems.append(f'{where}: relative_file_paths: empty ("No file paths were found in '
                        'metadata", sequential_reader.cpp L100-103)')
    facts: dict[str, McapFacts] = {}
    for name in meta.relative_file_paths:
        file_path = path / name  # R resolve_relative_paths L36-50, version >= 4
        if not file_path.is_file():
            problems.append(f'{where}: relative_file_paths: {name!r} does not exist in {path}')
            continue
        found = check_mcap(file_path, str(file_path), problems)
        if found is not None:
            facts[name] = found
    names_in_files = [entry['path'] for entry in meta.files if entry['path'] is not None]
    if meta.files and sorted(names_in_files) != sorted(meta.relative_file_paths):
        problems.append(f'{where}: files[].path {names_in_files} differ from '
                        f'relative_file_paths {meta.relative_file_paths} (the rosbag2 writer '
                        'lists the same files in both)')
    for index, entry in enumerate(meta.files):
        found = facts.get(entry['path'])
        if found is None:
            if entry['path'] is not None and not (path / entry['path']).is_file():
                problems.append(f'{where}: files[{index}].path: {entry["path"]!r} does not '
                                f'exist in {path}')
            continue
        _compare_times(problems, f'{where}: files[{index}]', entry['message_count'],
                       entry['starting_ns'], entry['duration_ns'], [found])
    if len(facts) == len(meta.relative_file_paths) and facts:
        _compare_times(problems, where, meta.message_count, meta.starting_ns, meta.duration_ns,
                       list(facts.values()))
        _compare_topics(problems, where, meta.topics, list(facts.values()))
    formats = {t['serialization_format'] for t in meta.topics}
    if len(formats) > 1:
        problems.append(f'{where}: topics have different serialization formats {formats} '
                        '(sequential_reader.cpp check_topics_serialization_formats L316-326)')
    return problems


def _compare_times(problems: list[str], where: str, count: int | None, start: int | None,
                   duration: int | None, files: list[McapFacts]) -> None:
    """message_count, starting_time and duration against the MCAP summaries."""
    total = sum(f.message_count for f in files)
    if count is not None and count != total:
        problems.append(f'{where}: message_count {count} but the MCAP summary counts {total} '
                        '(mcap_storage.cpp L461)')
    with_messages = [f for f in files if f.message_count]
    if not with_messages:
        return
    first = min(f.start_ns for f in with_messages)
    last = max(f.end_ns for f in with_messages)
    if start is not None and start != first:
        problems.append(f'{where}: starting_time {start} ns but the first message is logged at '
                        f'{first} ns (mcap_storage.cpp L462-463)')
    if duration is not None and duration != last - first:
        problems.append(f'{where}: duration {duration} ns but the messages span '
                        f'{last - first} ns (mcap_storage.cpp L462)')


def _compare_topics(problems: list[str], where: str, topics: list[dict[str, Any]],
                    files: list[McapFacts]) -> None:
    """Per-topic counts, types, formats and QoS against the MCAP channels."""
    merged: dict[str, dict[str, Any]] = {}
    for facts in files:
        for name, info in facts.topics.items():
            slot = merged.setdefault(name, {'message_count': 0, 'types': set(),
                                            'formats': set(), 'qos': info['qos'],
                                            'hash': info.get('hash')})
            slot['message_count'] += info['message_count']
            slot['types'] |= info['types']
            slot['formats'] |= info['formats']
    listed = {t['name'] for t in topics}
    for name in sorted(set(merged) - listed):
        problems.append(f'{where}: topic {name} is in the MCAP but not in '
                        'topics_with_message_count')
    for topic in topics:
        name = topic['name']
        info = merged.get(name)
        if info is None:
            if topic['message_count']:
                problems.append(f'{where}: topic {name} has no MCAP channel')
            continue
        if topic['message_count'] is not None and topic['message_count'] != \
                info['message_count']:
            problems.append(f'{where}: topic {name}: message_count {topic["message_count"]} '
                            f'but the MCAP summary counts {info["message_count"]} '
                            '(mcap_storage.cpp L494-500)')
        if topic['type'] is not None and info['types'] != {topic['type']}:
            problems.append(f'{where}: topic {name}: type {topic["type"]} but the MCAP schema '
                            f'says {sorted(map(str, info["types"]))} (mcap_storage.cpp L481)')
        if topic['serialization_format'] is not None and \
                info['formats'] != {topic['serialization_format']}:
            problems.append(f'{where}: topic {name}: serialization_format differs from the '
                            'MCAP message encoding (mcap_storage.cpp L480)')
        if info.get('hash') is not None and topic.get('type_description_hash') is not None \
                and info['hash'] != topic['type_description_hash']:
            problems.append(f'{where}: topic {name}: topic_type_hash of the MCAP channel differs '
                            'from type_description_hash in metadata.yaml (rosbag2 writes the '
                            'same hash to both: mcap_storage.cpp L938, yaml.hpp L137-138)')
        if topic.get('qos') is not None and info['qos'] is not None and \
                topic['qos'] != info['qos']:
            problems.append(f'{where}: topic {name}: offered_qos_profiles differ between '
                            'metadata.yaml and the MCAP channel (rosbag2 writes the same '
                            'profiles to both: mcap_storage.cpp L933-938)')
