"""Autoware in, Autoware out: the planner in wall mode between the two adapter nodes, driven
by Autoware-typed publishers with Autoware's QoS (docs/operations/real-vehicle.md), and the
vendored Autoware message packages (same type hashes as upstream's).

The scene is in ``map`` far from its origin, on a lane that heads 30 degrees north of east for
200 m and then bends to 60 degrees: ``x`` of the kinematic state is not a distance along the
road, the adapters make it one. No timing assertions: the commands are counted against the
planner's own (one ``Control`` per planner command)."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest
from support.paths import REPO

from trust_av.system.config import DEFAULT_PARAMS_FILE

sys.path.insert(0, str(REPO / 'benchmarks'))
from vehicle_loop import node_command, stop

ORIGIN = (89_000.0, 42_000.0)
HEADINGS = (math.radians(30.0), math.radians(60.0))
BASE_LINK_TO_FRONT_M = 3.79     # LaneAdapterConfig's default
VEHICLE_LENGTH_M = 4.5          # the shipped /** value
LEAD_HALF_LENGTH_M = 2.3        # a 4.6 m bounding box

UPSTREAM_HASHES = {
    'autoware_control_msgs/msg/Control':
        'RIHS01_7818be59aa790ebb777db06e55a2c15e3756de4cc35c80b1e8271afc5bab2e9d',
    'autoware_control_msgs/msg/Lateral':
        'RIHS01_94d39634041a92db4e460dae93def564fbeb89142e9c64f9c2ed540a182935a1',
    'autoware_control_msgs/msg/Longitudinal':
        'RIHS01_4ac4a6b5085ee6bb12067b763568abbf68ec3f2baf64b49e1da360aa6413edc1',
    'autoware_perception_msgs/msg/ObjectClassification':
        'RIHS01_38131fef2df46486c20c12c238faf778328309f4c3e9daa6ffd621732e48dd19',
    'autoware_perception_msgs/msg/PredictedObject':
        'RIHS01_07a517a2ed3cfcc961768dbbe769091566e8415177c3e3526a83fb392bcd3717',
    'autoware_perception_msgs/msg/PredictedObjectKinematics':
        'RIHS01_a7c128b84bbb8de1f927c8475930a99681b67832fe947aa5cb1ac6c5b3e6a80b',
    'autoware_perception_msgs/msg/PredictedObjects':
        'RIHS01_b63151309c3323bb6e3f09c54b3358aa53a8e66937a1cde15c5d5ede1ef80a08',
    'autoware_perception_msgs/msg/PredictedPath':
        'RIHS01_d7e3250f12551fcc92777897e1ae11d71f355f770b993189eb2053f10531ccd2',
    'autoware_perception_msgs/msg/Shape':
        'RIHS01_1a32ac3073c17e4822d39b7f4c263eb1c4a2bacbf707d6db96e77e867063562b',
}
"""The RIHS01 type hashes of autoware_msgs 1.12.0's own .msg files, built unchanged with the
same rosidl generators (rosidl_generator_type_description): a field that differs from
upstream's changes the hash, and an Autoware node would not match the topic."""


def test_vendored_autoware_messages_have_upstream_s_type_hashes() -> None:
    found = {}
    for name in UPSTREAM_HASHES:
        package, _, message = name.split('/')
        path = Path(sys.prefix) / 'share' / package / 'msg' / f'{message}.json'
        found[name] = json.loads(path.read_text())['type_hashes'][0]['hash_string']
    assert found == UPSTREAM_HASHES
    for package in ('autoware_control_msgs', 'autoware_perception_msgs'):
        vendored = REPO / 'vendor' / package
        assert 'Apache License' in (vendored / 'LICENSE').read_text()
        assert (vendored / 'NOTICE').is_file()


def on_lane(s_m: float, lateral_m: float = 0.0) -> tuple[float, float, float]:
    """(x, y, heading) in ``map`` of a point ``s_m`` along the lane, ``lateral_m`` left."""
    first = 200.0
    heading = HEADINGS[0] if s_m <= first else HEADINGS[1]
    if s_m <= first:
        x, y = ORIGIN[0] + s_m * math.cos(heading), ORIGIN[1] + s_m * math.sin(heading)
    else:
        bend = (ORIGIN[0] + first * math.cos(HEADINGS[0]),
                ORIGIN[1] + first * math.sin(HEADINGS[0]))
        x, y = (bend[0] + (s_m - first) * math.cos(heading),
                bend[1] + (s_m - first) * math.sin(heading))
    return x - lateral_m * math.sin(heading), y + lateral_m * math.cos(heading), heading


def dropped_commands(controls: list[float], commands: list[float]) -> int | None:
    """How many planner commands have no Control, if the Controls' accelerations are the
    commands' in order with some left out (to 1e-4); ``None`` if they are not: a Control
    with a value no command had, or out of order. The adapter takes its command keep last 1,
    as the planner sends it, so a command overtaken by a newer one before the adapter takes
    it is not sent on (the newest wins); every Control is one of the commands."""
    k = 0
    for value in controls:
        while k < len(commands) and abs(commands[k] - value) > 1e-4:
            k += 1
        if k == len(commands):
            return None
        k += 1
    return len(commands) - len(controls)


def test_dropped_commands_allows_gaps_and_refuses_other_values() -> None:
    commands = [0.5, 1.0, -1.5, 2.0, -2.5, 3.0, 0.25]
    assert dropped_commands(commands, commands) == 0
    assert dropped_commands(commands[2:], commands) == 2            # the first two overtaken
    assert dropped_commands([0.5, -1.5, 3.0], commands) == 4         # gaps anywhere
    assert dropped_commands([0.5, 1.0, 1.5], commands) is None      # a value changed
    assert dropped_commands(commands[::-1], commands) is None       # out of order
    assert dropped_commands([*commands, 0.25], commands) is None     # more Controls


@pytest.mark.wall_clock
def test_autoware_in_autoware_out(tmp_path: Path) -> None:
    """Centreline (latched), kinematic state at 30 Hz and objects at 10 Hz with Autoware's QoS
    in; the planner's commands come out as ``autoware_control_msgs/Control``, in order, one
    per command the adapter takes (keep last 1: the newest wins), with the planner's
    acceleration, a velocity target and the controller's lateral command. With the lead
    40 m ahead at the AV's speed the AV does not brake; with the lead 5 m ahead and 5 m/s
    slower it brakes. A kinematic state in another frame and an object with a NaN position
    are dropped and counted on ``/diagnostics``; the adapters live on."""
    import rclpy
    from autoware_control_msgs.msg import Control
    from autoware_perception_msgs.msg import (
        ObjectClassification,
        PredictedObject,
        PredictedObjects,
        Shape,
    )
    from diagnostic_msgs.msg import DiagnosticArray
    from geometry_msgs.msg import AccelStamped, PoseStamped
    from nav_msgs.msg import Odometry
    from nav_msgs.msg import Path as PathMsg
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

    from trust_av.graph.domains import lease_domain
    from trust_av.graph.lifecycle_client import set_states
    from trust_av_common.ros.messages import diagnostic_values, time_msg

    params = tmp_path / 'run.yaml'
    params.write_text("planner:\n  ros__parameters:\n    clock_mode: wall\n"
                      "    human_odom_topic: ''\n    lead_preview: constant_speed\n"
                      '    speed_max_from_trace: false\n')
    autoware = QoSProfile(depth=1)     # rclcpp::QoS{1}: reliable, volatile, keep last 1
    latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    processes: list[subprocess.Popen[bytes]] = []
    logs = []
    with lease_domain() as domain:
        env = dict(os.environ, ROS_DOMAIN_ID=str(domain), PYTHONUNBUFFERED='1',
                   ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST',
                   RMW_IMPLEMENTATION='rmw_fastrtps_cpp')
        for module, name, files in (
                ('trust_av_planner.planner_node', 'planner', [DEFAULT_PARAMS_FILE, params]),
                ('trust_av_autoware.lane_adapter_node', 'autoware_lane', []),
                ('trust_av_autoware.control_adapter_node', 'autoware_control', [])):
            log = (tmp_path / f'{name}.log').open('wb')
            logs.append(log)
            processes.append(subprocess.Popen(node_command(module, name, files, {}),
                                              stdout=log, stderr=subprocess.STDOUT, env=env,
                                              start_new_session=True))
        context = Context()
        rclpy.init(context=context, domain_id=domain)
        node = rclpy.create_node('autoware_stack', context=context)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        controls: list[Control] = []
        # reliable and volatile as vehicle_cmd_gate subscribes (rclcpp::QoS{1}); a deeper
        # history of its own (depth does not take part in QoS matching), so that a test
        # process slowed by a loaded host keeps every message it is sent
        every = QoSProfile(depth=100)
        node.create_subscription(Control, '/control/trust_av/control_cmd', controls.append,
                                 every)
        planned: list[float] = []
        node.create_subscription(AccelStamped, '/ego/accel_cmd',
                                 lambda m: planned.append(m.accel.linear.x), every)
        odoms: dict[str, Odometry] = {}
        for topic in ('/ego/odom', '/preceding_vehicle/odom'):
            node.create_subscription(Odometry, topic,
                                     lambda m, t=topic: odoms.__setitem__(t, m),
                                     QoSProfile(depth=1,
                                                reliability=ReliabilityPolicy.BEST_EFFORT))
        diagnostics: dict[str, dict[str, str]] = {}
        node.create_subscription(
            DiagnosticArray, '/diagnostics',
            lambda m: diagnostics.__setitem__(m.status[0].name, {
                'message': m.status[0].message, **diagnostic_values(m)}), QoSProfile(depth=50))
        pub_path = node.create_publisher(PathMsg, '/lane_centreline', latched)
        pub_state = node.create_publisher(Odometry, '/localization/kinematic_state', autoware)
        pub_objects = node.create_publisher(PredictedObjects,
                                            '/perception/object_recognition/objects', autoware)
        pub_follower = node.create_publisher(Control, '/control/trajectory_follower/control_cmd',
                                             QoSProfile(depth=1,
                                                        durability=DurabilityPolicy.TRANSIENT_LOCAL))

        path = PathMsg()
        path.header.frame_id = 'map'
        for s in range(0, 401, 10):
            pose = PoseStamped()
            pose.header.frame_id = 'map'
            pose.pose.position.x, pose.pose.position.y, _ = on_lane(float(s))
            path.poses.append(pose)
        pub_path.publish(path)

        ego_s_m, ego_speed_mps = 150.0, 10.0

        def kinematic_state(frame: str = 'map') -> Odometry:
            x, y, heading = on_lane(ego_s_m)
            msg = Odometry(child_frame_id='base_link')
            msg.header.stamp, msg.header.frame_id = time_msg(time.time_ns()), frame
            msg.pose.pose.position.x, msg.pose.pose.position.y = x, y
            msg.pose.pose.orientation.z = math.sin(heading / 2)
            msg.pose.pose.orientation.w = math.cos(heading / 2)
            msg.twist.twist.linear.x = ego_speed_mps
            return msg

        def obj(s_m: float, lateral_m: float, speed_mps: float, label: int) -> PredictedObject:
            x, y, heading = on_lane(s_m, lateral_m)
            o = PredictedObject(existence_probability=0.9)
            o.classification = [ObjectClassification(label=label, probability=0.9)]
            pose = o.kinematics.initial_pose_with_covariance.pose
            pose.position.x, pose.position.y = x, y
            pose.orientation.z, pose.orientation.w = math.sin(heading / 2), math.cos(heading / 2)
            o.kinematics.initial_twist_with_covariance.twist.linear.x = speed_mps
            o.shape.type = Shape.BOUNDING_BOX
            o.shape.dimensions.x, o.shape.dimensions.y = 2 * LEAD_HALF_LENGTH_M, 1.8
            return o

        def objects(gap_m: float, lead_speed_mps: float, nan: bool = False) -> PredictedObjects:
            front = ego_s_m + BASE_LINK_TO_FRONT_M
            msg = PredictedObjects()
            msg.header.stamp, msg.header.frame_id = time_msg(time.time_ns()), 'map'
            car = ObjectClassification.CAR
            msg.objects = [obj(front + 2.0 + LEAD_HALF_LENGTH_M, 3.5, 10.0, car),  # next lane
                           obj(ego_s_m - 20.0, 0.0, 10.0, car),                     # behind
                           obj(front + gap_m + LEAD_HALF_LENGTH_M, 0.4, lead_speed_mps, car)]
            if nan:
                msg.objects[0].kinematics.initial_pose_with_covariance.pose.position.y = math.nan
            return msg

        def drive(seconds: float, gap_m: float, lead_speed_mps: float, bad: bool = False) -> None:
            start = time.monotonic()
            tick = 0
            while tick < round(seconds * 30):      # 30 Hz by the clock, spinning between
                pub_state.publish(kinematic_state('odom' if bad and tick % 3 == 0 else 'map'))
                if tick % 3 == 0:
                    pub_objects.publish(objects(gap_m, lead_speed_mps, nan=bad))
                    follower = Control()
                    follower.lateral.steering_tire_angle = 0.05
                    pub_follower.publish(follower)
                tick += 1
                while (wait := start + tick / 30 - time.monotonic()) > 0:
                    executor.spin_once(timeout_sec=wait)

        trace: list[dict[str, Any]] = []

        def phase(name: str, seconds: float, gap_m: float, lead_speed_mps: float,
                  bad: bool = False) -> list[Control]:
            first = len(controls)
            drive(seconds, gap_m, lead_speed_mps, bad)
            received = controls[first:]
            for k, c in enumerate(received):
                trace.append({'phase': name, 'k': k, 'gap_m': gap_m,
                              'ego_speed_mps': ego_speed_mps,
                              'lead_speed_mps': lead_speed_mps,
                              'acceleration_mps2': round(c.longitudinal.acceleration, 3),
                              'velocity_mps': round(c.longitudinal.velocity, 3),
                              'steering_tire_angle': round(c.lateral.steering_tire_angle, 3)})
            return received

        try:
            deadline = time.monotonic() + 60.0
            while time.monotonic() < deadline and not (
                    node.count_subscribers('/localization/kinematic_state') >= 2
                    and node.count_publishers('/control/trust_av/control_cmd') >= 1):
                executor.spin_once(timeout_sec=0.1)
            # every command reaches this node from the first (the Controls are checked
            # against them): the planner's command publisher, made when it configures, is
            # matched here and by the adapter before it may command
            set_states(node, executor, ['planner'], 'inactive', 60.0)
            while time.monotonic() < deadline and not (
                    node.count_publishers('/ego/accel_cmd') >= 1
                    and node.count_subscribers('/ego/accel_cmd') >= 2):
                executor.spin_once(timeout_sec=0.1)
            assert node.count_subscribers('/ego/accel_cmd') >= 2, 'command not subscribed'
            set_states(node, executor, ['planner'], 'active', 60.0)
            drive(2.0, 40.0, 10.0)                                   # settle
            far = phase('far', 3.0, 40.0, 10.0)
            ego, lead = odoms['/ego/odom'], odoms['/preceding_vehicle/odom']
            assert ego.header.frame_id == lead.header.frame_id == 'map'
            assert ego.pose.pose.position.x == pytest.approx(ego_s_m + BASE_LINK_TO_FRONT_M)
            assert ego.twist.twist.linear.x == pytest.approx(ego_speed_mps)
            assert (lead.pose.pose.position.x - ego.pose.pose.position.x - VEHICLE_LENGTH_M ==
                    pytest.approx(40.0))
            close = phase('close', 3.0, 5.0, 5.0)
            phase('malformed', 1.5, 5.0, 5.0, bad=True)
            time.sleep(1.1)                                           # one diagnostics period
            executor.spin_once(timeout_sec=0.5)
            for _ in range(20):
                executor.spin_once(timeout_sec=0.05)
            # the Controls so far, and the commands a while later: a Control can come in
            # before the command it was made from (two topics, one process)
            sent_on = [c.longitudinal.acceleration for c in controls]
            commanded_by_then = len(planned)
            until = time.monotonic() + 2.0
            while (wait := until - time.monotonic()) > 0:
                executor.spin_once(timeout_sec=wait)
            commanded = list(planned)
        finally:
            executor.shutdown()
            node.destroy_node()
            rclpy.try_shutdown(context=context)
            alive = [p.poll() is None for p in processes]
            for process in processes:
                stop(process)
            for log in logs:
                log.close()
        (tmp_path / 'trace.json').write_text(json.dumps(trace))
        print('\n'.join(json.dumps(row) for row in trace if row['k'] < 6))
        dropped = dropped_commands(sent_on, commanded)
        print(f'far: {len(far)} Controls in 3 s; close: {len(close)} Controls in 3 s; '
              f'{len(sent_on)} Controls, each one of the {len(commanded)} planner commands '
              f'in order ({commanded_by_then} of them received by the count)')

    assert alive == [True, True, True]
    # the Controls are the planner's commands, in order, none made up or repeated
    assert dropped is not None, (sent_on, commanded)
    for commands in (far, close):
        assert len(commands) >= 15      # at the planner's rate (10 Hz over 3 s), give or take
        for c in commands:
            assert c.longitudinal.is_defined_acceleration and not c.longitudinal.is_defined_jerk
            assert c.longitudinal.velocity == pytest.approx(
                max(0.0, ego_speed_mps + 0.1 * c.longitudinal.acceleration), abs=1e-4)
            assert c.lateral.steering_tire_angle == pytest.approx(0.05)
            assert (c.stamp.sec, c.stamp.nanosec) == (c.longitudinal.stamp.sec,
                                                      c.longitudinal.stamp.nanosec)
    assert min(c.longitudinal.acceleration for c in far[-10:]) > -1.0
    assert max(c.longitudinal.acceleration for c in close[-10:]) < -1.0
    lane = next(v for k, v in diagnostics.items() if k.endswith('autoware_lane: autoware_lane'))
    assert int(lane['kinematic_state_dropped_frame']) >= 1
    assert int(lane['objects_dropped_not_finite']) >= 1
    control = next(v for k, v in diagnostics.items()
                   if k.endswith('autoware_control: autoware_control'))
    print({k: v for k, v in lane.items() if '_' in k and not k.startswith('input_age')})
    print({k: v for k, v in control.items() if '_' in k and not k.startswith('input_age')})
    assert int(control['control_cmd_published']) >= len(far) + len(close)
    assert int(control['control_cmd_published']) == int(control['accel_cmd_used'])
    for name in ('planner', 'autoware_lane', 'autoware_control'):
        text = (tmp_path / f'{name}.log').read_text()
        assert 'Traceback' not in text and 'incompatible QoS' not in text, text[-2000:]


def test_field_labels_name_trust_and_plan_values(tmp_path: Path) -> None:
    """``field_labels`` republishes trust (Vector3Stamped x, y, z) and a plan (one-joint
    JointTrajectory) as JointState with the values named, the source's stamp kept; a plan with
    a NaN is dropped and counted."""
    import rclpy
    from geometry_msgs.msg import Vector3Stamped
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import QoSProfile
    from sensor_msgs.msg import JointState

    from trust_av.graph.domains import lease_domain
    from trust_av_autoware.labels_node import LabelsNode
    from trust_av_common.ros.messages import time_msg, trajectory

    with lease_domain() as domain:
        rclpy.init(args=['--ros-args', '--log-level', 'warn'], domain_id=domain)
        try:
            labels = LabelsNode()
            node = rclpy.create_node('tool')
            executor = SingleThreadedExecutor()
            executor.add_node(labels)
            executor.add_node(node)
            got: dict[str, JointState] = {}
            for topic in ('/labelled/trust', '/labelled/plan'):
                node.create_subscription(JointState, topic,
                                         lambda m, t=topic: got.__setitem__(t, m),
                                         QoSProfile(depth=10))
            trust = node.create_publisher(Vector3Stamped, '/trust_monitor/trust',
                                          QoSProfile(depth=10))
            plan = node.create_publisher(type(trajectory(0, 1.0, frame_id='ego',
                                                         accelerations=[0.0])),
                                         '/ego/plan', QoSProfile(depth=10))
            deadline = time.monotonic() + 30.0
            while time.monotonic() < deadline and (
                    trust.get_subscription_count() < 1 or plan.get_subscription_count() < 1
                    or labels.pub_trust.get_subscription_count() < 1):
                executor.spin_once(timeout_sec=0.05)
            msg = Vector3Stamped()
            msg.header.stamp = time_msg(7_500_000_000)
            msg.vector.x, msg.vector.y, msg.vector.z = 0.25, 0.5, 0.75
            trust.publish(msg)
            plan.publish(trajectory(7_500_000_000, 1.0, frame_id='ego',
                                    accelerations=[0.5, -0.25, 0.0]))
            plan.publish(trajectory(8_500_000_000, 1.0, frame_id='ego',
                                    accelerations=[math.nan, 0.0, 0.0]))
            while time.monotonic() < deadline and (
                    len(got) < 2 or labels.status.counts['ego/plan_dropped_not_finite'] < 1):
                executor.spin_once(timeout_sec=0.05)
            counts = dict(labels.status.counts)
            executor.shutdown()
            labels.destroy_node()
            node.destroy_node()
        finally:
            rclpy.try_shutdown()
    assert list(got['/labelled/trust'].name) == ['explicability', 'performance', 'trust']
    assert list(got['/labelled/trust'].position) == [0.25, 0.5, 0.75]
    assert got['/labelled/trust'].header.stamp.sec == 7
    assert list(got['/labelled/plan'].name) == ['accel_mps2_at_0s', 'accel_mps2_at_1s',
                                                'accel_mps2_at_2s']
    assert list(got['/labelled/plan'].position) == [0.5, -0.25, 0.0]
    assert got['/labelled/plan'].header.frame_id == 'ego'
    assert counts['ego/plan_dropped_not_finite'] == 1 and counts['ego/plan_used'] == 1


def test_the_message_build_never_builds_over_an_installed_package(tmp_path: Path) -> None:
    """scripts/build_autoware_msgs.sh skips a package its environment already imports, and one
    that a prefix on AMENT_PREFIX_PATH holds (a native Autoware): nothing is built, one line
    says where it is."""
    script = REPO / 'scripts' / 'build_autoware_msgs.sh'
    env = dict(os.environ, AMENT_PREFIX_PATH='')
    here = subprocess.run(['bash', str(script), sys.prefix], capture_output=True, text=True,
                          env=env, timeout=120)
    assert here.returncode == 0, here.stderr
    assert here.stderr.splitlines() == [
        f'[bootstrap] {name}: already importable, not built'
        for name in ('autoware_control_msgs', 'autoware_perception_msgs')]
    # an environment that cannot import them, beside a native prefix that has them
    venv, native = tmp_path / 'venv', tmp_path / 'opt_autoware'
    (venv / 'bin').mkdir(parents=True)
    (venv / 'bin' / 'python').symlink_to(sys.executable)
    index = native / 'share' / 'ament_index' / 'resource_index' / 'packages'
    index.mkdir(parents=True)
    for name in ('autoware_control_msgs', 'autoware_perception_msgs'):
        (index / name).touch()
    env = dict(os.environ, AMENT_PREFIX_PATH=f'{tmp_path / "empty"}:{native}',
               PYTHONPATH='', PYTHONNOUSERSITE='1')
    native_run = subprocess.run(['bash', str(script), str(venv)], capture_output=True,
                                text=True, env=env, timeout=120, cwd=tmp_path)
    assert native_run.returncode == 0, native_run.stderr
    assert native_run.stderr.splitlines() == [
        f'[bootstrap] {name}: installed in {native}, not built over it'
        for name in ('autoware_control_msgs', 'autoware_perception_msgs')]
    assert sorted(p.name for p in venv.iterdir()) == ['bin']
