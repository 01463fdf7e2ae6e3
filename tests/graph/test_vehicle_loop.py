"""Real-vehicle mode: QoS events under the EventsExecutor, the stale-input policy, tuning on
the road, and a vehicle in the loop (docs/tutorials/connect-a-vehicle.md). No timing assertions:
jitter is measured by ``benchmarks/bench_shadow.py --vehicle``."""

from __future__ import annotations

import dataclasses
import json
import os
import re
import subprocess
import sys
import time
from pathlib import Path
from typing import Any, BinaryIO

import pytest
from support.paths import REPO

from trust_av.system.config import DEFAULT_PARAMS_FILE, load_run_config
from trust_av_common.ros.tuning import Tunable, check_request
from trust_av_common.wall_clock import WallClockConfig
from trust_av_planner.nmpc import PlannerConfig

sys.path.insert(0, str(REPO / 'benchmarks'))
from vehicle_loop import node_command, run_vehicle_loop, stop


def test_events_executor_delivers_qos_deadline_and_incompatibility_events() -> None:
    """rclpy's EventsExecutor (which every node spins) calls a subscription's deadline and
    incompatible-QoS callbacks (Jazzy: QoS event handlers are waitables it registers with
    rcl_event_set_callback)."""
    code = r"""
import os, time, rclpy
from rclpy.duration import Duration
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.experimental import EventsExecutor
from rclpy.qos import QoSProfile, ReliabilityPolicy
from std_msgs.msg import Empty
rclpy.init()
node = rclpy.create_node('qos_events')
seen = {'deadline': 0, 'incompatible': 0, 'messages': 0}
def count(key):
    return lambda *_: seen.__setitem__(key, seen[key] + 1)
wanted = QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT,
                    deadline=Duration(seconds=1.0))
events = SubscriptionEventCallbacks(deadline=count('deadline'),
                                    incompatible_qos=count('incompatible'))
node.create_subscription(Empty, 'with_deadline', count('messages'), wanted,
                         event_callbacks=events)
node.create_subscription(Empty, 'without', lambda _: None, wanted, event_callbacks=
                         SubscriptionEventCallbacks(incompatible_qos=count('incompatible')))
offers = node.create_publisher(Empty, 'with_deadline',
                               QoSProfile(depth=1, deadline=Duration(seconds=0.5)))
node.create_publisher(Empty, 'without', QoSProfile(depth=1))  # offers no deadline
executor = EventsExecutor()
executor.add_node(node)
end = time.monotonic() + 1.0
while time.monotonic() < end:
    offers.publish(Empty())
    executor.spin_once(timeout_sec=0.02)
during = dict(seen)
end = time.monotonic() + 3.0
while time.monotonic() < end:
    executor.spin_once(timeout_sec=0.05)
print(during['deadline'], seen['deadline'], seen['incompatible'], seen['messages'])
executor.shutdown(); node.destroy_node(); rclpy.try_shutdown()
"""
    from trust_av.graph.domains import lease_domain
    with lease_domain() as domain:
        proc = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                              timeout=60, env=dict(os.environ, ROS_DOMAIN_ID=str(domain),
                                                   ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST'))
    assert proc.returncode == 0, proc.stderr
    # the counts are the script's one line of four integers: Fast DDS may log to stdout
    # around it (a shared-memory transport warning, on a loaded host)
    counts = [line for line in proc.stdout.splitlines()
              if re.fullmatch(r'\d+ \d+ \d+ \d+', line.strip())]
    assert len(counts) == 1, proc.stdout
    during, after, incompatible, messages = map(int, counts[0].split())
    # no event while the deadline is kept: a message every 20 ms against a 1 s deadline
    # (0.2 s was missed once on a loaded host, the process descheduled that long)
    assert messages > 0 and during == 0
    assert after >= 2                     # 3 s of silence, 1 s deadline
    assert incompatible >= 1              # a publisher without a deadline is named


def _tunables(config: PlannerConfig) -> tuple[list[Tunable], dict[str, Any]]:
    held: dict[str, Any] = {'config': config}
    return [Tunable(PlannerConfig, lambda: held['config'],
                    lambda c: held.__setitem__('config', c))], held


def test_tuning_rules() -> None:
    """Run-time changes: wall mode only, writable fields only (the reason otherwise), the
    field's range and the dataclass's own rules, exactly as at start-up."""
    config = load_run_config().planner
    tunables, _ = _tunables(config)
    reason, new = check_request(tunables, {'alpha': 0.8, 'trust_min': -1.0}, wall=True)
    assert reason == '' and new[0].alpha == 0.8 and new[0].trust_min == -1.0
    assert new[0].time_headway_s == config.time_headway_s
    reason, _ = check_request(tunables, {'alpha': 0.8}, wall=False)
    assert 'lock-step' in reason
    reason, _ = check_request(tunables, {'alpha': 1.5}, wall=True)
    assert reason == 'alpha must be in [0, 1], got 1.5'
    reason, _ = check_request(tunables, {'gap_min_m': 2.0}, wall=True)
    assert reason == 'gap_min_m is read-only: a safety bound: fixed while the vehicle drives'
    reason, _ = check_request(tunables, {'solver_cpu_budget_s': 0.0}, wall=True)
    assert 'solver_cpu_budget_s must be in (0, 60]' in reason
    reason, _ = check_request(tunables, {'alpha': 'high'}, wall=True)
    assert 'expected a number' in reason
    writable = {f for f in PlannerConfig.__dataclass_fields__
                if not PlannerConfig.__dataclass_fields__[f].metadata['trust_av_param'].read_only}
    assert writable == {'alpha', 'trust_min', 'solver_cpu_budget_s'}
    assert all(PlannerConfig.__dataclass_fields__[f].metadata['trust_av_param'].reason
               for f in PlannerConfig.__dataclass_fields__ if f not in writable)


def test_stale_decel_is_bounded_by_the_acceleration_bound() -> None:
    config = load_run_config().planner
    with pytest.raises(ValueError, match='stale_decel_mps2 must be >= accel_min_mps2'):
        PlannerConfig(**{**config.__dict__, 'stale_decel_mps2': -3.5})
    with pytest.raises(ValueError, match='stale_decel_mps2'):
        PlannerConfig(**{**config.__dict__, 'stale_decel_mps2': 0.0})


VEHICLE_STACK_QOS = [(reliability, durability)
                     for reliability in ('RELIABLE', 'BEST_EFFORT')
                     for durability in ('VOLATILE', 'TRANSIENT_LOCAL')]
"""Publishers of vehicle stacks: keep last 1, no deadline, either reliability, either
durability. Autoware's EKF localizer publishes its kinematic state with
``create_publisher<nav_msgs::msg::Odometry>("ekf_odom", 1)`` (autowarefoundation/
autoware.universe, localization/ekf_localizer/src/ekf_localizer.cpp): rclcpp's ``QoS(1)``,
i.e. reliable, volatile, keep last 1, no deadline."""


@pytest.mark.parametrize(('reliability', 'durability'), VEHICLE_STACK_QOS)
def test_default_inputs_match_vehicle_stack_publishers(reliability: str,
                                                       durability: str) -> None:
    """rmw's own compatibility check (rclpy ``qos_check_compatible`` ->
    ``rmw_qos_profile_check_compatible``): the planner's input subscription matches each
    vehicle-stack publisher by default; requesting a deadline (``input_deadline_qos``) does
    not match a publisher that offers none ("Subscription has a deadline, but publisher
    does not"), and matches this project's publishers."""
    from rclpy.qos import (
        DurabilityPolicy,
        QoSCompatibility,
        QoSProfile,
        ReliabilityPolicy,
        qos_check_compatible,
    )

    from trust_av_common.ros.qos import topic_qos

    stack = QoSProfile(depth=1, reliability=ReliabilityPolicy[reliability],
                       durability=DurabilityPolicy[durability])
    default = WallClockConfig(clock_mode='wall')
    assert default.input_deadline_qos is False
    for topic in ('ego/odom', 'preceding_vehicle/odom', 'human/odom'):
        verdict, reason = qos_check_compatible(stack, topic_qos(topic, default))
        assert verdict != QoSCompatibility.ERROR, reason
    strict = WallClockConfig(clock_mode='wall', input_deadline_qos=True)
    verdict, reason = qos_check_compatible(stack, topic_qos('ego/odom', strict))
    assert verdict == QoSCompatibility.ERROR and 'deadline' in reason
    ours = topic_qos('ego/odom', strict, publisher=True)
    assert qos_check_compatible(ours, topic_qos('ego/odom', strict))[0] != \
        QoSCompatibility.ERROR


def start_planner(tmp_path: Path, params: Path, domain: int) -> tuple[
        subprocess.Popen[bytes], BinaryIO]:
    """The planner node alone on ``domain`` (the shipped params, then ``params``), its
    output in ``tmp_path/planner.log``; the process and the open log."""
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain), PYTHONUNBUFFERED='1',
               ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST', RMW_IMPLEMENTATION='rmw_fastrtps_cpp')
    log = (tmp_path / 'planner.log').open('wb')
    planner = subprocess.Popen(node_command('trust_av_planner.planner_node', 'planner',
                                            [DEFAULT_PARAMS_FILE, params], {}),
                               stdout=log, stderr=subprocess.STDOUT, env=env,
                               start_new_session=True)
    return planner, log


def test_planner_plans_from_publishers_with_autoware_qos(tmp_path: Path) -> None:
    """The planner in wall mode with the installed defaults, its inputs published at 30 Hz
    with Autoware's kinematic-state QoS (reliable, volatile, keep last 1, no deadline): it
    plans (solver status), not the stale-input deceleration, and commands in the AV's body
    frame as its odometry names it (``base_link``); a lead odometry in ``map`` while the AV's
    is in ``odom`` is not used (the reason names the frames); when the inputs stop they are
    stale (receive times)."""
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from geometry_msgs.msg import AccelStamped
    from nav_msgs.msg import Odometry
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import QoSProfile

    from trust_av.graph.domains import lease_domain
    from trust_av.graph.lifecycle_client import set_states
    from trust_av_common.ros.messages import diagnostic_values, odometry
    from trust_av_common.ros.qos import topic_qos

    params = tmp_path / 'run.yaml'
    params.write_text("planner:\n  ros__parameters:\n    clock_mode: wall\n"
                      "    human_odom_topic: ''\n    lead_preview: constant_speed\n"
                      '    speed_max_from_trace: false\n')
    autoware = QoSProfile(depth=1)     # rclcpp QoS(1): reliable, volatile, no deadline
    with lease_domain() as domain:
        planner, log = start_planner(tmp_path, params, domain)
        context = Context()
        rclpy.init(context=context, domain_id=domain)
        node = rclpy.create_node('autoware_like', context=context)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        statuses: list[dict[str, str]] = []
        node.create_subscription(DiagnosticArray, '/ego/planner_status',
                                 lambda m: statuses.append(diagnostic_values(m)),
                                 topic_qos('ego/planner_status',
                                           WallClockConfig(clock_mode='wall')))
        frames: list[str] = []
        node.create_subscription(AccelStamped, '/ego/accel_cmd',
                                 lambda m: frames.append(m.header.frame_id),
                                 topic_qos('ego/accel_cmd', WallClockConfig(clock_mode='wall')))
        lead = node.create_publisher(Odometry, '/preceding_vehicle/odom', autoware)
        ego = node.create_publisher(Odometry, '/ego/odom', autoware)

        def spin(seconds: float, publish: bool, lead_frame: str = 'odom') -> None:
            end = time.monotonic() + seconds
            while time.monotonic() < end:
                if publish:
                    ns = time.time_ns()
                    lead_msg = odometry(ns, 30.0, 10.0, 'lead')
                    lead_msg.header.frame_id = lead_frame
                    lead.publish(lead_msg)
                    ego.publish(odometry(ns, 0.0, 10.0, 'base_link'))
                executor.spin_once(timeout_sec=1 / 30)

        try:
            # a managed node in wall mode waits inactive until it is activated
            set_states(node, executor, ['planner'], 'active', 60.0)
            deadline = time.monotonic() + 60.0
            while not statuses and time.monotonic() < deadline:
                spin(0.2, publish=False)
            assert statuses, 'the planner never published a status'
            statuses.clear()
            spin(3.0, publish=True)
            planned = [v['status'] for v in statuses]
            assert planned and planned[-1] == 'Solve_Succeeded', planned[-5:]
            assert frames and frames[-1] == 'base_link'
            statuses.clear()
            spin(1.0, publish=True, lead_frame='map')
            assert statuses[-1]['status'] == 'stale_inputs'
            assert statuses[-1]['reason'] == ("positions in different frames: traffic in "
                                              "'map', ego in 'odom'"), statuses[-1]
            statuses.clear()
            spin(1.5, publish=False)
            assert statuses and statuses[-1]['status'] == 'stale_inputs'
            assert 'stale' in statuses[-1]['reason']
        finally:
            executor.shutdown()
            node.destroy_node()
            rclpy.try_shutdown(context=context)
            stop(planner)
            log.close()
    assert 'incompatible QoS' not in (tmp_path / 'planner.log').read_text()


@pytest.mark.parametrize('predictor', ['ca', 'gru'])
def test_planner_stale_inputs_decelerate_and_recover_and_alpha_is_tunable(
        tmp_path: Path, predictor: str) -> None:
    """The planner alone in wall mode: without inputs it commands the stale deceleration with
    status ERROR naming them; fresh inputs give normal plans; when they stop, the QoS deadline
    event names the input; alpha changes at run time (logged), a safety bound does not (its
    descriptor says why). With the CA predictor the human odometry is optional (here: no
    topic); the GRU needs it, so it is one of the inputs that must be fresh."""
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from geometry_msgs.msg import AccelStamped
    from nav_msgs.msg import Odometry
    from rcl_interfaces.srv import DescribeParameters, SetParameters
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter

    from trust_av.graph.domains import lease_domain
    from trust_av.graph.lifecycle_client import set_states
    from trust_av_common.ros.messages import diagnostic_values, odometry
    from trust_av_common.ros.qos import topic_qos

    params = tmp_path / 'run.yaml'
    human_topic = "    human_odom_topic: ''\n" if predictor == 'ca' else ''
    params.write_text('planner:\n  ros__parameters:\n    clock_mode: wall\n'
                      '    input_deadline_qos: true\n'
                      f'{human_topic}    predictor: {predictor}\n'
                      '    lead_preview: constant_speed\n'
                      '    speed_max_from_trace: false\n')
    inputs = 'traffic, ego' if predictor == 'ca' else 'traffic, ego, human'
    clock = WallClockConfig(clock_mode='wall', input_deadline_qos=True)
    with lease_domain() as domain:
        planner, log = start_planner(tmp_path, params, domain)
        context = Context()
        rclpy.init(context=context, domain_id=domain)
        node = rclpy.create_node('tester', context=context)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        statuses: list[tuple[int, dict[str, str]]] = []
        commands: list[float] = []
        node.create_subscription(DiagnosticArray, '/ego/planner_status',
                                 lambda m: statuses.append((int.from_bytes(m.status[0].level,
                                                                           'little'),
                                                            diagnostic_values(m))),
                                 topic_qos('ego/planner_status', clock))
        node.create_subscription(AccelStamped, '/ego/accel_cmd',
                                 lambda m: commands.append(m.accel.linear.x),
                                 topic_qos('ego/accel_cmd', clock))
        lead = node.create_publisher(Odometry, '/preceding_vehicle/odom',
                                     topic_qos('preceding_vehicle/odom', clock, True))
        ego = node.create_publisher(Odometry, '/ego/odom', topic_qos('ego/odom', clock, True))
        human = node.create_publisher(Odometry, '/human/odom',
                                      topic_qos('human/odom', clock, True))

        def spin(seconds: float, publish: bool = False) -> None:
            end = time.monotonic() + seconds
            while time.monotonic() < end:
                if publish:
                    ns = time.time_ns()
                    lead.publish(odometry(ns, 30.0, 10.0, 'lead'))
                    ego.publish(odometry(ns, 0.0, 10.0, 'ego'))
                    human.publish(odometry(ns, -30.0, 10.0, 'human'))
                executor.spin_once(timeout_sec=0.05)

        def call(client: Any, request: Any) -> Any:
            assert client.wait_for_service(timeout_sec=20.0)
            future = client.call_async(request)
            executor.spin_until_future_complete(future, timeout_sec=20.0)
            return future.result()

        try:
            # a managed node in wall mode waits inactive until it is activated
            set_states(node, executor, ['planner'], 'active', 60.0)
            deadline = time.monotonic() + 30.0
            while not statuses and time.monotonic() < deadline:
                spin(0.2)
            spin(1.0)
            level, values = statuses[-1]
            assert (level, values['status']) == (2, 'stale_inputs')
            assert values['reason'] == f'missing: {inputs}'
            assert commands and commands[-1] == -2.0
            statuses.clear()
            spin(3.0, publish=True)
            assert statuses[-1][1]['status'] == 'Solve_Succeeded' and statuses[-1][0] == 0
            assert commands[-1] > -2.0
            statuses.clear()
            spin(1.5)
            stale = [v for lvl, v in statuses if lvl == 2]
            assert stale and any(f'deadline missed (QoS event): {inputs}' in v['reason']
                                 for v in stale)
            setter = node.create_client(SetParameters, '/planner/set_parameters')
            result = call(setter, SetParameters.Request(parameters=[
                Parameter('alpha', value=0.9).to_parameter_msg()]))
            assert result.results[0].successful
            result = call(setter, SetParameters.Request(parameters=[
                Parameter('gap_min_m', value=2.0).to_parameter_msg()]))
            assert not result.results[0].successful
            describe = node.create_client(DescribeParameters, '/planner/describe_parameters')
            described = call(describe, DescribeParameters.Request(names=['gap_min_m', 'alpha']))
            gap, alpha = described.descriptors
            assert gap.read_only and 'read-only: a safety bound' in gap.description
            assert not alpha.read_only
        finally:
            executor.shutdown()
            node.destroy_node()
            rclpy.try_shutdown(context=context)
            stop(planner)
            log.close()
    text = (tmp_path / 'planner.log').read_text()
    assert 'parameter alpha: 0.5 -> 0.9 (from the next tick)' in text
    assert 'inputs fresh again: planning resumed' in text


_VEHICLE_RUNS: list[dict[str, Any]] = []
LOOP_S = 40.0     # the vehicle-in-the-loop run's wall time, s
OUTAGE_S = 15.0   # when the lead falls silent for 1 s


@pytest.fixture(scope='module')
def vehicle_run(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """40 s at 10 Hz against the stand-in vehicle (commute_am; measurements 50 ms late,
    5 % dropped, the lead silent for 1 s at 15 s), connected by remapping only. Run once per
    test process: an xdist worker handed one test at a time tears module fixtures down
    between the two tests that read it."""
    if not _VEHICLE_RUNS:
        out = tmp_path_factory.mktemp('vehicle_loop')
        data = run_vehicle_loop(out, duration_s=LOOP_S, rate_hz=10.0, outage_start_s=OUTAGE_S,
                                outage_s=1.0, drop_fraction=0.05, seed=1)
        (out / 'report.json').write_text(json.dumps(data))
        _VEHICLE_RUNS.append(data)
    return _VEHICLE_RUNS[0]


@pytest.mark.wall_clock
def test_vehicle_in_the_loop_gap_and_commands(vehicle_run: dict[str, Any]) -> None:
    config = load_run_config()
    ticks = vehicle_run['ticks']
    # it ran to its end; a timer tick late under load is skipped, not doubled, so the count
    # is a host figure: at least half the 10 Hz ticks is the behaviour (399 of 400 beside the
    # whole suite on a 2-core host)
    assert ticks[-1]['t_s'] >= LOOP_S - 1.0 and len(ticks) >= 0.5 * LOOP_S * 10
    margin = config.planner.standstill_gap_m - config.shared.safety_gap_margin_m
    assert min(t['gap_m'] for t in ticks) >= margin
    deadline = vehicle_run['command_deadline_s']
    assert deadline == pytest.approx(0.2)
    ages = [t['command_age_s'] for t in ticks if t['command_age_s'] is not None]
    # the loop closes: commands reach the vehicle and are applied; how many ticks had a fresh
    # one is a timing figure of the host (bench_shadow.py --vehicle prints it: 92-100 % beside
    # the whole suite on a 2-core host), so this asserts the behaviour, not the share
    assert len(ages) >= 0.5 * len(ticks)
    assert max(ages) <= deadline             # none applied older than its deadline
    assert all(t['applied_mps2'] == 0.0 for t in ticks if t['command_age_s'] is None)
    sent = vehicle_run['sent']
    dropped = sum(not s['sent'] for s in sent if not OUTAGE_S <= s['t_s'] < OUTAGE_S + 1.0)
    assert 0.02 < dropped / len(sent) < 0.09
    assert max(t['ego_speed_mps'] for t in ticks) > 5.0  # it drove


@pytest.mark.wall_clock
def test_vehicle_in_the_loop_outage_decelerates_then_recovers(
        vehicle_run: dict[str, Any]) -> None:
    statuses = vehicle_run['status']
    stale = [s for s in statuses if s['level'] == 2]
    assert stale, 'the lead outage produced no ERROR status'
    assert all(s['status'] == 'stale_inputs' and 'traffic' in s['reason']
               and s['command_mps2'] == -2.0 for s in stale)
    # the default inputs request no QoS deadline (they match any vehicle's publisher): the
    # outage is found from the receive times (the deadline events: the test above)
    assert any('stale: traffic' in s['reason'] for s in stale)
    assert not any('QoS event' in s['reason'] for s in stale)
    # Before the first inputs arrive the planner already ticks: 'missing' inputs, the same
    # deceleration (start-up, not the outage); after its first plan only the outage is stale.
    first_plan = min(s['t_s'] for s in statuses if s['level'] == 0)
    assert all(s['reason'].startswith('missing') for s in stale if s['t_s'] < first_plan)
    outage = [s for s in stale if s['t_s'] > first_plan]
    assert outage and all(OUTAGE_S + 0.3 <= s['t_s'] <= OUTAGE_S + 1.8 for s in outage), [
        (s['t_s'], s['reason']) for s in stale]             # the 1 s outage + 0.5 s stale
    assert min(s['t_s'] for s in outage) <= OUTAGE_S + 0.8
    applied = [t for t in vehicle_run['ticks'] if OUTAGE_S + 0.8 <= t['t_s'] <= OUTAGE_S + 1.2]
    assert any(t['applied_mps2'] == -2.0 for t in applied)
    after = [s for s in statuses if s['t_s'] > OUTAGE_S + 2.0]
    assert after and all(s['level'] != 2 for s in after)  # normal planning resumed
    trust = vehicle_run['trust']
    late = [t for t in trust if t['t_s'] > OUTAGE_S + 2.0]
    assert len(late) >= 0.8 * (LOOP_S - OUTAGE_S - 2.0) * 10          # trust goes on ...
    assert late[-1]['trust'] > late[0]['trust'] > 0.0                # ... and grows


def test_reproduce_with_lead_preview_adds_a_params_layer(tmp_path: Path) -> None:
    from trust_av.cli.reproduce import lead_preview_layer

    path = lead_preview_layer('constant_speed', tmp_path)
    derived, shipped = load_run_config([DEFAULT_PARAMS_FILE, path]), load_run_config()
    assert derived.planner.lead_preview == 'constant_speed'
    assert shipped.planner.lead_preview == 'recorded'
    assert derived.planner == dataclasses.replace(shipped.planner, lead_preview='constant_speed')
    assert derived.trust == shipped.trust and derived.driver == shipped.driver


@pytest.mark.parametrize(('option', 'value', 'message'), [
    ('--control-rate-hz', '0', 'must be a finite rate > 0 Hz'),
    ('--lead-preview', 'v2v', "invalid choice: 'v2v'")])
def test_simulate_rejects_bad_rate_and_preview(option: str, value: str, message: str) -> None:
    proc = subprocess.run([sys.executable, '-m', 'trust_av.cli', 'simulate', option,
                           value], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2 and message in proc.stderr
