"""``autoware_control`` node: the planner's acceleration command as Autoware's control command
(docs/operations/real-vehicle.md).

Inputs: the planner's command (``ego/accel_cmd``, ``geometry_msgs/AccelStamped`` in the AV's
body frame), the AV's kinematic state (``/localization/kinematic_state``: its current speed,
``twist.twist.linear.x`` in base_link) and, optionally, the stack's own controller's command
(``/control/trajectory_follower/control_cmd``), whose lateral part is kept. Output: one
``autoware_control_msgs/Control`` on ``/control/trust_av/control_cmd`` per planner command
it takes (keep last 1: a command overtaken by a newer one is not sent on), so at the
planner's rate: ``longitudinal.acceleration`` = the command,
``longitudinal.velocity`` = current speed + command x ``velocity_horizon_s`` (at least 0),
``is_defined_acceleration`` true, stamps = now, ``control_time`` = now +
``velocity_horizon_s``; ``lateral`` = the controller's if at most ``lateral_timeout_s`` old,
else zero (and the status says so). Autoware's vehicle_cmd_gate takes it by remapping its
``input/auto/control_cmd`` to the output topic.

A command in another frame than ``base_frame_id``, not finite or beyond
``max_abs_accel_mps2``, or arriving with no recent speed, is dropped and counted
(``/diagnostics``); so is a kinematic state whose speed is not finite or outside
``input_speed_min_mps``..``input_speed_max_mps`` (then no command is passed on until a usable
one), and a lateral command with a steering angle or rate out of range. The Control passes
its envelope last (:mod:`trust_av_autoware.control_output`: float32-finite, the velocity
clipped to ``input_speed_max_mps`` and counted as ``control_cmd_clipped``).
"""

from __future__ import annotations

import sys
import time

from autoware_control_msgs.msg import Control, Lateral
from geometry_msgs.msg import AccelStamped
from nav_msgs.msg import Odometry
from rclpy.node import Node

from trust_av_autoware.adapter_status import AdapterStatus
from trust_av_autoware.control_output import ControlAdapterConfig, lateral_problem, longitudinal
from trust_av_autoware.lane_inputs import InputError, check_frame, finite, in_range
from trust_av_autoware.ros.qos import (
    COMMAND_TOPIC,
    CONTROL_QOS,
    CONTROL_TOPIC,
    INPUT_QOS,
    KINEMATIC_STATE_TOPIC,
    LATERAL_QOS,
    LATERAL_TOPIC,
)
from trust_av_common.envelope import InputRanges
from trust_av_common.ros.diagnostics import NodeDiagnostics
from trust_av_common.ros.messages import time_msg
from trust_av_common.ros.parameters import declare_config
from trust_av_common.ros.qos import wall_qos
from trust_av_common.ros.spin import spin_node
from trust_av_common.wall_clock import WallClockConfig

__all__ = ['main']


class ControlAdapterNode(Node):
    """The ``autoware_control`` adapter (see the module docstring)."""

    def __init__(self) -> None:
        super().__init__('autoware_control')
        self.finished = False
        self.stopping = False
        self.exit_code = 0
        self.config = declare_config(self, ControlAdapterConfig)
        self.clock_config = declare_config(self, WallClockConfig)
        self.ranges = declare_config(self, InputRanges)
        self.status = AdapterStatus(('accel_cmd', 'kinematic_state', 'lateral'))
        self.speed_mps: float | None = None
        self.speed_ns: int | None = None
        self.lateral: Lateral | None = None
        self.lateral_ns: int | None = None
        self.last_accel_mps2: float | None = None
        self.pub = self.create_publisher(Control, CONTROL_TOPIC, CONTROL_QOS)
        self.create_subscription(AccelStamped, COMMAND_TOPIC, self.on_command,
                                 wall_qos('COMMAND', self.clock_config))
        self.create_subscription(Odometry, KINEMATIC_STATE_TOPIC, self.on_kinematic_state,
                                 INPUT_QOS)
        self.create_subscription(Control, LATERAL_TOPIC, self.on_lateral, LATERAL_QOS)
        self.diagnostics = NodeDiagnostics(self, 'autoware_control', self.report)
        self.ready_line = f'ready: {self.resolve_topic_name(COMMAND_TOPIC)} -> {CONTROL_TOPIC}'

    def lateral_fresh(self, now_ns: int) -> bool:
        return self.lateral_ns is not None and \
            (now_ns - self.lateral_ns) / 1e9 <= self.config.lateral_timeout_s

    def report(self) -> tuple[int, str, dict[str, str]]:
        """The ``/diagnostics`` status."""
        now = time.time_ns()
        missing = ('no kinematic state (current speed) received' if self.speed_ns is None
                   else 'no planner command received' if self.last_accel_mps2 is None else '')
        working = ('passing the planner command on' + ('' if self.lateral_fresh(now) else
               ', with lateral 0: no controller command on ' + LATERAL_TOPIC))
        extra = {'acceleration_mps2': 'none' if self.last_accel_mps2 is None
                 else repr(self.last_accel_mps2), 'lateral_copied': str(self.lateral_fresh(now))}
        return self.status.report(now, missing, working, extra)

    def drop(self, name: str, error: InputError) -> None:
        self.status.dropped(name, error.kind, str(error))
        self.get_logger().warning(f'dropped {name}: {error}', throttle_duration_sec=5.0)
        self.diagnostics.changed()

    def on_kinematic_state(self, msg: Odometry) -> None:
        """Keep the AV's current speed (body frame x)."""
        now = time.time_ns()
        self.status.received('kinematic_state', now)
        try:
            check_frame(msg.child_frame_id, self.config.base_frame_id,
                        'kinematic state twist (child_frame_id)')
            finite('not_finite', **{'twist.linear.x': msg.twist.twist.linear.x})
            in_range('twist.linear.x', msg.twist.twist.linear.x, self.ranges.input_speed_min_mps,
                     self.ranges.input_speed_max_mps)
        except InputError as error:
            self.drop('kinematic_state', error)
            self.speed_mps = None   # stale: no command until a usable one
            return
        self.status.used('kinematic_state')
        self.speed_mps, self.speed_ns = float(msg.twist.twist.linear.x), now
        self.diagnostics.changed()

    def on_lateral(self, msg: Control) -> None:
        """Keep the controller's lateral command."""
        now = time.time_ns()
        self.status.received('lateral', now)
        lat = msg.lateral
        try:
            lateral_problem(lat.steering_tire_angle, lat.steering_tire_rotation_rate)
        except InputError as error:
            self.drop('lateral', error)
            self.lateral = self.lateral_ns = None   # stale: lateral 0 until a usable one
            return
        self.status.used('lateral')
        self.lateral, self.lateral_ns = lat, now

    def on_command(self, msg: AccelStamped) -> None:
        """The planner's command -> one ``Control``."""
        now = time.time_ns()
        self.status.received('accel_cmd', now)
        try:
            check_frame(msg.header.frame_id, self.config.base_frame_id, 'accel_cmd')
            if self.speed_ns is None:
                raise InputError('no_speed', 'no kinematic state (current speed) yet')
            if self.speed_mps is None:
                raise InputError('no_speed', 'the newest kinematic state was dropped')
            age_s = (now - self.speed_ns) / 1e9
            if age_s > self.config.speed_timeout_s:
                raise InputError('no_speed', f'the newest kinematic state is {age_s:.3f} s old '
                                 f'(speed_timeout_s {self.config.speed_timeout_s:g})')
            command = longitudinal(msg.accel.linear.x, self.speed_mps, self.config,
                                   self.ranges.input_speed_max_mps)
        except InputError as error:
            self.drop('accel_cmd', error)
            return
        self.status.used('accel_cmd')
        stamp = time_msg(now)
        target = time_msg(now + int(self.config.velocity_horizon_s * 1e9))
        out = Control(stamp=stamp, control_time=target)
        out.longitudinal.stamp, out.longitudinal.control_time = stamp, target
        out.longitudinal.velocity = command.velocity_mps
        out.longitudinal.acceleration = command.acceleration_mps2
        out.longitudinal.is_defined_acceleration = True
        if self.lateral is not None and self.lateral_fresh(now):
            out.lateral = self.lateral
        else:
            out.lateral.stamp, out.lateral.control_time = stamp, stamp
        self.pub.publish(out)
        self.status.published('control_cmd')
        if command.clipped:
            self.status.counts['control_cmd_clipped'] += 1
        self.last_accel_mps2 = command.acceleration_mps2
        self.diagnostics.changed()

    def close(self) -> None:
        """Nothing to release."""


def main(args: list[str] | None = None) -> int:
    """Entry point: ``ros2 run trust_av_autoware autoware_control --ros-args ...``."""
    return spin_node(ControlAdapterNode, args)


if __name__ == '__main__':
    sys.exit(main())
