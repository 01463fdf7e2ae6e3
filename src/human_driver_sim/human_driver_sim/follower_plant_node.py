"""``follower_plant`` node: the participant's car, integrated from the person's pedal.

Takes the place of ``human_driver`` in a driver-in-the-loop drive (wall mode only). It
subscribes ``human/accel_cmd`` (``geometry_msgs/msg/AccelStamped``, ``accel.linear.x`` in
m/s^2, published by the drive's web server for every pedal sample) and publishes on the
topics the simulated follower uses, so the planner, its plan estimator and the trust monitor
see the person exactly as they see the simulated driver:

- ``human/odom`` (``nav_msgs/msg/Odometry``) and its transform on ``tf`` (``odom`` ->
  ``human``), stamped now: at once for every command (so the page sees its own input
  within one message) and on a timer at ``control_rate_hz`` (so the state flows without
  input);
- ``human/accel_applied`` (``AccelStamped``): the command just applied, its header stamp
  unchanged (the drive pairs it with the page's sample for the latency figure), the
  applied acceleration in ``accel.linear.x``; published right after the odometry the
  command led to;
- ``human/driver_status`` (``diagnostic_msgs/msg/DiagnosticArray``) on each tick: the
  phase of :func:`human_driver_sim.follower_plant.applied_accel` (``hold``, ``coast``,
  ``brake``, ``waiting``), the collisions so far (``collisions``) and whether the car
  touches the AV (``touching``); WARN while the participant is gone or the car touches.

It subscribes ``ego/odom`` for the collision check
(:func:`human_driver_sim.follower_plant.contact`, the AV's rear bumper extrapolated to now at
its speed and acceleration: :class:`human_driver_sim.follower_plant.AvTrack`): the car never
drives through the AV.

Until ``sim/start`` the car holds its initial state. Parameters: :class:`FollowerConfig`,
the initial state and the wall-clock settings.
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import AccelStamped
from nav_msgs.msg import Odometry
from rclpy.node import Node
from std_msgs.msg import Empty
from tf2_msgs.msg import TFMessage

from human_driver_sim.follower_plant import (
    APPLIED_TOPIC,
    COMMAND_TOPIC,
    HOLD,
    WAITING,
    AvTrack,
    FollowerConfig,
    applied_accel,
    contact,
)
from trust_av_common.kinematics import VehicleState, advance
from trust_av_common.params import check_fields, param
from trust_av_common.ros.messages import VehicleOdometry, diagnostics
from trust_av_common.ros.parameters import declare_config
from trust_av_common.ros.qos import QOS, topic_qos, wall_qos
from trust_av_common.ros.spin import WallLoop, now_ns, spin_node
from trust_av_common.topics import VEHICLE_FRAMES
from trust_av_common.wall_clock import NS_PER_S, WallClockConfig

__all__ = ['main']


@dataclass(frozen=True)
class FollowerStart:
    """Where the participant's car starts (the drive computes it)."""

    initial_position_m: float = param("the participant's car's initial position", unit='m',
                                      default=0.0, low=-1e7, high=1e7)
    initial_speed_mps: float = param("the participant's car's initial speed", unit='m/s',
                                     low=0.0, default=0.0, high=100.0)
    vehicle_length_m: float = param('length of the AV (its rear bumper is its position minus '
                                    'this)', unit='m', low=0.0, default=4.5, high=50.0)

    def __post_init__(self) -> None:
        check_fields(self)


class FollowerPlantNode(Node):
    """The participant's car: the newest pedal command integrated over real time."""

    def __init__(self) -> None:
        super().__init__('follower_plant')
        self.finished = False  # runs until it is stopped (trust_av_common.ros.spin.GraphNode)
        self.stopping = False  # set by spin_node on a stop request
        self.exit_code = 0
        self.config = declare_config(self, FollowerConfig)
        start = declare_config(self, FollowerStart)
        self.clock = declare_config(self, WallClockConfig)
        if not self.clock.wall:
            raise ValueError('follower_plant runs in wall mode only (clock_mode: wall)')
        self.state = VehicleState(start.initial_position_m, start.initial_speed_mps)
        self.length_m = start.vehicle_length_m
        self.av: AvTrack | None = None
        self.touching = False
        self.collisions = 0
        self.vehicle = VehicleOdometry(VEHICLE_FRAMES['human_driver'])
        self.pub = self.create_publisher(Odometry, 'human/odom',
                                         topic_qos('human/odom', self.clock, publisher=True))
        self.pub_tf = self.create_publisher(TFMessage, 'tf',
                                            topic_qos('tf', self.clock, publisher=True))
        state_qos = wall_qos('STATE', self.clock, publisher=True)
        self.pub_applied = self.create_publisher(AccelStamped, APPLIED_TOPIC, state_qos)
        self.pub_status = self.create_publisher(
            DiagnosticArray, 'human/driver_status',
            topic_qos('human/driver_status', self.clock, publisher=True))
        self.command: float | None = None
        self.command_at_ns = 0
        self.accel = 0.0
        self.phase = WAITING
        self.started = False
        self.last_ns = time.monotonic_ns()
        self.create_subscription(AccelStamped, COMMAND_TOPIC, self.on_command,
                                 wall_qos('STATE', self.clock))
        self.create_subscription(Empty, 'sim/start', self.on_start, QOS['LATCHED'])
        self.create_subscription(Odometry, 'ego/odom', self.on_av,
                                 topic_qos('ego/odom', self.clock))
        self.publish()
        self.loop = WallLoop(self, self.clock, self.tick)
        self.get_logger().info(f'ready: initial state {self.state}, {self.config}')

    def on_start(self, _msg: Empty) -> None:
        """Start moving."""
        self.started = True
        self.last_ns = time.monotonic_ns()

    def on_av(self, msg: Odometry) -> None:
        """The AV's newest state (for the collision check)."""
        stamp_ns = msg.header.stamp.sec * NS_PER_S + msg.header.stamp.nanosec
        position, speed = float(msg.pose.pose.position.x), float(msg.twist.twist.linear.x)
        received = time.monotonic_ns()
        self.av = (AvTrack.first(position, speed, stamp_ns, received) if self.av is None
                   else self.av.update(position, speed, stamp_ns, received))

    def advance_to(self, mono_ns: int) -> None:
        """Integrate the applied acceleration up to ``mono_ns`` (monotonic), stop behind the
        AV on contact, then choose the acceleration from there on."""
        if self.started:
            position, speed = advance(self.state.position_m, self.state.speed_mps, self.accel,
                                      (mono_ns - self.last_ns) / NS_PER_S)
            if self.av is not None:
                rear = self.av.rear_m(mono_ns, self.length_m)
                hit = contact(position, speed, rear, self.av.speed_mps, self.touching)
                position, speed, self.touching = hit.position_m, hit.speed_mps, hit.touching
                if hit.new_collision:
                    self.collisions += 1
                    self.get_logger().warning(f'collision {self.collisions}: the car stopped '
                                              "at the AV's rear bumper")
            self.state = VehicleState(position, speed)
        self.last_ns = mono_ns
        since = (mono_ns - self.command_at_ns) / NS_PER_S
        self.accel, self.phase = applied_accel(self.config, self.command, since)

    def publish(self) -> None:
        """The current state as odometry and its transform, stamped now."""
        odom, tf = self.vehicle.update(now_ns(self), self.state.position_m,
                                       self.state.speed_mps)
        self.pub.publish(odom)
        self.pub_tf.publish(tf)

    def on_command(self, msg: AccelStamped) -> None:
        """Apply the person's command now and publish the state it leads to."""
        mono = time.monotonic_ns()
        self.advance_to(mono)
        self.command, self.command_at_ns = float(msg.accel.linear.x), mono
        self.accel, self.phase = applied_accel(self.config, self.command, 0.0)
        self.publish()
        echo = AccelStamped(header=msg.header)   # after the odometry it led to
        echo.accel.linear.x = self.accel
        self.pub_applied.publish(echo)

    def tick(self) -> None:
        """Timer: integrate, apply the fallback if the person is gone, publish."""
        self.advance_to(time.monotonic_ns())
        self.publish()
        self.pub_status.publish(diagnostics(
            now_ns(self), 'follower_plant', self.phase in (HOLD, WAITING) and not self.touching,
            self.phase, {'phase': self.phase, 'accel_mps2': repr(self.accel),
                         'collisions': str(self.collisions),
                         'touching': str(self.touching).lower()}))

    def close(self) -> None:
        """At shutdown: the wall loop's jitter statistics."""
        self.loop.close()


def main(args: list[str] | None = None) -> int:
    """Entry point of ``ros2 run trust_av_planner follower_plant``."""
    return spin_node(FollowerPlantNode, args)


if __name__ == '__main__':
    sys.exit(main())
