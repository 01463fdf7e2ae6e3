"""``trust_monitor`` node: E, P and trust from the observed plan and the expected plan.

Subscribes ``ego/plan`` and ``ego/expected_plan`` (paired by header stamp), publishes
``trust_monitor/trust`` (``geometry_msgs/Vector3Stamped``: x = E, y = P, z = trust after
the step; ``frame_id`` empty, the three numbers are not a spatial vector), stamped like the
plans. Parameters: the trust model's (``config/trust_av.yaml``).

``clock_mode: wall``: a wall-clock timer at ``control_rate_hz`` scores the latest plan and
expected plan once (when both carry the same, new stamp) and stamps the trust with the
current time; loop jitter as in the planner.
"""

from __future__ import annotations

import sys
import time

from geometry_msgs.msg import Vector3Stamped
from rclpy.node import Node
from trajectory_msgs.msg import JointTrajectory

from trust_monitor.common.lockstep import StepBuffer
from trust_monitor.common.topics import NO_FRAME
from trust_monitor.common.wall_clock import LatestInputs, WallClockConfig
from trust_monitor.ros.messages import header, msg_ns, trajectory_values
from trust_monitor.ros.parameters import declare_config
from trust_monitor.ros.qos import QOS
from trust_monitor.ros.spin import WallLoop, now_ns, spin_node
from trust_monitor.trust_model import TrustConfig, TrustEstimator


class MonitorNode(Node):
    """Thin adapter over :class:`trust_monitor.trust_model.TrustEstimator`."""

    def __init__(self) -> None:
        super().__init__('trust_monitor')
        self.finished = False  # runs until it is stopped (trust_monitor.ros.spin.GraphNode)
        self.estimator = TrustEstimator(declare_config(self, TrustConfig))
        self.clock = declare_config(self, WallClockConfig)
        self.buffer = StepBuffer(['plan', 'expected'])
        self.latest = LatestInputs(['plan', 'expected'])
        self.scored_ns: int | None = None
        self.pub = self.create_publisher(Vector3Stamped, 'trust_monitor/trust', QOS['STEP'])
        callback = self.on_latest if self.clock.wall else self.on_input
        self.create_subscription(JointTrajectory, 'ego/plan',
                                 lambda m: callback('plan', m), QOS['STEP'])
        self.create_subscription(JointTrajectory, 'ego/expected_plan',
                                 lambda m: callback('expected', m), QOS['STEP'])
        self.loop = WallLoop(self, self.clock, self.wall_step) if self.clock.wall else None
        self.get_logger().info(f'ready ({self.clock.clock_mode})')

    def on_latest(self, name: str, msg: JointTrajectory) -> None:
        """Wall mode: keep the latest plan of each kind."""
        self.latest.put(name, time.monotonic_ns(), msg)

    def wall_step(self) -> None:
        """Wall mode: score the latest plan pair once, stamped now."""
        plan, expected = self.latest.get('plan'), self.latest.get('expected')
        if plan is None or expected is None:
            return
        ns = msg_ns(plan.header.stamp)
        if ns != msg_ns(expected.header.stamp) or ns == self.scored_ns:
            return
        self.scored_ns = ns
        self.publish(now_ns(self), plan, expected)

    def close(self) -> None:
        """At shutdown: the wall loop's jitter statistics."""
        if self.loop is not None:
            self.loop.close()

    def on_input(self, name: str, msg: JointTrajectory) -> None:
        """Store a plan; when both plans of a step are there, score them."""
        ns = msg_ns(msg.header.stamp)
        self.buffer.put(name, ns, msg)
        if not self.buffer.ready(ns):
            return
        items = self.buffer.pop(ns)
        self.publish(ns, items['plan'], items['expected'])  # type: ignore[arg-type]

    def publish(self, ns: int, plan: JointTrajectory, expected: JointTrajectory) -> None:
        """One trust step from a plan pair, published stamped ``ns``."""
        estimate = self.estimator.step(trajectory_values(plan, 'accelerations'),
                                       trajectory_values(expected, 'accelerations'))
        out = Vector3Stamped(header=header(ns, NO_FRAME))
        out.vector.x = estimate.explicability
        out.vector.y = estimate.performance
        out.vector.z = estimate.trust
        self.pub.publish(out)


def main(args: list[str] | None = None) -> int:
    """Entry point of ``ros2 run trust_monitor monitor``."""
    return spin_node(MonitorNode, args)


if __name__ == '__main__':
    sys.exit(main())
