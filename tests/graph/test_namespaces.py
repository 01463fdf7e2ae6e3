"""Namespaces on one ROS domain. Two planners under ``--ros-args -r __ns:=/car1`` and
``/car2``: each plans from its own namespace's inputs only, with the params file's values
(sections ``/**/planner`` match in any namespace), and nothing is published outside the
namespaces. Two whole graphs (``run_graph`` / ``trust-av run --namespace --domain-id``) under
``/car1`` and ``/car2`` on one domain: each bag equals its in-process run and holds only its
own namespace's topics; a publisher on a graph's namespaced topics stops that run; bad
namespaces and domain ids are one line naming the option."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from rosbags.highlevel import AnyReader
from support.graph import assert_records_equal  # the graph == in-process comparison
from support.processes import INTERRUPTED_RUN_STEPS, long_trace, wait_for_steps, wait_ready

from preceding_traffic.sources import load_trace
from preceding_traffic.traces import truncate
from trust_av.errors import TrustAvAppError
from trust_av.graph.bag_records import records_from_bag
from trust_av.graph.domains import check_domain_id, check_namespace, lease_domain
from trust_av.graph.orchestrator import run_graph, run_graph_records
from trust_av.graph.processes import GraphError
from trust_av.graph.session import clashing_participants
from trust_av.system.closed_loop import simulate
from trust_av.system.config import DEFAULT_PARAMS_FILE, RunConfig, load_run_config
from trust_av.system.metrics import StepRecord
from trust_av_common.kinematics import VehicleState
from trust_av_common.topics import TOPIC, TOPICS, qualified
from trust_av_planner.planner import AvPlanner

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

    from trust_av_common.ros.messages import message_class, odometry, trajectory
    from trust_av_common.ros.qos import QOS

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


# --- two whole graphs ---------------------------------------------------------------------

GRAPH_STEPS = 30
CARS = {'/car1': {'alpha': 0.0, 'predictor': 'ca'}, '/car2': {'alpha': 1.0, 'predictor': 'ca'}}
"""Per namespace, the planner's settings: different alpha, so different trajectories."""


def car_config(namespace: str) -> RunConfig:
    return load_run_config(overrides={'planner': CARS[namespace]})


def in_process(namespace: str) -> list[StepRecord]:
    config = car_config(namespace)
    trace = truncate(load_trace('us06', config.planner.dt_s, config.trace), GRAPH_STEPS)
    return simulate(config, trace).records


def recorded(namespace: str) -> dict[str, int]:
    """Full topic name -> messages a run of GRAPH_STEPS steps in ``namespace`` records."""
    return {qualified(t.name, namespace): t.messages(GRAPH_STEPS)
            for t in TOPICS if 'recorder' in t.subscribers}


def bag_topics(bag: Path) -> dict[str, int]:
    with AnyReader([bag]) as reader:
        return {c.topic: c.msgcount for c in reader.connections}


def cli_run(bag: Path, namespace: str, domain: int, steps: int = GRAPH_STEPS,
            trace: str = 'us06') -> list[str]:
    settings = CARS[namespace]
    return [sys.executable, '-m', 'trust_av.cli', 'run', '--trace', trace,
            '--alpha', str(settings['alpha']), '--predictor', settings['predictor'],
            '--max-steps', str(steps), '--bag', str(bag), '--no-progress', '--no-plot',
            '--namespace', namespace, '--domain-id', str(domain)]


@pytest.mark.slow
def test_two_whole_graphs_in_one_domain_do_not_hear_each_other(tmp_path: Path) -> None:
    """/car1 (``trust-av run``, a child process) and /car2 (``run_graph_records`` here) on one
    leased domain. /car2 starts once /car1's nodes are on the domain: its start-up check
    sees them and must not refuse them; then both run side by side. Each bag holds exactly
    its own namespace's topics with exactly one run's messages (a message heard from the
    other graph would add to a count or a topic) and equals its in-process run."""
    with lease_domain() as domain:
        car1 = subprocess.Popen(cli_run(tmp_path / 'car1', '/car1', domain),
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        try:
            deadline = time.monotonic() + 120
            while not clashing_participants(domain, '/car1', wait_s=0.3):
                assert car1.poll() is None, car1.communicate()
                assert time.monotonic() < deadline, 'the /car1 graph never appeared'
            assert car1.poll() is None                   # /car1 is up while /car2 starts
            config = car_config('/car2')
            trace = truncate(load_trace('us06', config.planner.dt_s, config.trace),
                             GRAPH_STEPS)
            run2, records2 = run_graph_records(config, 'us06', trace, tmp_path / 'car2',
                                               max_steps=GRAPH_STEPS, namespace='/car2',
                                               domain_id=domain)
            out, err = car1.communicate(timeout=300)
        finally:
            if car1.poll() is None:
                car1.kill()
                car1.communicate()
    assert car1.returncode == 0, out + err
    assert f'domain {domain}, namespace /car1' in out
    assert run2.domain_id == domain and run2.steps == GRAPH_STEPS
    for ns in CARS:
        assert bag_topics(tmp_path / ns.strip('/')) == recorded(ns), ns
    records1 = records_from_bag(tmp_path / 'car1', '/car1')
    assert_records_equal(records1, in_process('/car1'))
    assert_records_equal(records2, in_process('/car2'))
    # The comparison tells the two apart: each graph ran its own settings.
    assert [r.av_plan_mps2 for r in records1] != [r.av_plan_mps2 for r in records2]


def intruder(domain: int, topic: str, *, on_go: bool = False) -> subprocess.Popen[str]:
    """A node of someone else in namespace /elsewhere: publishes empty human plans on
    ``topic`` (a topic only the recorder subscribes: no node of the graph dies of it, so
    the watch is what stops the run). With ``on_go`` the node is up at once but creates its
    publisher only when it reads a line (:func:`go`): its node name is known by then, so the
    publisher is named as soon as it is discovered."""
    code = ('import rclpy, sys, time\n'
            'from trajectory_msgs.msg import JointTrajectory\n'
            'from trust_av_common.ros.qos import QOS\n'
            'rclpy.init()\n'
            "node = rclpy.create_node('intruder', namespace='/elsewhere')\n"
            "print('ready', flush=True)\n"
            f'if {on_go!r}: sys.stdin.readline()\n'
            f"pub = node.create_publisher(JointTrajectory, {topic!r}, QOS['STEP'])\n"
            'msg = JointTrajectory()\n'
            'while True:\n'
            '    pub.publish(msg); time.sleep(0.2)\n')
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST')
    process = subprocess.Popen([sys.executable, '-c', code], env=env, text=True,
                               stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                               stderr=subprocess.DEVNULL)
    wait_ready(process)
    return process


def go(process: subprocess.Popen[str]) -> None:
    """Let an ``on_go`` intruder publish."""
    assert process.stdin is not None
    process.stdin.write('go\n')
    process.stdin.flush()


@pytest.mark.slow
def test_a_publisher_on_the_graphs_own_namespaced_topic_stops_it(tmp_path: Path) -> None:
    """On a shared domain, once a node of someone else publishes on /car1's own human plan,
    the /car1 run stops with one line naming the namespaced topic and the node, exit 2.
    (Publishers on another namespace's topics leave a run alone: the watch looks only at
    the run's own topics, and in test_two_whole_graphs_in_one_domain_do_not_hear_each_other
    the /car1 run finishes, complete and equal to the in-process run, beside the /car2
    graph's publishers on /car2's topics; a separate /car1 run beside an intruder on
    /car2/human/plan repeated that.)"""
    with lease_domain() as domain:
        bag = tmp_path / 'intruded'
        mine = intruder(domain, '/car1/human/plan', on_go=True)   # a node, no publisher yet
        proc = subprocess.Popen(cli_run(bag, '/car1', domain, steps=INTERRUPTED_RUN_STEPS,
                                        trace=str(long_trace(tmp_path))),
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        try:
            wait_for_steps(bag, 20, proc=proc)
            go(mine)
            out, err = proc.communicate(timeout=120)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.communicate()
            mine.kill()
            mine.wait()
    assert proc.returncode == 2, out + err
    assert err.count('\n') == 1, err
    assert 'foreign publisher on /car1/human/plan: node /elsewhere/intruder' in err


def test_a_shared_domain_refuses_a_node_in_the_same_namespace(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A node already in /car1 on the domain: a /car1 run refuses to start (one line), while
    the check for /car2 finds nothing."""
    import rclpy
    from rclpy.context import Context

    config = load_run_config()
    trace = truncate(load_trace('us06', config.planner.dt_s, config.trace), 5)
    # Discovery of a participant can take up to Fast DDS's 3 s announcement period (what
    # the 1 s check misses, the watch during the run catches): here it must see it.
    monkeypatch.setattr('trust_av.graph.session.PROBE_S', 4.0)
    monkeypatch.setenv('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')    # as the graph's
    with lease_domain() as domain:
        context = Context()
        rclpy.init(context=context, domain_id=domain)
        try:
            squatter = rclpy.create_node('planner', namespace='/car1', context=context)
            with pytest.raises(GraphError, match=f'domain {domain} already has a graph in '
                                                 'namespace /car1: nodes /car1/planner'):
                run_graph(config, 'us06', trace, tmp_path / 'bag', namespace='/car1',
                          domain_id=domain)
            assert clashing_participants(domain, '/car2') == ''
            squatter.destroy_node()
        finally:
            rclpy.try_shutdown(context=context)
    assert not (tmp_path / 'bag').exists()


# --- bad namespaces and domain ids ----------------------------------------------------------

# rmw (jazzy) rmw/src/validate_namespace.c: rmw_validate_namespace, through
# validate_full_topic_name.c, with rmw_namespace_validation_result_string's reasons.
BAD_NAMESPACES = {
    '': 'namespace must not be empty',
    'car1': "namespace must be absolute, it must lead with a '/'",
    '/car1/': "namespace must not end with a '/', unless only a '/'",
    '/car-1': "namespace must not contain characters other than alphanumerics, '_', or '/'",
    '/car\u00e9': 'must not contain characters other than alphanumerics',
    '/car1//a': "namespace must not contain repeated '/'",
    '/1car': 'namespace must not have a token that starts with a number',
    '/car1/2': 'namespace must not have a token that starts with a number',
    '/' + 'a' * 245: 'namespace should not exceed 245 characters',
}
LONGEST_TOPIC = max(len(t.name) for t in TOPICS)
LONGEST_NAMESPACE = '/' + 'a' * (245 - LONGEST_TOPIC)
"""Its longest topic is exactly rmw's longest full topic name (247 characters)."""


@pytest.mark.parametrize('namespace', ['/', '/car1', '/_a/b_2/C', LONGEST_NAMESPACE])
def test_valid_namespaces_are_accepted(namespace: str) -> None:
    assert check_namespace(namespace) == namespace


@pytest.mark.parametrize(('namespace', 'reason'), BAD_NAMESPACES.items())
def test_bad_namespaces_are_one_line_naming_the_option(namespace: str, reason: str) -> None:
    with pytest.raises(TrustAvAppError, match='^--namespace .*' + re.escape(reason)):
        check_namespace(namespace, '--namespace')


def test_a_namespace_whose_topics_would_be_too_long_is_refused() -> None:
    """rmw's full topic name limit (247) applies to the graph's longest topic too."""
    assert len(qualified('x' * LONGEST_TOPIC, LONGEST_NAMESPACE)) == 247
    with pytest.raises(TrustAvAppError, match="longer than rmw's 247 characters"):
        check_namespace(LONGEST_NAMESPACE + 'a')


@pytest.mark.parametrize('domain_id', [0, 101, 232])
def test_domain_ids_fast_dds_can_use_are_accepted(domain_id: int) -> None:
    assert check_domain_id(domain_id) == domain_id


@pytest.mark.parametrize('domain_id', [-1, 233, 1000, True, 5.0, '5', None])
def test_bad_domain_ids_are_refused(domain_id: object) -> None:
    with pytest.raises(TrustAvAppError, match=r'^domain_id .*in 0\.\.232'):
        check_domain_id(domain_id)


def test_run_graph_checks_before_it_starts_anything(tmp_path: Path) -> None:
    config = load_run_config()
    trace = truncate(load_trace('us06', config.planner.dt_s, config.trace), 5)
    with pytest.raises(TrustAvAppError, match=r"^namespace 'car1': namespace must be abs"):
        run_graph(config, 'us06', trace, tmp_path / 'bag', namespace='car1')
    with pytest.raises(TrustAvAppError, match=r'^domain_id 233: '):
        run_graph(config, 'us06', trace, tmp_path / 'bag', domain_id=233)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(('option', 'value', 'words'), [
    ('--namespace', 'car1', "--namespace 'car1': namespace must be absolute"),
    ('--namespace', '/car 1', "--namespace '/car 1': namespace must not contain characters"),
    ('--domain-id', '233', '--domain-id 233: a ROS domain id is a whole number in 0..232'),
    ('--domain-id', '-1', '--domain-id -1: a ROS domain id'),
    ('--domain-id', 'abc', "--domain-id 'abc': a ROS domain id"),
])
def test_trust_av_run_refuses_bad_values_in_one_line(tmp_path: Path, option: str, value: str,
                                                     words: str) -> None:
    proc = subprocess.run([sys.executable, '-m', 'trust_av.cli', 'run', '--bag',
                           str(tmp_path / 'bag'), option, value], capture_output=True,
                          text=True, timeout=120)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert proc.stderr.startswith(f'trust-av run: error: {words}'), proc.stderr
    assert proc.stderr.count('\n') == 1, proc.stderr
    assert list(tmp_path.iterdir()) == []
