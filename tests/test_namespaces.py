"""Two planners under ``--ros-args -r __ns:=/car1`` and ``/car2`` on one ROS domain: each
plans from its own namespace's inputs only, with the params file's values (sections
``/**/planner`` match in any namespace), and nothing is published outside the namespaces."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest

from trust_av_planner.graph.domains import lease_domain
from trust_av_planner.planner import AvPlanner
from trust_av_planner.system.config import DEFAULT_PARAMS_FILE, load_run_config
from trust_monitor.common.kinematics import VehicleState
from trust_monitor.common.topics import TOPIC, qualified

NAMESPACES = ('/car1', '/car2')
# Per namespace: (traffic, ego, human) odometry (position m, speed m/s) at t = 0, and the
# preceding vehicle's speed preview: different enough to give different plans.
STATES = {'/car1': ((40.0, 10.0), (20.0, 10.0), (5.0, 10.0), (10.0, 10.5, 11.0)),
          '/car2': ((30.0, 5.0), (12.0, 7.0), (0.0, 6.0), (5.0, 4.0, 3.0))}
OUTPUTS = ('ego/plan', 'ego/expected_plan', 'ego/accel_cmd', 'ego/planner_status',
           'vehicle_markers')


def expected_plans(namespace: str) -> tuple[list[float], list[float]]:
    """The in-process planner's plan and expected plan for a namespace's inputs."""
    config = load_run_config()
    planner = AvPlanner(config.planner, config.trust, config.shared.vehicle_length_m)
    (traffic, ego, human, preview) = STATES[namespace]
    out = planner.step(VehicleState(*traffic), np.array(preview), VehicleState(*ego),
                       VehicleState(*human), config.trust.trust_initial)
    return out.result.plan_mps2.tolist(), out.expected_mps2.tolist()


@pytest.fixture()
def planners() -> Iterator[int]:
    """Two planner processes, /car1 and /car2, on one leased domain; yields the domain."""
    with lease_domain() as domain:
        env = dict(os.environ, ROS_DOMAIN_ID=str(domain),
                   ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST')
        procs = [subprocess.Popen([sys.executable, '-m', 'trust_av_planner.planner_node',
                                   '--ros-args', '-r', f'__ns:={ns}', '--params-file',
                                   str(DEFAULT_PARAMS_FILE)], env=env, text=True,
                                  stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
                 for ns in NAMESPACES]
        try:
            yield domain
        finally:
            for proc in procs:
                proc.send_signal(signal.SIGINT)
            for proc in procs:
                try:
                    out, _ = proc.communicate(timeout=20)
                except subprocess.TimeoutExpired:
                    proc.kill()
                    out, _ = proc.communicate()
                assert proc.returncode == 0, out


def test_two_namespaced_planners_do_not_hear_each_other(planners: int) -> None:
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor

    from trust_monitor.ros.messages import message_class, odometry, trajectory
    from trust_monitor.ros.qos import QOS

    context = Context()
    rclpy.init(context=context, domain_id=planners)
    try:
        node = rclpy.create_node('namespace_probe', context=context)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        received: dict[str, list[Any]] = {}

        for name in OUTPUTS:
            for ns in ('/', *NAMESPACES):                   # the root namespace: nothing
                full = qualified(name, ns)
                node.create_subscription(
                    message_class(TOPIC[name].msgtype), full,
                    lambda m, t=full: received.setdefault(t, []).append(m), QOS['STEP'])
        publishers = {}
        for ns in NAMESPACES:
            for name in ('preceding_vehicle/odom', 'preceding_vehicle/speed_preview',
                         'ego/odom', 'human/odom'):
                publishers[ns, name] = node.create_publisher(
                    message_class(TOPIC[name].msgtype), qualified(name, ns), QOS['STEP'])
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and not all(
                node.count_subscribers(qualified('ego/odom', ns)) >= 1 for ns in NAMESPACES):
            executor.spin_once(timeout_sec=0.1)
        for ns in NAMESPACES:
            (traffic, ego, human, preview) = STATES[ns]
            publishers[ns, 'preceding_vehicle/odom'].publish(
                odometry(0, *traffic, 'preceding_vehicle'))
            publishers[ns, 'preceding_vehicle/speed_preview'].publish(
                trajectory(0, 1.0, frame_id='preceding_vehicle', velocities=preview))
            publishers[ns, 'ego/odom'].publish(odometry(0, *ego, 'ego'))
            publishers[ns, 'human/odom'].publish(odometry(0, *human, 'human'))
        wanted = {qualified(name, ns) for name in OUTPUTS for ns in NAMESPACES}
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and not wanted <= set(received):
            executor.spin_once(timeout_sec=0.1)
        for _ in range(10):                                 # anything late or stray
            executor.spin_once(timeout_sec=0.05)
    finally:
        rclpy.try_shutdown(context=context)
    assert wanted <= set(received), wanted - set(received)
    assert set(received) == wanted                          # nothing outside the namespaces
    for ns in NAMESPACES:
        assert all(len(received[qualified(name, ns)]) == 1 for name in OUTPUTS), ns
        plan, expected = expected_plans(ns)
        got_plan = [p.accelerations[0] for p in received[qualified('ego/plan', ns)][0].points]
        got_expected = [p.accelerations[0]
                        for p in received[qualified('ego/expected_plan', ns)][0].points]
        assert got_plan == pytest.approx(plan, abs=1e-12), ns
        assert got_expected == pytest.approx(expected, abs=1e-12), ns
    assert expected_plans('/car1')[0] != pytest.approx(expected_plans('/car2')[0], abs=1e-3)
