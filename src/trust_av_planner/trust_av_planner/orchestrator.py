"""Start the node graph as separate processes, step it in lock-step, stop it cleanly.

ROS 2 launch is not available here, so this module does its job: every node is its own
process (``python -m <node module> --ros-args --params-file ... -p ...``, exactly what
``ros2 run`` would start), in its own process group, killed with the orchestrator if it
dies (``PR_SET_PDEATHSIG``). Each run leases a free ``ROS_DOMAIN_ID`` (a lock file per
domain, so parallel runs never share one) with localhost-only discovery.

Sequence: start the nodes; wait until every topic of the table has its publishers and
subscribers (timeout: a clear error naming what is missing); publish ``/sim/start``; follow
``/clock`` for progress; the run is complete when the recorder, holding every message of
every step, finishes its file and exits (until then every publisher stays up, so nothing
unacknowledged is lost); stop the rest in order (SIGINT, then SIGTERM, then SIGKILL
after grace periods). If any node dies, everything is stopped the same way, the recording
is finished (or repaired if the recorder itself died) and :class:`GraphError` names the
node and its last log lines.
"""

from __future__ import annotations

import contextlib
import ctypes
import fcntl
import os
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

import yaml

from preceding_traffic.traces import SpeedTrace
from trust_av_planner.bag_records import records_from_bag
from trust_av_planner.config import RunConfig
from trust_av_planner.errors import TrustAvError
from trust_av_planner.recorder import repair_mcap
from trust_av_planner.simulate import InitialState, StepRecord, equilibrium_start
from trust_monitor.graph_interface import TOPICS, expected_endpoints

DOMAIN_RANGE = range(1, 102)
"""ROS domain ids leased to runs (Fast DDS: 0-232 are valid; 1-101 avoid the defaults)."""
LOCK_DIR = Path(tempfile.gettempdir()) / 'trust_av_domains'
GRACE_S = {'SIGINT': 5.0, 'SIGTERM': 3.0}


class GraphError(TrustAvError):
    """The graph could not start or a node died; the message names the node."""


@dataclass(frozen=True)
class NodeSpec:
    """One node process."""

    name: str
    module: str
    params: dict[str, Any]


def node_specs(config: RunConfig, trace_arg: str, trace: SpeedTrace, initial: InitialState,
               bag: Path, max_steps: int) -> list[NodeSpec]:
    """The six processes of a simulated run and their per-run parameters."""
    cfg = config.for_trace(trace)
    start = trace.t0_s
    shared = {'speed_max_mps': cfg.planner.speed_max_mps, 'speed_max_from_trace': False}
    return [
        NodeSpec('recorder', 'trust_av_planner.recorder',
                 {'bag_path': str(bag), 'expected_steps': trace.steps}),
        NodeSpec('trust_monitor', 'trust_monitor.monitor_node', {}),
        NodeSpec('ego_plant', 'trust_av_planner.ego_plant_node',
                 {'initial_position_m': initial.av.position_m,
                  'initial_speed_mps': initial.av.speed_mps, 'start_time_s': start}),
        NodeSpec('human_driver', 'human_driver_sim.driver_node',
                 {**shared, 'initial_position_m': initial.human.position_m,
                  'initial_speed_mps': initial.human.speed_mps, 'start_time_s': start}),
        NodeSpec('planner', 'trust_av_planner.planner_node',
                 {**shared, 'alpha': cfg.planner.alpha, 'predictor': cfg.planner.predictor}),
        NodeSpec('preceding_traffic', 'preceding_traffic.traffic_node',
                 {'trace': trace_arg, 'initial_position_m': initial.traffic.position_m,
                  'max_steps': max_steps, 'bag_topic': config.trace.bag_topic,
                  'bag_message_type': config.trace.bag_message_type,
                  'max_sample_gap_s': config.trace.max_sample_gap_s}),
    ]


@contextlib.contextmanager
def lease_domain() -> Iterator[int]:
    """Hold an exclusive lock on a free ROS domain id for the duration of a run."""
    LOCK_DIR.mkdir(parents=True, exist_ok=True)
    for domain in DOMAIN_RANGE:
        handle = (LOCK_DIR / f'{domain}.lock').open('w')
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            handle.close()
            continue
        try:
            yield domain
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)
            handle.close()
        return
    raise GraphError(f'no free ROS domain id in {DOMAIN_RANGE.start}..{DOMAIN_RANGE.stop - 1}')


def _die_with_parent() -> None:
    """In the child: get SIGKILL when the orchestrator dies (no orphans)."""
    libc = ctypes.CDLL('libc.so.6', use_errno=True)
    libc.prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG


@dataclass
class Process:
    """A started node."""

    spec: NodeSpec
    popen: subprocess.Popen[bytes]
    log_path: Path
    log: IO[bytes]

    def tail(self, lines: int = 6) -> str:
        """The last lines of the node's output."""
        self.log.flush()
        text = self.log_path.read_text(errors='replace').strip().splitlines()
        return '\n'.join(text[-lines:])


@dataclass
class GraphRun:
    """Outcome of a graph run."""

    bag: Path
    domain_id: int
    steps: int
    wall_s: float
    startup_s: float


class Graph:
    """The processes of one run."""

    def __init__(self, specs: list[NodeSpec], params_file: Path, domain: int,
                 log_dir: Path) -> None:
        self.specs = specs
        self.params_file = params_file
        self.domain = domain
        self.log_dir = log_dir
        self.processes: list[Process] = []
        self.env = dict(os.environ, ROS_DOMAIN_ID=str(domain),
                        ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST',
                        RMW_IMPLEMENTATION='rmw_fastrtps_cpp', PYTHONUNBUFFERED='1',
                        ROS_LOG_DIR=str(log_dir / 'ros'))

    def start(self) -> None:
        """Start every node process.

        Per-run values go into a second params file with one section per node, after the
        user's file: a node-specific entry there beats the same key in the user's file
        (``-p`` would not: rcl lets a node's own section win over a command-line ``-p``).
        """
        self.log_dir.mkdir(parents=True, exist_ok=True)
        run_params = self.log_dir / 'run_params.yaml'
        run_params.write_text(yaml.safe_dump(
            {spec.name: {'ros__parameters': spec.params} for spec in self.specs if spec.params},
            sort_keys=True))
        for spec in self.specs:
            command = [sys.executable, '-m', spec.module, '--ros-args', '-r',
                       f'__node:={spec.name}', '--params-file', str(self.params_file),
                       '--params-file', str(run_params)]
            log_path = self.log_dir / f'{spec.name}.log'
            log = log_path.open('wb')
            popen = subprocess.Popen(command, stdout=log, stderr=subprocess.STDOUT,
                                     stdin=subprocess.DEVNULL, env=self.env,
                                     start_new_session=True, preexec_fn=_die_with_parent)
            self.processes.append(Process(spec, popen, log_path, log))

    def by_name(self, name: str) -> Process:
        """The process of a node."""
        return next(p for p in self.processes if p.spec.name == name)

    def check_alive(self, allowed_done: set[str]) -> None:
        """Raise :class:`GraphError` naming a node that exited when it should not have."""
        for process in self.processes:
            code = process.popen.poll()
            if code is None:
                continue
            if process.spec.name in allowed_done and code == 0:
                continue
            raise GraphError(f'node {process.spec.name} exited with code {code}'
                             f'{" (killed by signal " + str(-code) + ")" if code < 0 else ""}; '
                             f'last output:\n{process.tail()}')

    def stop(self, names: list[str] | None = None) -> None:
        """Stop nodes in order: SIGINT, then SIGTERM, then SIGKILL after grace periods."""
        targets = [p for p in self.processes if names is None or p.spec.name in names]
        for sig, grace in ((signal.SIGINT, GRACE_S['SIGINT']),
                           (signal.SIGTERM, GRACE_S['SIGTERM']), (signal.SIGKILL, 5.0)):
            alive = [p for p in targets if p.popen.poll() is None]
            if not alive:
                break
            for process in alive:
                with contextlib.suppress(ProcessLookupError):
                    os.killpg(process.popen.pid, sig)
            deadline = time.monotonic() + grace
            while time.monotonic() < deadline and any(p.popen.poll() is None for p in alive):
                time.sleep(0.02)
        for process in targets:
            if process.popen.poll() is None:
                process.popen.wait()
            with contextlib.suppress(ProcessLookupError):
                os.killpg(process.popen.pid, signal.SIGKILL)  # stray children of the group
            process.log.close()


@contextlib.contextmanager
def graph_session(graph: Graph, name: str) -> Iterator[tuple[Any, Any]]:
    """Start ``graph``'s node processes and this process's own rclpy node ``name`` (with a
    single-threaded executor) on the graph's domain; on exit, also on errors, destroy the
    node, shut its context down and stop every process.

    No rclpy signal handler is installed: SIGINT must reach the caller as
    KeyboardInterrupt so that the nodes are stopped and the recording is finished.
    """
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.signals import SignalHandlerOptions

    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    context = Context()
    try:
        graph.start()
        rclpy.init(context=context, domain_id=graph.domain,
                   signal_handler_options=SignalHandlerOptions.NO)
        node = rclpy.create_node(name, context=context)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        try:
            yield node, executor
        finally:
            node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)
        graph.stop()


def run_graph(config: RunConfig, trace_arg: str, trace: SpeedTrace, params_file: Path,
              bag: Path, *, max_steps: int = 0, startup_timeout_s: float = 30.0,
              step_timeout_s: float = 30.0,
              on_step: Callable[[int, int], None] | None = None) -> GraphRun:
    """Run the whole graph over ``trace`` (already truncated to ``max_steps``) into ``bag``.

    Raises:
        GraphError: the graph did not connect in time, a node died, or a step stalled.
    """
    from rosgraph_msgs.msg import Clock
    from std_msgs.msg import Empty

    from trust_monitor.ros_support import QOS

    initial = equilibrium_start(config.for_trace(trace), trace)
    specs = node_specs(config, trace_arg, trace, initial, bag, max_steps)
    started = time.monotonic()
    with lease_domain() as domain:
        graph = Graph(specs, params_file, domain, bag.with_suffix('.logs'))
        ok = False
        try:
            with graph_session(graph, 'orchestrator') as (node, executor):
                progress = {'step': -1}

                def on_clock(msg: Clock) -> None:
                    ns = msg.clock.sec * 1_000_000_000 + msg.clock.nanosec
                    progress['step'] = round((ns * 1e-9 - trace.t0_s) / trace.dt_s)
                    if on_step is not None:
                        on_step(progress['step'] + 1, trace.steps)

                node.create_subscription(Clock, '/clock', on_clock, QOS['CLOCK'])
                start_pub = node.create_publisher(Empty, '/sim/start', QOS['LATCHED'])
                _wait_connected(graph, node, executor, startup_timeout_s)
                startup = time.monotonic() - started
                start_pub.publish(Empty())
                # The run is complete when the recorder holds every message of every step
                # and exits by itself; the other nodes keep their publishers up until then.
                last_step, last_change = -1, time.monotonic()
                recorder = graph.by_name('recorder').popen
                while recorder.poll() is None:
                    executor.spin_once(timeout_sec=0.05)
                    graph.check_alive({'recorder'})
                    if progress['step'] != last_step:
                        last_step, last_change = progress['step'], time.monotonic()
                    elif time.monotonic() - last_change > step_timeout_s:
                        what = ('node recorder did not receive every message of the run'
                                if last_step + 1 >= trace.steps else
                                f'no progress at step {last_step}')
                        raise GraphError(f'{what} in {step_timeout_s:g} s; node logs in '
                                         f'{graph.log_dir}')
                graph.check_alive({'recorder'})
                ok = True
        finally:
            # graph_session has stopped every node by now; an unfinished recording is
            # closed so that what was recorded can still be read.
            recorder_ran = any(p.spec.name == 'recorder' for p in graph.processes)
            if (not ok and recorder_ran and bag.exists()
                    and graph.by_name('recorder').popen.returncode != 0):
                repair_mcap(bag)
    return GraphRun(bag=bag, domain_id=domain, steps=trace.steps,
                    wall_s=time.monotonic() - started, startup_s=startup)


def run_graph_records(config: RunConfig, trace_arg: str, trace: SpeedTrace, params_file: Path,
                      bag: Path, **options: Any) -> tuple[GraphRun, list[StepRecord]]:
    """:func:`run_graph`, then the recording read back (rosbags) as one record per step.

    Raises:
        GraphError: as :func:`run_graph`.
        TrustAvError: the recording does not hold every step of the run.
    """
    result = run_graph(config, trace_arg, trace, params_file, bag, **options)
    records = records_from_bag(bag)
    if len(records) != trace.steps:
        raise TrustAvError(f'{bag}: {len(records)} complete steps recorded, expected '
                           f'{trace.steps}')
    return result, records


def _wait_connected(graph: Graph, node: Any, executor: Any, timeout_s: float) -> None:
    """Wait until every topic has its expected publishers and subscribers."""
    expected = expected_endpoints()
    deadline = time.monotonic() + timeout_s
    missing: list[str] = []
    while time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.05)
        graph.check_alive(set())
        missing = []
        for topic in TOPICS:
            pubs, subs = expected[topic.name]
            have_pubs = node.count_publishers(topic.name)
            have_subs = node.count_subscribers(topic.name)
            if topic.name == '/clock':
                have_subs -= 1  # the orchestrator's own progress subscription
            if have_pubs < pubs or have_subs < subs:
                missing.append(f'{topic.name} ({have_pubs}/{pubs} publishers, '
                               f'{have_subs}/{subs} subscribers)')
        if not missing:
            return
    raise GraphError(f'graph not connected after {timeout_s:g} s: ' + '; '.join(missing))

