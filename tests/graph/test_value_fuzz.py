"""A running planner (wall mode, one process for the module) driven with arbitrary field values
on every input (hypothesis, derandomized): extreme and non-finite numbers, bad stamps, odd
frames, previews with no points, with ``positions`` instead of ``velocities``, with several
values per point, on times that do not increase. Every command on ``ego/accel_cmd`` is finite
and within the envelope (the acceleration bounds, the jerk limit over a control period), the
node stays active and answers lifecycle requests, and every refused message is counted on
``/diagnostics``. The issue's own cases are replayed one by one: each gives the stale-input
command (-2 m/s^2), with the refused field named in the planner's status.

In this process (no wire, so every message is seen): the Autoware adapters, a planner and a
trust monitor take arbitrary messages through their callbacks; every refusal is counted
exactly, every Control and odometry they publish is in range. A separate planner process
with an injected internal error hands over on the wire.

The malformed-bytes fuzz is tests/graph/test_raw_inputs.py; the decode checks and the envelope
alone, on many more cases, tests/core/test_envelope.py.
"""

from __future__ import annotations

import math
import os
import signal
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from support.lifecycle import ACTIVATE, ACTIVE, DEACTIVATE, INACTIVE, Manager, start, stop
from support.paths import TESTS

from trust_av.graph.domains import lease_domain

pytestmark = pytest.mark.wall_clock

ACCEL_MIN, ACCEL_MAX, STALE = -3.0, 3.0, -2.0     # the shipped planner section
JERK_MPS3 = 10.0      # the module's planner: -p command_jerk_max_mps3:=10 (shipped: 60)
JERK_STEP = JERK_MPS3 * 0.1                        # x one period at 10 Hz: 1 m/s^2
INPUTS = {'traffic': 'preceding_vehicle/odom', 'preview': 'preceding_vehicle/speed_preview',
          'ego': 'ego/odom', 'human': 'human/odom', 'trust': 'trust_monitor/trust'}
WIDE = st.one_of(st.floats(), st.sampled_from(
    [math.nan, math.inf, -math.inf, 500.0, -50.0, 1e39, 1e300, 3.5e38, -1e300, 0.0]))
TEXT = st.text(st.characters(blacklist_categories=('Cs',), blacklist_characters='\x00'),
               max_size=300)


@dataclass
class Drive:
    manager: Manager
    pubs: dict[str, Any]
    commands: list[Any]
    statuses: list[Any]
    diagnostics: list[Any]
    sent: dict[str, int] = field(default_factory=dict)
    refused: dict[str, int] = field(default_factory=dict)
    checked: int = 0
    jerk_from: int = 0   # the first command after the last activate
    start_s: float = 0.0


def activated_with_inputs(manager: Any) -> dict[str, Any]:
    """A publisher on each of the planner's inputs (wall mode's QoS), once the node has
    subscribed all of them; the node activated."""
    from geometry_msgs.msg import Vector3Stamped
    from nav_msgs.msg import Odometry
    from trajectory_msgs.msg import JointTrajectory

    from trust_av_common.ros.qos import topic_qos
    from trust_av_common.wall_clock import WallClockConfig

    wall = WallClockConfig(clock_mode='wall')
    types = {'traffic': Odometry, 'preview': JointTrajectory, 'ego': Odometry,
             'human': Odometry, 'trust': Vector3Stamped}
    pubs = {name: manager.node.create_publisher(
        types[name], topic, topic_qos(topic, wall, publisher=True))
        for name, topic in INPUTS.items()}
    assert manager.spin_until(lambda: all(p.get_subscription_count() for p in pubs.values()))
    assert manager.transition(ACTIVATE)
    return pubs


@pytest.fixture(scope='module')
def drive(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Drive]:
    from diagnostic_msgs.msg import DiagnosticArray
    from geometry_msgs.msg import AccelStamped
    from rclpy.qos import QoSProfile

    from trust_av_common.ros.diagnostics import QOS
    from trust_av_common.ros.qos import topic_qos
    from trust_av_common.wall_clock import WallClockConfig

    wall = WallClockConfig(clock_mode='wall')
    tmp_path = tmp_path_factory.mktemp('value_fuzz')
    started = time.monotonic()
    with lease_domain() as domain:
        proc = start(tmp_path, domain, 'trust_av_planner.planner_node', '-p', 'clock_mode:=wall',
                     '-p', 'predictor:=ca', '-p', f'command_jerk_max_mps3:={JERK_MPS3}')
        manager = Manager(domain, 'planner')
        try:
            for topic, msgtype in (('ego/accel_cmd', AccelStamped),
                                   ('ego/planner_status', DiagnosticArray)):
                # every message the node sends is kept (this process spins only between
                # bursts): keep last 1000 with the node's reliability
                manager.record(msgtype, topic, QoSProfile(
                    depth=1000, reliability=topic_qos(topic, wall).reliability))
            manager.record(DiagnosticArray, '/diagnostics', QOS)
            pubs = activated_with_inputs(manager)
            yield Drive(manager, pubs, manager.received['ego/accel_cmd'],
                        manager.received['ego/planner_status'],
                        manager.received['/diagnostics'], start_s=time.monotonic())
            statuses = list(manager.received['ego/planner_status'])
        finally:
            manager.close()
            out = stop(proc)
    assert 'internal error' not in out, out
    # the stale-input error: once per reason (which inputs, not their ages or values), then
    # at most every 10 s; before, once per tick while an input was stale by its age
    from trust_av_common.ros.messages import diagnostic_values
    from trust_av_planner.ros.planner_inputs import STALE_DETAIL

    keys = [STALE_DETAIL.sub('', diagnostic_values(s)['reason'])
            if diagnostic_values(s)['status'] == 'stale_inputs' else '' for s in statuses]
    changes = sum(1 for a, b in zip(['', *keys], keys, strict=False) if b and a != b)
    logged = out.count('stale inputs (')
    assert logged <= changes + 10 and keys.count('') < len(keys), (logged, changes, len(keys))
    assert out.count('still stale (') <= 1 + (time.monotonic() - started) / 10.0


def sane(name: str, t_s: float) -> Any:
    """A usable message of input ``name`` (the AV 30 m behind a lead at 15 m/s)."""
    from geometry_msgs.msg import Vector3Stamped

    from trust_av_common.ros.messages import header, odometry, trajectory

    ns = time.time_ns()
    if name == 'preview':
        return trajectory(ns, 0.1, frame_id='preceding_vehicle', velocities=[15.0] * 30)
    if name == 'trust':
        return Vector3Stamped(header=header(ns, ''))
    position = {'traffic': 60.0, 'ego': 30.0, 'human': 5.0}[name] + 15.0 * t_s
    return odometry(ns, position, 15.0, {'traffic': 'preceding_vehicle', 'ego': 'ego',
                                          'human': 'human'}[name])


@st.composite
def arbitrary(draw: Any, name: str) -> Any:
    """A message of input ``name`` with arbitrary values in the fields the planner reads
    (half of them the sane message with one field changed)."""
    from builtin_interfaces.msg import Duration
    from trajectory_msgs.msg import JointTrajectoryPoint

    msg = sane(name, 0.0)
    stamp = msg.header.stamp
    if draw(st.booleans()):
        stamp.sec = draw(st.integers(-2**31, 2**31 - 1))
        stamp.nanosec = draw(st.integers(0, 2**32 - 1))
    if draw(st.booleans()):
        msg.header.frame_id = draw(st.one_of(st.sampled_from(['odom', 'map', 'ego', '']), TEXT))
    if name == 'trust':
        for axis in 'xyz':
            setattr(msg.vector, axis, draw(WIDE))
    elif name == 'preview':
        points = []
        for k in range(draw(st.integers(0, 40))):
            point = JointTrajectoryPoint(time_from_start=Duration(sec=k))
            shape = draw(st.sampled_from(['velocity', 'velocity', 'positions', 'none', 'two']))
            value = draw(st.one_of(WIDE, st.floats(-10.0, 120.0)))
            if shape == 'velocity':
                point.velocities = [value]
            elif shape == 'positions':
                point.positions = [value]
            elif shape == 'two':
                point.velocities = [value, draw(WIDE)]
            if draw(st.integers(0, 9)) == 0:
                point.time_from_start = Duration(sec=draw(st.integers(-2**31, 2**31 - 1)),
                                                 nanosec=draw(st.integers(0, 2**32 - 1)))
            points.append(point)
        msg.points = points
    else:
        msg.pose.pose.position.x = draw(st.one_of(WIDE, st.floats(-1e10, 1e10)))
        msg.twist.twist.linear.x = draw(st.one_of(WIDE, st.floats(-10.0, 120.0)))
        if draw(st.booleans()):
            msg.child_frame_id = draw(st.one_of(st.sampled_from(['ego', '', 'base_link']), TEXT))
    return msg


def problem(name: str, msg: Any) -> str:
    """Why the planner must refuse ``msg`` on input ``name`` within the shipped ranges: the
    test's own statement of which field each input is checked on (not the node's code, so a
    node that stops checking an input fails here)."""
    from trust_av_common.envelope import (
        InputRanges,
        odometry_problem,
        trajectory_problem,
        vector_problem,
    )

    r = InputRanges()
    if name == 'preview':
        return trajectory_problem(msg, 'velocities', r.input_speed_min_mps,
                                  r.input_speed_max_mps, r.input_points_max)
    if name == 'trust':
        return vector_problem(msg, r.input_trust_abs_max)
    return odometry_problem(msg, r)


def check_commands(drive: Drive) -> None:
    """Every command so far finite, within the bounds, and within the jerk limit of the one
    received before it, over the control periods between their stamps (a best-effort command
    may be lost; the hand-over of a deactivate is exempt: :attr:`Drive.jerk_from`)."""
    from trust_av_common.ros.messages import msg_ns

    values = [c.accel.linear.x for c in drive.commands]
    for k in range(drive.checked, len(values)):
        value = values[k]
        assert math.isfinite(value) and ACCEL_MIN <= value <= ACCEL_MAX, (k, value)
        if k > drive.jerk_from:
            periods = max(1, math.ceil((msg_ns(drive.commands[k].header.stamp)
                                        - msg_ns(drive.commands[k - 1].header.stamp)) / 1e8
                                       - 1e-6))
            assert abs(value - values[k - 1]) <= JERK_STEP * periods + 1e-9, (
                k, values[k - 1], value, periods)
    drive.checked = len(values)


def test_an_internal_error_while_active_hands_over_reports_and_waits_inactive(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """An exception inside a planning step (injected: tests/support/faulty_planner.py):
    the hand-over command on the wire right after the last planned one, ERROR on
    ``/diagnostics`` naming it, the node inactive; activated again, it plans again."""
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
    from geometry_msgs.msg import AccelStamped

    from trust_av_common.ros.diagnostics import QOS
    from trust_av_common.ros.qos import topic_qos
    from trust_av_common.wall_clock import WallClockConfig

    monkeypatch.setenv('PYTHONPATH', f'{TESTS}{os.pathsep}{os.environ.get("PYTHONPATH", "")}')
    wall = WallClockConfig(clock_mode='wall')
    with lease_domain() as domain:
        proc = start(tmp_path, domain, 'support.faulty_planner', '-p', 'clock_mode:=wall',
                     '-p', 'predictor:=ca')
        manager = Manager(domain, 'planner')
        try:
            manager.record(AccelStamped, 'ego/accel_cmd', topic_qos('ego/accel_cmd', wall))
            manager.record(DiagnosticArray, '/diagnostics', QOS)
            pubs = activated_with_inputs(manager)
            start_s = time.monotonic()
            commands = manager.received['ego/accel_cmd']
            diagnostics = manager.received['/diagnostics']

            def feed_until(done: Any) -> bool:
                end = time.monotonic() + 60.0
                while time.monotonic() < end and not done():
                    for name, pub in pubs.items():
                        pub.publish(sane(name, time.monotonic() - start_s))
                    manager.spin_for(0.05)
                return bool(done())

            def errors() -> list[Any]:
                return [m.status[0] for m in diagnostics if m.status
                        and m.status[0].level == DiagnosticStatus.ERROR
                        and 'internal error' in m.status[0].message]

            assert feed_until(lambda: errors())
            assert manager.state() == INACTIVE
            manager.spin_for(0.5)
            values = [c.accel.linear.x for c in commands]
            assert values[-1] == STALE and len(values) >= 4, values   # 4 plans, the hand-over
            assert 'RuntimeError: injected internal error' in errors()[0].message
            assert manager.transition(ACTIVATE)
            handed = len(commands)
            assert feed_until(lambda: len(commands) >= handed + 3)
            assert all(math.isfinite(c.accel.linear.x) for c in commands)
        finally:
            manager.close()
            os.killpg(proc.pid, signal.SIGINT)
            out, _ = proc.communicate(timeout=60)
    assert proc.returncode == 0, out
    # the traceback once, then the node went on
    assert out.count('internal error (handing over and deactivating)') == 1, out
    assert out.count('Traceback') == 1, out
    assert 'deactivate: handed over with -2 m/s^2' in out


@pytest.fixture(scope='module')
def adapters() -> Iterator[tuple[Any, Any, list[Any], list[Any], Any]]:
    """The two Autoware adapters and a planner (wall mode, configured) in this process
    (default context), the adapters' publishers captured: (control adapter, lane adapter,
    Controls, odometries, planner)."""
    import rclpy

    from trust_av_autoware.control_adapter_node import ControlAdapterNode
    from trust_av_autoware.lane_adapter_node import LaneAdapterNode

    rclpy.init(args=['--ros-args', '-p', 'vehicle_length_m:=4.5', '-p', 'clock_mode:=wall',
                     '-p', 'predictor:=ca'])
    try:
        from trust_av_planner.planner_node import PlannerNode
        from trust_monitor.monitor_node import MonitorNode

        control, lane, planner = ControlAdapterNode(), LaneAdapterNode(), PlannerNode()
        monitor = MonitorNode()
        planner.start([])   # configured (wall mode: they wait inactive)
        monitor.start([])
        controls: list[Any] = []
        odometries: list[Any] = []
        control.pub.publish = controls.append
        lane.pub_ego.publish = lane.pub_lead.publish = odometries.append
        yield control, lane, controls, odometries, (planner, monitor)
        for node in (control, lane, planner, monitor):
            node.destroy_node()
    finally:
        rclpy.try_shutdown()


@settings(max_examples=150, deadline=None, derandomize=True)
@given(st.data())
def test_the_autoware_adapters_pass_only_values_in_range(
        adapters: tuple[Any, Any, list[Any], list[Any], Any], data: st.DataObject) -> None:
    """Arbitrary values in every field the adapters read (the kinematic state, the
    planner's command, the controller's lateral command, the objects): nothing raises, every
    Control is finite as float32 with the acceleration and velocity in range, every odometry
    they publish is in the planner's input ranges, and every message not used is counted."""
    import numpy as np
    from autoware_control_msgs.msg import Control
    from autoware_perception_msgs.msg import PredictedObject, PredictedObjects
    from geometry_msgs.msg import AccelStamped, PoseStamped
    from nav_msgs.msg import Odometry, Path

    from trust_av_common.envelope import InputRanges, odometry_problem

    control, lane, controls, odometries, _ = adapters
    ranges = InputRanges()
    if lane.lane is None:
        path = Path()
        path.header.frame_id = 'map'
        for x in (0.0, 1000.0):
            pose = PoseStamped()
            pose.pose.position.x = x
            path.poses.append(pose)
        lane.on_centreline(path)
    value = st.one_of(WIDE, st.floats(-10.0, 120.0), st.floats(-1.0, 1.0))
    state = Odometry(child_frame_id='base_link')
    state.header.frame_id = 'map'
    state.pose.pose.position.x = data.draw(value)
    state.pose.pose.position.y = data.draw(st.one_of(value, st.just(0.0)))
    state.pose.pose.orientation.w = data.draw(st.one_of(value, st.just(1.0)))
    state.twist.twist.linear.x = data.draw(value)
    state.twist.twist.linear.y = data.draw(st.one_of(value, st.just(0.0)))
    command = AccelStamped()
    command.header.frame_id = 'base_link'
    command.accel.linear.x = data.draw(value)
    lateral = Control()
    lateral.lateral.steering_tire_angle = np.float32(data.draw(st.floats(width=32)))
    lateral.lateral.steering_tire_rotation_rate = np.float32(data.draw(st.floats(width=32)))
    objects = PredictedObjects()
    objects.header.frame_id = 'map'
    for _ in range(data.draw(st.integers(0, 3))):
        obj = PredictedObject()
        kin = obj.kinematics
        kin.initial_pose_with_covariance.pose.position.x = data.draw(value)
        kin.initial_pose_with_covariance.pose.orientation.w = 1.0
        kin.initial_twist_with_covariance.twist.linear.x = data.draw(value)
        obj.shape.dimensions.x = data.draw(value)
        objects.objects.append(obj)
    before = (sum(control.status.counts.values()), sum(lane.status.counts.values()))
    control.on_kinematic_state(state)
    control.on_lateral(lateral)
    control.on_command(command)
    lane.on_kinematic_state(state)
    lane.on_objects(objects)
    # every message received is either used or dropped (counted by reason)
    for node, names in ((control, ('kinematic_state', 'lateral', 'accel_cmd')),
                        (lane, ('kinematic_state', 'objects'))):
        counts = node.status.counts
        for name in names:
            dropped = sum(v for k, v in counts.items() if k.startswith(f'{name}_dropped_'))
            assert counts[f'{name}_received'] == counts[f'{name}_used'] + dropped, counts
    assert sum(control.status.counts.values()) > before[0]
    for out in controls:
        lon = out.longitudinal
        assert np.isfinite(np.float32(lon.velocity)) and np.isfinite(np.float32(lon.acceleration))
        assert 0.0 <= lon.velocity <= ranges.input_speed_max_mps
        assert abs(lon.acceleration) <= control.config.max_abs_accel_mps2
    for odom in odometries:
        assert odometry_problem(odom, ranges) == '', odom
    controls.clear()
    odometries.clear()


def test_the_planner_counts_every_refused_message(
        adapters: tuple[Any, Any, list[Any], list[Any], Any]) -> None:
    """The planner node in this process (wall mode, configured), its input callback called
    directly with arbitrary messages (:func:`arbitrary`, hypothesis): every message the
    checks refuse is counted under its input, no other; nothing raises."""
    node = adapters[4][0]
    expected: dict[str, int] = dict(node.refusals)

    @settings(max_examples=150, deadline=None, derandomize=True, database=None,
              suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
    @given(st.sampled_from(sorted(INPUTS)), st.data())
    def deliver(name: str, data: st.DataObject) -> None:
        msg = data.draw(arbitrary(name))
        if problem(name, msg):
            expected[name] = expected.get(name, 0) + 1
        node.on_latest(name, msg)
        assert dict(node.refusals) == expected

    deliver()
    assert len(expected) == len(INPUTS) and node.faults == 0


def test_the_monitor_counts_every_refused_plan(
        adapters: tuple[Any, Any, list[Any], list[Any], Any]) -> None:
    """The trust monitor in this process (wall mode, configured), its plan callback called
    directly with arbitrary plans: every plan the checks refuse is counted, nothing raises."""
    from trust_av_common.envelope import InputRanges, trajectory_problem

    node = adapters[4][1]
    ranges = InputRanges()
    expected: dict[str, int] = dict(node.refusals)

    @settings(max_examples=100, deadline=None, derandomize=True, database=None,
              suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
    @given(st.sampled_from(['plan', 'expected']), arbitrary('preview'))
    def deliver(name: str, msg: Any) -> None:
        for point in msg.points:   # the preview's velocities as a plan's accelerations
            point.accelerations, point.velocities = point.velocities, []
        if trajectory_problem(msg, 'accelerations', -ranges.input_accel_abs_max_mps2,
                              ranges.input_accel_abs_max_mps2, ranges.input_points_max):
            expected[name] = expected.get(name, 0) + 1
        node.on_latest(name, msg)
        assert dict(node.refusals) == expected

    deliver()
    assert len(expected) == 2 and node.faults == 0


BURST = st.lists(st.tuples(st.sampled_from(sorted(INPUTS)), st.booleans()), min_size=1,
                 max_size=8)
EXAMPLES = 100


def latest_values(drive: Drive) -> dict[str, str]:
    from trust_av_common.ros.messages import diagnostic_values

    mine = [m for m in drive.diagnostics if m.status and m.status[0].name.startswith('planner')]
    return diagnostic_values(mine[-1]) if mine else {}


def test_arbitrary_values_on_every_input_never_leave_the_envelope(drive: Drive) -> None:
    """:data:`EXAMPLES` bursts of 1-8 messages on random inputs, each sane or with
    arbitrary values, 30 ms apart; then every refusal is counted on ``/diagnostics`` and the
    node answers its lifecycle requests (a deactivate hands over)."""

    @settings(max_examples=EXAMPLES, deadline=None, derandomize=True, database=None,
              suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
    @given(st.data())
    def burst(data: st.DataObject) -> None:
        t_s = time.monotonic() - drive.start_s
        for name, bad in data.draw(BURST):
            msg = data.draw(arbitrary(name)) if bad else sane(name, t_s)
            drive.pubs[name].publish(msg)
            drive.sent[name] = drive.sent.get(name, 0) + 1
            if problem(name, msg):
                drive.refused[name] = drive.refused.get(name, 0) + 1
        drive.manager.spin_for(0.03)
        check_commands(drive)

    burst()
    refused = sum(drive.refused.values())
    assert refused and len(drive.refused) == len(INPUTS)   # every input saw refusals
    # /diagnostics (once a second): every input's refusals counted; at most those sent (the
    # inputs are keep last 1, best effort: under load a message may be overwritten before
    # the node takes it; test_the_planner_counts_every_refused_message counts exactly)
    drive.manager.spin_for(1.5)
    values = latest_values(drive)
    for name, count in drive.refused.items():
        assert 1 <= int(values[f'refused_{name}']) <= count, (name, values, drive.refused)
    assert values['internal_errors'] == '0' and values['commands_clipped_not_finite'] == '0'
    check_commands(drive)
    assert drive.manager.state() == ACTIVE
    assert drive.manager.transition(DEACTIVATE)   # the hand-over, then silence
    drive.manager.spin_for(0.5)
    handed = len(drive.commands)
    drive.manager.spin_for(0.5)
    assert len(drive.commands) == handed and drive.commands[-1].accel.linear.x == STALE
    drive.checked = drive.jerk_from = handed   # the hand-over is exempt from the jerk limit
    assert drive.manager.transition(ACTIVATE)
    print(f'value fuzz: {sum(drive.sent.values())} messages ({refused} refused, '
          f'{values["refused_messages"]} counted), {len(drive.commands)} commands in '
          f'{time.monotonic() - drive.start_s:.1f} s')


CASES = {
    'NaN ego speed': ('ego', ('twist', 'twist', 'linear', 'x'), math.nan),
    '+inf ego speed': ('ego', ('twist', 'twist', 'linear', 'x'), math.inf),
    '-inf ego speed': ('ego', ('twist', 'twist', 'linear', 'x'), -math.inf),
    'NaN ego position': ('ego', ('pose', 'pose', 'position', 'x'), math.nan),
    'NaN lead position': ('traffic', ('pose', 'pose', 'position', 'x'), math.nan),
    'ego speed 500': ('ego', ('twist', 'twist', 'linear', 'x'), 500.0),
    'ego speed -50': ('ego', ('twist', 'twist', 'linear', 'x'), -50.0),
    'ego speed 1e39': ('ego', ('twist', 'twist', 'linear', 'x'), 1e39),
    'ego speed 1e300': ('ego', ('twist', 'twist', 'linear', 'x'), 1e300),
    'NaN in the preview': ('preview', 'nan', None),
    'preview with positions': ('preview', 'positions', None),
    'preview with no points': ('preview', 'empty', None),
}


@pytest.mark.parametrize('case', list(CASES))
def test_the_issue_s_cases_give_the_stale_input_command(drive: Drive, case: str) -> None:
    """Sane inputs until the planner commands, then the case's message on its input with
    the others sane: the next commands are the stale-input deceleration, the status names
    the refused field; sane inputs again: it plans again."""
    from trust_av_common.ros.messages import diagnostic_values

    name, path, value = CASES[case]

    def publish_all(bad: bool) -> None:
        t_s = time.monotonic() - drive.start_s
        for each in INPUTS:
            msg = sane(each, t_s)
            if bad and each == name:
                drive.refused[name] = drive.refused.get(name, 0) + 1
                if path == 'nan':
                    msg.points[3].velocities = [math.nan]
                elif path == 'positions':
                    for point in msg.points:
                        point.positions, point.velocities = list(point.velocities), []
                elif path == 'empty':
                    msg.points = []
                else:
                    owner = msg
                    for part in path[:-1]:
                        owner = getattr(owner, part)
                    setattr(owner, path[-1], value)
            drive.pubs[each].publish(msg)

    def ticks(bad: bool, until: Any) -> bool:
        end = time.monotonic() + 30.0
        while time.monotonic() < end:
            publish_all(bad)
            drive.manager.spin_for(0.05)
            if until():
                return True
        return False

    statuses = drive.statuses
    assert ticks(False, lambda: statuses and diagnostic_values(statuses[-1])['status']
                 != 'stale_inputs')
    seen = len(statuses)
    # the stale-input command, reached within the jerk limit (1 m/s^2 a period here)
    assert ticks(True, lambda: any(diagnostic_values(s).get('status') == 'stale_inputs'
                                   and 'refused' in diagnostic_values(s)['reason']
                                   and diagnostic_values(s)['command_mps2'] == repr(STALE)
                                   for s in statuses[seen:]))
    stale = [s for s in statuses[seen:] if diagnostic_values(s).get('status') == 'stale_inputs']
    reason = diagnostic_values(stale[-1])['reason']
    assert f'refused: {name}' in reason, reason
    assert diagnostic_values(stale[-1])['command_mps2'] == repr(STALE)
    check_commands(drive)
    seen = len(statuses)
    assert ticks(False, lambda: any(diagnostic_values(s)['status'] != 'stale_inputs'
                                    for s in statuses[seen:]))
    print(f'{case}: {reason}')
