"""One drive of a person through the node graph in wall mode, recorded to one bag.

Processes (on a leased domain, :class:`~trust_av_planner.graph.processes.Graph`):
``preceding_traffic``, ``planner``, ``ego_plant`` and ``trust_monitor`` as in a whole-graph
wall run (``trust-av shadow --whole-graph``), and ``follower_plant`` in place of
``human_driver`` (:mod:`trust_av_planner.drive.follower_node`). This process serves the page
(:class:`~trust_av_planner.drive.server.DriveServer`), publishes the person's pedal on
``human/accel_cmd`` the moment a sample arrives (from the server's thread), records every
topic (log time = header stamp = wall time) and writes what the person gives into the same
bag, on the same clock:

- ``driver/rating`` (``geometry_msgs/msg/Vector3Stamped``): x the in-drive rating mapped to
  [0, 1] (the monitor's trust scale), y the response time (s), z the rating as given (0-100);
- ``driver/questionnaire`` (``sensor_msgs/msg/JointState``): ``name`` the 12 items
  ``jian_01`` .. ``jian_12`` and ``trust_score``; ``position`` the answers (1-7) and the score
  in [0, 1];
- ``driver/latency`` (``Vector3Stamped``): per acknowledged pedal sample, x the round trip
  page -> graph -> page (s, the page's clock), y arrival here -> applied by the follower
  plant (s), z applied -> state sent to the page (s).

The bag's ``custom_data`` (rosbag2 ``metadata.yaml``) holds the study metadata:
participant, condition, alpha, predictor, trace, perturbation and its seed, code version,
seed, status and the latency percentiles.
"""

from __future__ import annotations

import logging
import queue
import time
from pathlib import Path
from typing import Any

from preceding_traffic.traces import SpeedTrace
from trust_av_planner.drive.follower import APPLIED_TOPIC, COMMAND_TOPIC, FollowerConfig
from trust_av_planner.drive.server import DriveServer
from trust_av_planner.drive.trust_rating import (
    JIAN_ITEMS,
    RatingError,
    rating_value,
)
from trust_av_planner.graph import stop_signals
from trust_av_planner.graph.bag_writer import BagWriter, DiskFullError
from trust_av_planner.graph.domains import lease_domain
from trust_av_planner.graph.drive_link import (
    DriveLink,
    DriveOutcome,
    joint_state_cdr,
    questionnaire_msg,
    vector_msg,
)
from trust_av_planner.graph.orchestrator import node_specs
from trust_av_planner.graph.processes import Graph, NodeSpec
from trust_av_planner.graph.session import foreign_participants, graph_session
from trust_av_planner.graph.shadow import _node_loops, _stop_and_drain, _wait_topics
from trust_av_planner.system.closed_loop import equilibrium_start
from trust_av_planner.system.config import RunConfig
from trust_monitor.common.topics import TOPICS, qualified
from trust_monitor.common.wall_clock import NS_PER_S, WallClockConfig

LOG = logging.getLogger(__name__)
DRIVE_NODES = ('preceding_traffic', 'planner', 'ego_plant', 'follower_plant', 'trust_monitor')
DRIVER_TOPICS = {'/human/accel_cmd': 'geometry_msgs/msg/AccelStamped',
                 '/human/accel_applied': 'geometry_msgs/msg/AccelStamped',
                 '/driver/rating': 'geometry_msgs/msg/Vector3Stamped',
                 '/driver/questionnaire': 'sensor_msgs/msg/JointState',
                 '/driver/latency': 'geometry_msgs/msg/Vector3Stamped'}
"""The drive's own topics, recorded beside the graph's."""
NOT_PUBLISHED = ('clock', 'sim/start', 'human/plan')
"""Topics of the table that no node of a drive publishes (no lock-step clock; the person
publishes no plan)."""


def drive_specs(config: RunConfig, trace_arg: str, trace: SpeedTrace, follower: FollowerConfig,
                rate_hz: float, log_dir: Path) -> list[NodeSpec]:
    """The five node processes of a drive: the whole-graph wall run's, with
    ``follower_plant`` in place of ``human_driver``."""
    initial = equilibrium_start(config.for_trace(trace), trace)
    wall = {'clock_mode': 'wall', 'control_rate_hz': rate_hz}
    specs = [NodeSpec(s.name, s.module,
                      {**s.params, **wall,
                       'jitter_report_path': str(log_dir / f'{s.name}.jitter.json')})
             for s in node_specs(config, trace_arg, trace, initial, log_dir / 'unused.mcap', 0)
             if s.name in DRIVE_NODES]
    specs.append(NodeSpec('follower_plant', 'trust_av_planner.drive.follower_node', {
        **wall, 'jitter_report_path': str(log_dir / 'follower_plant.jitter.json'),
        'initial_position_m': initial.human.position_m,
        'initial_speed_mps': initial.human.speed_mps,
        **{name: getattr(follower, name) for name in follower.__dataclass_fields__}}))
    return specs



def run_drive(config: RunConfig, trace_arg: str, trace: SpeedTrace, bag: Path, *,
              server: DriveServer, link: DriveLink, follower: FollowerConfig,
              metadata: dict[str, str], duration_s: float, rate_hz: float,
              abandon_after_s: float, start_timeout_s: float, questionnaire: bool,
              questionnaire_timeout_s: float, startup_timeout_s: float = 60.0) -> DriveOutcome:
    """Run one drive: start the graph, wait for the page's start, drive ``duration_s`` of
    wall time (or until the person has sent nothing for ``abandon_after_s``), stop the
    nodes, ask the questionnaire (if ``questionnaire`` and not abandoned), finish the bag.

    Raises:
        GraphError: the nodes did not connect in time or one died.
        DiskFullError: the disk filled up (the bag is finished with what it holds).
    """
    from rclpy.serialization import deserialize_message, serialize_message
    from std_msgs.msg import Empty

    from trust_av_planner.graph.bag_qos import offered_qos
    from trust_monitor.ros.messages import message_class, msg_ns
    from trust_monitor.ros.qos import QOS, record_qos, wall_qos

    recorded = [t for t in TOPICS if t.name not in NOT_PUBLISHED]
    log_dir = bag.with_name(bag.name + '.logs')
    outcome = DriveOutcome(bag=bag, status='abandoned', driven_s=0.0, counts={})
    state: dict[str, Any] = {'ack': None}
    with lease_domain(foreign_participants) as domain:  # skips a domain with leftovers
        graph = Graph(drive_specs(config, trace_arg, trace, follower, rate_hz, log_dir),
                      config.params_files, domain, log_dir)
        with graph_session(graph, 'drive') as session:
            node, executor = session.node, session.executor
            start_pub = node.create_publisher(Empty, '/sim/start', QOS['LATCHED'])
            clock = WallClockConfig(clock_mode='wall', control_rate_hz=rate_hz)
            state_qos = wall_qos('STATE', clock, publisher=True)
            command_pub = node.create_publisher(message_class(DRIVER_TOPICS['/human/accel_cmd']),
                                                COMMAND_TOPIC, state_qos)
            own_pubs = {name: node.create_publisher(message_class(kind), name, state_qos)
                        for name, kind in DRIVER_TOPICS.items()
                        if name.startswith('/driver/')}
            with BagWriter(bag) as recording:
                for key, value in metadata.items():
                    recording.set_custom_data(key, value)
                started: list[int] = []

                def t_s(ns: int) -> float:
                    return (ns - started[0]) / NS_PER_S if started else 0.0

                def on_graph(topic: str, data: bytes) -> None:
                    if recording.finished:
                        return
                    recording.write(topic, data)
                    if topic == '/human/accel_applied':
                        stamp = msg_ns(deserialize_message(
                            data, message_class(DRIVER_TOPICS[topic])).header.stamp)
                        with link.lock:
                            found = link.pending.pop(stamp, None)
                            for old in [s for s in link.pending if s < stamp]:
                                del link.pending[old]
                        if found is not None:     # the odometry it led to came first
                            state['ack'] = (found[0], found[1], time.time_ns())
                            send_state()
                    elif topic in VEHICLE_TOPICS:
                        odom = deserialize_message(data, message_class(
                            'nav_msgs/msg/Odometry'))
                        state[topic] = (float(odom.pose.pose.position.x),
                                        float(odom.twist.twist.linear.x))
                        if topic == '/human/odom':
                            send_state()
                    elif topic == '/trust_monitor/trust':
                        trust = deserialize_message(data, message_class(
                            'geometry_msgs/msg/Vector3Stamped'))
                        state['trust'] = float(trust.vector.z)

                def send_state() -> None:
                    now = time.time_ns()
                    frame: dict[str, Any] = {
                        'type': 'state', 't_s': t_s(now),
                        'vehicles': {name: state.get(topic) for name, topic in
                                     (('lead', '/preceding_vehicle/odom'),
                                      ('av', '/ego/odom'), ('you', '/human/odom'))},
                        'trust': state.get('trust')}
                    ack = state['ack']
                    if ack is not None:
                        seq, arrived, applied = ack
                        frame['ack'] = {'seq': seq, 'graph_ms': (applied - arrived) / 1e6,
                                        'back_ms': (now - applied) / 1e6}
                        state['ack'] = None
                    server.send(frame)

                for topic in recorded:
                    name = qualified(topic.name)
                    recording.add_topic(name, topic.msgtype, offered_qos(
                        wall_qos(topic.wall_qos, clock, publisher=True)))
                    node.create_subscription(message_class(topic.msgtype), name,
                                             lambda d, t=name: on_graph(t, d),
                                             record_qos(topic.wall_qos), raw=True)
                for name, kind in DRIVER_TOPICS.items():
                    recording.add_topic(name, kind, offered_qos(state_qos))
                node.create_subscription(message_class(DRIVER_TOPICS[APPLIED_TOPIC_ABS]),
                                         APPLIED_TOPIC_ABS,
                                         lambda d: on_graph(APPLIED_TOPIC_ABS, d),
                                         record_qos('STATE'), raw=True)

                def write_own(topic: str, msg: Any, data: bytes | None = None) -> None:
                    if topic in own_pubs:
                        own_pubs[topic].publish(msg)
                    if not recording.finished:
                        recording.write(topic, data if data is not None
                                        else serialize_message(msg))

                needs = {qualified(t.name): (len([p for p in t.publishers
                                                  if p != 'human_driver']) or 1, 0)
                         for t in recorded}
                needs['/sim/start'] = (1, 3)
                needs['/human/accel_cmd'] = (1, 1)
                needs[APPLIED_TOPIC_ABS] = (1, 1)
                _wait_topics(graph, node, executor, needs, startup_timeout_s)

                def handle(message: dict[str, Any], arrived: int) -> None:
                    kind = message['type']
                    if kind == 'command':
                        write_own('/human/accel_cmd', message['msg'])
                    elif kind == 'rating' and started:
                        try:
                            value = rating_value(message.get('value'))
                            response_s = max(0.0, (float(message['answered_ms'])
                                                   - float(message['shown_ms'])) / 1e3)
                        except (RatingError, KeyError, TypeError, ValueError) as err:
                            LOG.warning('a bad rating from the page dropped: %s', err)
                            return            # the page sends only valid ratings
                        write_own('/driver/rating', vector_msg(arrived, value, response_s,
                                                                value * 100.0))
                        outcome.ratings.append((t_s(arrived), value))
                    elif kind == 'latency' and started:
                        try:
                            trip = float(message['round_trip_ms']) / 1e3
                            graph_s = float(message['graph_ms']) / 1e3
                            back = float(message['back_ms']) / 1e3
                        except (KeyError, TypeError, ValueError) as err:
                            LOG.warning('a bad latency report dropped: %s', err)
                            return
                        write_own('/driver/latency', vector_msg(arrived, trip, graph_s, back))
                        outcome.latency_s.append((trip, graph_s, back))

                def drain() -> None:
                    while True:
                        try:
                            message, arrived = link.events.get_nowait()
                        except queue.Empty:
                            return
                        handle(message, arrived)
                        if message['type'] == 'ready' and not started:
                            state['ready'] = True
                        if message['type'] == 'questionnaire':
                            state['answers'] = message.get('answers')

                # wait for the participant's start
                link.greet = {'type': 'phase', 'phase': 'ready', **{
                    k: metadata.get(f'trust_av.{k}', '') for k in
                    ('drive', 'condition', 'participant')}, 'duration_s': duration_s}
                server.send(link.greet)
                deadline = time.monotonic() + start_timeout_s
                while not state.get('ready'):
                    if time.monotonic() > deadline:
                        break
                    stop_signals.spin_once(executor, 0.02)
                    drain()
                    graph.check_alive(set())
                if state.get('ready'):
                    with link.lock:
                        link.publisher = command_pub
                        link.last_input_ns = time.time_ns()
                    start_pub.publish(Empty())
                    started.append(time.time_ns())
                    recording.set_custom_data('trust_av.drive.start_ns', str(started[0]))
                    link.greet = {'type': 'phase', 'phase': 'driving',
                                  'duration_s': duration_s}
                    server.send(link.greet)
                    begin = time.monotonic()
                    next_chunk = begin + 1.0
                    outcome.status = 'done'
                    while time.monotonic() - begin < duration_s:
                        stop_signals.spin_once(executor, 0.005)
                        drain()
                        graph.check_alive(set())
                        if time.monotonic() >= next_chunk:
                            next_chunk += 1.0
                            if not recording.end_step():
                                break
                        with link.lock:
                            gone_s = (time.time_ns() - link.last_input_ns) / NS_PER_S
                        if gone_s > abandon_after_s:
                            outcome.status = 'abandoned'
                            break
                    outcome.driven_s = time.monotonic() - begin
                with link.lock:
                    link.publisher = None
                link.greet = {'type': 'phase', 'phase': 'wait'}
                server.send(link.greet)
                _stop_and_drain(graph, executor, DRIVE_NODES)
                drain()
                if questionnaire and outcome.status == 'done' and not recording.finished:
                    link.greet = {'type': 'phase', 'phase': 'questionnaire',
                                  'items': list(JIAN_ITEMS)}
                    server.send(link.greet)
                    deadline = time.monotonic() + questionnaire_timeout_s
                    while 'answers' not in state and time.monotonic() < deadline:
                        time.sleep(0.02)
                        drain()
                    answers = state.get('answers')
                    msg = None
                    if not isinstance(answers, list):
                        LOG.warning('no questionnaire answered within %g s',
                                    questionnaire_timeout_s)
                    else:
                        try:
                            msg = questionnaire_msg(time.time_ns(), answers)
                        except RatingError as err:
                            LOG.warning('no questionnaire recorded: %s', err)
                    if msg is not None:
                        write_own('/driver/questionnaire', msg, joint_state_cdr(msg))
                        outcome.questionnaire = [int(a) for a in answers]
                latency = outcome.latency_ms()
                recording.set_custom_data('trust_av.drive.status', outcome.status)
                recording.set_custom_data('trust_av.drive.driven_s', f'{outcome.driven_s:.3f}')
                for key, number in latency.items():
                    recording.set_custom_data(f'trust_av.drive.latency.{key}', f'{number:g}')
                recording.finish()
                if recording.disk_full:
                    raise DiskFullError(recording.disk_full)
                outcome.counts = dict(recording.counts)
    outcome.loops = _node_loops(graph, log_dir, DRIVE_NODES)
    return outcome


VEHICLE_TOPICS = ('/preceding_vehicle/odom', '/ego/odom', '/human/odom')
APPLIED_TOPIC_ABS = qualified(APPLIED_TOPIC)
