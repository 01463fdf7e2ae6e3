"""``/diagnostics`` (``diagnostic_msgs/DiagnosticArray``, as diagnostic_updater publishes it)
and no silent state: a wall-mode node that cannot run as configured says why, on
``/diagnostics``, in its status and in its log (trust_av_common/ros/diagnostics.py,
trust_av_common/ros/lifecycle.py)."""

from __future__ import annotations

import itertools
import time
from pathlib import Path
from typing import Any

from support.lifecycle import ACTIVATE, Manager, start, stop

from trust_av.graph.domains import lease_domain

WALL = ['-p', 'clock_mode:=wall', '-p', "human_odom_topic:=''", '-p', 'predictor:=ca',
        '-p', 'lead_preview:=constant_speed']


def statuses(manager: Manager, node: str) -> list[Any]:
    """The ``/diagnostics`` statuses of ``node`` received so far, in order."""
    return [s for array in manager.received['/diagnostics'] for s in array.status
            if s.name.startswith(f'{node}: ')]


def values(status: Any) -> dict[str, str]:
    return {kv.key: kv.value for kv in status.values}


def level(status: Any) -> int:
    return int.from_bytes(status.level, 'little')


def listen(manager: Manager) -> None:
    from diagnostic_msgs.msg import DiagnosticArray
    from geometry_msgs.msg import AccelStamped

    from trust_av_common.ros.diagnostics import QOS
    from trust_av_common.ros.qos import topic_qos
    from trust_av_common.wall_clock import WallClockConfig

    wall = WallClockConfig(clock_mode='wall')
    manager.record(DiagnosticArray, '/diagnostics', QOS)
    manager.record(AccelStamped, 'ego/accel_cmd', topic_qos('ego/accel_cmd', wall))
    manager.record(DiagnosticArray, 'ego/planner_status', topic_qos('ego/planner_status', wall))


def odometry_inputs(manager: Manager, frames: dict[str, str]) -> Any:
    """Lead and ego odometry at 100 Hz, stamped now, in ``frames[...]`` (changeable); the
    timer that publishes them."""
    from nav_msgs.msg import Odometry

    from trust_av_common.ros.messages import odometry
    from trust_av_common.ros.qos import topic_qos
    from trust_av_common.wall_clock import WallClockConfig

    wall = WallClockConfig(clock_mode='wall')
    pubs = {t: manager.node.create_publisher(Odometry, t, topic_qos(t, wall))
            for t in ('preceding_vehicle/odom', 'ego/odom')}

    def publish() -> None:
        ns, t_s = time.time_ns(), time.monotonic()
        for topic, x, child in (('preceding_vehicle/odom', 60.0, 'preceding_vehicle'),
                                ('ego/odom', 30.0, 'ego')):
            msg = odometry(ns, x + 15.0 * t_s, 15.0, child)
            msg.header.frame_id = frames[topic]
            pubs[topic].publish(msg)

    return manager.node.create_timer(0.01, publish)


def test_wall_mode_on_sim_time_says_why_it_does_not_command(tmp_path: Path) -> None:
    """``use_sim_time: true`` (a shared ``/**`` setting) in wall mode: before, the active
    planner published nothing and logged nothing (its timer waited for a /clock that never
    came). Now, with its inputs flowing: no command, its status ERROR ``not_running`` with
    the reason, ``/diagnostics`` ERROR naming it, one log line; with a simulated clock on
    /clock it names that instead."""
    from rosgraph_msgs.msg import Clock

    with lease_domain() as domain:
        proc = start(tmp_path, domain, 'trust_av_planner.planner_node', *WALL,
                     '-p', 'use_sim_time:=true')
        manager = Manager(domain, 'planner')
        try:
            listen(manager)
            odometry_inputs(manager, {'preceding_vehicle/odom': 'odom', 'ego/odom': 'odom'})
            assert manager.transition(ACTIVATE)

            def said(words: str) -> bool:
                return any(level(s) == 2 and words in s.message
                           for s in statuses(manager, 'planner'))

            assert manager.spin_until(lambda: said('no clock is published on /clock'))
            report = manager.received['ego/planner_status']
            assert manager.spin_until(lambda: len(report) >= 2)
            assert report[-1].status[0].message == 'not_running'
            assert 'use_sim_time is true' in values(report[-1].status[0])['reason']
            clock = manager.node.create_publisher(Clock, '/clock', 10)
            sim = manager.node.create_timer(
                0.05, lambda: clock.publish(Clock(clock=time_msg(123))))
            assert manager.spin_until(lambda: said('a simulated clock is published on /clock'))
            sim.cancel()
            assert manager.received['ego/accel_cmd'] == []
        finally:
            manager.close()
            log = stop(proc)
    assert log.count('not running: use_sim_time is true and no clock') == 1, log
    assert log.count('not running: use_sim_time is true and a simulated clock') == 1, log


def stale_inputs_keep_one_status_a_second(manager: Manager, feeding: Any) -> Any:
    """The inputs stop: ``/diagnostics`` says so (ERROR, the stale inputs named) and keeps its
    period while they age (their ages in ``values``, the message unchanged: before, it
    carried the ages and was published on every 0.1 s tick); the last such status."""
    feeding.cancel()

    def stale() -> list[Any]:
        return [s for s in statuses(manager, 'planner') if level(s) == 2 and 'stale:' in s.message]

    assert manager.spin_until(lambda: len(stale()) >= 5), [s.message for s in stale()]
    last = stale()[2:5]    # after the (at most two) changes: the timer's
    assert len({s.message for s in last}) == 1 and ' s old' not in last[0].message, \
        [s.message for s in last]
    ages = [float(values(s)['input_age_ego_s']) for s in last]
    assert ages[-1] - ages[0] >= 1.0, ages     # 2 s (0.2 s before), a late timer tick or not
    return last[-1]


def publishers_of_another_type_are_named(manager: Manager, domain: int) -> Any:
    """A ``std_msgs/String`` publisher on ``/ego/odom`` and a ``TwistStamped`` one on
    ``/preceding_vehicle/odom`` (a node of another participant: DDS never connects them): on
    ``/diagnostics`` (WARN at least, the message and ``wrong_type_on_<topic>``); the status."""
    import rclpy
    from geometry_msgs.msg import TwistStamped
    from std_msgs.msg import String

    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain)
    node = rclpy.create_node('wrong_types', context=context, start_parameter_services=False)
    try:
        node.create_publisher(String, '/ego/odom', 1)
        node.create_publisher(TwistStamped, '/preceding_vehicle/odom', 1)

        def named() -> list[Any]:
            return [s for s in statuses(manager, 'planner') if 'another type' in s.message and
                    'TwistStamped' in s.message and 'std_msgs/msg/String' in s.message]

        assert manager.spin_until(lambda: bool(named())), \
            [s.message for s in statuses(manager, 'planner')][-3:]
        assert level(named()[0]) == 2   # still the stale-input policy's ERROR
        manager.spin_for(1.5)           # more discovery traffic: no second log line
        return named()[-1]
    finally:
        node.destroy_node()
        rclpy.shutdown(context=context)


def time_msg(seconds: int) -> Any:
    from builtin_interfaces.msg import Time
    return Time(sec=seconds)


def test_diagnostics_once_a_second_with_solve_times_input_ages_and_frames(
        tmp_path: Path) -> None:
    """An active wall-mode planner and its monitor-less inputs: ``/diagnostics`` OK
    ``commanding`` about once a second (diagnostic_updater's period) with solve times, input
    ages, fallback counts and trust; inputs in frames it cannot relate (ego in ``map``, the
    lead in ``odom``): ERROR naming the frames at once, and its commands are the stale-input
    deceleration. Before it is configured it already reports its lifecycle state."""
    from nav_msgs.msg import Odometry

    from trust_av.system.config import load_run_config
    from trust_av_common.ros.qos import topic_qos
    from trust_av_common.wall_clock import WallClockConfig

    frames = {'preceding_vehicle/odom': 'odom', 'ego/odom': 'odom'}
    with lease_domain() as domain:
        proc = start(tmp_path, domain, 'trust_av_planner.planner_node', *WALL,
                     '-p', 'autostart:=false')
        manager = Manager(domain, 'planner')
        try:
            listen(manager)
            assert manager.spin_until(lambda: any(
                s.message == 'unconfigured: waiting for configure'
                for s in statuses(manager, 'planner')))
            feeding = odometry_inputs(manager, frames)
            assert manager.transition(1) and manager.transition(ACTIVATE)
            assert manager.spin_until(lambda: sum(
                s.message == 'commanding' for s in statuses(manager, 'planner')) >= 4), \
                [s.message for s in statuses(manager, 'planner')]
            frames['ego/odom'] = 'map'
            assert manager.spin_until(lambda: any(
                level(s) == 2 and 'frame' in s.message for s in statuses(manager, 'planner')))
            commands = manager.received['ego/accel_cmd']
            seen = len(commands)
            assert manager.spin_until(lambda: len(commands) >= seen + 5)
            # malformed bytes on an input (rclpy's own decoding on the vehicle path): dropped,
            # counted on /diagnostics, the node goes on
            raw = manager.node.create_publisher(Odometry, 'ego/odom', topic_qos(
                'ego/odom', WallClockConfig(clock_mode='wall')))
            assert manager.spin_until(lambda: raw.get_subscription_count() > 0)
            malformed = (b'\x00\x01\x00\x00\xff\xff', b'\x00\x01\x00\x00' + b'\x07' * 40)
            manager.node.create_timer(0.1, lambda: [raw.publish(data) for data in malformed])
            assert manager.spin_until(lambda: any(
                int(values(s).get('dropped_messages', 0)) >= 2
                for s in statuses(manager, 'planner')))
            stale = stale_inputs_keep_one_status_a_second(manager, feeding)
            wrong = publishers_of_another_type_are_named(manager, domain)
            assert proc.poll() is None
        finally:
            manager.close()
            log = stop(proc)
    # named once in the log, whatever the publisher sends and for however long
    assert log.count('input /ego/odom takes nav_msgs/msg/Odometry; not connected (another '
                     'type): std_msgs/msg/String (/wrong_types)') == 1, log
    assert 'input /preceding_vehicle/odom takes' in log and \
        'geometry_msgs/msg/TwistStamped (/wrong_types)' in log, log
    assert values(wrong)['wrong_type_on_/ego/odom'] == 'std_msgs/msg/String (/wrong_types)'
    assert stale.hardware_id == 'none' and values(stale)['node'] == '/planner'
    commanding = [s for s in statuses(manager, 'planner') if s.message == 'commanding']
    kv = values(commanding[-1])
    assert kv['lifecycle_state'] == 'active'
    assert int(kv['solves']) > 0 and int(kv['fallbacks']) >= 0
    assert float(kv['solve_time_last_s']) > 0.0
    assert float(kv['input_age_traffic_s']) < 0.5 and float(kv['input_age_ego_s']) < 0.5
    assert kv['input_age_trust_s'] == 'never' and 'trust' in kv
    mine = statuses(manager, 'planner')
    stamps = [a.header.stamp.sec + a.header.stamp.nanosec / 1e9
              for a in manager.received['/diagnostics']
              if a.status[0].name.startswith('planner: ')]
    changes = sum((a.level, a.message) != (b.level, b.message)
                  for a, b in itertools.pairwise(mine))
    span_s = stamps[-1] - stamps[0]
    # once a second from the timer (diagnostic_updater's period), plus one at each change
    assert span_s / 2 - 1 <= len(mine) - changes <= span_s + 2, (span_s, len(mine), changes)
    assert commands[-1].accel.linear.x == load_run_config().planner.stale_decel_mps2


def test_monitor_and_plain_nodes_publish_diagnostics(tmp_path: Path) -> None:
    """The trust monitor reports its state and, while active, its scores; a node that is not
    managed (the ego plant) reports that it runs."""
    with lease_domain() as domain:
        monitor = start(tmp_path, domain, 'trust_monitor.monitor_node', '-p', 'autostart:=false')
        plant = start(tmp_path, domain, 'trust_av_planner.ego_plant_node', '-p',
                      'initial_position_m:=0.0', '-p', 'initial_speed_mps:=0.0',
                      '-p', 'start_time_s:=0.0')
        manager = Manager(domain, 'trust_monitor')
        try:
            listen(manager)
            assert manager.spin_until(lambda: any(
                s.message == 'unconfigured: waiting for configure'
                for s in statuses(manager, 'trust_monitor')))
            assert manager.transition(1)
            assert manager.spin_until(lambda: any(
                s.message.startswith('inactive') for s in statuses(manager, 'trust_monitor')))
            assert manager.spin_until(lambda: any(
                s.message == 'running' for s in statuses(manager, 'ego_plant')))
        finally:
            manager.close()
            stop(monitor)
            stop(plant)
