"""``field_labels`` node: trust and plans with their values named, for PlotJuggler and
Foxglove (:mod:`trust_av_autoware.labels`; docs/operations/real-vehicle.md).

``trust_monitor/trust`` -> ``labelled/trust`` (``explicability``, ``performance``,
``trust``); ``ego/plan`` -> ``labelled/plan`` and ``ego/expected_plan`` ->
``labelled/expected_plan`` (``accel_mps2_at_<t>s`` per point), each a
``sensor_msgs/JointState`` with the source's header (stamp and frame). Subscribed best
effort, volatile, keep last 10 (matches the lock-step and the wall-mode publishers); published
reliable, volatile, keep last 10. A message with a value that is not finite, or a plan with
another joint or no acceleration, is dropped and counted (``/diagnostics``).
"""

from __future__ import annotations

import functools
import sys
import time
from typing import Any

from geometry_msgs.msg import Vector3Stamped
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory

from trust_av_autoware.adapter_status import AdapterStatus
from trust_av_autoware.labels import TRUST_NAMES, finite_values, plan_names
from trust_av_common.ros.diagnostics import NodeDiagnostics
from trust_av_common.ros.messages import trajectory_times
from trust_av_common.ros.spin import spin_node
from trust_av_common.topics import JOINT_NAME

__all__ = ['main']

IN_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10,
                    reliability=ReliabilityPolicy.BEST_EFFORT,
                    durability=DurabilityPolicy.VOLATILE)
OUT_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10,
                     reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.VOLATILE)
PLANS = {'ego/plan': 'labelled/plan', 'ego/expected_plan': 'labelled/expected_plan'}


class LabelsNode(Node):
    """The ``field_labels`` node (see the module docstring)."""

    def __init__(self) -> None:
        super().__init__('field_labels')
        self.finished = False
        self.stopping = False
        self.exit_code = 0
        self.status = AdapterStatus(('trust', *PLANS))
        self.pub_trust = self.create_publisher(JointState, 'labelled/trust', OUT_QOS)
        self.create_subscription(Vector3Stamped, 'trust_monitor/trust', self.on_trust, IN_QOS)
        for source, target in PLANS.items():
            publisher = self.create_publisher(JointState, target, OUT_QOS)
            self.create_subscription(
                JointTrajectory, source, functools.partial(self.on_plan, source, publisher),
                IN_QOS)
        self.diagnostics = NodeDiagnostics(
            self, 'field_labels',
            lambda: self.status.report(time.time_ns(), '', 'labelling trust and plans'))

    def on_trust(self, msg: Vector3Stamped) -> None:
        self.status.received('trust', time.time_ns())
        values = [msg.vector.x, msg.vector.y, msg.vector.z]
        if not finite_values(values):
            self.status.dropped('trust', 'not_finite', f'a value is not finite: {values}')
            return
        self.status.used('trust')
        self.pub_trust.publish(JointState(header=msg.header, name=list(TRUST_NAMES),
                                          position=values))
        self.status.published('labelled_trust')

    def on_plan(self, source: str, publisher: Any, msg: JointTrajectory) -> None:
        self.status.received(source, time.time_ns())
        if list(msg.joint_names) != [JOINT_NAME] or \
                any(len(p.accelerations) != 1 for p in msg.points):
            self.status.dropped(source, 'not_a_plan', f'joints {list(msg.joint_names)}, '
                                'expected one acceleration per point')
            return
        values = [float(p.accelerations[0]) for p in msg.points]
        if not finite_values(values):
            self.status.dropped(source, 'not_finite', 'an acceleration is not finite')
            return
        self.status.used(source)
        publisher.publish(JointState(
            header=msg.header, name=plan_names(trajectory_times(msg)), position=values))
        self.status.published(PLANS[source].replace('/', '_'))

    def close(self) -> None:
        """Nothing to release."""


def main(args: list[str] | None = None) -> int:
    """Entry point: ``ros2 run trust_av_autoware field_labels --ros-args ...``."""
    return spin_node(LabelsNode, args)


if __name__ == '__main__':
    sys.exit(main())
