"""``autoware_lane`` node: an Autoware stack's AV and perceived objects as the planner's
longitudinal inputs (docs/operations/real-vehicle.md).

Inputs: the lane's centreline (``lane_centreline``, ``nav_msgs/Path`` in ``frame_id``,
latched), the AV's kinematic state (``/localization/kinematic_state``, ``nav_msgs/Odometry``:
base_link pose in ``map``, twist in base_link) and the perceived objects
(``/perception/object_recognition/objects``, ``autoware_perception_msgs/PredictedObjects`` in
``map``). Outputs, each in ``frame_id`` as the planner's inputs: ``ego/odom`` once per
kinematic state (the front bumper's distance along the lane, speed along it, stamped as the
kinematic state) and ``preceding_vehicle/odom`` once per objects message that holds a lead on
the lane (stamped as the objects). The geometry is :mod:`trust_av_autoware.lane_inputs`.

A message that cannot be used (a frame other than ``frame_id``, a value not finite, the AV off
its lane, objects with no recent AV state) is dropped and counted; ``/diagnostics`` says what
is dropped and why, and what is missing. So is one whose positions or speeds (as given, and
along the lane) are outside the ``input_*`` ranges (``out_of_range``,
:class:`trust_av_common.envelope.InputRanges`): a dropped kinematic state publishes no
``ego/odom`` (the planner's ego input goes stale), dropped objects no lead.
"""

from __future__ import annotations

import sys
import time

from autoware_perception_msgs.msg import PredictedObject, PredictedObjects
from nav_msgs.msg import Odometry, Path
from rclpy.node import Node

from trust_av_autoware.adapter_status import AdapterStatus
from trust_av_autoware.lane import Centreline
from trust_av_autoware.lane_inputs import (
    InputError,
    LaneAdapterConfig,
    LaneState,
    Planar,
    Seen,
    centreline_from_points,
    check_frame,
    ego_on_lane,
    half_length_m,
    in_range,
    lead_from_objects,
    seen,
    yaw,
)
from trust_av_autoware.ros.qos import (
    CENTRELINE_QOS,
    CENTRELINE_TOPIC,
    EGO_TOPIC,
    INPUT_QOS,
    KINEMATIC_STATE_TOPIC,
    LEAD_TOPIC,
    OBJECTS_TOPIC,
)
from trust_av_common.envelope import InputRanges
from trust_av_common.params import MAX_VEHICLE_LENGTH_M
from trust_av_common.ros.diagnostics import NodeDiagnostics
from trust_av_common.ros.parameters import declare_config
from trust_av_common.ros.qos import wall_qos
from trust_av_common.ros.spin import spin_node
from trust_av_common.wall_clock import WallClockConfig

__all__ = ['main']

LEAD_CHILD_FRAME = 'preceding_vehicle'


class LaneAdapterNode(Node):
    """The ``autoware_lane`` adapter (see the module docstring)."""

    def __init__(self) -> None:
        super().__init__('autoware_lane')
        self.finished = False
        self.stopping = False
        self.exit_code = 0
        self.config = declare_config(self, LaneAdapterConfig)
        self.clock_config = declare_config(self, WallClockConfig)
        self.ranges = declare_config(self, InputRanges)
        self.status = AdapterStatus(('centreline', 'kinematic_state', 'objects'))
        self.lane: Centreline | None = None
        self.ego: LaneState | None = None
        self.ego_base_s_m = 0.0
        self.ego_received_ns: int | None = None
        self.last_gap_m: float | None = None
        sensor_out = wall_qos('SENSOR', self.clock_config, publisher=True)
        self.pub_ego = self.create_publisher(Odometry, EGO_TOPIC, sensor_out)
        self.pub_lead = self.create_publisher(Odometry, LEAD_TOPIC, sensor_out)
        self.create_subscription(Path, CENTRELINE_TOPIC, self.on_centreline, CENTRELINE_QOS)
        self.create_subscription(Odometry, KINEMATIC_STATE_TOPIC, self.on_kinematic_state,
                                 INPUT_QOS)
        self.create_subscription(PredictedObjects, OBJECTS_TOPIC, self.on_objects, INPUT_QOS)
        self.diagnostics = NodeDiagnostics(self, 'autoware_lane', self.report)
        self.ready_line = (f"ready: lane in '{self.config.frame_id}' from "
                           f'{self.resolve_topic_name(CENTRELINE_TOPIC)}, half width '
                           f'{0.5 * self.config.lane_width_m:g} m')

    def report(self) -> tuple[int, str, dict[str, str]]:
        """The ``/diagnostics`` status."""
        missing = ('no centreline received' if self.lane is None else
                   'no kinematic state received' if self.ego is None else '')
        extra = {'lead_gap_m': 'none' if self.last_gap_m is None else f'{self.last_gap_m:.3f}',
                 'centreline_length_m': 'none' if self.lane is None
                 else f'{self.lane.length_m:.3f}'}
        return self.status.report(time.time_ns(), missing, 'publishing the AV and its lead',
                                  extra)

    def drop(self, name: str, error: InputError) -> None:
        self.status.dropped(name, error.kind, str(error))
        self.get_logger().warning(f'dropped {name}: {error}', throttle_duration_sec=5.0)
        self.diagnostics.changed()

    def on_centreline(self, msg: Path) -> None:
        """A new centreline (replaces the last)."""
        self.status.received('centreline', time.time_ns())
        try:
            check_frame(msg.header.frame_id, self.config.frame_id, 'centreline')
            points = [(p.pose.position.x, p.pose.position.y) for p in msg.poses]
            self.lane = centreline_from_points(points)
            for k, (x, y) in enumerate(points):
                self.position(f'poses[{k}]', x, y)
        except InputError as error:
            self.drop('centreline', error)
            return
        self.status.used('centreline')
        self.get_logger().info(f'centreline: {len(msg.poses)} poses, '
                               f'{self.lane.length_m:.1f} m')
        self.diagnostics.changed()

    def on_kinematic_state(self, msg: Odometry) -> None:
        """The AV on the lane -> ``ego/odom``."""
        now = time.time_ns()
        self.status.received('kinematic_state', now)
        if self.lane is None:
            self.drop('kinematic_state', InputError('no_centreline', 'no centreline yet'))
            return
        try:
            check_frame(msg.header.frame_id, self.config.frame_id, 'kinematic state')
            pose, twist = msg.pose.pose, msg.twist.twist
            o = pose.orientation
            ego = Planar(pose.position.x, pose.position.y,
                         yaw(o.x, o.y, o.z, o.w, 'kinematic state'),
                         twist.linear.x, twist.linear.y)
            state = ego_on_lane(self.lane, ego, self.config)
            self.position('kinematic state', ego.x_m, ego.y_m)
            self.speed('kinematic state', twist.linear.x, twist.linear.y, state.speed_mps)
        except InputError as error:
            self.drop('kinematic_state', error)
            return
        self.status.used('kinematic_state')
        self.ego = state
        self.ego_base_s_m = state.position_m - self.config.base_link_to_front_m
        self.ego_received_ns = now
        self.pub_ego.publish(self.odometry(msg.header.stamp, state, msg.child_frame_id))
        self.status.published('ego_odom')
        self.diagnostics.changed()

    def on_objects(self, msg: PredictedObjects) -> None:
        """The lead on the lane -> ``preceding_vehicle/odom`` (nothing if there is none)."""
        now = time.time_ns()
        self.status.received('objects', now)
        try:
            check_frame(msg.header.frame_id, self.config.frame_id, 'objects')
            if self.lane is None or self.ego is None or self.ego_received_ns is None:
                raise InputError('no_ego', 'no centreline or kinematic state yet')
            age_s = (now - self.ego_received_ns) / 1e9
            if age_s > self.config.ego_timeout_s:
                raise InputError('no_ego', f'the newest kinematic state is {age_s:.3f} s old '
                                 f'(ego_timeout_s {self.config.ego_timeout_s:g})')
            objects = [self.seen(k, o) for k, o in enumerate(msg.objects)]
            for k, o in enumerate(objects):
                self.position(f'objects[{k}]', o.pose.x_m, o.pose.y_m)
                for axis, value in (('vx', o.pose.vx_mps), ('vy', o.pose.vy_mps)):
                    high = self.ranges.input_speed_max_mps   # any object, any direction
                    in_range(f'objects[{k}] {axis}', value, -high, high)
                in_range(f'objects[{k}] half length', o.half_length_m, 0.0,
                         MAX_VEHICLE_LENGTH_M)
        except InputError as error:
            self.drop('objects', error)
            return
        lead = lead_from_objects(self.lane, self.ego, self.ego_base_s_m, objects, self.config)
        self.status.used('objects')
        if lead is None:
            self.status.counts['objects_without_lead'] += 1
            self.last_gap_m = None
        else:
            self.last_gap_m = lead.gap_m
            self.pub_lead.publish(self.odometry(msg.header.stamp, lead.state, LEAD_CHILD_FRAME))
            self.status.published('preceding_vehicle_odom')
        self.diagnostics.changed()

    def position(self, what: str, x_m: float, y_m: float) -> None:
        """Raise :class:`InputError` ``out_of_range`` for a position beyond
        ``input_position_abs_max_m``."""
        limit = self.ranges.input_position_abs_max_m
        in_range(f'{what} x', x_m, -limit, limit)
        in_range(f'{what} y', y_m, -limit, limit)

    def speed(self, what: str, *speeds_mps: float) -> None:
        """Raise :class:`InputError` ``out_of_range`` for a speed (a twist component, a speed
        along the lane) outside the speed range; a sideways component within +-the largest
        speed."""
        low, high = self.ranges.input_speed_min_mps, self.ranges.input_speed_max_mps
        in_range(f'{what} speed', speeds_mps[0], low, high)
        for value in speeds_mps[1:]:
            in_range(f'{what} speed', value, -high, high)

    @staticmethod
    def seen(index: int, obj: PredictedObject) -> Seen:
        """One object's pose, twist and rear, checked (the whole message is dropped if one
        object is malformed: its other objects may be as wrong)."""
        kin = obj.kinematics
        pose = kin.initial_pose_with_covariance.pose
        twist = kin.initial_twist_with_covariance.twist
        o = pose.orientation
        what = f'objects[{index}]'
        try:
            shape = obj.shape
            return seen(Planar(pose.position.x, pose.position.y, yaw(o.x, o.y, o.z, o.w, what),
                               twist.linear.x, twist.linear.y),
                        half_length_m(int(shape.type), shape.dimensions.x,
                                      [p.x for p in shape.footprint.points]))
        except InputError as error:
            raise InputError(error.kind, f'{what}: {error}') from error

    def odometry(self, stamp: object, state: LaneState, child_frame_id: str) -> Odometry:
        """The planner's odometry input for one vehicle."""
        msg = Odometry(child_frame_id=child_frame_id)
        msg.header.stamp = stamp
        msg.header.frame_id = self.config.frame_id
        msg.pose.pose.position.x = state.position_m
        msg.pose.pose.orientation.w = 1.0
        msg.twist.twist.linear.x = state.speed_mps
        return msg

    def close(self) -> None:
        """Nothing to release."""


def main(args: list[str] | None = None) -> int:
    """Entry point: ``ros2 run trust_av_autoware autoware_lane --ros-args ...``."""
    return spin_node(LaneAdapterNode, args)


if __name__ == '__main__':
    sys.exit(main())
