"""``human_driver`` node: the simulated human follower (driver MPC of eq. 13).

Per step, on the expected AV plan ``/ego/expected_plan`` and the AV's odometry ``/ego/odom``
(paired by stamp), the driver plans against the plan it *expects*, publishes its plan
(``/human/plan``) and solver status, integrates its own odometry one step and publishes it
(``/human/odom``, stamped one step later; the initial state at start-up).
"""

from __future__ import annotations

import sys
from dataclasses import dataclass

from diagnostic_msgs.msg import DiagnosticArray
from nav_msgs.msg import Odometry
from rclpy.node import Node
from trajectory_msgs.msg import JointTrajectory

from human_driver_sim.driver_mpc import DriverConfig, DriverMpc
from trust_monitor.graph_interface import StepBuffer, stamp_ns
from trust_monitor.params import require
from trust_monitor.ros_support import (
    QOS,
    declare_config,
    diagnostics,
    msg_ns,
    odometry,
    spin_node,
    trajectory,
    trajectory_values,
)


@dataclass(frozen=True)
class FollowerState:
    """The human's initial odometry and the geometry that turns positions into gaps."""

    vehicle_length_m: float
    initial_position_m: float
    initial_speed_mps: float
    start_time_s: float

    def __post_init__(self) -> None:
        require(self.vehicle_length_m >= 0.0, 'vehicle_length_m must be >= 0')
        require(self.initial_speed_mps >= 0.0, 'initial_speed_mps must be >= 0')


class DriverNode(Node):
    """Thin adapter over :class:`human_driver_sim.driver_mpc.DriverMpc`."""

    def __init__(self) -> None:
        super().__init__('human_driver')
        self.config = declare_config(self, DriverConfig)
        self.follower = declare_config(self, FollowerState)
        self.mpc = DriverMpc(self.config)
        self.position_m = self.follower.initial_position_m
        self.speed_mps = self.follower.initial_speed_mps
        self.buffer = StepBuffer(['expected', 'ego'])
        self.pub_odom = self.create_publisher(Odometry, '/human/odom', QOS['STEP'])
        self.pub_plan = self.create_publisher(JointTrajectory, '/human/plan', QOS['STEP'])
        self.pub_status = self.create_publisher(DiagnosticArray, '/human/driver_status',
                                                QOS['STEP'])
        self.create_subscription(JointTrajectory, '/ego/expected_plan',
                                 lambda m: self.on_input('expected', m), QOS['STEP'])
        self.create_subscription(Odometry, '/ego/odom', lambda m: self.on_input('ego', m),
                                 QOS['STEP'])
        self.pub_odom.publish(odometry(stamp_ns(self.follower.start_time_s), self.position_m,
                                       self.speed_mps, 'human'))
        self.get_logger().info(f'ready: weights {self.config.weights.tolist()}')

    def on_input(self, name: str, msg: JointTrajectory | Odometry) -> None:
        """Store an input; when a step's expected plan and AV odometry are in, drive."""
        ns = msg_ns(msg.header.stamp)
        self.buffer.put(name, ns, msg)
        if self.buffer.ready(ns):
            items = self.buffer.pop(ns)
            self.drive(ns, items['expected'], items['ego'])  # type: ignore[arg-type]

    def drive(self, ns: int, expected_msg: JointTrajectory, ego: Odometry) -> None:
        """Plan, publish, integrate (x += v dt, v += u dt), publish the new odometry."""
        expected = trajectory_values(expected_msg, 'accelerations')
        av_position = float(ego.pose.pose.position.x)
        av_speed = float(ego.twist.twist.linear.x)
        gap = av_position - self.position_m - self.follower.vehicle_length_m
        result = self.mpc.solve(gap, self.speed_mps, av_speed, expected)  # type: ignore[arg-type]
        dt = self.config.dt_s
        self.pub_plan.publish(trajectory(ns, dt, accelerations=result.plan_mps2.tolist()))
        self.pub_status.publish(diagnostics(
            ns, 'driver_mpc', result.success, result.status,
            {'status': result.status, 'success': str(result.success),
             'solve_time_s': repr(result.solve_time_s), 'gap_m': repr(gap)}))
        accel = float(result.plan_mps2[0])
        self.position_m, self.speed_mps = (self.position_m + self.speed_mps * dt,
                                           self.speed_mps + accel * dt)
        self.pub_odom.publish(odometry(ns + stamp_ns(dt), self.position_m, self.speed_mps,
                                       'human'))


def main(args: list[str] | None = None) -> int:
    """Entry point of ``ros2 run human_driver_sim driver``."""
    return spin_node(DriverNode, args)


if __name__ == '__main__':
    sys.exit(main())
