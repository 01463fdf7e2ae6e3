"""``ego_plant`` node: the simulated AV, integrated from the planner's acceleration command.

Kept apart from the planner so that a real vehicle can take its place: it subscribes
``/ego/accel_cmd`` and publishes ``/ego/odom`` (the first message, the initial state, at
start-up; then one per command, stamped one step later), exactly what a real drive-by-wire
vehicle and its odometry would do. Parameters: ``dt_s`` and the initial state.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass

from geometry_msgs.msg import AccelStamped
from nav_msgs.msg import Odometry
from rclpy.node import Node

from trust_av_planner.plant import VehicleState, integrate
from trust_monitor.graph_interface import stamp_ns
from trust_monitor.params import require
from trust_monitor.ros_support import QOS, declare_config, msg_ns, odometry, spin_node


@dataclass(frozen=True)
class PlantConfig:
    """A simulated vehicle: step and initial odometry (the orchestrator computes these)."""

    dt_s: float
    initial_position_m: float
    initial_speed_mps: float
    start_time_s: float

    def __post_init__(self) -> None:
        require(self.dt_s > 0.0, f'dt_s must be > 0, got {self.dt_s}')
        require(self.initial_speed_mps >= 0.0, 'initial_speed_mps must be >= 0')


class EgoPlantNode(Node):
    """Explicit-Euler odometry of the AV (:func:`trust_av_planner.plant.integrate`)."""

    def __init__(self) -> None:
        super().__init__('ego_plant')
        self.config = declare_config(self, PlantConfig)
        self.state = VehicleState(self.config.initial_position_m, self.config.initial_speed_mps)
        self.pub = self.create_publisher(Odometry, '/ego/odom', QOS['STEP'])
        self.create_subscription(AccelStamped, '/ego/accel_cmd', self.on_command, QOS['STEP'])
        self.pub.publish(odometry(stamp_ns(self.config.start_time_s), self.state.position_m,
                                  self.state.speed_mps, 'ego'))
        self.get_logger().info(f'ready: initial state {self.state}')

    def on_command(self, msg: AccelStamped) -> None:
        """Apply the command for one step and publish the new odometry."""
        self.state = integrate(self.state, float(msg.accel.linear.x), self.config.dt_s)
        ns = msg_ns(msg.header.stamp) + stamp_ns(self.config.dt_s)
        self.pub.publish(odometry(ns, self.state.position_m, self.state.speed_mps, 'ego'))


def main(args: list[str] | None = None) -> int:
    """Entry point of ``ros2 run trust_av_planner ego_plant``."""
    return spin_node(EgoPlantNode, args)


if __name__ == '__main__':
    sys.exit(main())
