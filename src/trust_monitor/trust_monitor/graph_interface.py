"""The node graph's interface, shared by every node: topics, QoS profiles, step bookkeeping.

Pure Python (no rclpy import here): the nodes turn these names into publishers and
subscriptions. One table (:data:`TOPICS`) is the source of the README's topic table and of
the connection check the orchestrator makes before the first step.

Lock-step protocol (sim time). Step t starts when ``preceding_traffic`` publishes
``/clock`` = t, the preceding vehicle's odometry and its speed preview, all stamped t. Every
step output is stamped with the step's time t (odometry after a step: t + dt):

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

from collections import defaultdict
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


NODES = ('preceding_traffic', 'planner', 'ego_plant', 'human_driver', 'trust_monitor',
         'recorder')

TOPICS: tuple[Topic, ...] = (
    Topic('/clock', 'rosgraph_msgs/msg/Clock', 'preceding_traffic', ('recorder',),
          'CLOCK', 'once per step', 'sim time, s'),
    Topic('/preceding_vehicle/odom', 'nav_msgs/msg/Odometry', 'preceding_traffic',
          ('planner', 'recorder'), 'STEP', 'once per step',
          'pose.position.x: m along the road; twist.linear.x: m/s'),
    Topic('/preceding_vehicle/speed_preview', 'trajectory_msgs/msg/JointTrajectory',
          'preceding_traffic', ('planner', 'recorder'), 'STEP', 'once per step',
          'N points, velocities[0]: m/s, time_from_start k*dt'),
    Topic('/ego/odom', 'nav_msgs/msg/Odometry', 'ego_plant',
          ('planner', 'human_driver', 'preceding_traffic', 'recorder'), 'STEP',
          'once per step (+ the initial state)', 'as above'),
    Topic('/ego/plan', 'trajectory_msgs/msg/JointTrajectory', 'planner',
          ('trust_monitor', 'recorder'), 'STEP', 'once per step',
          'N points, accelerations[0]: m/s^2'),
    Topic('/ego/expected_plan', 'trajectory_msgs/msg/JointTrajectory', 'planner',
          ('trust_monitor', 'human_driver', 'recorder'), 'STEP', 'once per step',
          'u_R^H: N points, accelerations[0]: m/s^2'),
    Topic('/ego/accel_cmd', 'geometry_msgs/msg/AccelStamped', 'planner',
          ('ego_plant', 'recorder'), 'STEP', 'once per step', 'accel.linear.x: m/s^2'),
    Topic('/ego/planner_status', 'diagnostic_msgs/msg/DiagnosticArray', 'planner',
          ('preceding_traffic', 'recorder'), 'STEP', 'once per step',
          'solver status, iterations, solve time (s), fallback, E_max'),
    Topic('/human/odom', 'nav_msgs/msg/Odometry', 'human_driver',
          ('planner', 'preceding_traffic', 'recorder'), 'STEP',
          'once per step (+ the initial state)', 'as above'),
    Topic('/human/plan', 'trajectory_msgs/msg/JointTrajectory', 'human_driver',
          ('recorder',), 'STEP', 'once per step', 'N points, accelerations[0]: m/s^2'),
    Topic('/human/driver_status', 'diagnostic_msgs/msg/DiagnosticArray', 'human_driver',
          ('recorder',), 'STEP', 'once per step', 'solver status, solve time (s)'),
    Topic('/trust_monitor/trust', 'geometry_msgs/msg/Vector3Stamped', 'trust_monitor',
          ('planner', 'preceding_traffic', 'recorder'), 'STEP', 'once per step',
          'vector.x: E, vector.y: P, vector.z: trust after the step (dimensionless)'),
    Topic('/sim/start', 'std_msgs/msg/Empty', 'orchestrator', ('preceding_traffic',),
          'LATCHED', 'once', 'none: the go signal after the graph is connected'),
)
TOPIC = {t.name: t for t in TOPICS}

JOINT_NAME = 'longitudinal'
"""The one joint of every longitudinal JointTrajectory."""


def topic_table_markdown() -> str:
    """The README's topic table, generated from :data:`TOPICS` (a test keeps them equal)."""
    qos = {'STEP': 'reliable, transient local, keep last 1000',
           'CLOCK': 'reliable, transient local, keep last 1000',
           'LATCHED': 'reliable, transient local, keep last 1'}
    lines = ['| topic | type | publisher | subscribers | QoS | rate | units |',
             '|---|---|---|---|---|---|---|']
    for t in TOPICS:
        lines.append(f'| `{t.name}` | `{t.msgtype}` | {t.publisher} | '
                     f'{", ".join(t.subscribers)} | {qos[t.qos]} | {t.rate} | {t.units} |')
    return '\n'.join(lines) + '\n'


def stamp_ns(t_s: float) -> int:
    """Integer nanoseconds of a time in seconds (the key that pairs messages of a step)."""
    return round(t_s * 1e9)


def split_ns(ns: int) -> tuple[int, int]:
    """(sec, nanosec) of ``builtin_interfaces/Time``."""
    return ns // 1_000_000_000, ns % 1_000_000_000


def expected_endpoints(nodes: Iterable[str] = NODES) -> dict[str, tuple[int, int]]:
    """Topic -> (publishers, subscribers) when every node in ``nodes`` is up."""
    present = set(nodes) | {'orchestrator'}
    out = {}
    for topic in TOPICS:
        pubs = 1 if topic.publisher in present else 0
        subs = sum(1 for s in topic.subscribers if s in present)
        out[topic.name] = (pubs, subs)
    return out


class StepBuffer:
    """Messages keyed by (input, stamp); tells when every input of a stamp has arrived.

    Args:
        inputs: names of the inputs a step needs.
    """

    def __init__(self, inputs: Iterable[str]) -> None:
        self.inputs = tuple(inputs)
        self._items: dict[int, dict[str, object]] = defaultdict(dict)

    def put(self, name: str, stamp: int, item: object) -> None:
        """Store one input; a second message for the same input and stamp is an error."""
        if name not in self.inputs:
            raise KeyError(f'unknown input {name!r}')
        if name in self._items[stamp]:
            raise ValueError(f'duplicate {name} for stamp {stamp} ns')
        self._items[stamp][name] = item

    def ready(self, stamp: int, needed: Iterable[str] | None = None) -> bool:
        """True when every needed input of ``stamp`` is there."""
        have = self._items.get(stamp, {})
        return all(n in have for n in (self.inputs if needed is None else needed))

    def ready_stamps(self, needed: Iterable[str] | None = None) -> list[int]:
        """Stamps whose needed inputs are all there, oldest first."""
        needed = tuple(self.inputs if needed is None else needed)
        return sorted(s for s in self._items if self.ready(s, needed))

    def pop(self, stamp: int) -> dict[str, object]:
        """Take the inputs of ``stamp`` (and forget older stamps)."""
        items = self._items.pop(stamp)
        for old in [s for s in self._items if s < stamp]:
            del self._items[old]
        return items

    def take(self, name: str, stamp: int) -> object:
        """Take one stored input of ``stamp``."""
        return self._items[stamp].pop(name)
