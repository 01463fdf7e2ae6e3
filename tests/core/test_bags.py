"""Bags as speed sources: round trip, shipped commute bags, and every bad-bag error."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import StoragePlugin, Writer
from support.paths import REPO
from support.rosbag2_rules import check_bag_directory  # the test-side oracle module

from preceding_traffic.bags import (
    TWIST_STAMPED,
    TYPESTORE,
    BagError,
    load_bag_trace,
    odometry_messages,
    write_trace_bag,
)
from preceding_traffic.sources import load_trace
from preceding_traffic.traces import TraceConfig

TOPIC = '/preceding_vehicle/odom'
CONFIG = TraceConfig(trace='x', max_sample_gap_s=5.0)


@pytest.mark.parametrize('bag', ['commute_am', 'commute_pm', 'written'])
def test_bags_pass_rosbag2_jazzys_reader_rules(tmp_path: Path, bag: str) -> None:
    """The shipped commute bags and what ``trace-to-bag`` writes open in ``ros2 bag``
    (rosbag2 Jazzy's metadata and MCAP rules, tests/support/rosbag2_rules.py)."""
    path = REPO / 'bags' / bag
    if bag == 'written':
        path = tmp_path / 'us06_lead'
        done = subprocess.run([sys.executable, '-m', 'trust_av.cli', 'trace-to-bag',
                               'us06', str(path)], capture_output=True, text=True, timeout=120)
        assert done.returncode == 0, done.stderr
        assert sorted(p.name for p in tmp_path.iterdir()) == ['us06_lead']
    assert check_bag_directory(path) == []


def test_round_trip_keeps_times_and_speeds(tmp_path: Path) -> None:
    times = np.array([0.0, 0.4, 1.0, 2.5, 3.0, 7.0])   # irregular, with a 4 s hole
    speeds = np.array([0.0, 1.0, 2.0, 5.0, 5.0, 1.0])
    bag = tmp_path / 'bag'
    assert write_trace_bag(times, speeds, bag, TOPIC) == 6
    with AnyReader([bag], default_typestore=TYPESTORE) as reader:   # independent read-back
        msgs = [(t, reader.deserialize(raw, c.msgtype)) for c, t, raw in reader.messages()]
    assert [t for t, _ in msgs] == [round(x * 1e9) for x in times]   # log time = stamp
    assert [m.twist.twist.linear.x for _, m in msgs] == speeds.tolist()
    assert msgs[-1][1].pose.pose.position.x == pytest.approx(
        np.trapezoid(speeds, times))
    trace = load_bag_trace(bag, TOPIC, 'nav_msgs/msg/Odometry', 1.0, CONFIG)
    np.testing.assert_allclose(trace.speeds_mps, np.interp(np.arange(8.0), times, speeds))


@pytest.mark.parametrize('name', ['commute_am', 'commute_pm'])
def test_shipped_commute_bags_equal_their_traces(name: str) -> None:
    config = TraceConfig(trace=str(REPO / 'bags' / name), max_sample_gap_s=5.0)
    from_bag = load_trace(config.trace, 1.0, config)
    from_csv = load_trace(name, 1.0, config)
    assert from_bag.t0_s == from_csv.t0_s
    np.testing.assert_allclose(from_bag.speeds_mps, from_csv.speeds_mps, atol=1e-12)


def test_twist_stamped_source(tmp_path: Path) -> None:
    bag = tmp_path / 'twist'
    types = TYPESTORE.types
    with Writer(bag, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conn = writer.add_connection('/lead/twist', TWIST_STAMPED, typestore=TYPESTORE)
        for i, v in enumerate([3.0, 4.0, 5.0]):
            msg = types[TWIST_STAMPED](
                header=types['std_msgs/msg/Header'](
                    stamp=types['builtin_interfaces/msg/Time'](sec=10 + i, nanosec=0),
                    frame_id='base_link'),
                twist=types['geometry_msgs/msg/Twist'](
                    linear=types['geometry_msgs/msg/Vector3'](x=v, y=0.0, z=0.0),
                    angular=types['geometry_msgs/msg/Vector3'](x=0.0, y=0.0, z=0.0)))
            writer.write(conn, (10 + i) * 10**9, TYPESTORE.serialize_cdr(msg, TWIST_STAMPED))
    trace = load_bag_trace(bag, '/lead/twist', TWIST_STAMPED, 1.0, CONFIG)
    assert trace.t0_s == 10.0 and trace.speeds_mps.tolist() == [3.0, 4.0, 5.0]


def odometry_bag(path: Path, stamps_ns: list[int], log_times_ns: list[int],
                 speeds: list[float]) -> Path:
    """A bag of Odometry whose header stamps and log times differ (a sim-time recording)."""
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conn = writer.add_connection(TOPIC, 'nav_msgs/msg/Odometry', typestore=TYPESTORE)
        for (ns, msg), log_ns in zip(odometry_messages(np.array(stamps_ns) * 1e-9,
                                                       np.array(speeds), 'odom', 'lead'),
                                     log_times_ns, strict=True):
            assert ns == msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec
            writer.write(conn, log_ns, TYPESTORE.serialize_cdr(msg, 'nav_msgs/msg/Odometry'))
    return path


def test_header_stamps_from_zero_are_the_time_base(tmp_path: Path) -> None:
    """A simulation recorded on sim time: stamps 0, 1, 2, 3 s, logged at wall time."""
    wall = 1_790_000_000 * 10**9
    bag = odometry_bag(tmp_path / 'sim', [0, 10**9, 2 * 10**9, 3 * 10**9],
                       [wall + k * 10**6 for k in range(4)], [1.0, 2.0, 3.0, 4.0])
    trace = load_bag_trace(bag, TOPIC, 'nav_msgs/msg/Odometry', 1.0, CONFIG)
    assert trace.t0_s == 0.0 and trace.speeds_mps.tolist() == [1.0, 2.0, 3.0, 4.0]


def test_all_zero_stamps_use_the_log_times(tmp_path: Path) -> None:
    bag = odometry_bag(tmp_path / 'nostamp', [0, 0, 0], [5 * 10**9, 6 * 10**9, 7 * 10**9],
                       [1.0, 2.0, 3.0])
    trace = load_bag_trace(bag, TOPIC, 'nav_msgs/msg/Odometry', 1.0, CONFIG)
    assert trace.t0_s == 5.0 and trace.speeds_mps.tolist() == [1.0, 2.0, 3.0]


def test_impossible_speed_in_a_bag(tmp_path: Path) -> None:
    bag = odometry_bag(tmp_path / 'fast', [0, 10**9, 2 * 10**9], [0, 10**9, 2 * 10**9],
                       [1.0, 1e9, 2.0])
    with pytest.raises(BagError, match=r'message 1 at t = 1\.000 s: speed 1e\+09 m/s is above '
                                       r'100 m/s'):
        load_bag_trace(bag, TOPIC, 'nav_msgs/msg/Odometry', 1.0, CONFIG)


def test_bag_shorter_than_one_step(tmp_path: Path) -> None:
    bag = odometry_bag(tmp_path / 'short', [0, 5 * 10**8], [0, 5 * 10**8], [1.0, 2.0])
    with pytest.raises(BagError, match=r'spans 0\.5 s, shorter than one control step'):
        load_bag_trace(bag, TOPIC, 'nav_msgs/msg/Odometry', 1.0, CONFIG)


@pytest.fixture
def good_bag(tmp_path: Path) -> Path:
    bag = tmp_path / 'good'
    write_trace_bag(np.arange(5.0), np.full(5, 3.0), bag, TOPIC)
    return bag


def test_gap_over_limit_names_time(tmp_path: Path) -> None:
    bag = tmp_path / 'holey'
    write_trace_bag(np.array([0.0, 1.0, 9.0]), np.array([1.0, 1.0, 1.0]), bag, TOPIC)
    with pytest.raises(BagError, match=r'message 2 at t = 9\.000 s: gap of 8 s before t = 9 s '
                                       r'exceeds'):
        load_bag_trace(bag, TOPIC, 'nav_msgs/msg/Odometry', 1.0, CONFIG)


def test_missing_topic_lists_what_is_there(good_bag: Path) -> None:
    with pytest.raises(BagError, match=r'no topic /other; the bag has: '
                                       r'/preceding_vehicle/odom \(nav_msgs/msg/Odometry\)'):
        load_bag_trace(good_bag, '/other', 'nav_msgs/msg/Odometry', 1.0, CONFIG)


def test_wrong_message_type(good_bag: Path) -> None:
    with pytest.raises(BagError, match='has type nav_msgs/msg/Odometry, expected '
                                       'geometry_msgs/msg/TwistStamped'):
        load_bag_trace(good_bag, TOPIC, TWIST_STAMPED, 1.0, CONFIG)
    with pytest.raises(BagError, match='cannot read a speed from std_msgs/msg/Float64'):
        load_bag_trace(good_bag, TOPIC, 'std_msgs/msg/Float64', 1.0, CONFIG)


def test_zero_messages(tmp_path: Path) -> None:
    bag = tmp_path / 'empty'
    with Writer(bag, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        writer.add_connection(TOPIC, 'nav_msgs/msg/Odometry', typestore=TYPESTORE)
    with pytest.raises(BagError, match='has no messages'):
        load_bag_trace(bag, TOPIC, 'nav_msgs/msg/Odometry', 1.0, CONFIG)


def test_truncated_file(good_bag: Path, tmp_path: Path) -> None:
    source = next(good_bag.glob('*.mcap'))
    cut = tmp_path / 'cut.mcap'
    cut.write_bytes(source.read_bytes()[:200])
    with pytest.raises(BagError, match=r'cut\.mcap: cannot read bag'):
        load_bag_trace(cut, TOPIC, 'nav_msgs/msg/Odometry', 1.0, CONFIG)


def test_unsupported_storage(tmp_path: Path) -> None:
    bag = tmp_path / 'weird'
    bag.mkdir()
    (bag / 'metadata.yaml').write_text('rosbag2_bagfile_information:\n  version: 9\n'
                                       '  storage_identifier: leveldb\n')
    with pytest.raises(BagError, match='weird: cannot read bag'):
        load_bag_trace(bag, TOPIC, 'nav_msgs/msg/Odometry', 1.0, CONFIG)


def test_existing_output_is_not_overwritten(good_bag: Path) -> None:
    before = sorted(p.read_bytes() for p in good_bag.iterdir())
    with pytest.raises(BagError, match='exists already'):
        write_trace_bag(np.arange(3.0), np.ones(3), good_bag, TOPIC)
    assert sorted(p.read_bytes() for p in good_bag.iterdir()) == before


def test_cli_one_line_error_and_replay(good_bag: Path, tmp_path: Path) -> None:
    holey = tmp_path / 'h'
    write_trace_bag(np.array([0.0, 1.0, 20.0]), np.ones(3), holey, TOPIC)
    proc = subprocess.run([sys.executable, '-m', 'trust_av.cli', 'simulate',
                           '--trace', str(holey), '--no-progress'],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    assert proc.stderr.count('\n') == 1 and 'exceeds max_sample_gap_s' in proc.stderr
    out = tmp_path / 'again'
    proc = subprocess.run([sys.executable, '-m', 'trust_av.cli', 'trace-to-bag',
                           'nycc', str(out)], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    shutil.rmtree(out)


def test_write_trace_bag_creates_missing_parent_folders(tmp_path: Path) -> None:
    bag = tmp_path / 'bags' / 'sub' / 'trace'
    assert write_trace_bag(np.arange(3.0), np.ones(3), bag, TOPIC) == 3
    assert (bag / 'metadata.yaml').is_file()
    assert [p.name for p in bag.parent.iterdir()] == ['trace']     # no staging left


def test_write_trace_bag_under_a_file_names_it(tmp_path: Path) -> None:
    (tmp_path / 'notes').write_text('x')
    with pytest.raises(BagError, match=r'cannot write bag \(.*notes is not a folder\)'):
        write_trace_bag(np.arange(3.0), np.ones(3), tmp_path / 'notes' / 'trace', TOPIC)
