"""The ROS 2 node graph: equal to the in-process loop, recorded faithfully, isolated per run,
and failing loudly (naming the node, leaving no process behind) when a node dies."""

from __future__ import annotations

import dataclasses
import itertools
import math
import os
import signal
import subprocess
import time
from pathlib import Path

import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags.highlevel import AnyReader
from support.graph import STEPS, assert_records_equal, run_command
from support.paths import REPO
from support.processes import (
    INTERRUPTED_RUN_STEPS,
    assert_every_topic_complete,
    children_of,
    long_trace,
    wait_for_steps,
)
from support.rosbag2_rules import check_bag_directory  # the test-side oracle module

from preceding_traffic.sources import load_trace
from preceding_traffic.traces import truncate
from trust_av.graph.bag_records import message_stamp, records_from_bag
from trust_av.system.closed_loop import simulate
from trust_av.system.config import load_run_config
from trust_av.system.metrics import StepRecord
from trust_av.system.outputs import MARKER
from trust_av_common.topics import TOPICS, qualified

RECORDED = {qualified(t.name): t.messages(STEPS) for t in TOPICS if 'recorder' in t.subscribers}
"""Full topic name in a root-namespace run -> messages recorded in STEPS steps."""


def in_process(steps: int = STEPS, trace_arg: str = 'us06') -> list[StepRecord]:
    config = load_run_config(overrides={'planner': {'alpha': 0.5, 'predictor': 'ca'}})
    trace = truncate(load_trace(trace_arg, config.planner.dt_s, config.trace), steps)
    return simulate(config, trace).records


def interrupted_run(bag: Path) -> tuple[subprocess.Popen[str], str]:
    """A run of :func:`conftest.long_trace` that a test stops midway, and that trace."""
    trace = str(long_trace(bag.parent))
    proc = subprocess.Popen(run_command(bag, '--trace', trace, '--max-steps',
                                        str(INTERRUPTED_RUN_STEPS)),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    return proc, trace


def test_graph_equals_in_process(us06_graph_run: tuple[Path, str]) -> None:
    bag, stdout = us06_graph_run
    assert_records_equal(records_from_bag(bag), in_process())
    assert 'final trust' in stdout and bag.with_name('us06.png').stat().st_size > 10_000


def test_every_node_stops_with_its_messages_acknowledged(us06_graph_run: tuple[Path, str]) -> None:
    """On the stop every node waits until its subscribers have acknowledged what it
    published, and says which topics were not (trust_av_common.ros.spin._drain). Readers
    acknowledge on their writer's heartbeat: with Fast DDS's default period (3 s) every
    node's wait ran into its 1 s timeout; the run's profile sets 100 ms."""
    bag, _ = us06_graph_run
    logs = sorted(bag.with_name('us06.logs').glob('*.log'))
    assert {p.stem for p in logs} >= {'preceding_traffic', 'planner', 'ego_plant',
                                      'human_driver', 'trust_monitor', 'recorder'}
    for log in logs:
        assert 'not acknowledged' not in log.read_text(), log.read_text()


def test_the_graphs_own_ego_odometry_replays_as_a_lead(us06_graph_run: tuple[Path, str]) -> None:
    """The ego plant never reports a negative speed (it reported -2e-18 m/s, and -0.0, when
    braked exactly to a stop), so its /ego/odom loads as a preceding-vehicle trace."""
    bag, _ = us06_graph_run
    config = load_run_config(overrides={'preceding_traffic': {'bag_topic': '/ego/odom'}})
    trace = load_trace(str(bag), config.planner.dt_s, config.trace)
    assert trace.steps >= STEPS - 1
    speeds = [float(v) for v in trace.speeds_mps]
    assert min(speeds) >= 0.0 and not any(math.copysign(1.0, v) < 0 for v in speeds)


def test_recording_is_a_rosbag2_bag_by_rosbag2s_rules(us06_graph_run: tuple[Path, str]) -> None:
    """metadata.yaml and the MCAP pass the rules of rosbag2 Jazzy's reader
    (tests/support/rosbag2_rules.py, derived from rosbag2_storage yaml.hpp and the MCAP
    plugin), and rosbags' own rosbag2 reader opens the directory."""
    from rosbags.rosbag2 import Reader
    bag, _ = us06_graph_run
    assert sorted(p.name for p in bag.iterdir()) == [MARKER, 'metadata.yaml', 'us06.mcap']
    assert check_bag_directory(bag) == []
    with Reader(bag) as reader:
        assert reader.message_count == sum(RECORDED.values())
        assert {c.topic for c in reader.connections} == set(RECORDED)


def test_bag_reads_back_with_rosbags(us06_graph_run: tuple[Path, str]) -> None:
    bag, _ = us06_graph_run
    with AnyReader([bag]) as reader:
        topics = {c.topic: c.msgcount for c in reader.connections}
        assert topics == RECORDED         # odometry and tf: + the initial states
        for connection, log_time, raw in reader.messages():
            stamp = message_stamp(reader.deserialize(raw, connection.msgtype))
            assert log_time == stamp.sec * 10**9 + stamp.nanosec     # log time = sim time


def test_bag_decodes_with_mcap_ros2(us06_graph_run: tuple[Path, str]) -> None:
    bag, _ = us06_graph_run
    with (bag / f'{bag.name}.mcap').open('rb') as handle:
        reader = make_reader(handle, decoder_factories=[DecoderFactory()])
        assert reader.get_header().profile == 'ros2'
        summary = reader.get_summary()
        assert summary is not None
        assert {s.encoding for s in summary.schemas.values()} == {'ros2msg'}
        assert all('offered_qos_profiles' in c.metadata for c in summary.channels.values())
        assert any(m.name == 'rosbag2' for m in reader.iter_metadata())
        decoded = 0
        for _schema, channel, message, ros_msg in reader.iter_decoded_messages():
            assert channel.message_encoding == 'cdr'
            if channel.topic == '/trust_monitor/trust':
                stamp = ros_msg.header.stamp
                assert 0.0 <= ros_msg.vector.x <= 1.0
                assert message.log_time == stamp.sec * 10**9 + stamp.nanosec
            decoded += 1
    assert decoded == sum(RECORDED.values())


def command_line(pid: int) -> str:
    return (Path('/proc') / str(pid) / 'cmdline').read_bytes().replace(b'\0', b' ').decode()


def node_pid(orchestrator: int, node: str) -> int:
    """Pid of a node process started by the orchestrator (waits for it to appear)."""
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:
        for pid in children_of(orchestrator):
            if f'__node:={node}' in command_line(pid):
                return pid
        time.sleep(0.2)
    raise AssertionError(f'{node} process not found')


def assert_gone(pids: list[int]) -> None:
    """None of ``pids`` is alive (zombies awaiting their reaper count as gone)."""
    for pid in pids:
        assert not Path(f'/proc/{pid}').exists() or 'Z' in (
            Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[1].split()[0])


def test_killed_node_is_named_and_nothing_is_left(tmp_path: Path) -> None:
    bag = tmp_path / 'killed'
    proc, trace = interrupted_run(bag)
    planner = node_pid(proc.pid, 'planner')
    wait_for_steps(bag, 20)          # let it run some steps
    children = children_of(proc.pid)
    os.kill(planner, signal.SIGKILL)
    _out, err = proc.communicate(timeout=120)
    assert proc.returncode == 2
    assert 'node planner exited with code -9' in err
    assert err.startswith('trust-av run: error:')
    assert_gone(children)                                  # no orphans
    records = records_from_bag(bag)                         # readable up to the kill
    assert 0 < len(records) < INTERRUPTED_RUN_STEPS
    assert_records_equal(records, in_process(len(records), trace))


def test_documented_topic_table_is_the_code_table() -> None:
    """The topics page of the site is filled from the code's table at build time."""
    from trust_av.cli.reference import fill
    from trust_av_common.topics import topic_table_markdown
    page = REPO / 'docs' / 'reference' / 'topics-and-qos.md'
    assert topic_table_markdown() in fill(page.read_text())


@pytest.mark.parametrize('moment', ['at the first steps', 'mid-run'])
def test_sigint_stops_cleanly_with_a_finished_bag(tmp_path: Path, moment: str) -> None:
    """Ctrl-C at any moment: exit 130, one line, every topic holds every complete step."""
    bag = tmp_path / 'interrupted'
    proc, trace = interrupted_run(bag)
    if moment == 'mid-run':
        wait_for_steps(bag, 150)
    else:
        wait_for_steps(bag, 1)
    children = children_of(proc.pid)
    proc.send_signal(signal.SIGINT)
    _out, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    assert 'interrupted' in err and 'Traceback' not in err
    assert_gone(children)
    with AnyReader([bag]) as reader:                # finished normally: it has a summary
        assert reader.message_count > (100 if moment == 'mid-run' else -1)
    assert err.count('\n') == 1
    assert check_bag_directory(bag) == []
    records = records_from_bag(bag)
    assert len(records) == assert_every_topic_complete(bag) < INTERRUPTED_RUN_STEPS
    assert_records_equal(records, in_process(len(records), trace))


def test_killed_recorder_leaves_a_readable_bag(tmp_path: Path) -> None:
    """The recorder killed mid-run: exit 2 naming it, and the truncated MCAP is repaired."""
    bag = tmp_path / 'cut'
    proc, trace = interrupted_run(bag)
    wait_for_steps(bag, 20)
    os.kill(node_pid(proc.pid, 'recorder'), signal.SIGKILL)
    _out, err = proc.communicate(timeout=120)
    assert proc.returncode == 2
    assert 'node recorder exited with code -9' in err
    records = records_from_bag(bag)             # readable again after the repair
    assert 0 < len(records) < INTERRUPTED_RUN_STEPS
    assert_records_equal(records, in_process(len(records), trace))


def tiny_cpu_budget(directory: Path) -> Path:
    """The shipped parameters with a CPU budget per NMPC solve of 1 ns: every solve would
    overrun it."""
    params = directory / 'tiny_budget.yaml'
    params.write_text((REPO / 'config' / 'trust_av.yaml')
                      .read_text().replace('solver_cpu_budget_s: 0.02',
                                           'solver_cpu_budget_s: 0.000000001'))
    assert 'solver_cpu_budget_s: 0.000000001' in params.read_text()
    return params


def twist_stamped_bag(path: Path) -> Path:
    """A rosbag2 bag at ``path`` of a lead's TwistStamped on /vehicle/lead/twist, stamped
    from 100 s: 41 messages, a ramp from 0 to 15 m/s."""
    from rosbags.rosbag2 import StoragePlugin, Writer

    from preceding_traffic.bags import TWIST_STAMPED, TYPESTORE
    types = TYPESTORE.types
    speeds = [min(1.5 * t, 15.0) for t in range(41)]
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conn = writer.add_connection('/vehicle/lead/twist', TWIST_STAMPED, typestore=TYPESTORE)
        for i, v in enumerate(speeds):
            msg = types[TWIST_STAMPED](
                header=types['std_msgs/msg/Header'](
                    stamp=types['builtin_interfaces/msg/Time'](sec=100 + i, nanosec=0),
                    frame_id='base_link'),
                twist=types['geometry_msgs/msg/Twist'](
                    linear=types['geometry_msgs/msg/Vector3'](x=v, y=0.0, z=0.0),
                    angular=types['geometry_msgs/msg/Vector3'](x=0.0, y=0.0, z=0.0)))
            writer.write(conn, (100 + i) * 10**9, TYPESTORE.serialize_cdr(msg, TWIST_STAMPED))
    return path


COMMUTE = 'commute_am'
"""The real commute bag replayed as the preceding vehicle (one bag: the graph path is the
same for any; tests/core/test_bags.py reads every shipped commute bag)."""


def bag_in(command: list[str], source: str) -> list[str]:
    """``command`` with ``--bag-in SOURCE`` for its ``--trace us06`` (as documented; --trace
    BAG is alike)."""
    at = command.index('--trace')
    command[at:at + 2] = ['--bag-in', source]
    return command


@dataclasses.dataclass(frozen=True)
class Run:
    """One of :func:`parallel_runs`: its bag, exit status and output."""

    bag: Path
    returncode: int
    stdout: str
    stderr: str

    def assert_ok(self) -> None:
        assert self.returncode == 0, self.stdout + self.stderr


@pytest.fixture(scope='module')
def parallel_runs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Run]:
    """Two graph runs started at once (14 processes on 2 cores, beside the other test
    workers' runs), each of them a case of its own that the tests below read: ``commute``
    the real commute bag as the lead through ``--bag-in``, with a CPU budget per solve of
    1 ns (:func:`tiny_cpu_budget`, 60 steps); ``twist`` a TwistStamped bag on a remapped
    topic (:func:`twist_stamped_bag`, ``--bag-topic``/``--bag-type``, 30 steps). Starting
    them together is itself the isolation case (test_parallel_runs_are_isolated_and_equal):
    one graph start per case instead of one per case plus four for the isolation. (TAC-GRU
    through the graph == in-process: test_component_contract.py[predictors-gru].)"""
    from preceding_traffic.bags import TWIST_STAMPED
    folder = tmp_path_factory.mktemp('parallel')
    commands = {
        'commute': bag_in(run_command(folder / 'commute', '--max-steps', '60', '--params-file',
                                      str(tiny_cpu_budget(folder))), str(REPO / 'bags' / COMMUTE)),
        'twist': bag_in(run_command(folder / 'twist', '--max-steps', '30', '--bag-topic',
                                    '/vehicle/lead/twist', '--bag-type', TWIST_STAMPED),
                        str(twist_stamped_bag(folder / 'lead_twist')))}
    procs = {name: subprocess.Popen([*command, '--startup-timeout-s', '120'],
                                    stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
             for name, command in commands.items()}
    outputs = {name: proc.communicate(timeout=600) for name, proc in procs.items()}
    return {name: Run(folder / name, procs[name].returncode, *outputs[name]) for name in procs}


def test_parallel_runs_are_isolated_and_equal(parallel_runs: dict[str, Run]) -> None:
    """Graph runs started at once (:func:`parallel_runs`): each succeeds in a domain of its
    own; no cross-talk: every one equals its own in-process run (asserted by the test of
    each case below: test_commute_bag..., test_twist_stamped_bag...; a message of the
    other run would break that)."""
    runs = list(parallel_runs.values())
    for run in runs:
        run.assert_ok()
    # A run that ends before another starts may hand its domain on (seen under load in a
    # fresh-clone CI run with 8 runs: 7 domains); runs that overlap in time must not share one.
    # Each run's [params written, bag finished] lies inside the time it held its lease.
    domains = [run.stdout.split('domain ')[1].split(')')[0] for run in runs]
    spans = [((run.bag.with_name(run.bag.name + '.logs') / 'run_params.yaml').stat().st_mtime,
              (run.bag / 'metadata.yaml').stat().st_mtime) for run in runs]
    for i, j in itertools.combinations(range(len(runs)), 2):
        overlap = spans[i][0] < spans[j][1] and spans[j][0] < spans[i][1]
        assert not (overlap and domains[i] == domains[j]), (domains, spans)
    assert len(set(domains)) >= 2


def test_commute_bag_replays_through_the_graph_whatever_the_cpu_budget(
        parallel_runs: dict[str, Run]) -> None:
    """A real commute bag (:data:`COMMUTE`) as the preceding vehicle, graph == in-process.

    The graph runs with a tiny CPU budget per solve (:func:`tiny_cpu_budget`), the
    in-process reference with the shipped one: in lock-step the budget does not apply
    (results must not depend on timing: ``solver_max_iter`` bounds the work), so the two are
    equal. The budget's fallback in wall mode: test_shadow. (One run for both: each claim is
    graph == in-process on a run of real solves.) With ``--no-plot`` it draws no figure."""
    run = parallel_runs['commute']
    run.assert_ok()
    assert 'plot:' not in run.stdout and not run.bag.with_name('commute.png').exists()  # --no-plot
    trace_arg = str(REPO / 'bags' / COMMUTE)
    config = load_run_config(overrides={'planner': {'alpha': 0.5, 'predictor': 'ca'}})
    assert config.planner.solver_cpu_budget_s == 0.02
    trace = truncate(load_trace(trace_arg, config.planner.dt_s, config.trace), 60)
    assert trace.name == COMMUTE
    assert_records_equal(records_from_bag(run.bag), simulate(config, trace).records)


def test_twist_stamped_bag_on_a_remapped_topic_replays_through_the_graph(
        parallel_runs: dict[str, Run]) -> None:
    """``--bag-in`` with ``--bag-topic``/``--bag-type``: the traffic node replays the bag's own
    topic and type (the orchestrator hands both to the node), equal to the in-process run."""
    from preceding_traffic.bags import TWIST_STAMPED
    run = parallel_runs['twist']
    run.assert_ok()
    config = load_run_config(overrides={
        'planner': {'alpha': 0.5, 'predictor': 'ca'},
        'preceding_traffic': {'bag_topic': '/vehicle/lead/twist',
                              'bag_message_type': TWIST_STAMPED}})
    source = run.bag.with_name('lead_twist')
    trace = truncate(load_trace(str(source), config.planner.dt_s, config.trace), 30)
    assert trace.t0_s == 100.0
    records = records_from_bag(run.bag)
    assert records[0].traffic_speed_mps == 0.0 and records[-1].t_s == pytest.approx(129.0)
    assert_records_equal(records, simulate(config, trace).records)
