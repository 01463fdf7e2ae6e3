"""``human_driver`` node: the simulated human follower (driver MPC of eq. 13).

Per step, on the expected AV plan ``ego/expected_plan`` and the AV's odometry ``ego/odom``
(paired by stamp), the driver plans against the plan it *expects*, publishes its plan
(``human/plan``, frame ``human``) and solver status, integrates its own odometry one step
and publishes it (``human/odom``, stamped one step later; the initial state at start-up)
with its transform on ``tf`` (``odom`` -> ``human``).

``clock_mode: wall``: a wall-clock timer at ``control_rate_hz`` plans from the latest
expected plan and AV odometry (both fresher than ``input_timeout_s``), applies the plan's
first acceleration over the real time elapsed since the previous tick
(:func:`trust_av_common.kinematics.advance`, no reversing) and publishes plan, status and
odometry stamped now; until ``sim/start`` it holds its initial state. With a missing or
stale input it does not plan: the status says ``inputs_not_ready`` with the reason and the
simulated human coasts (0 m/s^2).
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from nav_msgs.msg import Odometry
from rclpy.node import Node
from std_msgs.msg import Empty
from tf2_msgs.msg import TFMessage
from trajectory_msgs.msg import JointTrajectory

from human_driver_sim.driver_mpc import DriverConfig
from human_driver_sim.followers import DRIVERS, FollowerConfig, make_follower
from trust_av_common import registry
from trust_av_common.grids import hold_at
from trust_av_common.kinematics import advance
from trust_av_common.lockstep import StepBuffer, stamp_ns
from trust_av_common.params import (
    MAX_POSITION_M,
    MAX_STAMP_S,
    MAX_VEHICLE_LENGTH_M,
    check_fields,
    param,
)
from trust_av_common.ros.messages import (
    TrajectoryBytes,
    VehicleOdometry,
    diagnostics,
    msg_ns,
    trajectory_times,
    trajectory_values,
)
from trust_av_common.ros.parameters import declare_config
from trust_av_common.ros.qos import QOS, topic_qos
from trust_av_common.ros.raw_inputs import subscribe
from trust_av_common.ros.spin import WallLoop, now_ns, spin_node
from trust_av_common.topics import VEHICLE_FRAMES
from trust_av_common.wall_clock import NS_PER_S, LatestInputs, WallClockConfig

__all__ = ['main']


@dataclass(frozen=True)
class FollowerState:
    """The human's initial odometry and the geometry that turns positions into gaps."""

    vehicle_length_m: float = param('vehicle length: odometry position to bumper-to-bumper gap',
                                    unit='m', low=0.0, high=MAX_VEHICLE_LENGTH_M)
    initial_position_m: float = param("the human's initial position", unit='m',
                                      low=-MAX_POSITION_M, high=MAX_POSITION_M)
    initial_speed_mps: float = param("the human's initial speed", unit='m/s', low=0.0,
                                     high=100.0)
    start_time_s: float = param('time of the initial odometry (the first step)', unit='s',
                                low=0.0, high=MAX_STAMP_S)

    def __post_init__(self) -> None:
        check_fields(self)


class DriverNode(Node):
    """Thin adapter over the follower model ``driver_model`` names
    (:func:`human_driver_sim.followers.make_follower`; the fitted MPC by default)."""

    def __init__(self) -> None:
        super().__init__('human_driver')
        self.finished = False  # runs until it is stopped (trust_av_common.ros.spin.GraphNode)
        self.stopping = False  # set by spin_node on a stop request
        self.exit_code = 0
        self.config = declare_config(self, DriverConfig)
        self.model = declare_config(self, FollowerConfig)
        # Every registered follower's parameters are declared (and checked), the chosen
        # one's are used: as trust-av's node_components reads the section.
        params: dict[str, object] = {c.name: declare_config(self, c.config_type)
                  for c in registry.components(DRIVERS) if c.config_type is not None}
        self.follower = declare_config(self, FollowerState)
        self.clock = declare_config(self, WallClockConfig)
        self.mpc = make_follower(self.config, self.model, params.get(self.model.driver_model))
        self.position_m = self.follower.initial_position_m
        self.speed_mps = self.follower.initial_speed_mps
        self.buffer = StepBuffer(['expected', 'ego'])
        self.latest = LatestInputs(['expected', 'ego'])
        self.last_tick_ns = time.monotonic_ns()
        self.frame = VEHICLE_FRAMES['human_driver']
        self.plan_bytes = TrajectoryBytes('accelerations', self.frame)
        self.vehicle = VehicleOdometry(self.frame)
        self.pub_odom = self.create_publisher(
            Odometry, 'human/odom', topic_qos('human/odom', self.clock, publisher=True))
        self.pub_tf = self.create_publisher(TFMessage, 'tf',
                                            topic_qos('tf', self.clock, publisher=True))
        self.pub_plan = self.create_publisher(JointTrajectory, 'human/plan',
                                              topic_qos('human/plan', self.clock))
        self.pub_status = self.create_publisher(DiagnosticArray, 'human/driver_status',
                                                topic_qos('human/driver_status', self.clock))
        callback = self.on_latest if self.clock.wall else self.on_input
        subscribe(self, JointTrajectory, 'ego/expected_plan',
                  lambda m: callback('expected', m), topic_qos('ego/expected_plan', self.clock))
        subscribe(self, Odometry, 'ego/odom', lambda m: callback('ego', m),
                  topic_qos('ego/odom', self.clock))
        start_ns = now_ns(self) if self.clock.wall else stamp_ns(self.follower.start_time_s)
        self.publish_odometry(start_ns)
        self.started = False
        if self.clock.wall:
            self.create_subscription(Empty, 'sim/start', self.on_start, QOS['LATCHED'])
        self.loop = WallLoop(self, self.clock, self.wall_step) if self.clock.wall else None
        self.get_logger().info(f'ready ({self.clock.clock_mode}): follower '
                               f'{self.model.driver_model}, weights '
                               f'{self.config.weights.tolist()}')

    def publish_odometry(self, ns: int) -> None:
        """The current state as odometry, then its transform, stamped ``ns``."""
        odom, tf = self.vehicle.update(ns, self.position_m, self.speed_mps)
        self.pub_odom.publish(odom)
        self.pub_tf.publish(tf)

    def on_start(self, _msg: Empty) -> None:
        """Wall mode: start driving."""
        self.started = True

    def on_latest(self, name: str, msg: JointTrajectory | Odometry) -> None:
        """Wall mode: keep the latest message of each input."""
        self.latest.put(name, time.monotonic_ns(), msg)

    def wall_step(self) -> None:
        """Wall mode: plan on the latest inputs (or coast without them), integrate over the
        elapsed wall time, publish stamped now."""
        tick = time.monotonic_ns()
        ns = now_ns(self)
        if not self.started:
            self.last_tick_ns = tick
            self.publish_odometry(ns)
            return
        why = self.latest.problems(tick, self.clock.input_timeout_s)
        accel = 0.0
        if why:
            self.pub_status.publish(diagnostics(
                ns, 'driver_mpc', False, 'inputs_not_ready',
                {'status': 'inputs_not_ready', 'success': 'False', 'reason': why}))
            self.get_logger().warning(f'coasting: {why}', throttle_duration_sec=5.0)
        else:
            accel = self.plan(ns, self.latest.get('expected'), self.latest.get('ego'))
        self.position_m, self.speed_mps = advance(self.position_m, self.speed_mps, accel,
                                                  (tick - self.last_tick_ns) / NS_PER_S)
        self.last_tick_ns = tick
        self.publish_odometry(ns)

    def close(self) -> None:
        """At shutdown: the wall loop's jitter statistics."""
        if self.loop is not None:
            self.loop.close()

    def on_input(self, name: str, msg: JointTrajectory | Odometry) -> None:
        """Store an input; when a step's expected plan and AV odometry are in, drive."""
        ns = msg_ns(msg.header.stamp)
        self.buffer.put(name, ns, msg)
        if self.buffer.ready(ns):
            items = self.buffer.pop(ns)
            self.drive(ns, items['expected'], items['ego'])

    def drive(self, ns: int, expected_msg: JointTrajectory, ego: Odometry) -> None:
        """Plan, publish, integrate one step (x += v dt, v += u dt), publish the odometry."""
        accel = self.plan(ns, expected_msg, ego)
        dt = self.config.dt_s
        self.position_m, self.speed_mps = (self.position_m + self.speed_mps * dt,
                                           self.speed_mps + accel * dt)
        self.publish_odometry(ns + stamp_ns(dt))

    def plan(self, ns: int, expected_msg: JointTrajectory, ego: Odometry) -> float:
        """Solve the driver MPC, publish its plan and status (stamped ``ns``); the first
        acceleration of the plan, m/s^2."""
        # The planner's expected plan is on its prediction grid: read it on this model's.
        expected = hold_at(np.array(trajectory_times(expected_msg)),
                           np.array(trajectory_values(expected_msg, 'accelerations')),
                           self.config.dt_s, self.config.horizon_steps)
        av_position = float(ego.pose.pose.position.x)
        av_speed = float(ego.twist.twist.linear.x)
        gap = av_position - self.position_m - self.follower.vehicle_length_m
        result = self.mpc.step(gap, self.speed_mps, av_speed, expected)
        dt = self.config.dt_s
        self.pub_plan.publish(self.plan_bytes.render(ns, dt, result.plan_mps2.tolist()))
        self.pub_status.publish(diagnostics(
            ns, 'driver_mpc', result.success, result.status,
            {'status': result.status, 'success': str(result.success),
             'solve_time_s': repr(result.solve_time_s), 'gap_m': repr(gap)}))
        return float(result.plan_mps2[0])


def main(args: list[str] | None = None) -> int:
    """Entry point of ``ros2 run human_driver_sim driver``."""
    return spin_node(DriverNode, args)


if __name__ == '__main__':
    sys.exit(main())
