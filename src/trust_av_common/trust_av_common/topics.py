"""The node graph's topic table, shared by every node, the recorder and the orchestrator.

Pure Python (no rclpy import here): the nodes turn these names into publishers and
subscriptions with the QoS profile named in each row (:mod:`trust_av_common.ros.qos`). One
table (:data:`TOPICS`) is the source of the documentation's topic table and of the connection
check the orchestrator makes before the first step.

Names are relative, so a graph started in a namespace (``--ros-args -r __ns:=/car1``)
publishes and subscribes only inside it (``/car1/ego/odom``); in the root namespace they are
the familiar ``/ego/odom``. That includes the step clock ``clock``: in the root namespace it
is ``/clock`` (what ``use_sim_time`` and ``ros2 bag play --clock`` use); under ``/car1`` it
is ``/car1/clock``, so two graphs in one domain never hear each other's step clock. No node
of the graph uses sim time (they pair messages by header stamp); a node that should follow a
namespaced graph's clock is started with ``-r /clock:=clock``.

Frames (REP-105, REP-103): every vehicle's odometry is in ``odom`` with the vehicle's body
frame as child (:data:`VEHICLE_FRAMES`); plans and commands are accelerations of one vehicle
along its own x axis, in its body frame; the node that publishes a vehicle's odometry also
publishes the transform ``odom`` -> vehicle on ``tf`` with the same stamp. Trust and
diagnostics hold no spatial quantity: ``frame_id`` empty (:data:`NO_FRAME`).

Lock-step protocol (sim time; the step bookkeeping is :mod:`trust_av_common.lockstep`).
Step t starts when ``preceding_traffic`` publishes ``clock`` = t, the preceding vehicle's
odometry and its speed preview, all stamped t. Every step output is stamped with the step's
time t (odometry after a step: t + dt):

- ``planner``: when it holds traffic odometry and preview (t), ego and human odometry (t)
  and the monitor's trust from step t - 1 (none at t = 0): publishes the plan, the expected
  plan, the acceleration command and its status (t);
- ``ego_plant``: on the command (t): integrates and publishes ego odometry (t + dt);
- ``human_driver``: on the expected plan and ego odometry (t): plans, publishes its plan and
  status (t) and its odometry (t + dt);
- ``trust_monitor``: on the plan and expected plan (t): publishes E, P and T(t + 1) (t);
- ``preceding_traffic`` advances to t + 1 only when it holds ego and human odometry
  (t + dt), the trust (t) and the planner status (t): the answer never depends on timing.
"""

from __future__ import annotations

import re
from collections.abc import Iterable
from dataclasses import dataclass

__all__ = ['JOINT_NAME', 'NO_FRAME', 'ODOM_FRAME', 'TOPIC', 'TOPICS', 'VEHICLE_FRAMES',
           'WALL_QOS_TEXT', 'Topic', 'expected_endpoints', 'is_topic_name', 'qualified',
           'topic_table_markdown']

ODOM_FRAME = 'odom'
"""The world-fixed frame (REP-105 ``odom``): x along the road in the direction of travel,
y to the left, z up (REP-103); a simulated run starts the human driver's front bumper at 0."""

VEHICLE_FRAMES = {'preceding_traffic': 'preceding_vehicle', 'ego_plant': 'ego',
                  'human_driver': 'human'}
"""Node -> the body frame of the vehicle whose odometry it publishes (REP-105 ``base_link``
role: x forward, origin at the front bumper, so the vehicle spans x in [-length, 0])."""

NO_FRAME = ''
"""frame_id of stamped messages that hold no spatial quantity (trust, diagnostics)."""


@dataclass(frozen=True)
class Topic:
    """One row of the topic table.

    Attributes:
        name: relative topic name (resolved in the node's namespace: ``ego/odom`` is
            ``/ego/odom`` in the root namespace and ``/car1/ego/odom`` under ``/car1``).
        msgtype: ``package/msg/Name``.
        publishers: the nodes that publish it (``tf``: every node that owns a vehicle's
            odometry).
        subscribers: the nodes that subscribe it.
        qos: profile name in :data:`trust_av_common.ros.qos.QOS`.
        rate: when it is published, in words.
        units: what its fields mean, with units.
        frames: ``header.frame_id`` (and ``child_frame_id``) of its messages.
        per_step: messages per lock-step step, all publishers together.
        initial: messages published before the first step (the initial states).
        wall_qos: profile name in wall mode (:func:`trust_av_common.ros.qos.wall_qos`).
    """

    name: str
    msgtype: str
    publishers: tuple[str, ...]
    subscribers: tuple[str, ...]
    qos: str
    rate: str
    units: str
    frames: str
    per_step: int = 1
    initial: int = 0
    wall_qos: str = 'STATE'

    def messages(self, steps: int) -> int:
        """Messages of a lock-step run of ``steps`` steps (what the recorder must hold)."""
        return self.per_step * steps + self.initial


NODES = ('preceding_traffic', 'planner', 'ego_plant', 'human_driver', 'trust_monitor',
         'recorder')

_ODOM_UNITS = 'pose.position.x: m along the road (front bumper); twist.linear.x: m/s'
_STATUS_FRAMES = "'' (not spatial)"
_AV_BODY = ("the AV's body frame: its odometry's child_frame_id (`ego` here), `base_frame_id` "
            '(default `base_link`) before the first')

TOPICS: tuple[Topic, ...] = (
    Topic('clock', 'rosgraph_msgs/msg/Clock', ('preceding_traffic',), ('recorder',),
          'CLOCK', 'once per step', 'sim time, s', 'none (no header)'),
    Topic('preceding_vehicle/odom', 'nav_msgs/msg/Odometry', ('preceding_traffic',),
          ('planner', 'recorder'), 'STEP', 'once per step', _ODOM_UNITS,
          '`odom`, child `preceding_vehicle`', wall_qos='SENSOR'),
    Topic('preceding_vehicle/speed_preview', 'trajectory_msgs/msg/JointTrajectory',
          ('preceding_traffic',), ('planner', 'recorder'), 'STEP', 'once per step',
          'N points, velocities[0]: m/s, time_from_start k*dt', '`preceding_vehicle`',
          wall_qos='SENSOR'),
    Topic('ego/odom', 'nav_msgs/msg/Odometry', ('ego_plant',),
          ('planner', 'human_driver', 'preceding_traffic', 'recorder'), 'STEP',
          'once per step (+ the initial state)', _ODOM_UNITS, '`odom`, child `ego`',
          initial=1, wall_qos='SENSOR'),
    Topic('ego/plan', 'trajectory_msgs/msg/JointTrajectory', ('planner',),
          ('trust_monitor', 'recorder'), 'STEP', 'once per step',
          'N points, accelerations[0]: m/s^2', _AV_BODY),
    Topic('ego/expected_plan', 'trajectory_msgs/msg/JointTrajectory', ('planner',),
          ('trust_monitor', 'human_driver', 'recorder'), 'STEP', 'once per step',
          'u_R^H: N points, accelerations[0]: m/s^2', _AV_BODY),
    Topic('ego/accel_cmd', 'geometry_msgs/msg/AccelStamped', ('planner',),
          ('ego_plant', 'recorder'), 'STEP', 'once per step', 'accel.linear.x: m/s^2',
          _AV_BODY, wall_qos='COMMAND'),
    Topic('ego/planner_status', 'diagnostic_msgs/msg/DiagnosticArray', ('planner',),
          ('preceding_traffic', 'recorder'), 'STEP', 'once per step',
          'solver status, iterations, solve time (s), fallback, gap bounds relaxed, E_max',
          _STATUS_FRAMES),
    Topic('human/odom', 'nav_msgs/msg/Odometry', ('human_driver',),
          ('planner', 'preceding_traffic', 'recorder'), 'STEP',
          'once per step (+ the initial state)', _ODOM_UNITS, '`odom`, child `human`',
          initial=1, wall_qos='SENSOR'),
    Topic('human/plan', 'trajectory_msgs/msg/JointTrajectory', ('human_driver',),
          ('recorder',), 'STEP', 'once per step', 'N points, accelerations[0]: m/s^2',
          '`human`'),
    Topic('human/driver_status', 'diagnostic_msgs/msg/DiagnosticArray', ('human_driver',),
          ('preceding_traffic', 'recorder'), 'STEP', 'once per step',
          'solver status, solve time (s)',
          _STATUS_FRAMES),
    Topic('trust_monitor/trust', 'geometry_msgs/msg/Vector3Stamped', ('trust_monitor',),
          ('planner', 'preceding_traffic', 'recorder'), 'STEP', 'once per step',
          'vector.x: E, vector.y: P, vector.z: trust after the step (dimensionless)',
          _STATUS_FRAMES),
    Topic('tf', 'tf2_msgs/msg/TFMessage', ('preceding_traffic', 'ego_plant', 'human_driver'),
          ('recorder',), 'STEP',
          'with every odometry message: 3 per step, 2 at start-up (ego and human)',
          'transform.translation.x: m, the odometry position; rotation identity',
          '`odom` to `preceding_vehicle`, `ego`, `human`', per_step=3, initial=2),
    Topic('vehicle_markers', 'visualization_msgs/msg/MarkerArray', ('planner',),
          ('recorder',), 'STEP', 'once per step',
          'per vehicle a box (x from -vehicle_length_m to 0, 1.8 m wide, 1.5 m high) and a '
          'label', "each vehicle's own frame, frame_locked"),
    Topic('sim/start', 'std_msgs/msg/Empty', ('orchestrator',), ('preceding_traffic',),
          'LATCHED', 'once', 'none: the go signal after the graph is connected',
          'none (no header)', per_step=0, initial=1, wall_qos='LATCHED'),
)
TOPIC = {t.name: t for t in TOPICS}

DIAGNOSTICS_TOPIC = Topic(
    '/diagnostics', 'diagnostic_msgs/msg/DiagnosticArray', NODES, (), 'DIAGNOSTICS',
    "once a second from a steady timer (diagnostic_updater's default period), and at once "
    'when a status changes; in every lifecycle state',
    "one status per message, named `<node's full name>: <task>`; level OK/WARN/ERROR; "
    'message: what it does or why not (`not running: ...`); values: lifecycle_state, '
    "dropped_messages and the planner's solves, fallbacks, stale_input_ticks, "
    'solve_time_last_s, solve_time_max_recent_s, trust, command_mps2, input_age_<input>_s '
    "(wall mode), the monitor's scored, explicability, performance, trust", _STATUS_FRAMES,
    per_step=0, wall_qos='DIAGNOSTICS')
"""The system's health topic (trust_av_common.ros.diagnostics): absolute, every node
publishes it, no node of the graph subscribes (tools do: rqt_robot_monitor,
diagnostic_aggregator, Foxglove); timed by the wall clock, so not part of a lock-step step
and not recorded (not in :data:`TOPICS`)."""


_TOPIC_NAME = re.compile(r'(~|~/|/)?[A-Za-z_][A-Za-z0-9_]*(/[A-Za-z_][A-Za-z0-9_]*)*', re.ASCII)


def is_topic_name(name: str) -> bool:
    """Whether ``name`` is a valid ROS 2 topic name, absolute or relative (rcl
    ``rcl_validate_topic_name``, without ``{}`` substitutions): tokens of letters, digits and
    underscores separated by ``/``, none starting with a digit, no empty token."""
    return _TOPIC_NAME.fullmatch(name) is not None


def qualified(name: str, namespace: str = '/') -> str:
    """The fully qualified name of a relative topic name in ``namespace`` (rcl's expansion
    of a relative name: ``qualified('ego/odom', '/car1') == '/car1/ego/odom'``)."""
    if name.startswith('/'):
        return name
    return f'{namespace.rstrip("/")}/{name}'


JOINT_NAME = 'longitudinal'
"""The one joint of every longitudinal JointTrajectory."""


LOCKSTEP_QOS_TEXT = {'STEP': 'reliable, transient local, keep last 1000',
                     'CLOCK': 'reliable, transient local, keep last 1000',
                     'LATCHED': 'reliable, transient local, keep last 1',
                 'DIAGNOSTICS': "reliable, volatile, keep last 1 (diagnostic_updater's)"}
"""The lock-step profiles (``qos`` column): nothing lost, late joiners served (determinism)."""

WALL_QOS_TEXT = {
    'SENSOR': 'best effort, volatile, keep last 1; subscriptions request no deadline unless '
              'input_deadline_qos (then input_timeout_s), publishers offer 2 control periods '
              "(sensor data: only the newest sample counts; matches any vehicle stack's "
              'publisher; an input older than input_timeout_s is stale)',
    'COMMAND': 'reliable, volatile, keep last 1, deadline 2 control periods (a command: the '
               'newest or none, never a backlog or an old one to a late joiner)',
    'STATE': 'reliable, volatile, keep last 10',
    'LATCHED': 'reliable, transient local, keep last 1',
    'DIAGNOSTICS': "reliable, volatile, keep last 1 (diagnostic_updater's)",
}
"""The wall-mode profiles (``wall_qos`` column) and why (``trust_av_common.ros.qos.wall_qos``)."""


def topic_table_markdown() -> str:
    """The topic table of docs/reference/topics-and-qos.md, generated from :data:`TOPICS`."""
    lines = ['| topic | type | publishers | subscribers | QoS (lock-step) | QoS (wall mode) | '
             'rate | units | frames |',
             '|---|---|---|---|---|---|---|---|---|']
    for t in (*TOPICS, DIAGNOSTICS_TOPIC):
        wall = 'not published' if t.name == 'clock' else WALL_QOS_TEXT[t.wall_qos]
        lines.append(f'| `{t.name}` | `{t.msgtype}` | {", ".join(t.publishers)} | '
                     f'{", ".join(t.subscribers)} | {LOCKSTEP_QOS_TEXT[t.qos]} | {wall} | '
                     f'{t.rate} | {t.units} | {t.frames} |')
    return '\n'.join(lines) + '\n'


def expected_endpoints(nodes: Iterable[str] = NODES) -> dict[str, tuple[int, int]]:
    """Topic -> (publishers, subscribers) when every node in ``nodes`` is up."""
    present = set(nodes) | {'orchestrator'}
    out = {}
    for topic in TOPICS:
        pubs = sum(1 for p in topic.publishers if p in present)
        subs = sum(1 for s in topic.subscribers if s in present)
        out[topic.name] = (pubs, subs)
    return out
