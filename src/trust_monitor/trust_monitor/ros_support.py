"""rclpy helpers shared by the nodes: named QoS profiles, parameters from config dataclasses,
message builders, and the node main loop. The only module of this package that imports
rclpy besides the node itself; the models never do.
"""

from __future__ import annotations

import dataclasses
import importlib
import signal
import sys
import time
import typing
from collections.abc import Callable, Sequence
from typing import Any, TypeVar

import rclpy
from builtin_interfaces.msg import Duration, Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from nav_msgs.msg import Odometry
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.exceptions import InvalidParameterValueException, ParameterUninitializedException
from rclpy.executors import ExternalShutdownException
from rclpy.experimental import EventsExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions
from std_msgs.msg import Header
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from trust_monitor.graph_interface import JOINT_NAME, split_ns
from trust_monitor.params import ParamsError, build_config
from trust_monitor.wall_clock import NS_PER_S, LoopStats, WallClockConfig, format_summary

T = TypeVar('T')

HISTORY_DEPTH = 1000
"""Samples kept per topic on both sides. The recorder is not part of the lock-step, so it may
fall behind the graph while the machine is busy; a reader whose history overflows drops
samples even on a reliable topic (seen with depth 10 on a loaded machine: 6 steps lost)."""

STEP_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=HISTORY_DEPTH,
                      reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL)
"""Every per-step topic: nothing may be lost, and a late subscriber still gets the first
steps."""

CLOCK_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=HISTORY_DEPTH,
                       reliability=ReliabilityPolicy.RELIABLE,
                       durability=DurabilityPolicy.TRANSIENT_LOCAL)
"""/clock: reliable and transient local, so that a subscriber whose match with the traffic
node completes after the first tick still gets it (seen with 8 runs at once); rclpy's own
volatile time-source subscriber is compatible with it."""

LATCHED_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                         reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
"""One-off signals (/sim/start) that a node started later must still receive."""

QOS = {'STEP': STEP_QOS, 'CLOCK': CLOCK_QOS, 'LATCHED': LATCHED_QOS}

DESCRIPTIONS = {
    'dt_s': 'control step, s',
    'horizon_steps': 'prediction horizon N, steps',
    'standstill_gap_m': 'standstill gap d_s, m',
    'vehicle_length_m': 'vehicle length: odometry position to bumper-to-bumper gap, m',
    'safety_gap_margin_m': 'a gap below d_s minus this margin is counted as unsafe, m',
    'speed_min_mps': 'lower speed bound, m/s',
    'speed_max_mps': 'upper speed bound, m/s (the orchestrator passes max(v_PT))',
    'speed_max_from_trace': 'use max(v_PT) of the trace as the speed bound (Table I)',
    'epsilon_mps2': 'acceleration offset eps of eq. (8), m/s^2',
    'trust_growth_rate': 'trust growth rate delta of eq. (10)',
    'performance_threshold': 'performance threshold P_thre of eq. (11)',
    'trust_initial': 'initial trust T(0)',
    'trace': 'shipped trace name, time_s,speed_mps CSV or rosbag2 bag',
    'max_sample_gap_s': 'longest hole in a trace that is interpolated, s',
    'bag_topic': 'topic replayed when trace is a bag',
    'bag_message_type': 'its type: nav_msgs/msg/Odometry or geometry_msgs/msg/TwistStamped',
    'alpha': 'relative weight of explicability in the cost, eq. (4)',
    'predictor': 'estimator of the plan the human expects',
    'time_headway_cap_s': 'cap of the time headway d_H / v_H when the human is stopped, s',
    'time_headway_s': 'desired time headway of the CTH policy, s',
    'gap_min_m': 'minimum gap to the preceding traffic, m',
    'gap_max_m': 'maximum gap to the preceding traffic, m',
    'accel_min_mps2': 'lower acceleration bound, m/s^2',
    'accel_max_mps2': 'upper acceleration bound, m/s^2',
    'trust_min': 'minimum trust T_min over the horizon, eq. (12)',
    'tracking_cost_scale_m2': 'scale of the CTH tracking cost, m^2',
    'explicability_scale': 'scale of the explicability cost',
    'solver_max_iter': 'SQP iterations before the step falls back',
    'solver_cpu_budget_s': 'CPU time per solve before the step falls back, s',
    'fallback_gap_gain_per_s2': 'gap gain of the fallback controller, 1/s^2',
    'fallback_speed_gain_per_s': 'speed gain of the fallback controller, 1/s',
    'weight_acceleration': 'driver feature weight: acceleration',
    'weight_desired_speed': 'driver feature weight: desired speed',
    'weight_relative_speed': 'driver feature weight: relative speed',
    'weight_relative_distance': 'driver feature weight: relative distance',
    'desired_standstill_gap_m': 'driver: standstill gap d_s inside the relative-distance '
                                'feature (fitted; the gap constraint uses standstill_gap_m), m',
    'gap_slack_weight': 'penalty weight on violating the driver gap bound',
    'clock_mode': 'lockstep (sim time, inputs paired by stamp) or wall (timer, latest inputs)',
    'control_rate_hz': 'wall mode: control loop rate, Hz',
    'input_timeout_s': 'wall mode: an input received longer ago than this is stale, s',
    'jitter_report_path': "wall mode: JSON file for the loop's jitter statistics at shutdown",
    'jitter_log_period_s': 'wall mode: period of the jitter log line, s',
    'lead_odom_topic': 'preceding vehicle odometry topic (nav_msgs/msg/Odometry)',
    'lead_preview_topic': 'preceding vehicle speed preview topic (JointTrajectory)',
    'ego_odom_topic': 'ego (AV) odometry topic (nav_msgs/msg/Odometry)',
    'human_odom_topic': "human follower odometry topic ('' = none, wall mode only)",
    'trust_topic': 'trust estimate topic (geometry_msgs/msg/Vector3Stamped)',
}
RANGES: dict[str, tuple[float, float]] = {'alpha': (0.0, 1.0), 'horizon_steps': (1, 50),
                                          'performance_threshold': (0.0, 1.0)}


def _descriptor(name: str, hint: Any) -> tuple[ParameterDescriptor, Parameter.Type]:
    kind = {float: Parameter.Type.DOUBLE, int: Parameter.Type.INTEGER,
            bool: Parameter.Type.BOOL, str: Parameter.Type.STRING}[hint]
    descriptor = ParameterDescriptor(name=name, description=DESCRIPTIONS.get(name, name),
                                     type=kind.value, read_only=True)
    if name in RANGES and kind == Parameter.Type.DOUBLE:
        lo, hi = RANGES[name]
        descriptor.floating_point_range = [FloatingPointRange(from_value=float(lo),
                                                              to_value=float(hi))]
    elif name in RANGES and kind == Parameter.Type.INTEGER:
        lo, hi = RANGES[name]
        descriptor.integer_range = [IntegerRange(from_value=int(lo), to_value=int(hi), step=1)]
    return descriptor, kind


def declare_config(node: Node, cls: type[T], extra: dict[str, Any] | None = None) -> T:
    """Declare every field of ``cls`` as a read-only parameter and build the validated config.

    Values come from ``--ros-args --params-file`` / ``-p``; a field without a value and
    without a dataclass default makes start-up fail naming it.

    Raises:
        ParamsError: missing parameter or a value the dataclass rejects.
    """
    hints = typing.get_type_hints(cls)
    values: dict[str, Any] = dict(extra or {})
    for field in dataclasses.fields(cls):  # type: ignore[arg-type]
        if field.name in values:
            continue
        descriptor, kind = _descriptor(field.name, hints[field.name])
        if not node.has_parameter(field.name):
            if field.default is not dataclasses.MISSING:
                node.declare_parameter(field.name, field.default, descriptor)
            else:
                node.declare_parameter(field.name, kind, descriptor)
        param = node.get_parameter(field.name)
        if param.type_ == Parameter.Type.NOT_SET:
            raise ParamsError(f'parameter {field.name} is missing ({cls.__name__})')
        values[field.name] = param.value
    return build_config(cls, values)


def message_class(msgtype: str) -> Any:
    """The Python class of ``pkg/msg/Name``."""
    package, _, name = msgtype.split('/')
    return getattr(importlib.import_module(f'{package}.msg'), name)


def time_msg(ns: int) -> Time:
    """``builtin_interfaces/Time`` of integer nanoseconds."""
    sec, nanosec = split_ns(ns)
    return Time(sec=sec, nanosec=nanosec)


def msg_ns(stamp: Time) -> int:
    """Integer nanoseconds of a ``builtin_interfaces/Time``."""
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def header(ns: int, frame_id: str) -> Header:
    """A header stamped ``ns``."""
    return Header(stamp=time_msg(ns), frame_id=frame_id)


def odometry(ns: int, position_m: float, speed_mps: float, child_frame_id: str) -> Odometry:
    """Longitudinal odometry: x along the road, speed in twist.linear.x."""
    msg = Odometry(header=header(ns, 'odom'), child_frame_id=child_frame_id)
    msg.pose.pose.position.x = float(position_m)
    msg.pose.pose.orientation.w = 1.0
    msg.twist.twist.linear.x = float(speed_mps)
    return msg


def trajectory(ns: int, dt_s: float, *, accelerations: Sequence[float] | None = None,
               velocities: Sequence[float] | None = None) -> JointTrajectory:
    """One-joint longitudinal trajectory, one point per step (time_from_start k*dt)."""
    values = accelerations if accelerations is not None else velocities
    assert values is not None
    msg = JointTrajectory(header=header(ns, 'odom'), joint_names=[JOINT_NAME])
    for k, value in enumerate(values):
        point = JointTrajectoryPoint()
        if accelerations is not None:
            point.accelerations = [float(value)]
        else:
            point.velocities = [float(value)]
        total = round(k * dt_s * 1e9)
        point.time_from_start = Duration(sec=total // 1_000_000_000,
                                         nanosec=total % 1_000_000_000)
        msg.points.append(point)
    return msg


def trajectory_values(msg: JointTrajectory, field: str) -> list[float]:
    """The joint's ``accelerations`` or ``velocities`` over the points."""
    return [float(getattr(p, field)[0]) for p in msg.points]


def diagnostics(ns: int, name: str, level_ok: bool, message: str,
                values: dict[str, str]) -> DiagnosticArray:
    """One DiagnosticStatus with key/values (floats as repr: exact round trip)."""
    status = DiagnosticStatus(level=DiagnosticStatus.OK if level_ok else DiagnosticStatus.WARN,
                              name=name, message=message, hardware_id='sim')
    status.values = [KeyValue(key=k, value=v) for k, v in values.items()]
    return DiagnosticArray(header=header(ns, ''), status=[status])


def diagnostic_values(msg: DiagnosticArray) -> dict[str, str]:
    """Key/values of the first status."""
    return {kv.key: kv.value for kv in msg.status[0].values}


class WallLoop:
    """A node's wall-clock control loop: a timer at ``control_rate_hz`` whose every tick is
    timed (:class:`trust_monitor.wall_clock.LoopStats`); p50/p99 are logged every
    ``jitter_log_period_s`` and written to ``jitter_report_path`` by :meth:`close`."""

    def __init__(self, node: Node, config: WallClockConfig, step: Callable[[], None]) -> None:
        self.node = node
        self.config = config
        self.step = step
        self.stats = LoopStats(config.period_ns)
        self._next_log_ns = time.monotonic_ns() + round(config.jitter_log_period_s * NS_PER_S)
        self.timer = node.create_timer(1.0 / config.control_rate_hz, self._tick)

    def _tick(self) -> None:
        start = time.monotonic_ns()
        self.stats.tick(start)
        self.step()
        end = time.monotonic_ns()
        self.stats.done(end - start)
        if end >= self._next_log_ns:
            self._next_log_ns = end + round(self.config.jitter_log_period_s * NS_PER_S)
            self.node.get_logger().info(f'loop: {format_summary(self.stats.summary())}')

    def close(self) -> None:
        """Log the final statistics and write them to ``jitter_report_path`` if set."""
        summary = self.stats.summary()
        self.node.get_logger().info(f'loop at shutdown: {format_summary(summary)}')
        if self.config.jitter_report_path:
            self.stats.write(self.config.jitter_report_path, self.node.get_name())


def now_ns(node: Node) -> int:
    """The node clock's time, integer ns (wall time unless use_sim_time)."""
    return int(node.get_clock().now().nanoseconds)


SPIN_TIMEOUT_S = 0.1
"""Longest wait of one executor spin: bounds how late a node notices a stop request."""


def spin_node(factory: Callable[[], Node], args: list[str] | None = None,
              user_errors: tuple[type[BaseException], ...] = (ValueError,)) -> int:
    """Init rclpy, build the node and spin until it is finished or shut down.

    A node that ends by itself sets ``finished = True``. Start-up errors of the kinds in
    ``user_errors`` (bad parameters, an unreadable trace) are printed as one line and give
    exit code 2; anything else propagates with its traceback, so the orchestrator can name
    the node that died. SIGINT ends the node cleanly (exit code 0).
    """
    # SIGINT and SIGTERM only *request* a stop; the loop below honours it between spins.
    # rclpy's own SIGINT handler shuts the context down asynchronously (which raced with the
    # next wait: "the given context is not valid"), and the EventsExecutor (C++) installs its
    # own SIGINT/SIGTERM handlers that do the same from inside spin_once. A KeyboardInterrupt
    # raised inside the executor's C++ code (e.g. while it registers the node's callbacks)
    # left callbacks registered and aborted the process at teardown ("Destroying callback
    # manager with callbacks remaining"). So no exception is ever raised into rclpy: the
    # handlers set a flag, spin_once returns within its timeout, and the finally block tears
    # down in order while the context is still valid. Set after the executor exists, so its
    # handlers are replaced; set explicitly, since a background process inherits SIGINT as
    # ignored.
    stop = {'requested': False}

    def request_stop(_signum: int, _frame: object) -> None:
        stop['requested'] = True

    rclpy.init(args=args if args is not None else sys.argv,
               signal_handler_options=SignalHandlerOptions.NO)
    node = None
    executor = EventsExecutor()
    signal.signal(signal.SIGINT, request_stop)
    signal.signal(signal.SIGTERM, request_stop)
    try:
        try:
            node = factory()
        except (*user_errors, InvalidParameterValueException,
                ParameterUninitializedException) as err:
            print(f'error: {err}', file=sys.stderr)
            return 2
        executor.add_node(node)
        while not stop['requested'] and rclpy.ok() and not getattr(node, 'finished', False):
            executor.spin_once(timeout_sec=SPIN_TIMEOUT_S)
    except ExternalShutdownException:
        pass  # the context was shut down from outside: clean exit below
    finally:
        if node is not None:
            close = getattr(node, 'close', None)
            if close is not None:
                close()
            executor.remove_node(node)
        executor.shutdown()
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return 0
