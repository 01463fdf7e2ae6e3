"""The Autoware adapters' topic names and QoS profiles, each profile with the Autoware source
it matches (autowarefoundation/autoware.universe; docs/operations/real-vehicle.md#qos)."""

from __future__ import annotations

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

__all__ = ['CENTRELINE_QOS', 'CENTRELINE_TOPIC', 'COMMAND_TOPIC', 'CONTROL_QOS', 'CONTROL_TOPIC',
           'EGO_TOPIC', 'INPUT_QOS', 'KINEMATIC_STATE_TOPIC', 'LATERAL_QOS', 'LATERAL_TOPIC',
           'LEAD_TOPIC', 'OBJECTS_TOPIC']

KINEMATIC_STATE_TOPIC = '/localization/kinematic_state'
OBJECTS_TOPIC = '/perception/object_recognition/objects'
CENTRELINE_TOPIC = 'lane_centreline'
EGO_TOPIC = 'ego/odom'
LEAD_TOPIC = 'preceding_vehicle/odom'
COMMAND_TOPIC = 'ego/accel_cmd'
LATERAL_TOPIC = '/control/trajectory_follower/control_cmd'
CONTROL_TOPIC = '/control/trust_av/control_cmd'

INPUT_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                       reliability=ReliabilityPolicy.BEST_EFFORT,
                       durability=DurabilityPolicy.VOLATILE)
"""Kinematic state and objects: best effort, volatile, keep last 1, no deadline. Autoware
publishes them reliable, volatile, keep last 1 (ekf_localizer: ``create_publisher<Odometry>(
..., 1)``; map_based_prediction: ``create_publisher<PredictedObjects>("~/output/objects",
rclcpp::QoS{1})``); this profile matches those and any other publisher (rmw's rules)."""

CENTRELINE_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                            reliability=ReliabilityPolicy.RELIABLE,
                            durability=DurabilityPolicy.TRANSIENT_LOCAL)
"""The centreline: reliable, transient local, keep last 1, as Autoware subscribes its map
(``/vector_map``, ``rclcpp::QoS{1}.transient_local()``): published once, latched, a late
adapter still gets it (a volatile publisher does not match it)."""

CONTROL_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                         reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
"""The output ``Control``: reliable, transient local, keep last 1, as Autoware's trajectory
follower publishes it (controller_node.cpp: ``create_publisher<Control>("~/output/control_cmd",
rclcpp::QoS{1}.transient_local())``); vehicle_cmd_gate subscribes with depth 1 (reliable,
volatile), which matches it."""

LATERAL_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                         reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.VOLATILE)
"""The controller's ``Control`` (its lateral part is kept), subscribed as vehicle_cmd_gate
does (``create_subscription<Control>("input/auto/control_cmd", 1, ...)``: reliable, volatile,
keep last 1)."""
