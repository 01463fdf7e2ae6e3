"""``trust_monitor`` node: E, P and trust from the observed plan and the expected plan.

Subscribes ``/ego/plan`` and ``/ego/expected_plan`` (paired by header stamp), publishes
``/trust_monitor/trust`` (``geometry_msgs/Vector3Stamped``: x = E, y = P, z = trust after
the step), stamped like the plans. Parameters: the trust model's (``config/trust_av.yaml``).
"""

from __future__ import annotations

import sys

from geometry_msgs.msg import Vector3Stamped
from rclpy.node import Node
from trajectory_msgs.msg import JointTrajectory

from trust_monitor.graph_interface import StepBuffer
from trust_monitor.ros_support import (
    QOS,
    declare_config,
    header,
    msg_ns,
    spin_node,
    trajectory_values,
)
from trust_monitor.trust_model import TrustConfig, TrustEstimator


class MonitorNode(Node):
    """Thin adapter over :class:`trust_monitor.trust_model.TrustEstimator`."""

    def __init__(self) -> None:
        super().__init__('trust_monitor')
        self.estimator = TrustEstimator(declare_config(self, TrustConfig))
        self.buffer = StepBuffer(['plan', 'expected'])
        self.pub = self.create_publisher(Vector3Stamped, '/trust_monitor/trust', QOS['STEP'])
        self.create_subscription(JointTrajectory, '/ego/plan',
                                 lambda m: self.on_input('plan', m), QOS['STEP'])
        self.create_subscription(JointTrajectory, '/ego/expected_plan',
                                 lambda m: self.on_input('expected', m), QOS['STEP'])
        self.get_logger().info('ready')

    def on_input(self, name: str, msg: JointTrajectory) -> None:
        """Store a plan; when both plans of a step are there, score them."""
        ns = msg_ns(msg.header.stamp)
        self.buffer.put(name, ns, msg)
        if not self.buffer.ready(ns):
            return
        items = self.buffer.pop(ns)
        estimate = self.estimator.step(
            trajectory_values(items['plan'], 'accelerations'),  # type: ignore[arg-type]
            trajectory_values(items['expected'], 'accelerations'))  # type: ignore[arg-type]
        out = Vector3Stamped(header=header(ns, ''))
        out.vector.x = estimate.explicability
        out.vector.y = estimate.performance
        out.vector.z = estimate.trust
        self.pub.publish(out)


def main(args: list[str] | None = None) -> int:
    """Entry point of ``ros2 run trust_monitor monitor``."""
    return spin_node(MonitorNode, args)


if __name__ == '__main__':
    sys.exit(main())
