"""The floor of the node graph: the same six processes with no computation, timed like it.

The replica has the graph's nodes as separate processes on a leased ROS domain, started,
connected, observed and stopped by the orchestrator's own machinery (its ``Graph`` and
``graph_session``, :mod:`trust_av.graph.session`), each node spun by
:func:`trust_av_common.ros.spin.spin_node` (the same executor). Built from the topic table
(:data:`trust_av_common.topics.TOPICS`): the same topics, message types and QoS
profiles (:data:`trust_av_common.ros.qos.QOS`), one message per topic and step plus the
initial states, and the same lock-step chain (who waits for which stamps,
:func:`trust_av_common.step_chain.step_chain`). A node publishes constant messages of the
graph's shapes (N-point trajectories, diagnostics with as many key/values as the graph's)
where only the stamp changes, and the recorder takes raw CDR and writes it to MCAP (zstd
chunks, as the project's recorder) with nothing else per message. So the floor changes
when the graph's table changes, and the graph's time over it is what its own work costs.

Timing, as for the graph in ``bench_graph.py``: the orchestrator's node receives every
``/clock``; start-up = launch to the first ``/clock``, steady state = first to last
``/clock`` per step, shutdown = last ``/clock`` until every process has stopped; CPU time
of every node process over the steady state (``/proc``), per step.

    python benchmarks/bench_floor.py [--steps 600] [--repeats 1] [--no-recorder] [--out F]

A node of the floor is this module, started by the orchestrator as
``python -m bench_floor --ros-args -r __node:=<node> --params-file ...``.
"""

from __future__ import annotations

import argparse
import datetime
import itertools
import json
import os
import statistics
import struct
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
MODULE = Path(__file__).stem
STAMP = {1: struct.Struct('<iI'), 0: struct.Struct('>iI')}
"""A stamp (sec, nanosec) by the CDR encapsulation's second byte (1: little-endian)."""


def cdr_stamp(data: bytes, offset: int) -> tuple[int, int]:
    """The (sec, nanosec) at ``offset`` of a serialised message, in its byte order."""
    sec, nanosec = STAMP[data[1] & 1].unpack_from(data, offset)
    return sec, nanosec
DIAGNOSTIC_VALUES = {'ego/planner_status': 8, 'human/driver_status': 4}
"""Key/values per status message, as planner_node and driver_node publish them."""


@dataclass(frozen=True)
class FloorConfig:
    """A floor node's parameters (``dt_s`` and ``horizon_steps`` from the params file).

    Attributes:
        dt_s: step, s.
        horizon_steps: points per trajectory.
        steps: steps of the run.
        recorder: a recorder ends the run (without one the source exits after the last step).
        bag_path: the recorder's MCAP file.
        compression: the recorder's chunk compression, ``zstd`` or ``none``.
        raw_inputs: the nodes take their inputs as bytes and read only the stamp (a floor
            below the specified one, which takes rclpy messages; for comparison with the
            graph, which reads its inputs from bytes).
    """

    dt_s: float
    horizon_steps: int
    steps: int = 0
    recorder: bool = True
    bag_path: str = ''
    compression: str = 'zstd'
    raw_inputs: bool = False


# ---------------------------------------------------------------------------- node side


def template(topic: str, msgtype: str, horizon: int, dt_s: float) -> tuple[Any, Any]:
    """A constant message of ``topic`` shaped like the graph's, and its stamp object."""
    from geometry_msgs.msg import TransformStamped
    from tf2_msgs.msg import TFMessage

    from trust_av_common.ros.messages import (
        diagnostics,
        header,
        message_class,
        odometry,
        trajectory,
        vehicle_markers,
    )

    if msgtype == 'nav_msgs/msg/Odometry':
        msg = odometry(0, 100.0, 10.0, topic.split('/')[0])
    elif msgtype == 'tf2_msgs/msg/TFMessage':
        msg = TFMessage(transforms=[TransformStamped(header=header(0, 'odom'),
                                                     child_frame_id='ego')])
        return msg, msg.transforms[0].header.stamp
    elif msgtype == 'visualization_msgs/msg/MarkerArray':
        msg = vehicle_markers(4.5)
        return msg, msg.markers[0].header.stamp
    elif msgtype == 'trajectory_msgs/msg/JointTrajectory':
        msg = trajectory(0, dt_s, frame_id='ego', accelerations=[0.25] * horizon)
    elif msgtype == 'diagnostic_msgs/msg/DiagnosticArray':
        count = DIAGNOSTIC_VALUES.get(topic, 4)
        msg = diagnostics(0, 'floor_status', True, 'Solve_Succeeded',
                          {f'value_{k:02d}': repr(1 / 3) for k in range(count)})
    else:
        msg = message_class(msgtype)()
    return msg, (msg.clock if msgtype == 'rosgraph_msgs/msg/Clock' else msg.header.stamp)


def _make_step_node(name: str) -> Any:
    from rclpy.node import Node
    from step_gate import StepGate

    from trust_av_common.lockstep import split_ns, stamp_ns
    from trust_av_common.ros.messages import message_class
    from trust_av_common.ros.parameters import declare_config
    from trust_av_common.ros.qos import QOS
    from trust_av_common.step_chain import step_chain
    from trust_av_common.topics import TOPIC

    class FloorNode(Node):  # type: ignore[misc]
        """One node of the chain: waits as the graph's node does, publishes constants."""

        def __init__(self) -> None:
            super().__init__(name)
            self.config = declare_config(self, FloorConfig)
            chain = step_chain()
            me = chain.node(name)
            self.is_source = name == chain.source
            self.dt_ns = stamp_ns(self.config.dt_s)
            self.gate = StepGate(me, 0, self.dt_ns)
            self.finished = False
            self.exit_code = 0
            self.stopping = False  # set by spin_node on a stop request: no further step
            self.started = False
            self.outputs = []
            for port in me.outputs:
                topic = TOPIC[port.topic]
                pub = self.create_publisher(message_class(topic.msgtype), topic.name,
                                            QOS[topic.qos])
                msg, stamp = template(topic.name, topic.msgtype, self.config.horizon_steps,
                                      self.config.dt_s)
                self.outputs.append((pub, msg, stamp, port.offset))
                if topic.name in me.initial:
                    pub.publish(msg)  # the initial state, stamped 0
            for port in me.inputs:
                topic = TOPIC[port.topic]
                if self.config.raw_inputs:  # the header's stamp, first after the CDR header
                    self.create_subscription(
                        message_class(topic.msgtype), topic.name,
                        lambda data, t=topic.name: self.on_stamp(t, cdr_stamp(data, 4)),
                        QOS[topic.qos], raw=True)
                else:
                    self.create_subscription(message_class(topic.msgtype), topic.name,
                                             lambda m, t=topic.name: self.on_input(t, m),
                                             QOS[topic.qos])
            for start in me.start:
                topic = TOPIC[start]
                self.create_subscription(message_class(topic.msgtype), topic.name,
                                         self.on_start, QOS[topic.qos])

        def on_start(self, _msg: Any) -> None:
            if not self.started:
                self.started = True
                self.publish_step(0)

        def on_input(self, topic: str, msg: Any) -> None:
            stamp = msg.header.stamp
            self.on_stamp(topic, (stamp.sec, stamp.nanosec))

        def on_stamp(self, topic: str, stamp: tuple[int, int]) -> None:
            for step in self.gate.put(topic, stamp[0] * 1_000_000_000 + stamp[1]):
                if not self.is_source:
                    self.publish_step(step)
                elif self.stopping:
                    continue  # a stop was requested: no further step
                elif step + 1 < self.config.steps:
                    self.publish_step(step + 1)
                else:
                    self.get_logger().info(f'done: {self.config.steps} steps')
                    self.finished = not self.config.recorder

        def publish_step(self, step: int) -> None:
            for pub, msg, stamp, offset in self.outputs:
                stamp.sec, stamp.nanosec = split_ns((step + offset) * self.dt_ns)
                pub.publish(msg)

    return FloorNode()


def _make_recorder() -> Any:
    from diagnostic_msgs.msg import DiagnosticArray
    from mcap.writer import CompressionType, Writer
    from rclpy.node import Node
    from rosbags.typesys import Stores, get_typestore

    from trust_av.graph.bag_writer import STAMP_IN_FIRST_ELEMENT
    from trust_av.graph.recorder_node import READY_CHECK_PERIOD_S
    from trust_av.graph.session import RECORDER_STATUS
    from trust_av_common.ros.messages import diagnostics, message_class
    from trust_av_common.ros.parameters import declare_config
    from trust_av_common.ros.qos import QOS
    from trust_av_common.step_chain import RECORDER, step_chain
    from trust_av_common.topics import TOPICS

    class FloorRecorder(Node):  # type: ignore[misc]
        """Raw subscriptions to every recorded topic; each message written as it comes.
        Says ``ready`` on ``recorder/status`` once every subscription has matched its
        publishers, as the project's recorder does (a message published before that, on a
        volatile subscription, would be lost and the floor would wait for it forever)."""

        def __init__(self) -> None:
            super().__init__(RECORDER)
            self.config = declare_config(self, FloorConfig)
            state = step_chain().state_topics
            store = get_typestore(Stores.ROS2_JAZZY)
            self.writer = Writer(self.config.bag_path, compression=CompressionType[
                self.config.compression.upper()])
            self.writer.start(profile='ros2', library='bench_floor')
            self.count = 0
            self.total = 0
            self.finished = False
            self.exit_code = 0
            schemas: dict[str, int] = {}
            offsets: dict[int, int] = {}
            self.offsets = offsets
            self.matching: list[tuple[Any, int]] = []
            for topic in TOPICS:
                if RECORDER not in topic.subscribers:
                    continue
                if topic.msgtype not in schemas:
                    text, _ = store.generate_msgdef(topic.msgtype, ros_version=2)
                    schemas[topic.msgtype] = self.writer.register_schema(
                        topic.msgtype, 'ros2msg', text.encode())
                channel = self.writer.register_channel(topic.name, 'cdr',
                                                       schemas[topic.msgtype])
                self.total += topic.per_step * self.config.steps + (topic.name in state)
                offsets[channel] = 8 if topic.msgtype in STAMP_IN_FIRST_ELEMENT else 4
                sub = self.create_subscription(message_class(topic.msgtype), topic.name,
                                               lambda data, c=channel: self.on_message(c, data),
                                               QOS[topic.qos], raw=True)
                self.matching.append((sub, len(topic.publishers)))
            self.pub_status = self.create_publisher(DiagnosticArray, RECORDER_STATUS,
                                                    QOS['LATCHED'])
            self.ready_timer = self.create_timer(READY_CHECK_PERIOD_S, self.check_ready)

        def check_ready(self) -> None:
            if all(sub.get_publisher_count() >= needed for sub, needed in self.matching):
                self.ready_timer.cancel()
                self.pub_status.publish(diagnostics(0, RECORDER, True, 'ready',
                                                    {'state': 'ready', 'steps': '0'}))

        def on_message(self, channel: int, data: bytes) -> None:
            sec, nanosec = cdr_stamp(data, self.offsets[channel])
            ns = sec * 1_000_000_000 + nanosec
            self.writer.add_message(channel, log_time=ns, data=data, publish_time=ns)
            self.count += 1
            if self.count == self.total:
                self.close()

        def close(self) -> None:
            if not self.finished:
                self.finished = True
                self.writer.finish()  # closes the file it opened
                self.get_logger().info(f'recorded {self.count} messages')

    return FloorRecorder()


def node_main(argv: list[str]) -> int:
    """A floor node process (``--ros-args -r __node:=<name> ...``)."""
    from trust_av_common.ros.spin import spin_node
    from trust_av_common.step_chain import RECORDER

    name = next(a.split(':=', 1)[1] for a in argv if a.startswith('__node:='))
    factory: Callable[[], Any] = (_make_recorder if name == RECORDER
                                  else lambda: _make_step_node(name))
    return spin_node(factory, [sys.argv[0], *argv])


# ---------------------------------------------------------------------- orchestrator side


def task_cpu_s(pid: int) -> float:
    """CPU time of a process's live threads, s (``/proc/<pid>/task/*/schedstat``, ns: the
    per-step figures need finer than the 10 ms ticks of ``/proc/<pid>/stat``)."""
    total = 0
    for task in os.listdir(f'/proc/{pid}/task'):
        try:
            total += int(Path(f'/proc/{pid}/task/{task}/schedstat').read_text().split()[0])
        except (FileNotFoundError, ProcessLookupError):
            continue  # the thread ended meanwhile
    return total * 1e-9


def cpu_seconds() -> dict[str, float]:
    """CPU time (s) of this process (``orchestrator``) and of each child process, by node
    name (``__node:=`` of its command line)."""
    me = os.getpid()
    out = {'orchestrator': task_cpu_s(me)}
    for entry in os.listdir('/proc'):
        if not entry.isdigit():
            continue
        try:
            stat = Path(f'/proc/{entry}/stat').read_text()
            if int(stat.rsplit(')', 1)[1].split()[1]) != me:
                continue
            cmdline = Path(f'/proc/{entry}/cmdline').read_bytes().split(b'\0')
            name = next((a.split(b':=', 1)[1].decode() for a in cmdline
                         if a.startswith(b'__node:=')), f'pid {entry}')
            out[name] = task_cpu_s(int(entry))
        except (FileNotFoundError, ProcessLookupError):
            continue  # the process ended meanwhile
    return out


class StepClock:
    """Wall times at which the observer received each step's ``/clock``; CPU of every
    process at the first and the last one.

    Args:
        steps: steps of the run.
    """

    def __init__(self, steps: int) -> None:
        self.steps = steps
        self.started = time.monotonic()
        self.received: dict[int, float] = {}
        self.cpu: list[dict[str, float]] = []
        self.ended: float | None = None

    def on_step(self, step: int, _total: int = 0) -> None:
        """The observer got ``/clock`` of 1-based ``step`` (the orchestrator's on_step)."""
        self.received.setdefault(step - 1, time.monotonic())
        if step == 1 or step == self.steps:
            self.cpu.append(cpu_seconds())

    def end(self) -> None:
        """Every process has stopped."""
        self.ended = time.monotonic()

    def figures(self) -> dict[str, Any]:
        """Start-up, steady state and shutdown, s and ms per step; CPU ms per step."""
        assert self.ended is not None and self.received
        first, last = min(self.received), max(self.received)
        t_first, t_last = self.received[first], self.received[last]
        intervals = max(last - first, 1)
        cpu: dict[str, float] = {}
        if len(self.cpu) == 2:
            before, after = self.cpu
            cpu = {k: 1e3 * (after[k] - before[k]) / intervals for k in after if k in before}
            cpu['total'] = sum(cpu.values())
        times = [self.received[k] for k in sorted(self.received)]
        gaps = sorted(1e3 * (b - a) for a, b in itertools.pairwise(times)) or [0.0]
        return {'steps': self.steps, 'clocks_seen': len(self.received),
                'step_ms': {'p50': gaps[len(gaps) // 2], 'p99': gaps[int(0.99 * (len(gaps) - 1))],
                            'max': gaps[-1]},
                'startup_s': t_first - self.started,
                'steady_ms_per_step': 1e3 * (t_last - t_first) / intervals,
                'shutdown_s': self.ended - t_last, 'cpu_ms_per_step': cpu}


def _wait_connected(session: Any, nodes: tuple[str, ...], timeout_s: float) -> None:
    """Wait until every topic has its expected publishers and subscribers (the orchestrator's
    own /clock subscription not counted) and the recorder, if any, says ``ready``."""
    from trust_av.graph.processes import RECORDER, GraphError
    from trust_av_common.topics import expected_endpoints

    expected = expected_endpoints(nodes)
    deadline = time.monotonic() + timeout_s
    missing: list[str] = []
    while time.monotonic() < deadline:
        session.executor.spin_once(timeout_sec=0.05)
        session.graph.check_alive(set())
        missing = [name for name, (pubs, subs) in expected.items()
                   if session.node.count_publishers(name) < pubs
                   or session.node.count_subscribers(name) - (name == 'clock') < subs]
        if RECORDER in nodes and session.recorder_state != 'ready':
            missing.append('the recorder has not matched every publisher')
        if not missing:
            return
    raise GraphError(f'floor not connected after {timeout_s:g} s: {", ".join(missing)}')


def run_floor(steps: int, work: Path, *, recorder: bool = True, compression: str = 'zstd',
              project_recorder: bool = False, raw_inputs: bool = False,
              startup_timeout_s: float = 30.0, step_timeout_s: float = 30.0
              ) -> dict[str, Any]:
    """Run the floor for ``steps`` steps with logs and the bag under ``work``.

    ``project_recorder``: the project's recorder node instead of the raw one (an ablation:
    the difference is the recorder's own cost over the floor's).

    The sequence of :func:`trust_av.graph.orchestrator.run_graph`: start the processes,
    wait until connected, publish ``/sim/start``, spin the orchestrator's node until the
    recorder (or, without one, the source) exits, stop everything.

    Returns:
        :meth:`StepClock.figures`, plus ``bag_bytes``.

    Raises:
        GraphError: the floor did not connect, a node died, or a step stalled.
    """
    from rosgraph_msgs.msg import Clock
    from std_msgs.msg import Empty

    from trust_av.graph.domains import lease_domain
    from trust_av.graph.processes import Graph, GraphError, NodeSpec
    from trust_av.graph.session import graph_session
    from trust_av.system.config import DEFAULT_PARAMS_FILE, load_run_config
    from trust_av_common.lockstep import stamp_ns
    from trust_av_common.ros.messages import msg_ns
    from trust_av_common.ros.qos import QOS
    from trust_av_common.step_chain import RECORDER, step_chain

    chain = step_chain()
    dt_ns = stamp_ns(load_run_config(DEFAULT_PARAMS_FILE).planner.dt_s)
    names = ((RECORDER,) if recorder else ()) + tuple(n.name for n in reversed(chain.nodes))
    ender = RECORDER if recorder else chain.source
    bag = work / 'floor.mcap'
    params = {'steps': steps, 'recorder': recorder, 'bag_path': str(bag),
              'compression': compression, 'raw_inputs': raw_inputs}
    specs = [NodeSpec(name, MODULE, dict(params)) for name in names]  # no YAML aliases
    if recorder and project_recorder:
        bag = work / 'project_bag'
        specs[0] = NodeSpec(RECORDER, 'trust_av.graph.recorder_node',
                            {'bag_path': str(bag), 'expected_steps': steps})
    clock = StepClock(steps)
    with lease_domain() as domain:
        graph = Graph(specs, (DEFAULT_PARAMS_FILE,), domain, work / 'logs')
        graph.env['PYTHONPATH'] = os.pathsep.join(
            [str(HERE), *filter(None, [graph.env.get('PYTHONPATH')])])
        with graph_session(graph, 'orchestrator') as session:
            node, executor = session.node, session.executor
            node.create_subscription(
                Clock, 'clock', lambda msg: clock.on_step(msg_ns(msg.clock) // dt_ns + 1),
                QOS['CLOCK'])
            start_pub = node.create_publisher(Empty, 'sim/start', QOS['LATCHED'])
            _wait_connected(session, names, startup_timeout_s)
            start_pub.publish(Empty())
            process = graph.by_name(ender).popen
            seen, last_change = 0, time.monotonic()
            while process.poll() is None:
                executor.spin_once(timeout_sec=0.05)
                graph.check_alive({ender})
                if len(clock.received) != seen:
                    seen, last_change = len(clock.received), time.monotonic()
                elif time.monotonic() - last_change > step_timeout_s:
                    raise GraphError(f'floor: no progress after {seen} clocks in '
                                     f'{step_timeout_s:g} s; logs in {graph.log_dir}')
            graph.check_alive({ender})
    clock.end()
    figures = clock.figures()
    figures['bag_bytes'] = (sum(f.stat().st_size for f in bag.rglob('*')) if bag.is_dir()
                            else bag.stat().st_size) if recorder else 0
    return figures


def summary(values: list[float]) -> dict[str, float]:
    """Median, min and max."""
    return {'median': statistics.median(values), 'min': min(values), 'max': max(values)}


def describe(name: str, figures: dict[str, Any]) -> str:
    """One line of a run's figures."""
    cpu = figures['cpu_ms_per_step'].get('total', float('nan'))
    return (f"{name}: {figures['steady_ms_per_step']:.2f} ms/step steady "
            f"({figures['steps']} steps, {figures['clocks_seen']} clocks seen), start-up "
            f"{figures['startup_s']:.2f} s, shutdown {figures['shutdown_s']:.2f} s, CPU "
            f'{cpu:.2f} ms/step (all processes)')


def load() -> str:
    """The 1, 5 and 15 minute load averages, as ``uptime`` shows them."""
    return ', '.join(f'{x:.2f}' for x in os.getloadavg())


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if '--ros-args' in argv:
        return node_main(argv)
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--steps', type=int, default=600)
    parser.add_argument('--repeats', type=int, default=1)
    parser.add_argument('--no-recorder', action='store_true',
                        help='without the recorder (the source ends the run)')
    parser.add_argument('--compression', choices=('zstd', 'none'), default='zstd')
    parser.add_argument('--project-recorder', action='store_true',
                        help="the project's recorder node instead of the raw one (ablation)")
    parser.add_argument('--raw-inputs', action='store_true',
                        help='the nodes take their inputs as bytes and read only the stamp '
                             '(a lower floor than the specified one; the graph reads its '
                             'inputs from bytes too)')
    parser.add_argument('--keep', type=Path, help='keep logs and bag in this directory')
    parser.add_argument('--out', type=Path, help='results JSON')
    args = parser.parse_args(argv)
    if args.steps < 2 or args.repeats < 1:
        print(f'error: --steps must be >= 2 and --repeats >= 1, got {args.steps}, '
              f'{args.repeats}', file=sys.stderr)
        return 2
    runs = []
    for repeat in range(args.repeats):
        with tempfile.TemporaryDirectory() as tmp:
            work = args.keep / f'floor_{repeat}' if args.keep else Path(tmp)
            work.mkdir(parents=True, exist_ok=True)
            load_before = load()
            figures = run_floor(args.steps, work, recorder=not args.no_recorder,
                                compression=args.compression,
                                project_recorder=args.project_recorder,
                                raw_inputs=args.raw_inputs)
            figures['load_before'], figures['load_after'] = load_before, load()
            runs.append(figures)
            print(describe(f'floor run {repeat + 1}', figures) + f' (load {load_before})',
                  flush=True)
    result = {
        'date': datetime.datetime.now(datetime.UTC).isoformat(timespec='seconds'),
        'cpu_count': os.cpu_count(), 'steps': args.steps, 'recorder': not args.no_recorder,
        'compression': args.compression, 'project_recorder': args.project_recorder,
        'raw_inputs': args.raw_inputs,
        'runs': runs,
        'steady_ms_per_step': summary([r['steady_ms_per_step'] for r in runs]),
    }
    if args.out:
        args.out.write_text(json.dumps(result, indent=2) + '\n')
        print(f'wrote {args.out}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
