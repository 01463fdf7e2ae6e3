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

import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from preceding_traffic.replay import LeadReplay
from preceding_traffic.traces import SpeedTrace
from trust_av.graph.lifecycle_client import MANAGED_NODES
from trust_av.graph.orchestrator import node_specs, write_record
from trust_av.graph.processes import NodeSpec
from trust_av.graph.publication_ledger import Lost, check_lossless
from trust_av.graph.wall_run import (
    RecordedTopic,
    WallHooks,
    WallPlan,
    WallRun,
    initial_messages,
    run_wall,
    tf_frames,
)
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


class _Player(WallHooks):
    """Shadow's player: at every tick the lead's odometry and preview from the trace and
    the simulated ego's odometry, which follows the latest ``/ego/accel_cmd``."""

    def __init__(self, config: RunConfig, trace: SpeedTrace, topics: PlannerTopics,
                 duration_s: float, rate_hz: float) -> None:
        self.cfg = config.for_trace(trace)
        initial = equilibrium_start(self.cfg, trace)
        self.lead = LeadReplay(trace, initial.traffic.position_m)
        self.ego = initial.av
        self.topics = topics
        self.duration_s = duration_s
        self.wall = WallClockConfig(clock_mode='wall', control_rate_hz=rate_hz)
        self.stats = LoopStats(self.wall.period_ns)
        self.accel_mps2 = 0.0
        self.start_ns = self.last_ns = 0
        self.pubs: list[Any] = []

    def setup(self, run: WallRun) -> None:
        from trust_av_common.ros.messages import message_class
        from trust_av_common.ros.qos import RECORD_QOS, wall_qos

        sensor = wall_qos('SENSOR', self.wall, publisher=True)
        self.pubs = [run.node.create_publisher(message_class(TOPIC[row].msgtype), name, sensor)
                     for row, name in (('preceding_vehicle/odom', self.topics.lead_odom_topic),
                                       ('preceding_vehicle/speed_preview',
                                        self.topics.lead_preview_topic),
                                       ('ego/odom', self.topics.ego_odom_topic))]
        run.node.create_subscription(message_class(TOPIC['ego/accel_cmd'].msgtype),
                                     '/ego/accel_cmd', self.on_command, RECORD_QOS)

    def on_command(self, msg: Any) -> None:
        self.accel_mps2 = float(msg.accel.linear.x)

    def publishers(self, topic: str, data: bytes) -> tuple[str, ...]:
        """The inputs: this player; the outputs: their node."""
        return (TOPIC[topic.lstrip('/')].publishers[0] if topic in OUTPUTS else 'shadow_player',)

    def start(self, run: WallRun) -> bool:
        self.start_ns = self.last_ns = time.monotonic_ns()
        return True

    def should_stop(self, run: WallRun, now_ns: int) -> bool:
        self.stats.tick(now_ns)
        return (now_ns - self.start_ns) / NS_PER_S > self.duration_s

    def every_tick(self, run: WallRun, now_ns: int) -> None:
        from trust_av_common.ros.messages import odometry, trajectory

        elapsed_s = (now_ns - self.start_ns) / NS_PER_S
        self.ego = _advance(self.ego, self.accel_mps2, (now_ns - self.last_ns) / NS_PER_S)
        self.last_ns = now_ns
        stamp = time.time_ns()
        state = self.lead.state(elapsed_s)
        planner = self.cfg.planner
        pub_lead, pub_preview, pub_ego = self.pubs
        pub_lead.publish(odometry(stamp, state.position_m, state.speed_mps, 'preceding_vehicle'))
        pub_preview.publish(trajectory(
            stamp, planner.dt_s, frame_id='preceding_vehicle',
            velocities=self.lead.preview(elapsed_s, planner.horizon_steps,
                                         planner.dt_s).tolist()))
        pub_ego.publish(odometry(stamp, self.ego.position_m, self.ego.speed_mps, 'ego'))
        for sent in self.pubs:
            self.stats.publish(sent.topic_name)
        self.stats.done(time.monotonic_ns() - now_ns)

    def own_loops(self) -> dict[str, Any]:
        return {'shadow_player': {'node': 'shadow_player', **self.stats.summary()}}


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
    from trust_av_common.ros.qos import record_qos, wall_qos

    topics = topics if topics is not None else PlannerTopics()
    # actual topic name -> the topic-table entry it stands for (message type, QoS)
    recorded = {qualified(topics.lead_odom_topic): TOPIC['preceding_vehicle/odom'],
                qualified(topics.ego_odom_topic): TOPIC['ego/odom'],
                **{name: TOPIC[name.lstrip('/')] for name in OUTPUTS}}
    wall = WallClockConfig(clock_mode='wall', control_rate_hz=rate_hz)
    player = _Player(config, trace, topics, duration_s, rate_hz)
    needs = {qualified(topics.lead_odom_topic): (1, 2),
             qualified(topics.lead_preview_topic): (1, 1),
             qualified(topics.ego_odom_topic): (1, 2), '/ego/plan': (1, 2),
             '/ego/expected_plan': (1, 2),
             '/ego/accel_cmd': (1, 2), '/ego/planner_status': (1, 1),
             '/trust_monitor/trust': (1, 2)}
    plan = WallPlan(
        'shadow_player', lambda log_dir: shadow_specs(config, trace, rate_hz, log_dir),
        config.params_files, bag,
        [RecordedTopic(name, topic.msgtype,
                       offered_profiles(wall_qos(topic.wall_qos, wall, publisher=True),
                                        len(topic.publishers)), record_qos(topic.wall_qos))
         for name, topic in recorded.items()],
        needs, SHADOW_NODES, startup_timeout_s,
        custom_data=lambda graph: write_record(config, trace, graph),
        tick_s=1.0 / rate_hz)
    result = run_wall(plan, player)
    check_lossless(result.ledger, result.losses)
    return ShadowRun(bag=bag, duration_s=duration_s, counts=result.counts, loops=result.loops)


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


class _WallRecorder(WallHooks):
    """The whole-graph wall run's recorder: ``/sim/start`` once every publisher is heard
    here, then every topic recorded until ``duration_s`` has passed."""

    def __init__(self, duration_s: float,
                 every_second: Callable[[dict[str, int], float], None] | None,
                 on_message: Callable[[str, int, bytes], None] | None) -> None:
        self.duration_s = duration_s
        self.callbacks = every_second, on_message
        self.tf_before_start = {VEHICLE_FRAMES[n] for n in TOPIC['tf'].publishers
                                if n != 'preceding_traffic'}
        self.tf_seen: set[str] = set()     # child frames heard on tf before /sim/start
        self.vehicle_node = {frame: name for name, frame in VEHICLE_FRAMES.items()}
        self.started = 0.0
        self.start_pub: Any = None
        self.pids: dict[str, int] = {}

    def setup(self, run: WallRun) -> None:
        from std_msgs.msg import Empty

        from trust_av_common.ros.qos import QOS

        self.start_pub = run.node.create_publisher(Empty, '/sim/start', QOS['LATCHED'])

    def publishers(self, topic: str, data: bytes) -> Iterable[str]:
        if topic != TF_TOPIC:
            return (TOPIC[topic.lstrip('/')].publishers[0],)
        frames = tf_frames(data)          # three publishers: told apart by frame
        if not self.started:
            self.tf_seen.update(frames)
        return {self.vehicle_node.get(frame, frame) for frame in frames}

    def on_message(self, run: WallRun, topic: str, data: bytes, info: dict[str, Any]) -> None:
        if self.callbacks[1] is not None:
            self.callbacks[1](topic, int(info['publication_sequence_number']), data)

    def pending(self, run: WallRun) -> list[str]:
        """/sim/start only once this process receives every publisher: the graph's endpoint
        counts say that a publisher exists, not that it sends here (the wall profiles are
        volatile: what a publisher sent before it matched this subscription is never
        resent). Proof is a message received from each publisher (on tf: each vehicle's
        child frame); for a publisher that starts only after /sim/start, this
        subscription's own match with it."""
        publishers = {qualified(t.name): len(t.publishers) for t in TOPICS}
        missing = [f'{sub.topic_name} (not every publisher matched here yet)'
                   for sub in run.subscriptions
                   if sub.get_publisher_count() < publishers[sub.topic_name]]
        missing += [f'{sub.topic_name} (not received here yet)' for sub in run.subscriptions
                    if sub.topic_name not in AFTER_START
                    and run.recording.count(sub.topic_name) < 1]
        missing += [f'{TF_TOPIC} from {frame} (not received here yet)'
                    for frame in sorted(self.tf_before_start - self.tf_seen)]
        return missing

    def start(self, run: WallRun) -> bool:
        from std_msgs.msg import Empty

        self.start_pub.publish(Empty())
        self.started = time.monotonic()
        self.pids = {p.spec.name: p.popen.pid for p in run.graph.processes}
        return True

    def should_stop(self, run: WallRun, now_ns: int) -> bool:
        return time.monotonic() >= self.started + self.duration_s

    def every_second(self, run: WallRun, now_ns: int) -> None:
        if self.callbacks[0] is not None:
            self.callbacks[0](self.pids, time.monotonic() - self.started)


TF_TOPIC = qualified('tf')


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
    from trust_av.graph.bag_qos import offered_profiles
    from trust_av_common.ros.qos import QOS, record_qos

    recorded = [t for t in TOPICS if t.name not in ('clock', 'sim/start')]
    # In wall mode the traffic node subscribes nothing but /sim/start (as do the two simulated
    # vehicles, which hold still until then); this process records.
    needs = {qualified(t.name): (len(t.publishers),
                                 len([s for s in t.subscribers if s != 'preceding_traffic']))
             for t in recorded}
    needs['/sim/start'] = (1, 3)
    # the publishers that start only once /sim/start has come: every message is the run's
    from_first = {(name, node) for name in AFTER_START
                  for node in TOPIC[name.lstrip('/')].publishers}
    from_first.add((TF_TOPIC, 'preceding_traffic'))
    plan = WallPlan(
        'wall_recorder', lambda log_dir: wall_specs(config, trace_arg, trace, rate_hz, log_dir),
        config.params_files, bag,
        [RecordedTopic(qualified(t.name), t.msgtype,
                       offered_profiles(QOS[t.qos], len(t.publishers)),
                       record_qos(t.wall_qos)) for t in recorded],
        needs, WALL_GRAPH_NODES, startup_timeout_s,
        custom_data=lambda graph: write_record(config, trace, graph),
        from_first=from_first,
        stop_edge={(qualified(t.name), n) for t in recorded if t.wall_qos == 'SENSOR'
                   for n in t.publishers},
        initial=initial_messages(recorded, {}))
    result = run_wall(plan, _WallRecorder(duration_s, every_second, on_message))
    if lossless:
        check_lossless(result.ledger, result.losses)
    return ShadowRun(bag=bag, duration_s=duration_s, counts=result.counts, loops=result.loops,
                     losses=result.losses)


def _advance(ego: VehicleState, accel_mps2: float, dt_s: float) -> VehicleState:
    """The simulated ego over ``dt_s`` of wall time; speed kept >= 0 (no reversing)."""
    return VehicleState(*advance(ego.position_m, ego.speed_mps, accel_mps2, dt_s))


