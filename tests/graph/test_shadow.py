"""Real-vehicle mode end to end: a short shadow run of a commute bag (planner and monitor in
wall mode), read back with rosbags; a remapped input topic; every node in wall mode; the
lead replay and the wall-time integrator (pure).

No timing thresholds: loop timings depend on machine load; the p99 figure comes from
benchmarks/bench_shadow.py."""

from __future__ import annotations

import json
import math
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from rosbags.highlevel import AnyReader
from support.cli import trust_av_run
from support.paths import REPO
from support.rosbag2_rules import check_bag_directory  # the test-side oracle module

from preceding_traffic.bags import TYPESTORE
from preceding_traffic.replay import LeadReplay
from preceding_traffic.traces import SpeedTrace
from trust_av.graph.bag_records import message_stamp
from trust_av.graph.bag_writer import STAMP_IN_FIRST_ELEMENT, header_stamp_ns
from trust_av_common.kinematics import advance
from trust_av_common.topics import TOPICS, qualified

PARAMS = REPO / 'config' / 'trust_av.yaml'
SHADOW_S = '3'
ACCEL_MIN, ACCEL_MAX = -3.0, 3.0


def shadow(tmp_path: Path, *extra: str) -> tuple[subprocess.CompletedProcess[str], Path, Path]:
    out, stats = tmp_path / 'shadow', tmp_path / 'shadow.json'
    result = subprocess.run(
        [sys.executable, '-m', 'trust_av.cli', 'shadow', '--bag',
         str(REPO / 'bags' / 'commute_am'), '--duration-s', SHADOW_S, '--out', str(out),
         '--json', str(stats), *extra], capture_output=True, text=True, timeout=120,
        check=False)
    assert result.returncode == 0, result.stdout + result.stderr
    return result, out, stats


def read(path: Path) -> dict[str, list[object]]:
    out: dict[str, list[object]] = {}
    with AnyReader([path], default_typestore=TYPESTORE) as reader:
        for connection, _t, raw in reader.messages():
            out.setdefault(connection.topic, []).append(
                reader.deserialize(raw, connection.msgtype))
    return out


@pytest.mark.wall_clock
def test_shadow_run_records_bounded_outputs_and_jitter(tmp_path: Path) -> None:
    result, out, stats = shadow(tmp_path)
    assert check_bag_directory(out) == []          # ros2 bag opens it (rosbag2 Jazzy's rules)
    messages = read(out)
    for topic in ('/ego/plan', '/ego/expected_plan', '/ego/accel_cmd', '/ego/planner_status',
                  '/trust_monitor/trust', '/preceding_vehicle/odom', '/ego/odom'):
        assert messages.get(topic), f'nothing recorded on {topic}'
    accels = [m.accel.linear.x for m in messages['/ego/accel_cmd']]  # type: ignore[attr-defined]
    assert all(math.isfinite(a) and ACCEL_MIN - 1e-9 <= a <= ACCEL_MAX + 1e-9 for a in accels)
    for msg in messages['/ego/plan']:
        values = [p.accelerations[0] for p in msg.points]  # type: ignore[attr-defined]
        assert all(math.isfinite(a) and ACCEL_MIN - 1e-9 <= a <= ACCEL_MAX + 1e-9
                   for a in values)
    trust = [m.vector.z for m in messages['/trust_monitor/trust']]  # type: ignore[attr-defined]
    assert trust and all(math.isfinite(t) for t in trust)
    loops = json.loads(stats.read_text())['loops']
    for name in ('planner', 'trust_monitor', 'shadow_player'):
        assert loops[name]['ticks'] > 0
        for key in ('p50', 'p99', 'max'):
            assert math.isfinite(loops[name]['jitter_ms'][key])
            assert math.isfinite(loops[name]['compute_ms'][key])
        assert f'{name}:' in result.stdout


@pytest.fixture(scope='module')
def remapped_overrun(tmp_path_factory: pytest.TempPathFactory) -> dict[str, list[object]]:
    """One shadow run read by the two tests below: its input odometry remapped to
    /vehicle/lead/odom and /vehicle/ego/odom, and a CPU budget per NMPC solve of 1 ns (the
    two settings are independent: the budget acts on the solve, the topics on its inputs);
    the messages it recorded."""
    folder = tmp_path_factory.mktemp('remapped_overrun')
    params = folder / 'remapped_overrun.yaml'
    text = PARAMS.read_text().replace('lead_odom_topic: preceding_vehicle/odom',
                                      'lead_odom_topic: /vehicle/lead/odom')
    text = text.replace('ego_odom_topic: ego/odom', 'ego_odom_topic: /vehicle/ego/odom')
    text = text.replace('solver_cpu_budget_s: 0.02', 'solver_cpu_budget_s: 0.000000001')
    assert '/vehicle/lead/odom' in text and '/vehicle/ego/odom' in text
    assert 'solver_cpu_budget_s: 0.000000001' in text
    params.write_text(text)
    _result, out, _stats = shadow(folder, '--params-file', str(params))
    return read(out)


@pytest.mark.wall_clock
def test_remapped_input_topics_are_honoured(remapped_overrun: dict[str, list[object]]) -> None:
    """The player publishes, and the planner plans from, the remapped input topics (a
    solved status, not a stale one, needs both inputs: the test below)."""
    messages = remapped_overrun
    assert messages.get('/vehicle/lead/odom') and messages.get('/vehicle/ego/odom')
    assert '/preceding_vehicle/odom' not in messages
    assert messages.get('/ego/plan'), 'the planner did not plan from the remapped topics'


@pytest.mark.wall_clock
def test_cpu_budget_overrun_publishes_the_fallback_and_goes_on(
        remapped_overrun: dict[str, list[object]]) -> None:
    """Against the wall clock a tiny CPU budget makes every NMPC solve overrun: the planner
    publishes the fallback plan with the reason in its status and keeps commanding."""
    messages = remapped_overrun
    statuses = [m.status[0].message for m in messages['/ego/planner_status']]  # type: ignore[attr-defined]
    solved = [s for s in statuses if not s.startswith('stale')]
    assert solved and all(s.startswith('fallback: CPU budget exceeded') for s in solved), (
        sorted(set(statuses)))
    assert len(messages['/ego/accel_cmd']) >= len(solved)


@pytest.mark.parametrize(('rate', 'message'), [
    ('0', 'must be a finite rate > 0 Hz'),
    ('abc', 'expected a rate in Hz'),
    ('0.5', 'control_rate_hz 0.5: a 2 s control period is longer than the model step'),
    ('101', 'needs 303 steps (at most 300)'),
])
def test_bad_rate_is_one_line_before_anything_starts(tmp_path: Path, rate: str,
                                                     message: str) -> None:
    """The planner node's rule for its rate, applied by the command before any node or
    output exists (a 0.5 Hz shadow run used to start, leave its --out directory and stop on
    the node's refusal)."""
    out = tmp_path / 'shadow'
    result = trust_av_run('shadow', '--bag', str(REPO / 'bags' / 'commute_am'), '--duration-s',
                          '1', '--out', str(out), '--rate-hz', rate)    # in-process
    assert result.returncode == 2, result.stdout + result.stderr
    assert message in result.stderr.strip().splitlines()[-1]  # argparse's usage, then one line
    assert 'Traceback' not in result.stderr and not out.exists()


@pytest.mark.wall_clock
@pytest.mark.parametrize('mode', [(), ('--whole-graph',)], ids=['planner_monitor', 'whole_graph'])
def test_a_full_disk_stops_a_wall_run_with_one_line_and_a_finished_bag(
        small_disk: Path, mode: tuple[str, ...]) -> None:
    """On a 200 kB disk a wall-clock recording fills it within seconds: the run stops its
    nodes and ends with one line and exit 2, and the bag holds the complete seconds and
    passes rosbag2's reader rules. (It used to go on writing to the finished bag: a
    traceback, EBADF.)"""
    out = small_disk / 'shadow'
    proc = subprocess.run(
        [sys.executable, '-m', 'trust_av.cli', 'shadow', '--bag',
         str(REPO / 'bags' / 'commute_am'), '--duration-s', '60', '--out', str(out), *mode],
        capture_output=True, text=True, timeout=120, check=False)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert proc.stderr.startswith(f'trust-av shadow: error: {out}: disk full (No space left '
                                  'on device) after ') and proc.stderr.count('\n') == 1
    assert check_bag_directory(out) == []
    seconds = int(proc.stderr.split(' after ')[1].split()[0])   # on 200 kB: 0 to 3
    assert bool(read(out)) == (seconds > 0)


def test_lead_replay_interpolates_and_integrates() -> None:
    trace = SpeedTrace('t', 1.0, np.array([0.0, 2.0, 2.0]))
    lead = LeadReplay(trace, 10.0)
    assert lead.state(0.5).speed_mps == pytest.approx(1.0)
    assert lead.state(1.0).position_m == pytest.approx(11.0)
    assert lead.state(2.0).position_m == pytest.approx(13.0)
    assert lead.state(0.5).position_m == pytest.approx(10.25)
    assert lead.state(99.0).position_m == pytest.approx(13.0)
    np.testing.assert_allclose(lead.preview(0.5, 3, 1.0), [1.0, 2.0, 2.0])


@pytest.mark.wall_clock
def test_whole_graph_in_wall_mode_drives_at_real_time(tmp_path: Path) -> None:
    """Every node in wall mode (``--whole-graph``, GRU predictor): the lead of a constant
    10 m/s trace advances at 10 m/s of *wall* time, the simulated AV and human follow it
    without collision, every topic is recorded as ``ros2 bag record`` records it: log time =
    receive time (wall time, not before the stamp), publish time = header stamp."""
    trace = tmp_path / 'steady.csv'
    trace.write_text('time_s,speed_mps\n' + ''.join(f'{t},10.0\n' for t in range(61)))
    out, stats = tmp_path / 'wall', tmp_path / 'wall.json'
    before_ns = time.time_ns()
    result = subprocess.run(
        [sys.executable, '-m', 'trust_av.cli', 'shadow', '--whole-graph', '--bag',
         str(trace), '--predictor', 'gru', '--duration-s', SHADOW_S, '--out', str(out),
         '--json', str(stats)], capture_output=True, text=True, timeout=120, check=False)
    after_ns = time.time_ns()
    assert result.returncode == 0, result.stdout + result.stderr
    assert check_bag_directory(out) == []
    stamped: dict[str, list[tuple[int, object]]] = {}
    with AnyReader([out], default_typestore=TYPESTORE) as reader:
        for connection, log_ns, raw in reader.messages():
            msg = reader.deserialize(raw, connection.msgtype)
            stamp = message_stamp(msg)
            stamp_ns = stamp.sec * 1_000_000_000 + stamp.nanosec
            assert before_ns <= stamp_ns <= log_ns <= after_ns, connection.topic
            stamped.setdefault(connection.topic, []).append((stamp_ns, msg))
    from mcap.reader import make_reader
    with next(out.glob('*.mcap')).open('rb') as stream:
        for schema, channel, message in make_reader(stream).iter_messages():
            offset = 8 if schema.name in STAMP_IN_FIRST_ELEMENT else 4   # tf, markers
            assert message.publish_time == header_stamp_ns(message.data, offset), channel.topic
    recorded = {qualified(t.name) for t in TOPICS} - {'/clock', '/sim/start'}
    assert recorded <= set(stamped), recorded - set(stamped)
    lead = stamped['/preceding_vehicle/odom']
    (t0, first), (t1, last) = lead[0], lead[-1]
    speed = ((last.pose.pose.position.x - first.pose.pose.position.x)  # type: ignore[attr-defined]
             / ((t1 - t0) * 1e-9))
    assert speed == pytest.approx(10.0, rel=0.02)
    for topic in ('/ego/odom', '/human/odom'):
        assert stamped[topic][-1][1].twist.twist.linear.x > 5.0, topic  # type: ignore[attr-defined]
    gaps = [float(next(v.value for v in m.status[0].values if v.key == 'gap_m'))  # type: ignore[attr-defined]
            for topic in ('/ego/planner_status', '/human/driver_status')
            for _t, m in stamped[topic]
            if any(v.key == 'gap_m' for v in m.status[0].values)]  # type: ignore[attr-defined]
    assert gaps and min(gaps) > 0.0
    statuses = [m.status[0].message for _t, m in stamped['/ego/planner_status']]  # type: ignore[attr-defined]
    assert 'Solve_Succeeded' in statuses
    loops = json.loads(stats.read_text())['loops']
    assert set(loops) == {'preceding_traffic', 'planner', 'ego_plant', 'human_driver',
                          'trust_monitor'}
    assert all(loop['ticks'] > 0 for loop in loops.values())


def test_advance_stops_at_zero_speed() -> None:
    assert advance(10.0, 4.0, 1.0, 0.5) == pytest.approx((12.0, 4.5))
    assert advance(10.0, 1.0, -3.0, 0.5) == pytest.approx((10.5, 0.0))  # would be -0.5 m/s
    with pytest.raises(ValueError, match='dt_s'):
        advance(0.0, 0.0, 0.0, -0.1)


@pytest.mark.wall_clock
def test_a_wall_recorder_that_falls_behind_names_what_it_lost(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Wall mode does not wait for the recorder: one stalled for 2 s with room for only 3
    samples per topic (its subscriptions' depth, patched in this process; the nodes keep
    theirs) loses messages, and the run says which in one error naming every publisher,
    with a finished bag holding the rest. Checked against the nodes' own counts: for each
    publisher that starts after the recording, recorded + lost = published."""
    import trust_av_common.ros.qos as qos
    from preceding_traffic.sources import load_trace
    from trust_av.graph.publication_ledger import RecordingLossError
    from trust_av.graph.shadow import AFTER_START, run_wall_graph
    from trust_av.system.config import load_run_config

    monkeypatch.setattr(qos, 'HISTORY_DEPTH', 3)
    trace_csv = tmp_path / 'steady.csv'
    trace_csv.write_text('time_s,speed_mps\n' + ''.join(f'{t},10.0\n' for t in range(61)))
    config = load_run_config((), {'preceding_traffic': {'trace': str(trace_csv)}})
    trace = load_trace(str(trace_csv), config.planner.dt_s, config.trace)
    stalls: list[float] = []

    def stall(_pids: dict[str, int], elapsed_s: float) -> None:
        if not stalls:
            stalls.append(elapsed_s)
            time.sleep(2.0)            # the recording loop takes nothing meanwhile

    bag = tmp_path / 'wall'
    with pytest.raises(RecordingLossError) as lost:
        run_wall_graph(config, str(trace_csv), trace, bag, duration_s=5.0, rate_hz=10.0,
                       every_second=stall)
    assert stalls and '\n' not in str(lost.value)
    assert check_bag_directory(bag) == []
    recorded = {topic: len(messages) for topic, messages in read(bag).items()}
    losses = {(loss.topic, loss.node): loss.count for loss in lost.value.losses}
    reports = {path.name.split('.')[0]: json.loads(path.read_text())['published']
               for path in (tmp_path / 'wall.logs').glob('*.jitter.json')}
    for topic in AFTER_START:           # each has one publisher
        node = next(t.publishers[0] for t in TOPICS if qualified(t.name) == topic)
        assert losses.get((topic, node), 0) > 0, (topic, losses)   # 2 s at 10 Hz > 3
        assert recorded[topic] + losses[(topic, node)] == reports[node][topic], topic
