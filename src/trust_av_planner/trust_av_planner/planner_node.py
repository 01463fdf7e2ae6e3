"""``planner`` node (``ros2 run trust_av_planner planner``): the trust-aware AV planner.

Subscribes the preceding vehicle's odometry and speed preview, the ego and human odometry
and the monitor's trust; per step (inputs paired by header stamp) it runs
:class:`trust_av_planner.planner.AvPlanner` (plan estimator + NMPC) and publishes the
plan, the expected plan (``JointTrajectory``), the acceleration command (``AccelStamped``),
all three in the AV's frame ``ego``, the solver status (``DiagnosticArray``) and the three
vehicles' markers (``vehicle_markers``, each in its vehicle's frame). Topic names are
relative (the node's namespace). Parameters: the ``planner`` section of
``config/trust_av.yaml``.

``clock_mode: wall`` (real-vehicle mode): a wall-clock timer at ``control_rate_hz`` plans
from the LATEST inputs instead (input topics from the ``*_topic`` parameters), outputs
stamped with the current time. The lead odometry, preview and ego odometry must be fresher
than ``input_timeout_s``; otherwise nothing is commanded and the status (level WARN,
``status: inputs_not_ready``) says which input is missing or stale. The human odometry is
used when fresh; without it the plan estimator observes only the AV's own acceleration
(enough for the CA predictor; an empty ``human_odom_topic`` requires ``predictor: ca``).
Trust: the latest estimate, ``trust_initial`` before the first.
"""

from __future__ import annotations

import sys
import time

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import AccelStamped, Vector3Stamped
from nav_msgs.msg import Odometry
from rclpy.node import Node
from trajectory_msgs.msg import JointTrajectory
from visualization_msgs.msg import MarkerArray

from trust_av_planner.errors import TrustAvPlannerError
from trust_av_planner.nmpc import PlannerConfig
from trust_av_planner.planner import AvPlanner
from trust_av_planner.system.config import PlannerTopics, SharedConfig
from trust_monitor.common.kinematics import VehicleState
from trust_monitor.common.lockstep import StepBuffer
from trust_monitor.common.topics import VEHICLE_FRAMES
from trust_monitor.common.wall_clock import LatestInputs, WallClockConfig
from trust_monitor.ros.messages import (
    VehicleMarkers,
    diagnostics,
    header,
    msg_ns,
    trajectory,
    trajectory_values,
)
from trust_monitor.ros.parameters import declare_config
from trust_monitor.ros.qos import QOS
from trust_monitor.ros.spin import WallLoop, now_ns, spin_node
from trust_monitor.trust_model import TrustConfig

STEP_INPUTS = ('traffic', 'preview', 'ego', 'human')
WALL_REQUIRED = ['traffic', 'preview', 'ego']


def vehicle(msg: Odometry) -> VehicleState:
    """Odometry to the core's vehicle state."""
    return VehicleState(float(msg.pose.pose.position.x), float(msg.twist.twist.linear.x))


class PlannerNode(Node):
    """Thin adapter over :class:`~trust_av_planner.planner.AvPlanner`."""

    def __init__(self) -> None:
        super().__init__('planner')
        self.finished = False  # runs until it is stopped (trust_monitor.ros.spin.GraphNode)
        self.config = declare_config(self, PlannerConfig)
        trust = declare_config(self, TrustConfig)
        shared = declare_config(self, SharedConfig)
        self.clock = declare_config(self, WallClockConfig)
        topics = declare_config(self, PlannerTopics)
        self.planner = AvPlanner(self.config, trust, shared.vehicle_length_m)
        self.trust_initial = trust.trust_initial
        self.previous_ns: int | None = None
        self.buffer = StepBuffer([*STEP_INPUTS, 'trust'])
        self.latest = LatestInputs([*STEP_INPUTS, 'trust'])
        self.has_human = bool(topics.human_odom_topic)
        if not self.has_human and (not self.clock.wall or self.config.predictor != 'ca'):
            raise ValueError('parameter human_odom_topic: may be empty only with '
                             'clock_mode wall and predictor ca')
        self.frame = VEHICLE_FRAMES['ego_plant']
        self.markers = VehicleMarkers(shared.vehicle_length_m)
        self.pub_plan = self.create_publisher(JointTrajectory, 'ego/plan', QOS['STEP'])
        self.pub_expected = self.create_publisher(JointTrajectory, 'ego/expected_plan',
                                                  QOS['STEP'])
        self.pub_accel = self.create_publisher(AccelStamped, 'ego/accel_cmd', QOS['STEP'])
        self.pub_status = self.create_publisher(DiagnosticArray, 'ego/planner_status',
                                                QOS['STEP'])
        self.pub_markers = self.create_publisher(MarkerArray, 'vehicle_markers', QOS['STEP'])
        inputs = (('traffic', Odometry, topics.lead_odom_topic),
                  ('preview', JointTrajectory, topics.lead_preview_topic),
                  ('ego', Odometry, topics.ego_odom_topic),
                  ('human', Odometry, topics.human_odom_topic),
                  ('trust', Vector3Stamped, topics.trust_topic))
        callback = self.on_latest if self.clock.wall else self.on_input
        for name, msgtype, topic in inputs:
            if topic:
                self.create_subscription(msgtype, topic,
                                         lambda m, n=name: callback(n, m), QOS['STEP'])
        self.loop = WallLoop(self, self.clock, self.wall_step) if self.clock.wall else None
        mode = (f'wall clock at {self.clock.control_rate_hz:g} Hz' if self.clock.wall
                else 'lock-step')
        self.get_logger().info(f'ready ({mode}): predictor {self.config.predictor}, alpha '
                               f'{self.config.alpha:g}, horizon {self.config.horizon_steps}, '
                               f'inputs {", ".join(t for _, _, t in inputs if t)}')

    def on_latest(self, name: str, msg: Odometry | JointTrajectory | Vector3Stamped) -> None:
        """Wall mode: keep the latest message of each input with its receive time."""
        self.latest.put(name, time.monotonic_ns(), msg)

    def wall_step(self) -> None:
        """Wall mode: one planning step from the latest inputs, stamped now."""
        ns = now_ns(self)
        why = self.latest.problems(time.monotonic_ns(), self.clock.input_timeout_s,
                                   WALL_REQUIRED)
        if why:
            self.pub_status.publish(diagnostics(
                ns, 'trust_aware_nmpc', False, 'inputs_not_ready',
                {'status': 'inputs_not_ready', 'success': 'False', 'fallback': 'True',
                 'reason': why}))
            self.get_logger().warning(f'no command: {why}', throttle_duration_sec=5.0)
            return
        human_ok = self.has_human and not self.latest.problems(
            time.monotonic_ns(), self.clock.input_timeout_s, ['human'])
        trust_msg = self.latest.get('trust')
        trust = self.trust_initial if trust_msg is None else float(trust_msg.vector.z)
        items: dict[str, object] = {name: self.latest.get(name) for name in WALL_REQUIRED}
        items['human'] = self.latest.get('human') if human_ok else None
        self.plan(ns, items, trust)

    def close(self) -> None:
        """At shutdown: the wall loop's jitter statistics."""
        if self.loop is not None:
            self.loop.close()

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
                                vehicle(items['ego']),  # type: ignore[arg-type]
                                None if items['human'] is None
                                else vehicle(items['human']),  # type: ignore[arg-type]
                                trust)
        result, dt = out.result, self.config.dt_s
        self.pub_plan.publish(trajectory(ns, dt, frame_id=self.frame,
                                         accelerations=result.plan_mps2.tolist()))
        self.pub_expected.publish(trajectory(ns, dt, frame_id=self.frame,
                                             accelerations=out.expected_mps2.tolist()))
        accel = AccelStamped(header=header(ns, self.frame))
        accel.accel.linear.x = float(result.plan_mps2[0])
        self.pub_accel.publish(accel)
        self.pub_status.publish(diagnostics(
            ns, 'trust_aware_nmpc', result.success, result.status,
            {'status': result.status, 'success': str(result.success),
             'fallback': str(result.fallback), 'iterations': str(result.iterations),
             'solve_time_s': repr(result.solve_time_s),
             'explicability_max': repr(result.explicability_max),
             'gap_m': repr(out.gap_m), 'trust': repr(trust)}))
        self.pub_markers.publish(self.markers.update(ns))
        if result.fallback:
            self.get_logger().warning(f'NMPC fallback: {result.status}',
                                      throttle_duration_sec=5.0)


def main(args: list[str] | None = None) -> int:
    """Entry point of ``ros2 run trust_av_planner planner``."""
    return spin_node(PlannerNode, args, user_errors=(ValueError, TrustAvPlannerError))


if __name__ == '__main__':
    sys.exit(main())
