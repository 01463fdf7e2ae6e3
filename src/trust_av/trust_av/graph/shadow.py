"""``trust-av shadow``: a recorded bag replayed at real-time speed into the planner and the
trust monitor running in wall-clock mode; their outputs recorded to MCAP.

Processes: ``planner`` and ``trust_monitor`` (``clock_mode: wall``, started and stopped by
:class:`trust_av.graph.processes.Graph` on a leased domain). This process is the
player and the recorder: a wall-clock loop at the same control rate publishes the lead
vehicle's odometry and speed preview (:class:`~preceding_traffic.replay.LeadReplay`,
stamps = now) and the ego odometry, which is *simulated*: the latest ``/ego/accel_cmd``
integrated over the real elapsed time (:func:`trust_av_common.kinematics.integrate`), because
the commute bags hold only the lead vehicle. There is no human follower: the planner runs
with ``human_odom_topic: ''`` (its plan estimator observes only the AV's acceleration, so a
shadow run requires one that does not declare the ``follower_state`` need, e.g. ca or cv).
Recorded as ``ros2 bag record`` does: log time = receive time, publish time = header stamp.
The player publishes on the planner's input topics (``lead_odom_topic``, ...), so a params
file that remaps them is exercised end to end.

:func:`run_wall_graph` (``trust-av shadow --whole-graph``) runs every node in wall mode
instead: ``preceding_traffic`` replays the bag at real time after ``/sim/start``,
``ego_plant`` and ``human_driver`` simulate the two vehicles over real elapsed time, and this
process only records every topic. With a follower, any plan estimator may be used.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Collection
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from preceding_traffic.replay import LeadReplay
from preceding_traffic.traces import SpeedTrace
from trust_av.graph import stop_signals
from trust_av.graph.bag_writer import BagWriter, DiskFullError
from trust_av.graph.domains import lease_domain
from trust_av.graph.lifecycle_client import MANAGED_NODES, set_states
from trust_av.graph.orchestrator import node_specs, write_record
from trust_av.graph.processes import Graph, GraphError, NodeSpec
from trust_av.graph.publication_ledger import Lost, PublicationLedger, Publisher, check_lossless
from trust_av.graph.session import foreign_participants, graph_session
from trust_av.system.closed_loop import equilibrium_start
from trust_av.system.config import RunConfig
from trust_av_common.kinematics import VehicleState, advance
from trust_av_common.topics import TOPIC, TOPICS, VEHICLE_FRAMES, qualified
from trust_av_common.wall_clock import NS_PER_S, LoopStats, WallClockConfig
from trust_av_planner.planner_params import PlannerTopics

__all__ = ['AFTER_START', 'ShadowRun', 'run_shadow', 'run_wall_graph']

OUTPUTS = ('/ego/plan', '/ego/expected_plan', '/ego/accel_cmd', '/ego/planner_status',
           '/trust_monitor/trust')
"""The two nodes' outputs, recorded with the replayed lead and ego odometry."""
SHADOW_NODES = ('planner', 'trust_monitor')
WALL_GRAPH_NODES = ('preceding_traffic', 'planner', 'ego_plant', 'human_driver', 'trust_monitor')
"""The nodes of :func:`run_wall_graph` (this process records in place of ``recorder``)."""
AFTER_START = ('/preceding_vehicle/odom', '/preceding_vehicle/speed_preview', '/human/plan',
               '/human/driver_status')
"""In a whole-graph wall run, the topics published only once ``/sim/start`` has come; the
others are published from each node's first tick."""


@dataclass
class ShadowRun:
    """Outcome of a shadow run: the recording and the loop statistics per loop."""

    bag: Path
    duration_s: float
    counts: dict[str, int]
    loops: dict[str, dict[str, Any]]
    losses: tuple[Lost, ...] = ()
    """What the recording lost (only ``run_wall_graph(..., lossless=False)`` returns any)."""


def shadow_specs(config: RunConfig, trace: SpeedTrace, rate_hz: float,
                 log_dir: Path) -> list[NodeSpec]:
    """The two node processes of a shadow run, in wall mode."""
    cfg = config.for_trace(trace)
    wall = {'clock_mode': 'wall', 'control_rate_hz': rate_hz, 'autostart': False}
    return [
        NodeSpec('trust_monitor', 'trust_monitor.monitor_node',
                 {**wall, 'jitter_report_path': str(log_dir / 'trust_monitor.jitter.json')}),
        NodeSpec('planner', 'trust_av_planner.planner_node',
                 {**wall, 'jitter_report_path': str(log_dir / 'planner.jitter.json'),
                  'human_odom_topic': '', 'speed_max_mps': cfg.planner.speed_max_mps,
                  'speed_max_from_trace': False, 'alpha': cfg.planner.alpha,
                  'predictor': cfg.planner.predictor}),
    ]


def run_shadow(config: RunConfig, trace: SpeedTrace, bag: Path, *,
               duration_s: float, rate_hz: float, topics: PlannerTopics | None = None,
               startup_timeout_s: float = 30.0) -> ShadowRun:
    """Replay ``trace`` for ``duration_s`` of wall time at ``rate_hz`` into the two nodes.

    Raises:
        RecordingLossError: messages were lost; the bag holds the rest.
        GraphError: the nodes did not connect in time or one died.
        DiskFullError: the disk filled up; the nodes were stopped and the bag finished with
            every complete second.
    """
    from trust_av.graph.bag_qos import offered_profiles
    from trust_av_common.ros.messages import message_class, odometry, trajectory
    from trust_av_common.ros.qos import RECORD_QOS, record_qos, wall_qos

    topics = topics if topics is not None else PlannerTopics()
    # actual topic name -> the topic-table entry it stands for (message type, QoS)
    recorded = {qualified(topics.lead_odom_topic): TOPIC['preceding_vehicle/odom'],
                qualified(topics.ego_odom_topic): TOPIC['ego/odom'],
                **{name: TOPIC[name.lstrip('/')] for name in OUTPUTS}}
    cfg = config.for_trace(trace)
    initial = equilibrium_start(cfg, trace)
    lead = LeadReplay(trace, initial.traffic.position_m)
    log_dir = bag.with_name(bag.name + '.logs')
    period_ns = round(NS_PER_S / rate_hz)
    with lease_domain(foreign_participants) as domain:  # skips a domain with leftovers
        graph = Graph(shadow_specs(config, trace, rate_hz, log_dir), config.params_files, domain,
                      log_dir)
        with graph_session(graph, 'shadow_player') as session:
            node, executor = session.node, session.executor
            wall = WallClockConfig(clock_mode='wall', control_rate_hz=rate_hz)
            sensor = wall_qos('SENSOR', wall, publisher=True)
            pub_lead = node.create_publisher(
                message_class(TOPIC['preceding_vehicle/odom'].msgtype),
                topics.lead_odom_topic, sensor)
            pub_preview = node.create_publisher(
                message_class(TOPIC['preceding_vehicle/speed_preview'].msgtype),
                topics.lead_preview_topic, sensor)
            pub_ego = node.create_publisher(message_class(TOPIC['ego/odom'].msgtype),
                                            topics.ego_odom_topic, sensor)
            command = {'accel_mps2': 0.0}
            stats = LoopStats(period_ns)
            ledger = PublicationLedger()
            # the node that publishes each recorded topic (the inputs: this player)
            publisher = {name: 'shadow_player' if name not in OUTPUTS else topic.publishers[0]
                         for name, topic in recorded.items()}
            with BagWriter(bag, custom_data=write_record(config, trace, graph)) as recording:
                def on_message(topic: str, data: bytes, info: dict[str, Any]) -> None:
                    if not recording.finished:   # finished early only by a full disk
                        recording.write(topic, data,
                                        receive_time_ns=int(info['received_timestamp']))
                        ledger.received(topic, publisher[topic],
                                        int(info['publication_sequence_number']))

                for name, topic in recorded.items():
                    offered = wall_qos(topic.wall_qos, wall, publisher=True)
                    recording.add_topic(name, topic.msgtype,
                                        offered_profiles(offered, len(topic.publishers)))
                    node.create_subscription(message_class(topic.msgtype), name,
                                             lambda d, info, t=name: on_message(t, d, info),
                                             record_qos(topic.wall_qos), raw=True)

                def on_command(msg: Any) -> None:
                    command['accel_mps2'] = float(msg.accel.linear.x)

                node.create_subscription(message_class(TOPIC['ego/accel_cmd'].msgtype),
                                         '/ego/accel_cmd', on_command, RECORD_QOS)
                _wait_nodes(graph, node, executor, topics, startup_timeout_s)
                ego = initial.av
                start = last = time.monotonic_ns()
                next_tick = next_chunk = start
                while True:
                    now = time.monotonic_ns()
                    if now < next_tick:
                        stop_signals.spin_once(executor, (next_tick - now) / NS_PER_S)
                        continue
                    stats.tick(now)
                    elapsed_s = (now - start) / NS_PER_S
                    if elapsed_s > duration_s:
                        break
                    ego = _advance(ego, command['accel_mps2'], (now - last) / NS_PER_S)
                    last = now
                    stamp = time.time_ns()
                    state = lead.state(elapsed_s)
                    pub_lead.publish(odometry(stamp, state.position_m, state.speed_mps,
                                              'preceding_vehicle'))
                    pub_preview.publish(trajectory(
                        stamp, cfg.planner.dt_s, frame_id='preceding_vehicle',
                        velocities=lead.preview(
                            elapsed_s, cfg.planner.horizon_steps, cfg.planner.dt_s).tolist()))
                    pub_ego.publish(odometry(stamp, ego.position_m, ego.speed_mps, 'ego'))
                    for sent in (pub_lead, pub_preview, pub_ego):
                        stats.publish(sent.topic_name)
                    if now >= next_chunk:
                        if not recording.end_step():
                            break                # the disk is full: stop, raised below
                        next_chunk = now + NS_PER_S
                    stats.done(time.monotonic_ns() - now)
                    next_tick += period_ns
                    graph.check_alive(set())
                _stop_and_drain(graph, executor, SHADOW_NODES, node=node)
                if recording.disk_full:
                    raise DiskFullError(recording.disk_full)
                counts = dict(recording.counts)
    loops = {'shadow_player': {'node': 'shadow_player', **stats.summary()},
             **_node_loops(graph, log_dir, SHADOW_NODES)}
    check_lossless(ledger, ledger.lost(_published(loops, recorded)))
    return ShadowRun(bag=bag, duration_s=duration_s, counts=counts, loops=loops)


def wall_specs(config: RunConfig, trace_arg: str, trace: SpeedTrace, rate_hz: float,
               log_dir: Path) -> list[NodeSpec]:
    """The five node processes of a whole-graph wall run: the lock-step graph's per-run
    parameters (initial states, trace) plus wall mode and a jitter report each."""
    specs = node_specs(config, trace_arg, trace, equilibrium_start(config.for_trace(trace),
                                                                   trace),
                       log_dir / 'unused.mcap', 0)
    return [NodeSpec(spec.name, spec.module,
                     {**spec.params, 'clock_mode': 'wall', 'control_rate_hz': rate_hz,
                      **({'autostart': False} if spec.name in MANAGED_NODES else {}),
                      'jitter_report_path': str(log_dir / f'{spec.name}.jitter.json')})
            for spec in specs if spec.name in WALL_GRAPH_NODES]


def run_wall_graph(config: RunConfig, trace_arg: str, trace: SpeedTrace, bag: Path, *,
                   duration_s: float, rate_hz: float,
                   startup_timeout_s: float = 30.0,
                   every_second: Callable[[dict[str, int], float], None] | None = None,
                   on_message: Callable[[str, int, bytes], None] | None = None,
                   lossless: bool = True) -> ShadowRun:
    """Every node in wall mode for ``duration_s`` of wall time after ``/sim/start``; every
    topic recorded to the bag directory ``bag`` (log time = header stamp = wall time).

    The nodes use the standard topic names (:data:`trust_av_common.topics.TOPICS`).
    ``/sim/start`` is published once this process receives every publisher, so every
    message published after it is in the bag. ``every_second``, if given, is called about
    once a second while the nodes run, with their process ids by node name and the wall time
    since ``/sim/start`` (s); it runs in the recording loop, so it must return quickly.
    ``on_message``, if given, is called for every recorded message with its topic, its DDS
    publication sequence number (the publisher's count of messages, from 1) and its
    serialized bytes (which tell the publishers of one topic apart). Every recorded
    message is accounted for (:mod:`~trust_av.graph.publication_ledger`); with
    ``lossless`` False, what was lost is returned in the result's ``losses`` instead.

    Raises:
        RecordingLossError: messages were lost (``lossless``); the bag holds the rest.
        GraphError: the nodes did not connect in time or one died.
        DiskFullError: the disk filled up; the nodes were stopped and the bag finished with
            every complete second.
    """
    from rclpy.serialization import deserialize_message
    from std_msgs.msg import Empty
    from tf2_msgs.msg import TFMessage

    from trust_av.graph.bag_qos import offered_profiles
    from trust_av_common.ros.messages import message_class
    from trust_av_common.ros.qos import QOS, record_qos

    recorded = [t for t in TOPICS if t.name not in ('clock', 'sim/start')]
    # In wall mode the traffic node subscribes nothing but /sim/start (as do the two simulated
    # vehicles, which hold still until then); this process records.
    needs = {qualified(t.name): (len(t.publishers),
                                 len([s for s in t.subscribers if s != 'preceding_traffic']))
             for t in recorded}
    needs['/sim/start'] = (1, 3)
    log_dir = bag.with_name(bag.name + '.logs')
    with lease_domain(foreign_participants) as domain:  # skips a domain with leftovers
        graph = Graph(wall_specs(config, trace_arg, trace, rate_hz, log_dir), config.params_files,
                      domain, log_dir)
        with graph_session(graph, 'wall_recorder') as session:
            node, executor = session.node, session.executor
            start_pub = node.create_publisher(Empty, '/sim/start', QOS['LATCHED'])
            tf_topic = qualified('tf')
            tf_before_start = {VEHICLE_FRAMES[n] for n in TOPIC['tf'].publishers
                               if n != 'preceding_traffic'}
            tf_seen: set[str] = set()     # child frames heard on tf before /sim/start
            started_at: list[float] = []
            ledger = PublicationLedger()
            vehicle_node = {frame: name for name, frame in VEHICLE_FRAMES.items()}
            with BagWriter(bag, custom_data=write_record(config, trace, graph)) as recording:
                def record(topic: str, data: bytes, info: dict[str, Any]) -> None:
                    if recording.finished:       # finished early only by a full disk
                        return
                    recording.write(topic, data, receive_time_ns=int(info['received_timestamp']))
                    sequence = int(info['publication_sequence_number'])
                    if topic == tf_topic:        # three publishers: told apart by frame
                        frames = [t.child_frame_id for t in
                                  deserialize_message(data, TFMessage).transforms]
                        if not started_at:
                            tf_seen.update(frames)
                        for name in {vehicle_node.get(frame, frame) for frame in frames}:
                            ledger.received(topic, name, sequence)
                    else:
                        ledger.received(topic, TOPIC[topic.lstrip('/')].publishers[0],
                                        sequence)
                    if on_message is not None:
                        on_message(topic, int(info['publication_sequence_number']), data)

                subscriptions = []
                for topic in recorded:
                    name = qualified(topic.name)
                    recording.add_topic(name, topic.msgtype, offered_profiles(
                        QOS[topic.qos], len(topic.publishers)))
                    subscriptions.append(node.create_subscription(
                        message_class(topic.msgtype), name,
                        lambda d, info, t=name: record(t, d, info), record_qos(topic.wall_qos),
                        raw=True))
                # /sim/start only once this process receives every publisher: the graph's
                # endpoint counts say that a publisher exists, not that it sends here (the
                # wall profiles are volatile: what a publisher sent before it matched this
                # subscription is never resent). Proof is a message received from each
                # publisher (on tf: each vehicle's child frame); for a publisher that
                # starts only after /sim/start, this subscription's own match with it.
                publishers = {qualified(t.name): len(t.publishers) for t in recorded}

                def not_received() -> list[str]:
                    missing = [f'{sub.topic_name} (not every publisher matched here yet)'
                               for sub in subscriptions
                               if sub.get_publisher_count() < publishers[sub.topic_name]]
                    missing += [f'{sub.topic_name} (not received here yet)'
                                for sub in subscriptions
                                if sub.topic_name not in AFTER_START
                                and recording.count(sub.topic_name) < 1]
                    missing += [f'{tf_topic} from {frame} (not received here yet)'
                                for frame in sorted(tf_before_start - tf_seen)]
                    return missing

                _wait_topics(graph, node, executor, needs, startup_timeout_s, not_received)
                start_pub.publish(Empty())
                started = time.monotonic()
                started_at.append(started)
                end = started + duration_s
                next_chunk = started + 1.0
                pids = {p.spec.name: p.popen.pid for p in graph.processes}
                while time.monotonic() < end:
                    stop_signals.spin_once(executor, 0.05)
                    graph.check_alive(set())
                    if time.monotonic() >= next_chunk:
                        if not recording.end_step():
                            break                # the disk is full: stop, raised below
                        next_chunk += 1.0
                        if every_second is not None:
                            every_second(pids, time.monotonic() - started)
                _stop_and_drain(graph, executor, WALL_GRAPH_NODES, node=node)
                if recording.disk_full:
                    raise DiskFullError(recording.disk_full)
                counts = dict(recording.counts)
    loops = _node_loops(graph, log_dir, WALL_GRAPH_NODES)
    # the publishers that start only once /sim/start has come: every message is the run's
    from_first = {(name, node) for name in AFTER_START
                  for node in TOPIC[name.lstrip('/')].publishers}
    from_first.add((tf_topic, 'preceding_traffic'))
    published = _published(loops, {qualified(t.name) for t in recorded})
    # + what each vehicle node publishes before its loop starts (the table's initial
    # messages, one per vehicle node; the traffic node publishes nothing before /sim/start)
    for topic in recorded:
        vehicles = [n for n in topic.publishers if n != 'preceding_traffic']
        for name in vehicles if topic.initial else ():
            key = (qualified(topic.name), name)
            published[key] = published.get(key, 0) + topic.initial // len(vehicles)
    sensors = {(qualified(t.name), n) for t in recorded if t.wall_qos == 'SENSOR'
               for n in t.publishers}
    losses = tuple(ledger.lost(published, from_first, stop_edge=sensors))
    if lossless:
        check_lossless(ledger, losses)
    return ShadowRun(bag=bag, duration_s=duration_s, counts=counts, loops=loops, losses=losses)


def _published(loops: dict[str, Any], recorded: Collection[str]) -> dict[Publisher, int]:
    """(topic, node) -> messages the node reported publishing, for the recorded topics."""
    return {(topic, node): int(count) for node, loop in loops.items()
            for topic, count in loop.get('published', {}).items() if topic in recorded}


def _stop_and_drain(graph: Graph, executor: Any, names: tuple[str, ...],
                    drain_s: float = 0.5, node: Any = None) -> None:
    """Deactivate the managed nodes through ``node`` if given (the planner hands over), stop
    the nodes (they write their loop statistics) while taking what they publish, then the last.

    The stop runs in a thread so that the executor keeps spinning: the command topics keep
    only the last message (keep-last 1), so a node that ticks twice while being stopped
    (seen under a load average of 21: two ticks between the last take and the node's
    exit) would otherwise overwrite the first before it was recorded.
    """
    import threading

    set_states(node, executor, MANAGED_NODES if node is not None else (), 'inactive', graph=graph)
    errors: list[BaseException] = []

    def stop() -> None:
        try:
            graph.stop(list(names))
        except BaseException as err:  # re-raised below, in the caller's thread
            errors.append(err)

    stopper = threading.Thread(target=stop, name='stop-nodes')
    stopper.start()
    while stopper.is_alive():
        stop_signals.spin_once(executor, 0.02)
    stopper.join()
    if errors:
        raise errors[0]
    drain_until = time.monotonic() + drain_s
    while time.monotonic() < drain_until:
        stop_signals.spin_once(executor, 0.05)


def _node_loops(graph: Graph, log_dir: Path, names: tuple[str, ...]) -> dict[str, Any]:
    """After a wall run: every node exited cleanly and wrote its loop statistics."""
    for process in graph.processes:
        if process.popen.returncode not in (0, None):
            raise GraphError(process.exit_message(process.popen.returncode))
    loops = {}
    for name in names:
        path = log_dir / f'{name}.jitter.json'
        if not path.exists():
            raise GraphError(f'node {name} wrote no loop statistics ({path}); node logs in '
                             f'{log_dir}')
        loops[name] = json.loads(path.read_text())
    return loops


def _advance(ego: VehicleState, accel_mps2: float, dt_s: float) -> VehicleState:
    """The simulated ego over ``dt_s`` of wall time; speed kept >= 0 (no reversing)."""
    return VehicleState(*advance(ego.position_m, ego.speed_mps, accel_mps2, dt_s))


def _wait_nodes(graph: Graph, node: Any, executor: Any, topics: PlannerTopics,
                timeout_s: float) -> None:
    """Wait until both nodes publish and subscribe what the player exchanges with them."""
    needs = {qualified(topics.lead_odom_topic): (1, 2),
             qualified(topics.lead_preview_topic): (1, 1),
             qualified(topics.ego_odom_topic): (1, 2), '/ego/plan': (1, 2),
             '/ego/expected_plan': (1, 2),
             '/ego/accel_cmd': (1, 2), '/ego/planner_status': (1, 1),
             '/trust_monitor/trust': (1, 2)}
    _wait_topics(graph, node, executor, needs, timeout_s)


def _wait_topics(graph: Graph, node: Any, executor: Any, needs: dict[str, tuple[int, int]],
                 timeout_s: float, pending: Callable[[], list[str]] | None = None) -> None:
    """Bring the managed nodes to active (configure, activate), then wait until every topic
    has its (publishers, subscribers) and ``pending`` (if given) names nothing more."""
    set_states(node, executor, MANAGED_NODES, 'active', timeout_s, graph)
    deadline = time.monotonic() + timeout_s
    missing: list[str] = []
    while time.monotonic() < deadline:
        stop_signals.spin_once(executor, 0.05)
        graph.check_alive(set())
        missing = [f'{topic} ({node.count_publishers(topic)}/{pubs} publishers, '
                   f'{node.count_subscribers(topic)}/{subs} subscribers)'
                   for topic, (pubs, subs) in needs.items()
                   if node.count_publishers(topic) < pubs or node.count_subscribers(topic) < subs]
        missing += pending() if pending is not None else []
        if not missing:
            return
    raise GraphError(f'shadow nodes not connected after {timeout_s:g} s: ' + '; '.join(missing))
