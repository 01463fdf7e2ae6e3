"""Bags against rosbag2 Jazzy's own reading rules (tests/support/rosbag2_rules.py cites the
source).

A bag written with rosbags' ``Writer(version=9, storage_plugin=StoragePlugin.MCAP)`` must
pass; taking away or retyping any field that rosbag2's ``convert<BagMetadata>::decode``
(``rosbag2_storage/include/rosbag2_storage/yaml.hpp``, jazzy) or the QoS decoder
(``rosbag2_storage/src/rosbag2_storage/qos.cpp``) reads must fail; a bare MCAP as the
project's recorder writes it today must fail with the reason.
"""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from mcap.reader import make_reader
from rosbags.interfaces import (
    Qos,
    QosDurability,
    QosHistory,
    QosLiveliness,
    QosReliability,
    QosTime,
)
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore
from support.rosbag2_rules import (
    REQUIRED_V9,
    Decoder,
    check_bag_directory,
    compose,
    decode_qos_list,
    decode_qos_string,
    time_ordered_read,
)

TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
INFINITE = QosTime(2147483647, 4294967295)
# The project's profile for lock-step topics (trust_av_common.ros.qos.QOS['STEP']).
STEP_QOS = Qos(QosHistory.KEEP_LAST, 1000, QosReliability.RELIABLE,
               QosDurability.TRANSIENT_LOCAL, INFINITE, INFINITE, QosLiveliness.AUTOMATIC,
               INFINITE, False)
T0_NS = 1_700_000_000_000_000_000
STEPS = 5

# The fields yaml.hpp convert<BagMetadata>::decode reads for version 9, with the wrong-typed
# value each must refuse (yaml-cpp reads any scalar as a string, so strings get a mapping).
# Listed here from the source, independently of rosbag2_rules.REQUIRED_V9.
FIELDS: dict[str, Any] = {
    'version': 'nine',                                                     # L279 as<int>
    'storage_identifier': {'a': 1},                                        # L280 as<string>
    'duration': 5,                                                         # L281
    'duration.nanoseconds': 'long',                                        # L230 as<uint64>
    'starting_time': 5,                                                    # L282
    'starting_time.nanoseconds_since_epoch': -1,                           # L249 as<uint64>
    'message_count': 'many',                                               # L284 as<uint64>
    'topics_with_message_count': 'none',                                   # L182 IsSequence
    'topics_with_message_count[].topic_metadata': 'x',                     # L160
    'topics_with_message_count[].topic_metadata.name': {'a': 1},           # L127
    'topics_with_message_count[].topic_metadata.type': ['a'],              # L128
    'topics_with_message_count[].topic_metadata.serialization_format': {'a': 1},  # L129
    'topics_with_message_count[].topic_metadata.offered_qos_profiles': 'x',       # L130-132
    'topics_with_message_count[].topic_metadata.type_description_hash': {'a': 1},  # L138
    'topics_with_message_count[].message_count': 1.5,                      # L162 as<uint64>
    'relative_file_paths': 'bag.mcap',                                     # L289 vector
    'compression_format': {'a': 1},                                        # L292
    'compression_mode': ['a'],                                             # L293
    'files': {'a': 1},                                                     # L296-297 vector
    'files[].path': {'a': 1},                                              # L209
    'files[].starting_time.nanoseconds_since_epoch': 'x',                  # L210-211
    'files[].duration.nanoseconds': 'x',                                   # L212
    'files[].message_count': -3,                                           # L213
    'custom_data': ['a'],                                                  # L301, L61-67
    'ros_distro': {'a': 1},                                                # L304
}
# qos.cpp convert<rclcpp::QoS>::decode L167-213 for the first profile of the first topic.
QOS_FIELDS: dict[str, Any] = {
    'history': {'a': 1}, 'depth': 'deep', 'reliability': 'very', 'durability': 'forever',
    'deadline': 'x', 'deadline.sec': -1, 'lifespan.nsec': 'x', 'liveliness': 'alive',
    'liveliness_lease_duration.sec': 'x', 'avoid_ros_namespace_conventions': 'maybe',
}
QOS_PREFIX = 'topics_with_message_count[].topic_metadata.offered_qos_profiles[].'


def _odometry(stamp_ns: int, speed: float) -> bytes:
    ts = TYPESTORE.types
    header = ts['std_msgs/msg/Header'](
        stamp=ts['builtin_interfaces/msg/Time'](sec=stamp_ns // 10**9,
                                                nanosec=stamp_ns % 10**9), frame_id='odom')
    vec = ts['geometry_msgs/msg/Vector3']
    msg = ts['nav_msgs/msg/Odometry'](
        header=header, child_frame_id='ego',
        pose=ts['geometry_msgs/msg/PoseWithCovariance'](
            pose=ts['geometry_msgs/msg/Pose'](
                position=ts['geometry_msgs/msg/Point'](x=speed, y=0.0, z=0.0),
                orientation=ts['geometry_msgs/msg/Quaternion'](x=0.0, y=0.0, z=0.0, w=1.0)),
            covariance=np.zeros(36)),
        twist=ts['geometry_msgs/msg/TwistWithCovariance'](
            twist=ts['geometry_msgs/msg/Twist'](linear=vec(x=speed, y=0.0, z=0.0),
                                                angular=vec(x=0.0, y=0.0, z=0.0)),
            covariance=np.zeros(36)))
    return bytes(TYPESTORE.serialize_cdr(msg, 'nav_msgs/msg/Odometry'))


def _trust(stamp_ns: int, value: float) -> bytes:
    ts = TYPESTORE.types
    header = ts['std_msgs/msg/Header'](
        stamp=ts['builtin_interfaces/msg/Time'](sec=stamp_ns // 10**9,
                                                nanosec=stamp_ns % 10**9), frame_id='')
    msg = ts['geometry_msgs/msg/Vector3Stamped'](
        header=header, vector=ts['geometry_msgs/msg/Vector3'](x=0.1, y=0.9, z=value))
    return bytes(TYPESTORE.serialize_cdr(msg, 'geometry_msgs/msg/Vector3Stamped'))


def _write_bag(path: Path) -> Path:
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        odom = writer.add_connection('/ego/odom', 'nav_msgs/msg/Odometry', typestore=TYPESTORE,
                                     offered_qos_profiles=[STEP_QOS])
        trust = writer.add_connection('/trust_monitor/trust',
                                      'geometry_msgs/msg/Vector3Stamped', typestore=TYPESTORE,
                                      offered_qos_profiles=[STEP_QOS])
        for step in range(STEPS):
            stamp = T0_NS + step * 10**9
            writer.write(odom, stamp, _odometry(stamp, 20.0 + step))
            if step:
                writer.write(trust, stamp, _trust(stamp, 0.5))
    return path


@pytest.fixture(scope='module')
def good_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A bag directory written by rosbags' Writer, version 9, MCAP."""
    return _write_bag(tmp_path_factory.mktemp('bags') / 'good')


def _copy_bag(src: Path, dst: Path) -> Path:
    dst.mkdir()
    for item in src.iterdir():
        (dst / item.name).write_bytes(item.read_bytes())
    return dst


def _edit(bag: Path, dotted: str, value: Any, *, remove: bool) -> None:
    """Remove or replace one field of metadata.yaml (``[]`` = the first element)."""
    meta_path = bag / 'metadata.yaml'
    data = yaml.safe_load(meta_path.read_text())
    node = data['rosbag2_bagfile_information']
    parts = dotted.replace('[]', '.[]').split('.')
    for part in parts[:-1]:
        node = node[0] if part == '[]' else node[part]
    if remove:
        del node[parts[-1]]
    else:
        node[parts[-1]] = copy.deepcopy(value)
    meta_path.write_text(yaml.safe_dump(data))


def test_rosbags_writer_bag_passes(good_bag: Path) -> None:
    assert check_bag_directory(good_bag) == []


def test_field_list_matches_the_decoder_reading() -> None:
    assert set(REQUIRED_V9) <= set(FIELDS) | {f for f in FIELDS if '.' in f}
    assert {f for f in FIELDS if f not in {'duration', 'starting_time',
                                           'topics_with_message_count[].topic_metadata'}} \
        == set(REQUIRED_V9)


@pytest.mark.parametrize('field', sorted(FIELDS))
@pytest.mark.parametrize('remove', [True, False], ids=['removed', 'retyped'])
def test_each_required_field(good_bag: Path, tmp_path: Path, field: str, remove: bool) -> None:
    bag = _copy_bag(good_bag, tmp_path / 'bag')
    _edit(bag, field, FIELDS[field], remove=remove)
    problems = check_bag_directory(bag)
    leaf = field.rsplit('.', 1)[-1].replace('[]', '')
    assert problems, f'{field} {"removed" if remove else "retyped"} but the bag passes'
    assert any(leaf in p for p in problems), problems


@pytest.mark.parametrize('field', sorted(QOS_FIELDS))
@pytest.mark.parametrize('remove', [True, False], ids=['removed', 'retyped'])
def test_each_qos_field(good_bag: Path, tmp_path: Path, field: str, remove: bool) -> None:
    bag = _copy_bag(good_bag, tmp_path / 'bag')
    _edit(bag, QOS_PREFIX + field, QOS_FIELDS[field], remove=remove)
    problems = check_bag_directory(bag)
    assert any(field.split('.')[0] in p for p in problems), problems


def test_what_rosbags_writes_for_qos(good_bag: Path) -> None:
    """metadata.yaml (v9): a sequence of maps with policy names; the MCAP channel: the same
    as a YAML string. Both decode to the profile given, as rmw enum values."""
    want = {'history': 1, 'depth': 1000, 'reliability': 1, 'durability': 1,
            'deadline': (2147483647, 4294967295), 'lifespan': (2147483647, 4294967295),
            'liveliness': 1, 'liveliness_lease_duration': (2147483647, 4294967295),
            'avoid_ros_namespace_conventions': False}
    meta = yaml.safe_load((good_bag / 'metadata.yaml').read_text())
    topic = meta['rosbag2_bagfile_information']['topics_with_message_count'][0]
    written = topic['topic_metadata']['offered_qos_profiles']
    assert isinstance(written, list) and written[0]['history'] == 'keep_last'
    dec = Decoder('metadata.yaml')
    node = compose(yaml.safe_dump(written))
    assert decode_qos_list(dec, node, 'qos') == [want] and dec.problems == []
    with (good_bag / 'good.mcap').open('rb') as stream:
        channels = make_reader(stream).get_summary().channels  # type: ignore[union-attr]
    for channel in channels.values():
        assert set(channel.metadata) == {'offered_qos_profiles'}  # no topic_type_hash
        assert decode_qos_string(dec, channel.metadata['offered_qos_profiles'], 'ch') == [want]
    assert dec.problems == []


def test_numeric_qos_of_version_8_still_decodes() -> None:
    """qos.cpp L176-181: an integer history switches to the version-8 numeric form."""
    text = ('- history: 1\n  depth: 5\n  reliability: 2\n  durability: 2\n'
            '  deadline: {sec: 0, nsec: 0}\n  lifespan: {sec: 0, nsec: 0}\n  liveliness: 1\n'
            '  liveliness_lease_duration: {sec: 0, nsec: 0}\n'
            '  avoid_ros_namespace_conventions: false\n')
    dec = Decoder('x')
    profiles = decode_qos_string(dec, text, 'qos')
    assert dec.problems == [] and profiles is not None and profiles[0]['reliability'] == 2


def test_counts_and_times_must_match_the_mcap(good_bag: Path, tmp_path: Path) -> None:
    for field, value, word in (('message_count', 2 * STEPS, 'message_count'),
                               ('starting_time.nanoseconds_since_epoch', T0_NS + 1,
                                'starting_time'),
                               ('duration.nanoseconds', 1, 'duration'),
                               ('topics_with_message_count[].message_count', 1, '/ego/odom'),
                               ('files[].message_count', 1, 'files[0]'),
                               ('relative_file_paths', ['other.mcap'], 'does not exist'),
                               ('topics_with_message_count[].topic_metadata.type',
                                'nav_msgs/msg/Path', 'schema'),
                               ('topics_with_message_count[].topic_metadata.'
                                'type_description_hash', 'RIHS01_abc', 'RIHS01'),
                               ('topics_with_message_count[].topic_metadata.'
                                'type_description_hash', 'RIHS01_' + '0' * 64, 'RIHS01 hash')):
        bag = _copy_bag(good_bag, tmp_path / f'bag_{len(list(tmp_path.iterdir()))}')
        _edit(bag, field, value, remove=False)
        problems = check_bag_directory(bag)
        assert any(word in p for p in problems), (field, problems)


def test_the_project_s_recorder_writes_what_rosbag2_reads(tmp_path: Path) -> None:
    """The recorder's writer (trust_av.graph.bag_writer.BagWriter: the mcap
    library's public Writer, one chunk per step) passes every rule; the same file without
    its metadata.yaml, as a lone .mcap, does not."""
    from trust_av.graph.bag_writer import BagWriter, qos_profile

    path = tmp_path / 'run'
    with BagWriter(path) as bag:
        bag.add_topic('/ego/odom', 'nav_msgs/msg/Odometry',
                      qos_profile(reliable=True, transient_local=True, depth=1000))
        for step in range(STEPS):
            bag.write('/ego/odom', _odometry(T0_NS + step * 10**9, 20.0))
            bag.end_step()
    assert check_bag_directory(path) == []
    (path / 'metadata.yaml').unlink()
    problems = check_bag_directory(path)
    assert 'metadata.yaml: missing' in problems[0]


def test_a_first_chunk_without_messages_cannot_be_read_in_time_order(tmp_path: Path) -> None:
    """The mcap C++ reader rosbag2 Jazzy pins (v1.3.0) refuses a time-ordered read when the
    first chunk index has no message index: a chunk of schema and channel records only.
    Nothing comes back, though every Python reader reads the file."""
    path = tmp_path / 'first_chunk_empty'
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        odom = writer.add_connection('/ego/odom', 'nav_msgs/msg/Odometry', typestore=TYPESTORE,
                                     offered_qos_profiles=[STEP_QOS])
        writer.storage.close_chunk()  # type: ignore[union-attr]  # the schema/channel chunk
        for step in range(STEPS):
            writer.write(odom, T0_NS + step, _odometry(T0_NS + step, 20.0))
    count, refusal = time_ordered_read(path / 'first_chunk_empty.mcap')
    assert (count, refusal) == (0, 'cannot read MCAP in time order with no message indexes')
    problems = check_bag_directory(path)
    assert len(problems) == 1 and f'0 of {STEPS} messages come back' in problems[0], problems


def test_the_recorder_never_writes_a_chunk_without_messages(tmp_path: Path) -> None:
    """Steps without messages, a topic added mid-recording and one added after the last
    message: every message reads back in time order under the pinned reader's rule, and
    every chunk has a message index."""
    from trust_av.graph.bag_writer import BagWriter, qos_profile

    path = tmp_path / 'run'
    qos = qos_profile(reliable=True, transient_local=False, depth=1)
    with BagWriter(path) as bag:
        bag.add_topic('/ego/odom', 'nav_msgs/msg/Odometry', qos)
        bag.end_step()                                   # a tick before the first message
        for step in range(STEPS):
            if step == 2:
                bag.add_topic('/trust_monitor/trust', 'geometry_msgs/msg/Vector3Stamped', qos)
                bag.end_step()
            bag.write('/ego/odom', _odometry(T0_NS + step * 10**9, 20.0))
            if step >= 2:
                bag.write('/trust_monitor/trust', _trust(T0_NS + step * 10**9, 0.5))
            bag.end_step()
        bag.add_topic('/late', 'geometry_msgs/msg/Vector3Stamped', qos)
    assert check_bag_directory(path) == []
    assert time_ordered_read(path / 'run.mcap') == (2 * STEPS - 2, '')
    with (path / 'run.mcap').open('rb') as stream:
        summary = make_reader(stream).get_summary()
    assert summary is not None and len(summary.chunk_indexes) == STEPS
    assert all(index.message_index_length for index in summary.chunk_indexes)
    assert {channel.topic for channel in summary.channels.values()} == {
        '/ego/odom', '/trust_monitor/trust', '/late'}


def test_the_recorder_writes_type_hashes_and_a_profile_per_publisher(tmp_path: Path) -> None:
    """As rosbag2 Jazzy writes them: the MCAP channel's ``topic_type_hash`` is the type's
    RIHS01 hash (the installed type description's, and metadata.yaml's
    type_description_hash: mcap_storage.cpp create_topic L933-938), and a topic with three
    publishers has three offered profiles, in the channel and in metadata.yaml."""
    from support.rosbag2_rules import installed_type_hash

    from trust_av.graph.bag_writer import BagWriter, qos_profile

    path = tmp_path / 'run'
    qos = qos_profile(reliable=True, transient_local=True, depth=1000)
    with BagWriter(path) as bag:
        bag.add_topic('/ego/odom', 'nav_msgs/msg/Odometry', qos)
        bag.add_topic('/tf', 'tf2_msgs/msg/TFMessage', [qos, qos, qos])
        bag.write('/ego/odom', _odometry(T0_NS, 20.0))
        bag.end_step()
    assert check_bag_directory(path) == []
    with (path / 'run.mcap').open('rb') as stream:
        summary = make_reader(stream).get_summary()
    assert summary is not None
    meta = yaml.safe_load((path / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    listed = {t['topic_metadata']['name']: t['topic_metadata']
              for t in meta['topics_with_message_count']}
    for channel in summary.channels.values():
        schema = summary.schemas[channel.schema_id].name
        wanted = installed_type_hash(schema)
        assert wanted is not None and channel.metadata['topic_type_hash'] == wanted
        assert listed[channel.topic]['type_description_hash'] == wanted
        profiles = decode_qos_string(Decoder('ch'), channel.metadata['offered_qos_profiles'],
                                     'qos')
        assert profiles is not None
        assert len(profiles) == len(listed[channel.topic]['offered_qos_profiles']) == (
            3 if channel.topic == '/tf' else 1)
