"""``planner`` node (``ros2 run trust_av_planner planner``): the trust-aware AV planner.

Subscribes the preceding vehicle's odometry and speed preview, the ego and human odometry
and the monitor's trust; per step (inputs paired by header stamp) it runs
:class:`trust_av_planner.planner_core.AvPlanner` (plan estimator + NMPC) and publishes the
plan, the expected plan (``JointTrajectory``), the acceleration command (``AccelStamped``)
and the solver status (``DiagnosticArray``). Parameters: the ``planner`` section of
``config/trust_av.yaml``.
"""

from __future__ import annotations

import sys

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import AccelStamped, Vector3Stamped
from nav_msgs.msg import Odometry
from rclpy.node import Node
from trajectory_msgs.msg import JointTrajectory

from trust_av_planner.config import SharedConfig
from trust_av_planner.errors import TrustAvError
from trust_av_planner.nmpc import PlannerConfig
from trust_av_planner.planner_core import AvPlanner
from trust_av_planner.plant import VehicleState
from trust_monitor.graph_interface import StepBuffer
from trust_monitor.ros_support import (
    QOS,
    declare_config,
    diagnostics,
    header,
    msg_ns,
    spin_node,
    trajectory,
    trajectory_values,
)
from trust_monitor.trust_model import TrustConfig

STEP_INPUTS = ('traffic', 'preview', 'ego', 'human')


def vehicle(msg: Odometry) -> VehicleState:
    """Odometry to the core's vehicle state."""
    return VehicleState(float(msg.pose.pose.position.x), float(msg.twist.twist.linear.x))


class PlannerNode(Node):
    """Thin adapter over :class:`~trust_av_planner.planner_core.AvPlanner`."""

    def __init__(self) -> None:
        super().__init__('planner')
        self.config = declare_config(self, PlannerConfig)
        trust = declare_config(self, TrustConfig)
        shared = declare_config(self, SharedConfig)
        self.planner = AvPlanner(self.config, trust, shared.vehicle_length_m)
        self.trust_initial = trust.trust_initial
        self.previous_ns: int | None = None
        self.buffer = StepBuffer([*STEP_INPUTS, 'trust'])
        self.pub_plan = self.create_publisher(JointTrajectory, '/ego/plan', QOS['STEP'])
        self.pub_expected = self.create_publisher(JointTrajectory, '/ego/expected_plan',
                                                  QOS['STEP'])
        self.pub_accel = self.create_publisher(AccelStamped, '/ego/accel_cmd', QOS['STEP'])
        self.pub_status = self.create_publisher(DiagnosticArray, '/ego/planner_status',
                                                QOS['STEP'])
        for name, msgtype, topic in (
                ('traffic', Odometry, '/preceding_vehicle/odom'),
                ('preview', JointTrajectory, '/preceding_vehicle/speed_preview'),
                ('ego', Odometry, '/ego/odom'), ('human', Odometry, '/human/odom'),
                ('trust', Vector3Stamped, '/trust_monitor/trust')):
            self.create_subscription(msgtype, topic,
                                     lambda m, n=name: self.on_input(n, m), QOS['STEP'])
        self.get_logger().info(f'ready: predictor {self.config.predictor}, alpha '
                               f'{self.config.alpha:g}, horizon {self.config.horizon_steps}')

    def on_input(self, name: str, msg: Odometry | JointTrajectory | Vector3Stamped) -> None:
        """Store an input; plan every step whose inputs are complete, in order."""
        self.buffer.put(name, msg_ns(msg.header.stamp), msg)
        self.try_plan()

    def try_plan(self) -> None:
        """Plan the next step if its inputs (and the previous step's trust) are in."""
        for ns in self.buffer.ready_stamps(STEP_INPUTS):
            if self.previous_ns is not None and not self.buffer.ready(self.previous_ns,
                                                                      ['trust']):
                return
            trust = (self.trust_initial if self.previous_ns is None
                     else self.buffer.take('trust', self.previous_ns).vector.z)  # type: ignore[attr-defined]
            items = self.buffer.pop(ns)
            self.plan(ns, items, float(trust))
            self.previous_ns = ns

    def plan(self, ns: int, items: dict[str, object], trust: float) -> None:
        """One planning step and its four outputs."""
        preview = trajectory_values(items['preview'], 'velocities')  # type: ignore[arg-type]
        out = self.planner.step(vehicle(items['traffic']), preview,  # type: ignore[arg-type]
                                vehicle(items['ego']), vehicle(items['human']),  # type: ignore[arg-type]
                                trust)
        result, dt = out.result, self.config.dt_s
        self.pub_plan.publish(trajectory(ns, dt, accelerations=result.plan_mps2.tolist()))
        self.pub_expected.publish(trajectory(ns, dt,
                                             accelerations=out.expected_mps2.tolist()))
        accel = AccelStamped(header=header(ns, 'base_link'))
        accel.accel.linear.x = float(result.plan_mps2[0])
        self.pub_accel.publish(accel)
        self.pub_status.publish(diagnostics(
            ns, 'trust_aware_nmpc', result.success, result.status,
            {'status': result.status, 'success': str(result.success),
             'fallback': str(result.fallback), 'iterations': str(result.iterations),
             'solve_time_s': repr(result.solve_time_s),
             'explicability_max': repr(result.explicability_max),
             'gap_m': repr(out.gap_m), 'trust': repr(trust)}))
        if result.fallback:
            self.get_logger().warning(f'NMPC fallback: {result.status}',
                                      throttle_duration_sec=5.0)


def main(args: list[str] | None = None) -> int:
    """Entry point of ``ros2 run trust_av_planner planner``."""
    return spin_node(PlannerNode, args, user_errors=(ValueError, TrustAvError))


if __name__ == '__main__':
    sys.exit(main())
