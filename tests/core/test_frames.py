"""REP-105 frames: one convention in the topic table, and the messages the nodes build follow
it (odometry and tf in ``odom`` with the vehicle's body frame as child, the vehicles' markers
in their own frames, serialised once with only the stamp and values written in)."""

from __future__ import annotations

import numpy as np
import pytest
from geometry_msgs.msg import AccelStamped, Vector3Stamped
from nav_msgs.msg import Odometry
from rclpy.serialization import deserialize_message
from std_msgs.msg import Header
from tf2_msgs.msg import TFMessage
from trajectory_msgs.msg import JointTrajectory
from visualization_msgs.msg import MarkerArray

from trust_av_common.ros.messages import (
    SerializedTemplate,
    TrajectoryBytes,
    VehicleMarkers,
    VehicleOdometry,
    accel_command_bytes,
    diagnostics,
    message_class,
    trajectory,
    vector3_bytes,
)
from trust_av_common.ros.messages import odometry as plain_odometry
from trust_av_common.topics import (
    NO_FRAME,
    ODOM_FRAME,
    TOPIC,
    TOPICS,
    VEHICLE_FRAMES,
    is_topic_name,
    qualified,
)


def test_every_row_is_relative_and_names_its_frames() -> None:
    for topic in TOPICS:
        assert is_topic_name(topic.name) and not topic.name.startswith('/'), topic.name
        assert topic.frames, topic.name
        message_class(topic.msgtype)                        # the type is installed
    # each vehicle's odometry row names odom and the frame of the node that publishes it
    for name, node in (('preceding_vehicle/odom', 'preceding_traffic'),
                       ('ego/odom', 'ego_plant'), ('human/odom', 'human_driver')):
        assert TOPIC[name].publishers == (node,)
        assert TOPIC[name].frames == f'`{ODOM_FRAME}`, child `{VEHICLE_FRAMES[node]}`'
    # tf: published by exactly the odometry owners, one transform per odometry message
    odometry = [t for t in TOPICS if t.msgtype == 'nav_msgs/msg/Odometry']
    assert set(TOPIC['tf'].publishers) == set(VEHICLE_FRAMES) == {
        p for t in odometry for p in t.publishers}
    assert TOPIC['tf'].messages(7) == sum(t.messages(7) for t in odometry)
    # the AV's plans and command: its body frame as its odometry names it (`ego` here)
    for name in ('ego/accel_cmd', 'ego/plan', 'ego/expected_plan'):
        assert f'`{VEHICLE_FRAMES["ego_plant"]}` here' in TOPIC[name].frames
        assert '`base_link`' in TOPIC[name].frames


def test_qualified_names_and_topic_name_rules() -> None:
    assert qualified('ego/odom') == '/ego/odom'
    assert qualified('ego/odom', '/car1') == '/car1/ego/odom'
    assert qualified('ego/odom', '/car1/') == '/car1/ego/odom'
    assert qualified('/clock', '/car1') == '/clock'
    for good in ('ego/odom', '/ego/odom', 'clock', '~/status', '_x/y2'):
        assert is_topic_name(good), good
    for bad in ('', '/', 'ego//odom', 'ego/odom/', '1ego', 'ego/2odom', 'ego odom', 'ego-odom'):
        assert not is_topic_name(bad), bad


def test_vehicle_odometry_and_its_transform_share_stamp_and_position() -> None:
    vehicle = VehicleOdometry('human')
    for ns, x, v in ((12_500_000_000, 103.25, 9.5), (13_000_000_000, 112.75, 0.0),
                     (-1_000_000_001, -0.5, 31.0)):
        odometry_bytes, tf_bytes = vehicle.update(ns, x, v)
        odometry = deserialize_message(odometry_bytes, Odometry)
        (transform,) = deserialize_message(tf_bytes, TFMessage).transforms
        for header in (odometry.header, transform.header):
            assert header.frame_id == ODOM_FRAME
            assert header.stamp.sec * 10**9 + header.stamp.nanosec == ns
        assert odometry.child_frame_id == transform.child_frame_id == 'human'
        assert odometry.pose.pose.position.x == transform.transform.translation.x == x
        assert odometry.twist.twist.linear.x == v
        assert odometry.pose.pose.orientation.w == transform.transform.rotation.w == 1.0
        # every other field as the plain builder makes it (CDR padding bytes may differ)
        assert odometry == plain_odometry(ns, x, v, 'human')


def test_markers_box_each_vehicle_in_its_own_frame() -> None:
    markers = VehicleMarkers(4.5)
    markers.update(7_000_000_001)
    data = markers.update(8_000_000_000)
    msg = deserialize_message(data, MarkerArray)
    boxes = [m for m in msg.markers if m.type == m.CUBE]
    labels = [m for m in msg.markers if m.type == m.TEXT_VIEW_FACING]
    assert sorted(m.header.frame_id for m in boxes) == sorted(VEHICLE_FRAMES.values())
    assert sorted(m.header.frame_id for m in labels) == sorted(VEHICLE_FRAMES.values())
    assert len({(m.ns, m.id) for m in msg.markers}) == len(msg.markers)
    for box in boxes:
        # the frame origin is the front bumper: the box spans x in [-length, 0]
        assert box.scale.x == 4.5
        assert box.pose.position.x - box.scale.x / 2 == pytest.approx(-4.5)
        assert box.pose.position.x + box.scale.x / 2 == pytest.approx(0.0)
        assert box.frame_locked and box.color.a > 0
    assert all(label.text for label in labels)
    assert all((m.header.stamp.sec, m.header.stamp.nanosec) == (8, 0) for m in msg.markers)


def test_template_refuses_a_sentinel_it_cannot_place() -> None:
    header = Header(frame_id='odom')
    with pytest.raises(ValueError, match=r'found 1 times.*expected 2'):
        SerializedTemplate(header, [header.stamp, header.stamp])


def test_plans_diagnostics_and_trust_frames() -> None:
    plan = trajectory(0, 1.0, frame_id='ego', accelerations=[0.5, 0.0, -0.5])
    assert plan.header.frame_id == 'ego'
    assert diagnostics(0, 'x', True, 'ok', {}).header.frame_id == NO_FRAME == ''
    with pytest.raises(TypeError):
        trajectory(0, 1.0, accelerations=[0.0])  # type: ignore[call-arg]  # frame required


@pytest.mark.parametrize('field', ['accelerations', 'velocities'])
def test_serialised_plans_are_the_plain_builders_messages(field: str) -> None:
    """Plans, previews, commands and trust published as bytes decode to exactly what the
    plain builders make, for any length, grid and value (extremes and signed zero
    included), the template of one length unaffected by another's."""
    rng = np.random.default_rng(7)
    plans = TrajectoryBytes(field, 'ego')
    for n in (0, 1, 3, 3, 30, 1):
        for dt_s in (1.0, 0.1, 0.05):
            values = (rng.normal(size=n) * rng.choice([1.0, 1e-300, 1e300])).tolist()
            if n:
                values[0] = -0.0
            ns = int(rng.integers(-10**18, 10**18))
            msg = deserialize_message(plans.render(ns, dt_s, values), JointTrajectory)
            assert msg == trajectory(ns, dt_s, frame_id='ego', **{field: values})
    command = deserialize_message(accel_command_bytes('ego').render(5_000_000_001, -2.5),
                                  AccelStamped)
    assert command.header.frame_id == 'ego' and command.accel.linear.x == -2.5
    assert (command.header.stamp.sec, command.header.stamp.nanosec) == (5, 1)
    trust = deserialize_message(vector3_bytes(NO_FRAME).render(0, 0.1, 0.2, 59.5),
                                Vector3Stamped)
    assert (trust.vector.x, trust.vector.y, trust.vector.z) == (0.1, 0.2, 59.5)
    with pytest.raises(ValueError, match='accelerations or velocities'):
        TrajectoryBytes('positions', 'ego')


def test_serialised_messages_have_their_exact_cdr_length() -> None:
    """rosbags refuses a message whose bytes run past its last field ("CDR message size
    mismatch"); rmw_fastrtps' serialize gives its size estimate as the length, so every
    template cuts its bytes to the message's end."""
    from rosbags.serde import SerdeError
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    odometry, tf = VehicleOdometry('ego').update(5, 1.0, 2.0)
    cases = [(TrajectoryBytes('velocities', 'x').render(5, 0.1, [1.0] * n),
              'trajectory_msgs/msg/JointTrajectory') for n in (0, 1, 3, 30)]
    cases += [(VehicleMarkers(4.5).update(5), 'visualization_msgs/msg/MarkerArray'),
              (odometry, 'nav_msgs/msg/Odometry'), (tf, 'tf2_msgs/msg/TFMessage'),
              (accel_command_bytes('ego').render(5, 1.0), 'geometry_msgs/msg/AccelStamped'),
              (vector3_bytes('').render(5, 1.0, 2.0, 3.0), 'geometry_msgs/msg/Vector3Stamped')]
    for data, msgtype in cases:
        store.deserialize_cdr(data, msgtype)            # raises on a size mismatch
        with pytest.raises(SerdeError, match='size mismatch'):
            store.deserialize_cdr(data + bytes(4), msgtype)


def test_frame_ids_are_rep105_parameters_and_positions_must_share_one() -> None:
    from trust_av_common.frames import FrameConfig, body_frame, position_frame_problem
    from trust_av_common.params import ParamsError

    config = FrameConfig()
    assert (config.map_frame_id, config.odom_frame_id, config.base_frame_id) == (
        'map', 'odom', 'base_link')
    assert position_frame_problem({'traffic': 'odom', 'ego': 'odom'}, config) == ''
    assert position_frame_problem({'traffic': 'map', 'ego': 'map'}, config) == ''
    assert position_frame_problem({'traffic': 'map', 'ego': 'odom'}, config) == (
        "positions in different frames: traffic in 'map', ego in 'odom'")
    assert position_frame_problem({'traffic': 'odom', 'ego': 'base_link'}, config) == (
        "frame_id not 'odom' or 'map': ego in 'base_link'")
    assert position_frame_problem({'ego': 'world'}, FrameConfig(odom_frame_id='world')) == ''
    assert body_frame('', config) == 'base_link' and body_frame('ego', config) == 'ego'
    for bad in ('', '/odom', ' odom'):
        with pytest.raises((ValueError, ParamsError), match='odom_frame_id must be a tf2'):
            FrameConfig(odom_frame_id=bad)


def test_centreline_projection_gives_distance_along_and_signed_offset() -> None:
    """An L-shaped lane in ``map``: 100 m east, then 50 m north. A point beside the first leg
    reads its easting as distance along, left (north) positive; beside the second leg the
    distance continues past the corner; before the start and past the end it is clamped;
    the velocity along the lane is the component along the leg."""
    import math

    from trust_av_autoware.lane import Centreline, LaneError

    lane = Centreline([(1000.0, 2000.0), (1100.0, 2000.0), (1100.0, 2050.0)])
    assert lane.length_m == 150.0
    first = lane.project(1030.0, 2001.5)
    assert (first.s_m, first.lateral_m, first.heading_rad) == (30.0, 1.5, 0.0)
    assert lane.project(1030.0, 1998.0).lateral_m == -2.0
    second = lane.project(1101.0, 2020.0)
    assert (second.s_m, second.lateral_m) == (120.0, -1.0)
    assert second.heading_rad == math.pi / 2
    assert lane.project(900.0, 2000.0).s_m == 0.0
    assert lane.project(1100.0, 2100.0).s_m == 150.0
    assert lane.along(first, 10.0, 3.0) == 10.0
    assert abs(lane.along(second, 10.0, 3.0) - 3.0) < 1e-12
    for bad, words in (([(0.0, 0.0)], 'at least 2 points'),
                       ([(0.0, 0.0), (0.0, 0.0)], 'points 0 and 1 are equal'),
                       ([(0.0, 0.0), (math.nan, 1.0)], 'not finite')):
        with pytest.raises(LaneError, match=words):
            Centreline(bad)
    with pytest.raises(LaneError, match='not finite'):
        lane.project(math.inf, 0.0)


def test_lead_is_the_nearest_object_ahead_on_the_lane() -> None:
    """Behind the AV, beside the lane (more than half a lane width off) or farther ahead:
    not the lead; none qualifying: None."""
    from trust_av_autoware.lane import LaneError, OnLane, lead_on_lane

    objects = [OnLane(40.0, 0.2, 0.0),    # behind the AV at 50 m
               OnLane(70.0, 3.5, 0.0),    # next lane
               OnLane(90.0, -1.0, 0.0),   # ahead, on the lane
               OnLane(80.0, 1.7, 0.0)]    # ahead, on the lane, nearer
    assert lead_on_lane(50.0, objects, 3.5) == 3
    assert lead_on_lane(50.0, objects[:3], 3.5) == 2
    assert lead_on_lane(95.0, objects, 3.5) is None
    with pytest.raises(LaneError, match='lane_width_m'):
        lead_on_lane(0.0, objects, 0.0)
