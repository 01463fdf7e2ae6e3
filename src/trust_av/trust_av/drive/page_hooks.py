"""The drive's page protocol as hooks of the wall run engine
(:class:`~trust_av.graph.wall_run.WallHooks`): :class:`DrivePage` serves one drive of
:func:`~trust_av.drive.graph_run.run_drive` (the start screen, the state frames and the
pedal's acknowledgements, rating prompts, collisions, the end, the questionnaire) and writes
what the person gives into the drive's bag; its state is what the page is shown and the
drive's times."""

from __future__ import annotations

import logging
import queue
import time
from dataclasses import dataclass, field
from typing import Any

from human_driver_sim.follower_plant import APPLIED_TOPIC, COMMAND_TOPIC
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
from trust_av.graph.wall_run import WallHooks, WallResult, WallRun, tf_frames
from trust_av.system.config import RunConfig
from trust_av_common.topics import TOPIC, VEHICLE_FRAMES, qualified
from trust_av_common.wall_clock import NS_PER_S, WallClockConfig

__all__ = ['APPLIED_TOPIC_ABS', 'DRIVER_TOPICS', 'IN_PLACE', 'DrivePage', 'DriveSettings']

LOG = logging.getLogger(__name__)
DRIVER_TOPICS = {'/human/accel_cmd': 'geometry_msgs/msg/AccelStamped',
                 '/human/accel_applied': 'geometry_msgs/msg/AccelStamped',
                 '/driver/rating': 'geometry_msgs/msg/Vector3Stamped',
                 '/driver/questionnaire': 'sensor_msgs/msg/JointState',
                 '/driver/latency': 'geometry_msgs/msg/Vector3Stamped',
                 '/driver/model_trust': 'sensor_msgs/msg/JointState',
                 '/driver/events': 'diagnostic_msgs/msg/DiagnosticArray'}
"""The drive's own topics, recorded beside the graph's."""
IN_PLACE = {'human_driver': 'follower_plant'}
"""The table's node -> the drive's node that publishes its topics."""
CRASH_SHOWN_NS = 3_000_000_000
"""The page shows a collision this long."""
VEHICLE_TOPICS = ('/preceding_vehicle/odom', '/ego/odom', '/human/odom')
APPLIED_TOPIC_ABS = qualified(APPLIED_TOPIC)
TF_TOPIC = qualified('tf')


@dataclass
class DriveSettings:
    """How one drive runs (:func:`run_drive`'s arguments)."""

    duration_s: float
    rate_hz: float
    abandon_after_s: float
    start_timeout_s: float
    questionnaire: bool
    questionnaire_timeout_s: float
    rating_period_s: float = 15.0
    on_collision: str = 'continue'
    rating_mode: str = 'prompt'
    page_info: dict[str, Any] = field(default_factory=dict)


class DrivePage(WallHooks):
    """The drive's page protocol over a wall run: the start screen, the state frames, the
    pedal's acknowledgements, rating prompts, collisions, the end, the questionnaire; the
    person's messages written into the bag. Its state: what the page is shown (the
    vehicles, the AV's command, the collisions) and the drive's times."""

    def __init__(self, config: RunConfig, server: DriveServer, link: DriveLink,
                 settings: DriveSettings, outcome: DriveOutcome) -> None:
        self.server, self.link, self.gate = server, link, link.gate
        self.settings = settings
        self.outcome = outcome
        self.models = ModelTrust(config.trust, dict(config.trust_model_params))
        self.vehicles: dict[str, tuple[float, float]] = {}
        self.av_accel: float | None = None
        self.ack: tuple[int, int, int] | None = None
        self.collisions = 0
        self.crash_ns = 0
        self.ready = False
        self.answers: Any = None
        self.start_ns = 0            # wall time of the start (0: not started)
        self.begin = 0.0             # monotonic time of the start
        self.next_prompt = 0.0
        self.pubs: dict[str, Any] = {}
        self.run: WallRun | None = None
        self.frames = {frame: IN_PLACE.get(name, name) for name, frame in VEHICLE_FRAMES.items()}

    # --- this process's messages ---

    def setup(self, run: WallRun) -> None:
        from std_msgs.msg import Empty

        from trust_av_common.ros.messages import message_class
        from trust_av_common.ros.qos import QOS, wall_qos

        self.run = run
        state = wall_qos('STATE', WallClockConfig(clock_mode='wall',
                                                  control_rate_hz=self.settings.rate_hz),
                         publisher=True)
        self.pubs['/sim/start'] = run.node.create_publisher(Empty, '/sim/start', QOS['LATCHED'])
        self.pubs[COMMAND_TOPIC] = run.node.create_publisher(
            message_class(DRIVER_TOPICS['/human/accel_cmd']), COMMAND_TOPIC, state)
        self.pubs.update({name: run.node.create_publisher(message_class(kind), name, state)
                          for name, kind in DRIVER_TOPICS.items() if name.startswith('/driver/')})

    def write_own(self, topic: str, msg: Any, data: bytes | None = None) -> None:
        """Publish (a ``/driver/`` topic) and record one of the drive's own messages."""
        from rclpy.serialization import serialize_message

        if topic.startswith('/driver/'):
            self.pubs[topic].publish(msg)
        assert self.run is not None
        self.run.write(topic, data if data is not None else serialize_message(msg))

    def t_s(self, ns: int) -> float:
        """Drive time of wall time ``ns`` (0 before the start)."""
        return (ns - self.start_ns) / NS_PER_S if self.start_ns else 0.0

    def left_s(self) -> float:
        return (max(0.0, self.settings.duration_s - (time.monotonic() - self.begin))
                if self.start_ns else self.settings.duration_s)

    def event(self, kind: str, ns: int, **values: Any) -> None:
        self.write_own('/driver/events', event_msg(ns, kind, {k: str(v)
                                                              for k, v in values.items()}))
        self.outcome.events.append((self.t_s(ns), kind))

    def set_phase(self, phase: str, **extra: Any) -> None:
        self.gate.set_phase(phase)
        self.link.greet = {'type': 'phase', 'phase': phase, **extra}
        self.server.send(self.link.greet)

    def send_state(self) -> None:
        """A state frame to the page (acknowledging the pedal sample last applied)."""
        now = time.time_ns()
        frame: dict[str, Any] = {
            'type': 'state', 't_s': self.t_s(now), 'left_s': round(self.left_s(), 2),
            'vehicles': {name: self.vehicles.get(topic) for name, topic in
                         (('lead', '/preceding_vehicle/odom'), ('av', '/ego/odom'),
                          ('you', '/human/odom'))},
            'av_accel_mps2': self.av_accel, 'collisions': self.collisions,
            'crash': self.crash_ns > 0 and now - self.crash_ns < CRASH_SHOWN_NS}
        if self.ack is not None:
            seq, arrived, applied = self.ack
            frame['ack'] = seq
            self.gate.sent_ack(seq, arrived, applied, now)
            self.ack = None
        self.server.send(frame)

    # --- the graph's messages ---

    def publishers(self, topic: str, data: bytes) -> set[str]:
        if topic == TF_TOPIC:
            return {self.frames.get(frame, frame) for frame in tf_frames(data)}
        if topic == APPLIED_TOPIC_ABS:
            return {'follower_plant'}
        name = TOPIC[topic.lstrip('/')].publishers[0]
        return {IN_PLACE.get(name, name)}

    def on_message(self, run: WallRun, topic: str, data: bytes, info: dict[str, Any]) -> None:
        from rclpy.serialization import deserialize_message

        from trust_av_common.ros.messages import message_class, msg_ns

        if topic == APPLIED_TOPIC_ABS:
            stamp = msg_ns(deserialize_message(
                data, message_class(DRIVER_TOPICS[topic])).header.stamp)
            with self.link.lock:
                found = self.link.pending.pop(stamp, None)
                for old in [s for s in self.link.pending if s < stamp]:
                    del self.link.pending[old]
            if found is not None:     # the odometry it led to came first
                self.ack = (found[0], found[1], time.time_ns())
                self.send_state()
        elif topic in VEHICLE_TOPICS:
            odom = deserialize_message(data, message_class('nav_msgs/msg/Odometry'))
            self.vehicles[topic] = (float(odom.pose.pose.position.x),
                                    float(odom.twist.twist.linear.x))
            if topic == '/human/odom':
                self.send_state()
        elif topic == '/ego/accel_cmd':
            self.av_accel = float(deserialize_message(data, message_class(
                'geometry_msgs/msg/AccelStamped')).accel.linear.x)
        elif topic in ('/ego/plan', '/ego/expected_plan'):
            self.on_plan(topic, data)
        elif topic == '/human/driver_status' and self.start_ns:
            self.on_status(data)

    def on_plan(self, topic: str, data: bytes) -> None:
        """Every model's live trust, from the drive's plans only (none before the start)."""
        from rclpy.serialization import deserialize_message

        from trust_av_common.ros.messages import message_class, msg_ns

        plan = deserialize_message(data, message_class('trajectory_msgs/msg/JointTrajectory'))
        stamp = msg_ns(plan.header.stamp)
        if not self.start_ns or stamp < self.start_ns:
            return
        trust = self.models.add('plan' if topic == '/ego/plan' else 'expected', stamp,
                                [float(p.accelerations[0]) for p in plan.points])
        if trust is not None:
            msg = self.models.message(stamp, trust)
            self.write_own('/driver/model_trust', msg, joint_state_cdr(msg))

    def on_status(self, data: bytes) -> None:
        """The follower's status: a new collision is an event (and may end the drive)."""
        from rclpy.serialization import deserialize_message

        from trust_av_common.ros.messages import diagnostic_values, message_class

        values = diagnostic_values(deserialize_message(data, message_class(
            'diagnostic_msgs/msg/DiagnosticArray')))
        count = int(values.get('collisions', '0'))
        if count > self.collisions:
            self.collisions = self.outcome.collisions = count
            now = time.time_ns()
            self.crash_ns = now
            self.event('collision', now, count=count, protocol=self.settings.on_collision)
            self.send_state()

    # --- the page's messages ---

    def handle(self, message: dict[str, Any], arrived: int) -> None:
        """One admitted message of the page."""
        kind = message['type']
        if kind == 'command':
            self.write_own('/human/accel_cmd', message['msg'])
        elif kind == 'event':
            self.event(message['event'], arrived, left_s=f'{self.left_s():.2f}')
        elif kind == 'ready':
            self.ready = True
        elif kind == 'rating':
            rated = self.gate.rating(message, arrived)
            if rated is not None:
                _prompt, value, response_s = rated
                self.write_own('/driver/rating', vector_msg(arrived, value / 100.0, response_s,
                                                            value))
                self.outcome.ratings.append((self.t_s(arrived), value / 100.0))
        elif kind == 'trust':
            self.gate.trust(message, arrived)    # the scale's position, sampled every tick
        elif kind == 'ack':
            latency = self.gate.echo(message, arrived)
            if latency is not None:
                self.write_own('/driver/latency', vector_msg(arrived, *latency))
                self.outcome.latency_s.append(latency)
        elif kind == 'questionnaire':
            try:
                msg = questionnaire_msg(arrived, message.get('answers'))  # type: ignore[arg-type]
            except (RatingError, TypeError) as err:
                self.gate.refuse('questionnaire with bad answers')
                LOG.warning('a questionnaire refused: %s', err)
                return
            if self.gate.take_questionnaire():
                self.answers = msg

    def drain(self) -> None:
        """Handle every message of the page that came."""
        while True:
            try:
                message, arrived = self.link.events.get_nowait()
            except queue.Empty:
                return
            self.handle(message, arrived)

    # --- the drive's course ---

    def start(self, run: WallRun) -> bool:
        """The start screen until the participant presses Start (or the start times out)."""
        from std_msgs.msg import Empty

        settings = self.settings
        self.set_phase(READY, duration_s=settings.duration_s, **settings.page_info)
        self.event('waiting', time.time_ns())
        deadline = time.monotonic() + settings.start_timeout_s
        while not self.ready:
            if time.monotonic() > deadline:
                return False
            run.spin(0.02)
            run.take_queued()
            self.drain()
            run.graph.check_alive(set())
        with self.link.lock:
            self.link.publisher = self.pubs[COMMAND_TOPIC]
            self.link.last_input_ns = time.time_ns()
        self.pubs['/sim/start'].publish(Empty())
        self.start_ns = time.time_ns()
        run.recording.set_custom_data('trust_av.drive.start_ns', str(self.start_ns))
        self.begin = time.monotonic()
        self.set_phase(DRIVING, duration_s=settings.duration_s)
        self.event('start', self.start_ns)
        # the continuous scale's first sample is its position at the start
        self.next_prompt = self.begin + (0.0 if settings.rating_mode == 'continuous'
                                         else settings.rating_period_s)
        self.outcome.status = 'done'
        return True

    def should_stop(self, run: WallRun, now_ns: int) -> bool:
        """Over when the time is up, at a collision (``on_collision: end``) or when the
        person has sent nothing for ``abandon_after_s`` (abandoned)."""
        if time.monotonic() - self.begin >= self.settings.duration_s:
            return True
        if self.settings.on_collision == 'end' and self.collisions:
            self.outcome.ended_by = 'collision'
            return True
        with self.link.lock:
            gone_s = (time.time_ns() - self.link.last_input_ns) / NS_PER_S
        if gone_s > self.settings.abandon_after_s:
            self.outcome.status = 'abandoned'
            return True
        return False

    def every_tick(self, run: WallRun, now_ns: int) -> None:
        """The page's messages; every ``rating_period_s`` on the drive's clock a rating
        prompt (its event says when it was due), or (continuous) the scale's position
        recorded as a rating, stamped when it was taken: a late tick is late, the schedule
        stays."""
        self.drain()
        if time.monotonic() < self.next_prompt:
            return
        due_s = self.next_prompt - self.begin
        self.next_prompt += self.settings.rating_period_s
        if self.settings.rating_mode == 'continuous':
            self.sample_scale(due_s)
        elif not self.gate.open_prompts():     # one still open stays open
            prompt = self.gate.open_prompt(time.time_ns())
            self.server.send({'type': 'rate', 'id': prompt})
            self.event('rating_prompt', time.time_ns(), id=prompt, due_s=f'{due_s:.3f}')

    def sample_scale(self, due_s: float) -> None:
        """The continuous scale's position now, as a ``/driver/rating`` (y: how long it has
        stood there, s); nothing while it is unset (not touched since the start screen)."""
        scale = self.gate.trust_now()
        if scale is None:
            self.event('rating_unset', time.time_ns(), due_s=f'{due_s:.3f}')
            return
        value, set_ns = scale
        now = time.time_ns()
        self.write_own('/driver/rating', vector_msg(now, value / 100.0,
                                                    max(0, now - set_ns) / NS_PER_S, value))
        self.outcome.ratings.append((self.t_s(now), value / 100.0))

    def stopping(self, run: WallRun) -> None:
        """The end: the drive's time and what ended it; the page waits."""
        if self.start_ns:
            outcome = self.outcome
            outcome.driven_s = time.monotonic() - self.begin
            outcome.ended_by = outcome.ended_by or ('time' if outcome.status == 'done'
                                                    else 'no input')
            end_ns = time.time_ns()
            run.recording.set_custom_data('trust_av.drive.end_ns', str(end_ns))
            self.event('end', end_ns, ended_by=outcome.ended_by)
        with self.link.lock:
            self.link.publisher = None
        self.set_phase(WAIT, ended_by=self.outcome.ended_by)

    def after_stop(self, run: WallRun) -> None:
        """The questionnaire (a finished drive's), then nothing more is admitted."""
        self.drain()
        if (self.settings.questionnaire and self.outcome.status == 'done'
                and not run.recording.finished):
            self.set_phase(QUESTIONNAIRE, items=list(JIAN_ITEMS))
            deadline = time.monotonic() + self.settings.questionnaire_timeout_s
            while self.answers is None and time.monotonic() < deadline:
                time.sleep(0.02)
                self.drain()
            if self.answers is None:
                LOG.warning('no questionnaire answered within %g s',
                            self.settings.questionnaire_timeout_s)
            else:
                self.write_own('/driver/questionnaire', self.answers,
                               joint_state_cdr(self.answers))
                self.outcome.questionnaire = [int(a) for a in self.answers.position[:-1]]
        self.gate.set_phase(IDLE)       # nothing more is admitted: what was is handled
        self.drain()

    def finish(self, run: WallRun, result: WallResult) -> None:
        """The drive's metadata."""
        outcome = self.outcome
        outcome.refused = self.gate.refused_counts()
        outcome.losses = result.losses
        entries = {'trust_av.drive.status': outcome.status,
                   'trust_av.drive.driven_s': f'{outcome.driven_s:.3f}',
                   'trust_av.drive.ended_by': outcome.ended_by,
                   'trust_av.drive.collisions': str(outcome.collisions),
                   'trust_av.drive.on_collision': self.settings.on_collision,
                   'trust_av.drive.refused': str(sum(outcome.refused.values())),
                   **{f'trust_av.drive.refused.{reason_key(reason)}': str(count)
                      for reason, count in sorted(outcome.refused.items())},
                   **{f'trust_av.drive.latency.{key}': f'{number:g}'
                      for key, number in outcome.latency_ms().items()}}
        for key, value in entries.items():   # the keys whole: scripts/doc_names.py reads them
            run.recording.set_custom_data(key, value)
