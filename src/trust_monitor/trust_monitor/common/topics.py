"""The node graph's topic table, shared by every node, the recorder and the orchestrator.

Pure Python (no rclpy import here): the nodes turn these names into publishers and
subscriptions with the QoS profile named in each row (:mod:`trust_monitor.ros.qos`). One
table (:data:`TOPICS`) is the source of the README's topic table and of the connection
check the orchestrator makes before the first step.

Lock-step protocol (sim time; the step bookkeeping is :mod:`trust_monitor.common.lockstep`).
Step t starts when ``preceding_traffic`` publishes ``/clock`` = t, the preceding vehicle's
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

from collections.abc import Iterable
from dataclasses import dataclass


@dataclass(frozen=True)
class Topic:
    """One row of the topic table."""

    name: str
    msgtype: str
    publisher: str
    subscribers: tuple[str, ...]
    qos: str
    rate: str
    units: str
    wall_qos: str = 'STATE'


NODES = ('preceding_traffic', 'planner', 'ego_plant', 'human_driver', 'trust_monitor',
         'recorder')

TOPICS: tuple[Topic, ...] = (
    Topic('/clock', 'rosgraph_msgs/msg/Clock', 'preceding_traffic', ('recorder',),
          'CLOCK', 'once per step', 'sim time, s'),
    Topic('/preceding_vehicle/odom', 'nav_msgs/msg/Odometry', 'preceding_traffic',
          ('planner', 'recorder'), 'STEP', 'once per step',
          'pose.position.x: m along the road; twist.linear.x: m/s', wall_qos='SENSOR'),
    Topic('/preceding_vehicle/speed_preview', 'trajectory_msgs/msg/JointTrajectory',
          'preceding_traffic', ('planner', 'recorder'), 'STEP', 'once per step',
          'N points, velocities[0]: m/s, time_from_start k*dt', wall_qos='SENSOR'),
    Topic('/ego/odom', 'nav_msgs/msg/Odometry', 'ego_plant',
          ('planner', 'human_driver', 'preceding_traffic', 'recorder'), 'STEP',
          'once per step (+ the initial state)', 'as above', wall_qos='SENSOR'),
    Topic('/ego/plan', 'trajectory_msgs/msg/JointTrajectory', 'planner',
          ('trust_monitor', 'recorder'), 'STEP', 'once per step',
          'N points, accelerations[0]: m/s^2'),
    Topic('/ego/expected_plan', 'trajectory_msgs/msg/JointTrajectory', 'planner',
          ('trust_monitor', 'human_driver', 'recorder'), 'STEP', 'once per step',
          'u_R^H: N points, accelerations[0]: m/s^2'),
    Topic('/ego/accel_cmd', 'geometry_msgs/msg/AccelStamped', 'planner',
          ('ego_plant', 'recorder'), 'STEP', 'once per step', 'accel.linear.x: m/s^2',
          wall_qos='COMMAND'),
    Topic('/ego/planner_status', 'diagnostic_msgs/msg/DiagnosticArray', 'planner',
          ('preceding_traffic', 'recorder'), 'STEP', 'once per step',
          'solver status, iterations, solve time (s), fallback, E_max'),
    Topic('/human/odom', 'nav_msgs/msg/Odometry', 'human_driver',
          ('planner', 'preceding_traffic', 'recorder'), 'STEP',
          'once per step (+ the initial state)', 'as above', wall_qos='SENSOR'),
    Topic('/human/plan', 'trajectory_msgs/msg/JointTrajectory', 'human_driver',
          ('recorder',), 'STEP', 'once per step', 'N points, accelerations[0]: m/s^2'),
    Topic('/human/driver_status', 'diagnostic_msgs/msg/DiagnosticArray', 'human_driver',
          ('recorder',), 'STEP', 'once per step', 'solver status, solve time (s)'),
    Topic('/trust_monitor/trust', 'geometry_msgs/msg/Vector3Stamped', 'trust_monitor',
          ('planner', 'preceding_traffic', 'recorder'), 'STEP', 'once per step',
          'vector.x: E, vector.y: P, vector.z: trust after the step (dimensionless)'),
    Topic('/sim/start', 'std_msgs/msg/Empty', 'orchestrator', ('preceding_traffic',),
          'LATCHED', 'once', 'none: the go signal after the graph is connected',
          wall_qos='LATCHED'),
)
TOPIC = {t.name: t for t in TOPICS}

JOINT_NAME = 'longitudinal'
"""The one joint of every longitudinal JointTrajectory."""


LOCKSTEP_QOS_TEXT = {'STEP': 'reliable, transient local, keep last 1000',
                     'CLOCK': 'reliable, transient local, keep last 1000',
                     'LATCHED': 'reliable, transient local, keep last 1'}
"""The lock-step profiles (``qos`` column): nothing lost, late joiners served (determinism)."""

WALL_QOS_TEXT = {
    'SENSOR': 'best effort, volatile, keep last 1, deadline input_timeout_s (sensor data: only '
              'the newest sample counts; the deadline tells the planner an input stopped)',
    'COMMAND': 'reliable, volatile, keep last 1, deadline 2 control periods (a command: the '
               'newest or none, never a backlog or an old one to a late joiner)',
    'STATE': 'reliable, volatile, keep last 10',
    'LATCHED': 'reliable, transient local, keep last 1',
}
"""The wall-mode profiles (``wall_qos`` column) and why (``trust_monitor.ros.qos.wall_qos``)."""


def topic_table_markdown() -> str:
    """The README's topic table, generated from :data:`TOPICS` (a test keeps them equal)."""
    lines = ['| topic | type | publisher | subscribers | QoS (lock-step) | QoS (wall mode) | '
             'rate | units |',
             '|---|---|---|---|---|---|---|---|']
    for t in TOPICS:
        wall = 'not published' if t.name == '/clock' else WALL_QOS_TEXT[t.wall_qos]
        lines.append(f'| `{t.name}` | `{t.msgtype}` | {t.publisher} | '
                     f'{", ".join(t.subscribers)} | {LOCKSTEP_QOS_TEXT[t.qos]} | {wall} | '
                     f'{t.rate} | {t.units} |')
    return '\n'.join(lines) + '\n'


def expected_endpoints(nodes: Iterable[str] = NODES) -> dict[str, tuple[int, int]]:
    """Topic -> (publishers, subscribers) when every node in ``nodes`` is up."""
    present = set(nodes) | {'orchestrator'}
    out = {}
    for topic in TOPICS:
        pubs = 1 if topic.publisher in present else 0
        subs = sum(1 for s in topic.subscribers if s in present)
        out[topic.name] = (pubs, subs)
    return out
