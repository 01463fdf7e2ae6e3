"""Start the node graph as separate processes, step it in lock-step, stop it cleanly.

ROS 2 launch is not available here, so this module does its job: every node is its own
process (:mod:`trust_av_planner.graph.processes`), and each run leases a free
``ROS_DOMAIN_ID`` (:mod:`trust_av_planner.graph.domains`) with localhost-only discovery.

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
import os
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from preceding_traffic.traces import SpeedTrace
from trust_av_planner.errors import TrustAvPlannerError
from trust_av_planner.graph.bag_records import records_from_bag
from trust_av_planner.graph.domains import lease_domain
from trust_av_planner.graph.processes import Graph, GraphError, NodeSpec
from trust_av_planner.graph.recorder import repair_mcap
from trust_av_planner.system.closed_loop import InitialState, equilibrium_start
from trust_av_planner.system.config import RunConfig
from trust_av_planner.system.metrics import StepRecord
from trust_monitor.common.topics import TOPICS, expected_endpoints


def node_specs(config: RunConfig, trace_arg: str, trace: SpeedTrace, initial: InitialState,
               bag: Path, max_steps: int) -> list[NodeSpec]:
    """The six processes of a simulated run and their per-run parameters."""
    cfg = config.for_trace(trace)
    start = trace.t0_s
    shared = {'speed_max_mps': cfg.planner.speed_max_mps, 'speed_max_from_trace': False}
    return [
        NodeSpec('recorder', 'trust_av_planner.graph.recorder_node',
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


@dataclass
class GraphRun:
    """Outcome of a graph run."""

    bag: Path
    domain_id: int
    steps: int
    wall_s: float
    startup_s: float


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

    from trust_monitor.ros.qos import QOS

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

                node.create_subscription(Clock, 'clock', on_clock, QOS['CLOCK'])
                start_pub = node.create_publisher(Empty, 'sim/start', QOS['LATCHED'])
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
        TrustAvPlannerError: the recording does not hold every step of the run.
    """
    result = run_graph(config, trace_arg, trace, params_file, bag, **options)
    records = records_from_bag(bag)
    if len(records) != trace.steps:
        raise TrustAvPlannerError(f'{bag}: {len(records)} complete steps recorded, expected '
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
            if topic.name == 'clock':
                have_subs -= 1  # the orchestrator's own progress subscription
            if have_pubs < pubs or have_subs < subs:
                missing.append(f'{topic.name} ({have_pubs}/{pubs} publishers, '
                               f'{have_subs}/{subs} subscribers)')
        if not missing:
            return
    raise GraphError(f'graph not connected after {timeout_s:g} s: ' + '; '.join(missing))

