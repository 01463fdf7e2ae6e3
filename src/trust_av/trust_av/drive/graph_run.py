"""One drive of a person through the node graph in wall mode, recorded to one bag.

Processes (on a leased domain, :class:`~trust_av.graph.processes.Graph`):
``preceding_traffic``, ``planner``, ``ego_plant`` and ``trust_monitor`` as in a whole-graph
wall run (``trust-av shadow --whole-graph``), and ``follower_plant`` in place of
``human_driver`` (:mod:`human_driver_sim.follower_plant_node`). This process serves the page
(:class:`~trust_av.drive.server.DriveServer`), publishes the person's pedal on
``human/accel_cmd`` the moment a sample arrives (from the server's thread), records every
topic (log time = header stamp = wall time) and writes what the person gives into the same
bag, on the same clock:

- ``driver/rating`` (``geometry_msgs/msg/Vector3Stamped``): x the in-drive rating mapped to
  [0, 1] (the monitor's trust scale), y the response time (s), z the rating as given (0-100);
- ``driver/questionnaire`` (``sensor_msgs/msg/JointState``): ``name`` the 12 items
  ``jian_01`` .. ``jian_12`` and ``trust_score``; ``position`` the answers (1-7) and the score
  in [0, 1];
- ``driver/latency`` (``Vector3Stamped``): per acknowledged pedal sample, measured here on
  this process's clock (no time of the page's): x the round trip (sample received ->
  the page's echo of the state frame acknowledging it received, s), y received -> applied
  by the follower plant (s), z applied -> echo received (s). Only sequence numbers this
  process issued and sent are accepted, each once;
- ``driver/model_trust`` (``sensor_msgs/msg/JointState``): every registered trust model's
  trust on the common scale [0, 1] (``name`` the models;
  :func:`~trust_monitor.model_interface.common_trust`), live at each plan pair
  (:class:`~trust_av.drive.link.ModelTrust`);
- ``driver/events`` (``diagnostic_msgs/msg/DiagnosticArray``): the drive's events as the
  status message: ``waiting``, ``start``, ``end`` (``ended_by``), ``page_connected``,
  ``page_lost`` (with the time left: an interruption), ``take_over`` (another tab took the
  control), ``collision`` (the count and the protocol), ``rating_prompt`` (its id).

Only the page's admitted messages reach the drive (:mod:`trust_av.drive.gate`: the
phase, the rate, the pedal's range, open prompts); the refused ones are counted, never
stored (``custom_data`` ``trust_av.drive.refused``: the total, and
``trust_av.drive.refused.<reason>`` per reason, :func:`~trust_av.drive.gate.reason_key`).

The bag's ``custom_data`` (rosbag2 ``metadata.yaml``) holds the study metadata:
participant, condition, alpha, predictor, trace, perturbation and its seed, code version,
seed, status, what ended the drive, the collisions, the refused messages and the latency
percentiles.
"""

from __future__ import annotations

import logging
import queue
import time
from pathlib import Path
from typing import Any

from human_driver_sim.follower_plant import APPLIED_TOPIC, COMMAND_TOPIC, FollowerConfig
from preceding_traffic.traces import SpeedTrace
from trust_av.drive.gate import DRIVING, IDLE, QUESTIONNAIRE, READY, WAIT, reason_key
from trust_av.drive.link import (
    DriveLink,
    DriveOutcome,
    ModelTrust,
    event_msg,
    joint_state_cdr,
    questionnaire_msg,
    vector_msg,
)
from trust_av.drive.server import DriveServer
from trust_av.drive.trust_rating import JIAN_ITEMS, RatingError
from trust_av.graph import stop_signals
from trust_av.graph.bag_writer import BagWriter, DiskFullError
from trust_av.graph.domains import lease_domain
from trust_av.graph.orchestrator import node_specs
from trust_av.graph.processes import Graph, NodeSpec
from trust_av.graph.session import foreign_participants, graph_session
from trust_av.graph.shadow import _node_loops, _stop_and_drain, _wait_topics
from trust_av.system.closed_loop import equilibrium_start
from trust_av.system.config import RunConfig
from trust_av_common.topics import TOPICS, qualified
from trust_av_common.wall_clock import NS_PER_S, WallClockConfig

__all__ = ['run_drive']

LOG = logging.getLogger(__name__)
DRIVE_NODES = ('preceding_traffic', 'planner', 'ego_plant', 'follower_plant', 'trust_monitor')
DRIVER_TOPICS = {'/human/accel_cmd': 'geometry_msgs/msg/AccelStamped',
                 '/human/accel_applied': 'geometry_msgs/msg/AccelStamped',
                 '/driver/rating': 'geometry_msgs/msg/Vector3Stamped',
                 '/driver/questionnaire': 'sensor_msgs/msg/JointState',
                 '/driver/latency': 'geometry_msgs/msg/Vector3Stamped',
                 '/driver/model_trust': 'sensor_msgs/msg/JointState',
                 '/driver/events': 'diagnostic_msgs/msg/DiagnosticArray'}
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
    specs.append(NodeSpec('follower_plant', 'human_driver_sim.follower_plant_node', {
        **wall, 'jitter_report_path': str(log_dir / 'follower_plant.jitter.json'),
        'initial_position_m': initial.human.position_m,
        'initial_speed_mps': initial.human.speed_mps,
        'vehicle_length_m': config.shared.vehicle_length_m,
        **{name: getattr(follower, name) for name in follower.__dataclass_fields__}}))
    return specs



def run_drive(config: RunConfig, trace_arg: str, trace: SpeedTrace, bag: Path, *,
              server: DriveServer, link: DriveLink, follower: FollowerConfig,
              metadata: dict[str, str], duration_s: float, rate_hz: float,
              abandon_after_s: float, start_timeout_s: float, questionnaire: bool,
              questionnaire_timeout_s: float, rating_period_s: float = 15.0,
              on_collision: str = 'continue', page_info: dict[str, Any] | None = None,
              startup_timeout_s: float = 60.0) -> DriveOutcome:
    """Run one drive: start the graph, wait for the page's start, drive ``duration_s`` of
    wall time (or until the person has sent nothing for ``abandon_after_s``, or until a
    collision if ``on_collision`` is ``end``), asking a rating every ``rating_period_s``,
    stop the nodes, ask the questionnaire (if ``questionnaire`` and not abandoned), finish
    the bag. ``page_info`` is shown on the start screen (drive ``number`` ``of``).

    Raises:
        GraphError: the nodes did not connect in time or one died.
        DiskFullError: the disk filled up (the bag is finished with what it holds).
    """
    from rclpy.serialization import deserialize_message, serialize_message
    from std_msgs.msg import Empty

    from trust_av.graph.bag_qos import offered_qos
    from trust_av_common.ros.messages import diagnostic_values, message_class, msg_ns
    from trust_av_common.ros.qos import QOS, record_qos, wall_qos

    recorded = [t for t in TOPICS if t.name not in NOT_PUBLISHED]
    log_dir = bag.with_name(bag.name + '.logs')
    outcome = DriveOutcome(bag=bag, status='abandoned', driven_s=0.0, counts={})
    gate = link.gate
    state: dict[str, Any] = {'ack': None, 'collisions': 0, 'crash_ns': 0}
    models = ModelTrust(config.trust, dict(config.trust_model_params))
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
                begin: list[float] = []

                def t_s(ns: int) -> float:
                    return (ns - started[0]) / NS_PER_S if started else 0.0

                def left_s() -> float:
                    return max(0.0, duration_s - (time.monotonic() - begin[0])) if begin \
                        else duration_s

                def write_own(topic: str, msg: Any, data: bytes | None = None) -> None:
                    if topic in own_pubs:
                        own_pubs[topic].publish(msg)
                    if not recording.finished:
                        recording.write(topic, data if data is not None
                                        else serialize_message(msg))

                def event(kind: str, ns: int, **values: Any) -> None:
                    write_own('/driver/events', event_msg(ns, kind, {
                        k: str(v) for k, v in values.items()}))
                    outcome.events.append((t_s(ns), kind))

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
                    elif topic == '/ego/accel_cmd':
                        state['av_accel'] = float(deserialize_message(data, message_class(
                            'geometry_msgs/msg/AccelStamped')).accel.linear.x)
                    elif topic in ('/ego/plan', '/ego/expected_plan'):
                        plan = deserialize_message(data, message_class(
                            'trajectory_msgs/msg/JointTrajectory'))
                        stamp = msg_ns(plan.header.stamp)
                        trust = models.add('plan' if topic == '/ego/plan' else 'expected',
                                           stamp, [float(p.accelerations[0])
                                                   for p in plan.points])
                        if trust is not None:
                            msg = models.message(stamp, trust)
                            write_own('/driver/model_trust', msg, joint_state_cdr(msg))
                    elif topic == '/human/driver_status' and started:
                        values = diagnostic_values(deserialize_message(data, message_class(
                            'diagnostic_msgs/msg/DiagnosticArray')))
                        count = int(values.get('collisions', '0'))
                        if count > state['collisions']:
                            state['collisions'] = outcome.collisions = count
                            now = time.time_ns()
                            state['crash_ns'] = now
                            event('collision', now, count=count, protocol=on_collision)
                            send_state()

                def send_state() -> None:
                    now = time.time_ns()
                    frame: dict[str, Any] = {
                        'type': 'state', 't_s': t_s(now), 'left_s': round(left_s(), 2),
                        'vehicles': {name: state.get(topic) for name, topic in
                                     (('lead', '/preceding_vehicle/odom'),
                                      ('av', '/ego/odom'), ('you', '/human/odom'))},
                        'av_accel_mps2': state.get('av_accel'),
                        'collisions': state['collisions'],
                        'crash': state['crash_ns'] > 0
                        and now - state['crash_ns'] < CRASH_SHOWN_NS}
                    ack = state['ack']
                    if ack is not None:
                        seq, arrived, applied = ack
                        frame['ack'] = seq
                        gate.sent_ack(seq, arrived, applied, now)
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
                    elif kind == 'event':
                        event(message['event'], arrived, left_s=f'{left_s():.2f}')
                    elif kind == 'ready':
                        state['ready'] = True
                    elif kind == 'rating':
                        rated = gate.rating(message, arrived)
                        if rated is not None:
                            _prompt, value, response_s = rated
                            write_own('/driver/rating', vector_msg(
                                arrived, value / 100.0, response_s, value))
                            outcome.ratings.append((t_s(arrived), value / 100.0))
                    elif kind == 'ack':
                        latency = gate.echo(message, arrived)
                        if latency is not None:
                            write_own('/driver/latency', vector_msg(arrived, *latency))
                            outcome.latency_s.append(latency)
                    elif kind == 'questionnaire':
                        answers = message.get('answers')
                        try:
                            msg = questionnaire_msg(arrived, answers)  # type: ignore[arg-type]
                        except (RatingError, TypeError) as err:
                            gate.refuse('questionnaire with bad answers')
                            LOG.warning('a questionnaire refused: %s', err)
                            return
                        if gate.take_questionnaire():
                            state['answers'] = msg

                def drain() -> None:
                    while True:
                        try:
                            message, arrived = link.events.get_nowait()
                        except queue.Empty:
                            return
                        handle(message, arrived)

                def set_phase(phase: str, **extra: Any) -> None:
                    gate.set_phase(phase)
                    link.greet = {'type': 'phase', 'phase': phase, **extra}
                    server.send(link.greet)

                # wait for the participant's start
                set_phase(READY, duration_s=duration_s, **(page_info or {}))
                event('waiting', time.time_ns())
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
                    begin.append(time.monotonic())
                    set_phase(DRIVING, duration_s=duration_s)
                    event('start', started[0])
                    next_chunk = begin[0] + 1.0
                    next_prompt = begin[0] + rating_period_s
                    outcome.status = 'done'
                    while time.monotonic() - begin[0] < duration_s:
                        stop_signals.spin_once(executor, 0.005)
                        drain()
                        graph.check_alive(set())
                        now = time.monotonic()
                        if now >= next_chunk:
                            next_chunk += 1.0
                            if not recording.end_step():
                                break
                        if now >= next_prompt:
                            next_prompt += rating_period_s
                            if not gate.open_prompts():     # one still open stays open
                                prompt = gate.open_prompt(time.time_ns())
                                server.send({'type': 'rate', 'id': prompt})
                                event('rating_prompt', time.time_ns(), id=prompt)
                        if on_collision == 'end' and state['collisions']:
                            outcome.ended_by = 'collision'
                            break
                        with link.lock:
                            gone_s = (time.time_ns() - link.last_input_ns) / NS_PER_S
                        if gone_s > abandon_after_s:
                            outcome.status = 'abandoned'
                            break
                    outcome.driven_s = time.monotonic() - begin[0]
                    outcome.ended_by = outcome.ended_by or (
                        'time' if outcome.status == 'done' else 'no input')
                    event('end', time.time_ns(), ended_by=outcome.ended_by)
                with link.lock:
                    link.publisher = None
                set_phase(WAIT, ended_by=outcome.ended_by)
                _stop_and_drain(graph, executor, DRIVE_NODES)
                drain()
                if questionnaire and outcome.status == 'done' and not recording.finished:
                    set_phase(QUESTIONNAIRE, items=list(JIAN_ITEMS))
                    deadline = time.monotonic() + questionnaire_timeout_s
                    while 'answers' not in state and time.monotonic() < deadline:
                        time.sleep(0.02)
                        drain()
                    msg = state.get('answers')
                    if msg is None:
                        LOG.warning('no questionnaire answered within %g s',
                                    questionnaire_timeout_s)
                    else:
                        write_own('/driver/questionnaire', msg, joint_state_cdr(msg))
                        outcome.questionnaire = [int(a) for a in msg.position[:-1]]
                gate.set_phase(IDLE)       # nothing more is admitted: what was is handled
                drain()
                outcome.refused = gate.refused_counts()
                latency = outcome.latency_ms()
                recording.set_custom_data('trust_av.drive.status', outcome.status)
                recording.set_custom_data('trust_av.drive.driven_s', f'{outcome.driven_s:.3f}')
                recording.set_custom_data('trust_av.drive.ended_by', outcome.ended_by)
                recording.set_custom_data('trust_av.drive.collisions', str(outcome.collisions))
                recording.set_custom_data('trust_av.drive.on_collision', on_collision)
                recording.set_custom_data('trust_av.drive.refused',
                                          str(sum(outcome.refused.values())))
                for reason, count in sorted(outcome.refused.items()):
                    recording.set_custom_data(f'trust_av.drive.refused.{reason_key(reason)}',
                                              str(count))
                for key, number in latency.items():
                    recording.set_custom_data(f'trust_av.drive.latency.{key}', f'{number:g}')
                recording.finish()
                if recording.disk_full:
                    raise DiskFullError(recording.disk_full)
                outcome.counts = dict(recording.counts)
    outcome.loops = _node_loops(graph, log_dir, DRIVE_NODES)
    return outcome


CRASH_SHOWN_NS = 3_000_000_000
"""The page shows a collision this long."""
VEHICLE_TOPICS = ('/preceding_vehicle/odom', '/ego/odom', '/human/odom')
APPLIED_TOPIC_ABS = qualified(APPLIED_TOPIC)
