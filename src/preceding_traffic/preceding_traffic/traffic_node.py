"""``preceding_traffic`` node: the preceding vehicle, and the step authority in simulation.

Publishes, once per step t (sim time): the step clock ``clock``, the preceding vehicle's
odometry ``preceding_vehicle/odom`` with its transform on ``tf`` (``odom`` ->
``preceding_vehicle``) and its speed over the horizon ``preceding_vehicle/speed_preview``
(the trace's future; a replayed bag's recorded future). All names are relative (the node's
namespace). It starts after ``sim/start`` and
advances to t + 1 only when the step's outputs are in: ego and human odometry stamped
t + dt, the trust, the planner and the driver status stamped t (lock-step, see
:mod:`trust_av_common.step_chain`), and, with ``recorder_window_steps`` > 0 (a recorded
run), only while the recorder has acknowledged (``recorder/ack``) every step but the last
``recorder_window_steps``: back-pressure, so that a suspended or slow recorder holds the
graph back instead of losing messages (:mod:`trust_av_common.record_window`). Once
asked to stop it completes the step in progress and starts no other. A step whose statuses
show a gap at or below 0 m (a collision, :func:`step_collision`) is the last step, as in
the in-process loop: the recorder ends the recording with it. After the last step
it logs ``done`` and keeps its publishers alive until it is stopped: a writer that exits
takes the samples a slow subscriber (the recorder) has not acknowledged yet with it.

``clock_mode: wall``: no ``clock`` and no stepping; after ``sim/start`` the trace (or bag)
is replayed at real-time speed (:class:`preceding_traffic.replay.LeadReplay`: speed
interpolated, position its integral): a wall-clock timer at ``control_rate_hz`` publishes
the odometry, its transform and the preview of the recorded future, stamped now. At the end
of the trace it logs ``done`` and stops publishing, so the planner reports its inputs stale.
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import Vector3Stamped
from nav_msgs.msg import Odometry
from rclpy.node import Node
from rosgraph_msgs.msg import Clock
from std_msgs.msg import Empty, UInt64
from tf2_msgs.msg import TFMessage
from trajectory_msgs.msg import JointTrajectory

from preceding_traffic.replay import LeadReplay
from preceding_traffic.sources import load_trace
from preceding_traffic.traces import TraceConfig, truncate
from trust_av_common.kinematics import Collision, collision
from trust_av_common.lockstep import StepBuffer, stamp_ns
from trust_av_common.params import MAX_POSITION_M, check_fields, control_step_param, param
from trust_av_common.record_window import ACK_TOPIC, may_start, window_steps
from trust_av_common.ros.messages import (
    TrajectoryBytes,
    VehicleOdometry,
    msg_ns,
    status_gap_m,
    time_msg,
)
from trust_av_common.ros.parameters import declare_config
from trust_av_common.ros.qos import QOS, topic_qos
from trust_av_common.ros.raw_inputs import subscribe
from trust_av_common.ros.spin import WallLoop, now_ns, spin_node
from trust_av_common.topics import VEHICLE_FRAMES
from trust_av_common.wall_clock import NS_PER_S, WallClockConfig

__all__ = ['main']


@dataclass(frozen=True)
class TrafficRunConfig:
    """The traffic node's own parameters.

    Attributes:
        dt_s: control step, s.
        horizon_steps: preview length N.
        initial_position_m: the preceding vehicle's position at the first step, m.
        max_steps: stop after this many steps (0: the whole trace).
    """

    dt_s: float = control_step_param()
    horizon_steps: int = param('prediction horizon N', unit='steps', low=1, high=50)
    initial_position_m: float = param("the preceding vehicle's position at the first step",
                                      unit='m', low=-MAX_POSITION_M, high=MAX_POSITION_M,
                                      default=0.0)
    max_steps: int = param('stop after this many steps (0: the whole trace)', low=0,
                           high=10_000_000, default=0)
    recorder_window_steps: int = param(
        'lock-step: start a step only while the recorder has acknowledged all but this many '
        '(0: no recorder to wait for)', unit='steps', low=0, high=window_steps(), default=0)

    def __post_init__(self) -> None:
        check_fields(self)


class TrafficNode(Node):
    """Replays a trace (CSV or bag) as the preceding vehicle and steps the graph."""

    def __init__(self) -> None:
        super().__init__('preceding_traffic')
        self.finished = False  # runs until it is stopped (trust_av_common.ros.spin.GraphNode)
        self.exit_code = 0
        self.stopping = False  # a stop was requested: no further step
        self.run = declare_config(self, TrafficRunConfig)
        trace_config = declare_config(self, TraceConfig)
        self.clock = declare_config(self, WallClockConfig)
        trace = load_trace(trace_config.trace, self.run.dt_s, trace_config)
        self.trace = truncate(trace, self.run.max_steps)  # the length only: same preview
        self.position_m = self.run.initial_position_m
        self.step = -1
        self.done = False
        self.buffer = StepBuffer(['ego', 'human', 'trust', 'status', 'driver'])
        self.frame = VEHICLE_FRAMES['preceding_traffic']
        self.preview_bytes = TrajectoryBytes('velocities', self.frame)
        self.vehicle = VehicleOdometry(self.frame)
        self.pub_clock = self.create_publisher(Clock, 'clock', QOS['CLOCK'])
        self.pub_odom = self.create_publisher(
            Odometry, 'preceding_vehicle/odom',
            topic_qos('preceding_vehicle/odom', self.clock, publisher=True))
        self.pub_tf = self.create_publisher(TFMessage, 'tf',
                                            topic_qos('tf', self.clock, publisher=True))
        self.pub_preview = self.create_publisher(
            JointTrajectory, 'preceding_vehicle/speed_preview',
            topic_qos('preceding_vehicle/speed_preview', self.clock, publisher=True))
        self.create_subscription(Empty, 'sim/start', self.on_start, QOS['LATCHED'])
        self.acked = 0          # steps the recorder holds (recorder/ack)
        self.waiting = -1       # a step ready to start but held back for the recorder
        if self.run.recorder_window_steps and not self.clock.wall:
            self.create_subscription(UInt64, ACK_TOPIC, self.on_ack, QOS['LATCHED'])
        self.replay = LeadReplay(trace, self.run.initial_position_m)
        self.start_ns: int | None = None
        self.loop = WallLoop(self, self.clock, self.wall_step) if self.clock.wall else None
        if self.clock.wall:
            self.get_logger().info(f'trace {trace.name}: {self.replay.duration_s:g} s to replay '
                                   f'at real time, {self.clock.control_rate_hz:g} Hz; waiting '
                                   f'for {self.resolve_topic_name("sim/start")}')
            return
        subscribe(self, Odometry, 'ego/odom', lambda m: self.on_done('ego', m, 1), QOS['STEP'])
        subscribe(self, Odometry, 'human/odom', lambda m: self.on_done('human', m, 1),
                  QOS['STEP'])
        subscribe(self, Vector3Stamped, 'trust_monitor/trust',
                  lambda m: self.on_done('trust', m, 0), QOS['STEP'])
        self.create_subscription(DiagnosticArray, 'ego/planner_status',
                                 lambda m: self.on_done('status', m, 0), QOS['STEP'])
        self.create_subscription(DiagnosticArray, 'human/driver_status',
                                 lambda m: self.on_done('driver', m, 0), QOS['STEP'])
        self.get_logger().info(f'trace {trace.name}: {trace.steps} steps of {trace.dt_s} s; '
                               f'waiting for {self.resolve_topic_name("sim/start")}')

    def wall_step(self) -> None:
        """Wall mode: the trace at the elapsed wall time, stamped now; nothing after its end."""
        if self.done or self.start_ns is None:
            return
        elapsed_s = (time.monotonic_ns() - self.start_ns) / NS_PER_S
        if elapsed_s > self.replay.duration_s:
            self.get_logger().info(f'done: {self.replay.duration_s:g} s replayed')
            self.done = True
            return
        ns = now_ns(self)
        state = self.replay.state(elapsed_s)
        odom, tf = self.vehicle.update(ns, state.position_m, state.speed_mps)
        self.pub_odom.publish(odom)
        self.pub_preview.publish(self.preview_bytes.render(
            ns, self.run.dt_s, self.replay.preview(elapsed_s, self.run.horizon_steps,
                                                   self.run.dt_s).tolist()))
        self.pub_tf.publish(tf)

    def close(self) -> None:
        """At shutdown: the wall loop's jitter statistics."""
        if self.loop is not None:
            self.loop.close()

    def stamp(self, step: int) -> int:
        """Header stamp (ns) of a step."""
        return stamp_ns(self.trace.time_s(step))

    def on_start(self, _msg: Empty) -> None:
        """Go: publish the first step (wall mode: start the replay clock)."""
        if self.clock.wall:
            if self.start_ns is None:
                self.start_ns = time.monotonic_ns()
        elif self.step < 0:
            self.publish_step(0)

    def publish_step(self, step: int) -> None:
        """Publish the clock, odometry, transform and preview of ``step``."""
        self.step = step
        ns = self.stamp(step)
        speed = float(self.trace.speeds_mps[step])
        odom, tf = self.vehicle.update(ns, self.position_m, speed)
        self.pub_clock.publish(Clock(clock=time_msg(ns)))
        self.pub_odom.publish(odom)
        self.pub_preview.publish(self.preview_bytes.render(
            ns, self.run.dt_s, self.trace.preview(step, self.run.horizon_steps).tolist()))
        self.pub_tf.publish(tf)  # after the planner's inputs: not on the chain

    def on_ack(self, msg: UInt64) -> None:
        """The recorder holds ``msg.data`` steps: start a step held back for it."""
        self.acked = max(self.acked, int(msg.data))
        if self.waiting >= 0:
            self.advance(self.waiting)

    def advance(self, step: int) -> None:
        """Start ``step`` unless a stop was asked for or the recorder is a window behind
        (then ``on_ack`` starts it)."""
        if self.stopping:
            self.get_logger().info(f'stopped after step {step - 1}')
            self.done = True
            self.waiting = -1
        elif may_start(step, self.acked, self.run.recorder_window_steps):
            self.waiting = -1
            self.publish_step(step)
        else:
            self.waiting = step

    def on_done(self, name: str, msg: Odometry | Vector3Stamped | DiagnosticArray,
                offset: int) -> None:
        """Collect a step output; advance when the current step is complete.

        ``offset`` is 1 for odometry (stamped with the step's end), 0 otherwise.
        """
        ns = msg_ns(msg.header.stamp)
        step = round((ns * 1e-9 - self.trace.t0_s) / self.run.dt_s) - offset
        if step < 0:
            return  # the initial odometry, published before the first step
        self.buffer.put(name, step, msg)
        if self.step >= 0 and self.buffer.ready(self.step):
            outputs = self.buffer.pop(self.step)
            self.position_m += float(self.trace.speeds_mps[self.step]) * self.run.dt_s
            crash = step_collision(self.step, self.trace.time_s(self.step),
                                   outputs['status'], outputs['driver'])
            if crash is not None:
                self.get_logger().info(f'done: {crash.line()}; no further step')
                self.done = True
            elif self.step + 1 >= self.trace.steps:
                self.get_logger().info(f'done: {self.trace.steps} steps')
                self.done = True
            else:
                self.advance(self.step + 1)


def step_collision(step: int, t_s: float, planner_status: DiagnosticArray,
                   driver_status: DiagnosticArray) -> Collision | None:
    """The collision a complete step's statuses show (the gaps its record holds, see
    :func:`trust_av.graph.bag_records.records_from_bag`), or None: the run ends with
    that step, as the in-process loop does."""
    av_gap = status_gap_m(planner_status)
    if av_gap is None:
        return None
    return collision(step, t_s, av_gap, status_gap_m(driver_status))


def main(args: list[str] | None = None) -> int:
    """Entry point of ``ros2 run preceding_traffic traffic``."""
    return spin_node(TrafficNode, args)


if __name__ == '__main__':
    sys.exit(main())
