"""``ego_plant`` node: the simulated AV, integrated from the planner's acceleration command.

Kept apart from the planner so that a real vehicle can take its place: it subscribes
``ego/accel_cmd`` and publishes ``ego/odom`` with its transform on ``tf`` (``odom`` ->
``ego``; the first message, the initial state, at start-up; then one per command, stamped
one step later), exactly what a real drive-by-wire vehicle and its odometry would do.
Parameters: ``dt_s`` and the initial state.

``clock_mode: wall``: a wall-clock timer at ``control_rate_hz`` integrates the latest
command over the real time elapsed since the previous tick
(:func:`trust_av_common.kinematics.advance`, no reversing) and publishes the odometry stamped
now (sensor-data QoS) with its transform; until ``sim/start`` the vehicle holds its initial
state (the traffic node starts its replay then). A command older than its deadline (two
control periods, by its stamp; the command QoS carries the same deadline) or none yet is not
applied: the vehicle coasts (0 m/s^2) and a warning names the reason, as a drive-by-wire unit
drops a stale set-point.
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass

from geometry_msgs.msg import AccelStamped
from nav_msgs.msg import Odometry
from rclpy.node import Node
from std_msgs.msg import Empty
from tf2_msgs.msg import TFMessage

from trust_av_common.kinematics import VehicleState, advance, integrate
from trust_av_common.lockstep import stamp_ns
from trust_av_common.params import (
    MAX_POSITION_M,
    MAX_STAMP_S,
    check_fields,
    control_step_param,
    param,
)
from trust_av_common.ros.messages import VehicleOdometry, msg_ns
from trust_av_common.ros.parameters import declare_config
from trust_av_common.ros.qos import QOS, command_deadline_s, topic_qos
from trust_av_common.ros.raw_inputs import subscribe
from trust_av_common.ros.spin import WallLoop, now_ns, spin_node
from trust_av_common.topics import VEHICLE_FRAMES
from trust_av_common.wall_clock import NS_PER_S, LatestInputs, WallClockConfig

__all__ = ['main']


@dataclass(frozen=True)
class PlantConfig:
    """A simulated vehicle: step and initial odometry (the orchestrator computes these)."""

    dt_s: float = control_step_param()
    initial_position_m: float = param("the AV's initial position", unit='m',
                                      low=-MAX_POSITION_M, high=MAX_POSITION_M)
    initial_speed_mps: float = param("the AV's initial speed", unit='m/s', low=0.0, high=100.0)
    start_time_s: float = param('time of the initial odometry (the first step)', unit='s',
                                low=0.0, high=MAX_STAMP_S)

    def __post_init__(self) -> None:
        check_fields(self)


def command_problem(command: AccelStamped | None, now_ns: int, deadline_s: float) -> str:
    """Why a command must not be applied now ('' when it may): none yet, or older than its
    deadline by its stamp."""
    if command is None:
        return 'none received'
    age_s = (now_ns - msg_ns(command.header.stamp)) / NS_PER_S
    return f'{age_s:.3f} s old (deadline {deadline_s:g} s)' if age_s > deadline_s else ''


class EgoPlantNode(Node):
    """Explicit-Euler odometry of the AV (:func:`trust_av_common.kinematics.integrate`)."""

    def __init__(self) -> None:
        super().__init__('ego_plant')
        self.finished = False  # runs until it is stopped (trust_av_common.ros.spin.GraphNode)
        self.stopping = False  # set by spin_node on a stop request
        self.exit_code = 0
        self.config = declare_config(self, PlantConfig)
        self.clock = declare_config(self, WallClockConfig)
        self.state = VehicleState(self.config.initial_position_m, self.config.initial_speed_mps)
        self.vehicle = VehicleOdometry(VEHICLE_FRAMES['ego_plant'])
        self.pub = self.create_publisher(Odometry, 'ego/odom',
                                         topic_qos('ego/odom', self.clock, publisher=True))
        self.pub_tf = self.create_publisher(TFMessage, 'tf',
                                            topic_qos('tf', self.clock, publisher=True))
        self.latest = LatestInputs(['command'])
        subscribe(self, AccelStamped, 'ego/accel_cmd',
                  self.on_latest if self.clock.wall else self.on_command,
                  topic_qos('ego/accel_cmd', self.clock))
        self.last_tick_ns = time.monotonic_ns()
        start_ns = now_ns(self) if self.clock.wall else stamp_ns(self.config.start_time_s)
        self.publish(start_ns)
        self.started = False
        if self.clock.wall:
            self.create_subscription(Empty, 'sim/start', self.on_start, QOS['LATCHED'])
        self.loop = WallLoop(self, self.clock, self.wall_step) if self.clock.wall else None
        self.get_logger().info(f'ready ({self.clock.clock_mode}): initial state {self.state}')

    def publish(self, ns: int) -> None:
        """The current state as odometry, then its transform, stamped ``ns``."""
        odom, tf = self.vehicle.update(ns, self.state.position_m, self.state.speed_mps)
        self.pub.publish(odom)
        self.pub_tf.publish(tf)

    def on_start(self, _msg: Empty) -> None:
        """Wall mode: start moving."""
        self.started = True

    def on_command(self, msg: AccelStamped) -> None:
        """Apply the command for one step and publish the new odometry."""
        self.state = integrate(self.state, float(msg.accel.linear.x), self.config.dt_s)
        self.publish(msg_ns(msg.header.stamp) + stamp_ns(self.config.dt_s))

    def on_latest(self, msg: AccelStamped) -> None:
        """Wall mode: keep the latest command."""
        self.latest.put('command', time.monotonic_ns(), msg)

    def wall_step(self) -> None:
        """Wall mode: apply the latest fresh command over the elapsed time, publish."""
        tick = time.monotonic_ns()
        command = self.latest.get('command')
        why = command_problem(command, now_ns(self), command_deadline_s(self.clock))
        accel = 0.0 if why or command is None else float(command.accel.linear.x)
        if not self.started:
            self.last_tick_ns = tick
            self.publish(now_ns(self))
            return
        if why:
            self.get_logger().warning(f'coasting: command {why}', throttle_duration_sec=5.0)
        position, speed = advance(self.state.position_m, self.state.speed_mps, accel,
                                  (tick - self.last_tick_ns) / NS_PER_S)
        self.state, self.last_tick_ns = VehicleState(position, speed), tick
        self.publish(now_ns(self))

    def close(self) -> None:
        """At shutdown: the wall loop's jitter statistics."""
        if self.loop is not None:
            self.loop.close()


def main(args: list[str] | None = None) -> int:
    """Entry point of ``ros2 run trust_av_planner ego_plant``."""
    return spin_node(EgoPlantNode, args)


if __name__ == '__main__':
    sys.exit(main())
