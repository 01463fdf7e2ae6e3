"""The planner and the trust monitor are managed (lifecycle) nodes, driven as
``ros2 lifecycle set`` drives them: ``lifecycle_msgs/srv/ChangeState`` on
``/<node>/change_state``, ``GetState`` on ``/<node>/get_state``.

The rules checked are rclpy's and rcl_lifecycle's, from their sources:

- ``rclpy/lifecycle/node.py`` (rclpy 7.1, ``LifecycleNodeMixin.__on_change_state``): the
  answer's ``success`` is True only when the transition callback returned SUCCESS; an
  exception raised by a callback is turned into ERROR there (``__execute_callback``), so our
  callbacks catch and report it themselves.
- ``rcl_lifecycle/src/default_state_machine.c``: configure goes unconfigured -> inactive,
  activate inactive -> active, deactivate active -> inactive; a configure that FAILs returns
  to unconfigured. A transition not valid from the current state fails in
  ``rcl_lifecycle/src/rcl_lifecycle.c`` ("Transition is not registered"), which rclpy 7.1
  raises out of the service callback (ending the process); our nodes answer ``success``
  False and stay in their state (``trust_av_common/ros/lifecycle.py``).
- ``lifecycle_msgs/msg/State``: ids 1 unconfigured, 2 inactive, 3 active;
  ``lifecycle_msgs/msg/Transition``: configure 1, activate 3, deactivate 4.
- ``rclpy/lifecycle/publisher.py``: a ``LifecyclePublisher`` publishes nothing unless
  activated.
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
import signal
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
from support.lifecycle import (
    ACTIVATE,
    ACTIVE,
    CONFIGURE,
    DEACTIVATE,
    INACTIVE,
    STEP_NS,
    UNCONFIGURED,
    Manager,
    start,
    stop,
)

from trust_av.graph.domains import lease_domain


def lockstep_qos(topic: str) -> Any:
    from trust_av_common.ros.qos import topic_qos
    from trust_av_common.wall_clock import WallClockConfig

    return topic_qos(topic, WallClockConfig())


@contextlib.contextmanager
def planner_inputs(manager: Manager) -> Iterator[Callable[[int], None]]:
    """A function publishing one lock-step step's inputs (and the trust of the step before)
    to the planner, stamped ``ns``."""
    from geometry_msgs.msg import Vector3Stamped
    from nav_msgs.msg import Odometry
    from trajectory_msgs.msg import JointTrajectory

    from trust_av_common.ros.messages import header, odometry, trajectory

    node = manager.node
    pubs = {name: node.create_publisher(msgtype, name, lockstep_qos(name))
            for name, msgtype in (('preceding_vehicle/odom', Odometry),
                                  ('preceding_vehicle/speed_preview', JointTrajectory),
                                  ('ego/odom', Odometry), ('human/odom', Odometry),
                                  ('trust_monitor/trust', Vector3Stamped))}
    assert manager.spin_until(lambda: all(p.get_subscription_count() for p in pubs.values()))

    def publish(ns: int) -> None:
        t_s = ns / 1e9
        pubs['preceding_vehicle/odom'].publish(
            odometry(ns, 60.0 + 15.0 * t_s, 15.0, 'preceding_vehicle'))
        pubs['preceding_vehicle/speed_preview'].publish(
            trajectory(ns, 0.1, frame_id='preceding_vehicle', velocities=[15.0] * 30))
        pubs['ego/odom'].publish(odometry(ns, 30.0 + 15.0 * t_s, 15.0, 'ego'))
        pubs['human/odom'].publish(odometry(ns, 15.0 * t_s, 15.0, 'human'))
        if ns > STEP_NS:   # the monitor's trust after the previous step
            pubs['trust_monitor/trust'].publish(Vector3Stamped(header=header(ns - STEP_NS, '')))

    yield publish


def test_hand_started_planner_is_driven_through_its_lifecycle(tmp_path: Path) -> None:
    """Started by hand with ``autostart: false``: unconfigured; a transition not valid there
    (activate) is refused and changes nothing; configure -> inactive: a complete step's
    inputs are kept but not planned, nothing is published; activate -> active: that step is
    planned, then one command per step; deactivate -> one hand-over command of
    ``stale_decel_mps2``, then none although the next step is complete; activate again ->
    that step's command (what held it was the state: the lock-step chain paused)."""
    from geometry_msgs.msg import AccelStamped

    from trust_av.system.config import load_run_config
    from trust_av_common.ros.messages import msg_ns

    with lease_domain() as domain:
        proc = start(tmp_path, domain, 'trust_av_planner.planner_node', '-p', 'autostart:=false')
        manager = Manager(domain, 'planner')
        try:
            manager.record(AccelStamped, 'ego/accel_cmd', lockstep_qos('ego/accel_cmd'))
            commands = manager.received['ego/accel_cmd']
            assert manager.state() == UNCONFIGURED
            assert not manager.transition(ACTIVATE)          # not valid from unconfigured
            assert manager.state() == UNCONFIGURED
            assert manager.transition(CONFIGURE)
            assert manager.state() == INACTIVE
            with planner_inputs(manager) as publish:
                publish(1 * STEP_NS)                          # complete, but inactive
                manager.spin_for(2.0)
                assert commands == []
                assert manager.transition(ACTIVATE)
                assert manager.state() == ACTIVE
                assert manager.spin_until(lambda: len(commands) >= 1)
                publish(2 * STEP_NS)
                publish(3 * STEP_NS)
                assert manager.spin_until(lambda: len(commands) >= 3)
                assert [msg_ns(c.header.stamp) for c in commands] == [
                    1 * STEP_NS, 2 * STEP_NS, 3 * STEP_NS]
                assert manager.transition(DEACTIVATE)
                assert manager.state() == INACTIVE
                assert manager.spin_until(lambda: len(commands) >= 4)
                assert commands[3].accel.linear.x == load_run_config().planner.stale_decel_mps2
                publish(4 * STEP_NS)                          # complete, trust of step 3 in
                manager.spin_for(2.0)
                assert len(commands) == 4
                assert manager.transition(ACTIVATE)
                assert manager.spin_until(lambda: len(commands) >= 5)
                assert msg_ns(commands[4].header.stamp) == 4 * STEP_NS
        finally:
            manager.close()
            out = stop(proc)
    assert 'unconfigured: waiting for configure (autostart false)' in out
    assert 'deactivate: handed over with' in out


def test_a_bad_parameter_fails_configure_with_one_line_and_the_node_lives(
        tmp_path: Path) -> None:
    """``autostart: false`` and an out-of-range value: configure fails (rclpy answers
    success False, the state returns to unconfigured), the log holds one line naming the
    parameter and no traceback, the process keeps serving; with ``autostart: true`` the same
    value ends the process with one ``error:`` line and exit 2, as before."""
    with lease_domain() as domain:
        proc = start(tmp_path, domain, 'trust_av_planner.planner_node', '-p', 'autostart:=false',
                     '-p', 'alpha:=1.5')
        manager = Manager(domain, 'planner')
        try:
            assert not manager.transition(CONFIGURE)
            assert manager.state() == UNCONFIGURED
            assert not manager.transition(CONFIGURE)          # the same answer again
            assert proc.poll() is None
        finally:
            manager.close()
            out = stop(proc)
    failures = [line for line in out.splitlines() if 'configure failed' in line]
    assert len(failures) == 2, out
    assert 'alpha' in failures[0] and '1.5' in failures[0], failures[0]
    with lease_domain() as domain:
        auto = start(tmp_path, domain, 'trust_av_planner.planner_node', '-p', 'alpha:=1.5')
        out, _ = auto.communicate(timeout=120)
    assert auto.returncode == 2, out
    errors = [line for line in out.splitlines() if line.startswith('error:')]
    assert len(errors) == 1 and 'alpha' in errors[0], out
    assert 'Traceback' not in out


def test_wall_mode_planner_waits_inactive_then_hands_over(tmp_path: Path) -> None:
    """``clock_mode: wall``, shipped ``autostart: true``: the planner configures itself
    (and warms its solver) but publishes nothing until activated, although it ticks on the
    wall clock and its inputs are missing (before, it braked from start-up); active: the
    stale-input command every tick; deactivate: the hand-over command, then silence; a
    SIGINT while active hands over too."""
    from geometry_msgs.msg import AccelStamped

    from trust_av_common.ros.qos import topic_qos
    from trust_av_common.wall_clock import WallClockConfig

    with lease_domain() as domain:
        proc = start(tmp_path, domain, 'trust_av_planner.planner_node', '-p', 'clock_mode:=wall',
                     '-p', "human_odom_topic:=''", '-p', 'predictor:=ca')
        manager = Manager(domain, 'planner')
        try:
            qos = topic_qos('ego/accel_cmd', WallClockConfig(clock_mode='wall'))
            manager.record(AccelStamped, 'ego/accel_cmd', qos)
            commands = manager.received['ego/accel_cmd']
            assert manager.state() == INACTIVE
            assert manager.spin_until(lambda: manager.change.service_is_ready())
            manager.spin_for(1.5)                              # 15 periods of 0.1 s
            assert commands == []
            assert manager.transition(ACTIVATE)
            assert manager.spin_until(lambda: len(commands) >= 3)
            assert manager.transition(DEACTIVATE)
            manager.spin_for(0.5)                              # the last ones in flight
            seen = len(commands)
            manager.spin_for(1.5)
            assert len(commands) == seen
            assert manager.transition(ACTIVATE)   # then stopped by SIGINT while active
        finally:
            manager.close()
            out = stop(proc)
    assert 'solver warmed: 3 solves' in out
    assert 'inactive: waiting for activate (clock_mode wall)' in out
    # a stop request deactivates an active wall-mode planner first: it hands over again
    assert out.count('deactivate: handed over with') == 2, out


def test_monitor_publishes_trust_only_while_active(tmp_path: Path) -> None:
    """The trust monitor, ``autostart: false``: a plan pair scored only while active."""
    from geometry_msgs.msg import Vector3Stamped
    from trajectory_msgs.msg import JointTrajectory

    from trust_av_common.ros.messages import trajectory

    with lease_domain() as domain:
        proc = start(tmp_path, domain, 'trust_monitor.monitor_node', '-p', 'autostart:=false')
        manager = Manager(domain, 'trust_monitor')
        try:
            manager.record(Vector3Stamped, 'trust_monitor/trust',
                           lockstep_qos('trust_monitor/trust'))
            trust = manager.received['trust_monitor/trust']
            assert manager.transition(CONFIGURE)
            pubs = [manager.node.create_publisher(JointTrajectory, name, lockstep_qos(name))
                    for name in ('ego/plan', 'ego/expected_plan')]
            assert manager.spin_until(lambda: all(p.get_subscription_count() for p in pubs))

            def plans(ns: int) -> None:
                for pub in pubs:
                    pub.publish(trajectory(ns, 0.1, frame_id='ego', accelerations=[0.0] * 30))

            plans(STEP_NS)
            manager.spin_for(1.5)
            assert trust == []
            assert manager.transition(ACTIVATE)
            plans(2 * STEP_NS)
            assert manager.spin_until(lambda: len(trust) >= 1)
            assert len(trust) == 1
        finally:
            manager.close()
            stop(proc)


@pytest.mark.parametrize('module', ['trust_av_planner.planner_node',
                                    'trust_monitor.monitor_node'])
def test_a_cleaned_up_node_configures_again(tmp_path: Path, module: str) -> None:
    """configure -> cleanup -> configure: the parameters stay declared (read-only), the
    core and the outputs are made again; shutdown from inactive finalizes the node."""
    from lifecycle_msgs.msg import Transition

    name = 'planner' if 'planner' in module else 'trust_monitor'
    with lease_domain() as domain:
        proc = start(tmp_path, domain, module, '-p', 'autostart:=false')
        manager = Manager(domain, name)
        try:
            assert manager.transition(CONFIGURE)
            assert manager.transition(Transition.TRANSITION_CLEANUP)
            assert manager.state() == UNCONFIGURED
            assert manager.transition(CONFIGURE)
            assert manager.state() == INACTIVE
            assert manager.transition(Transition.TRANSITION_INACTIVE_SHUTDOWN)
            assert manager.state() == 4   # lifecycle_msgs/msg/State PRIMARY_STATE_FINALIZED
        finally:
            manager.close()
            out = stop(proc)
    assert 'configure failed' not in out


SIX = {'preceding_traffic.traffic_node': 'waiting for /sim/start',
       'trust_av_planner.planner_node': 'active',
       'trust_monitor.monitor_node': 'active',
       'trust_av_planner.ego_plant_node': ('parameters initial_position_m, initial_speed_mps, '
                                           'start_time_s are missing (PlantConfig): no params '
                                           'file sets them, each run supplies them (trust-av '
                                           'does; by hand: pass --ros-args -p '
                                           'initial_position_m:=VALUE -p initial_speed_mps:=VALUE'
                                           ' -p start_time_s:=VALUE)'),
       'human_driver_sim.driver_node': ('parameters initial_position_m, initial_speed_mps, '
                                        'start_time_s are missing (FollowerState): no params '
                                        'file sets them, each run supplies them (trust-av does; '
                                        'by hand: pass --ros-args -p initial_position_m:=VALUE '
                                        '-p initial_speed_mps:=VALUE -p start_time_s:=VALUE)'),
       'trust_av.graph.recorder_node': ('parameter bag_path is missing (RecorderConfig): '
                                                'no params file sets it, each run supplies it '
                                                '(trust-av does; by hand: pass --ros-args -p '
                                                'bag_path:=VALUE)')}
"""The graph's six executables started from the shipped params file alone: the line that
says it is up, or the one error line naming what a run must supply."""


def test_the_six_executables_from_the_shipped_params_file_alone(tmp_path: Path) -> None:
    """Three come up (the managed ones active, lock-step autostart); the three with per-run
    values end with one ``error:`` line naming each value and who supplies it, exit 2."""
    from trust_av.system.config import DEFAULT_PARAMS_FILE

    with lease_domain() as domain:
        procs = {module: start(tmp_path, domain, module, '--params-file',
                               str(DEFAULT_PARAMS_FILE)) for module in SIX}
        outputs: dict[str, str] = {}
        try:
            for module, proc in procs.items():
                assert proc.stdout is not None
                if SIX[module].startswith('parameter'):
                    outputs[module] = proc.communicate(timeout=120)[0]
                    assert proc.returncode == 2, outputs[module]
                    continue
                seen = []
                for line in proc.stdout:   # until it is up (or it ends: the asserts fail)
                    seen.append(line)
                    if line.rstrip().endswith(SIX[module]):
                        break
                outputs[module] = ''.join(seen) + stop(proc)
        finally:                           # none is left on the domain for the next lease
            for proc in procs.values():
                if proc.poll() is None:
                    os.killpg(proc.pid, signal.SIGKILL)
                    proc.wait()
    for module, expected in SIX.items():
        assert 'Traceback' not in outputs[module], outputs[module]
        if expected.startswith('parameter'):
            errors = [line for line in outputs[module].splitlines() if line.startswith('error:')]
            assert errors == [f'error: {expected}'], outputs[module]
        else:
            assert any(line.rstrip().endswith(expected)
                       for line in outputs[module].splitlines()), outputs[module]


class _Future:
    def __init__(self, result: Any = None, done: bool = True) -> None:
        self._result, self._done = result, done

    def done(self) -> bool:
        return self._done

    def result(self) -> Any:
        return self._result


class _LossyNode:
    """A managed node's lifecycle services as a client sees them, losing what ``lose`` says:
    ('answer', transition) applies the transition and loses its answer once; ('request',
    transition) loses the request once."""

    def __init__(self, lose: list[tuple[str, int]]) -> None:
        self.state, self.lose, self.applied = 1, list(lose), []
        self.pending: list[_Future] = []     # unanswered requests not yet withdrawn

    def create_client(self, srv: Any, name: str) -> Any:
        from lifecycle_msgs.srv import ChangeState, GetState
        lossy = self

        class Client:
            def service_is_ready(self) -> bool:
                return True

            def call_async(self, request: Any) -> _Future:
                if srv is GetState:
                    answer = GetState.Response()
                    answer.current_state.id = lossy.state
                    return _Future(answer)
                transition = request.transition.id
                if ('request', transition) in lossy.lose:
                    lossy.lose.remove(('request', transition))
                    return lossy.unanswered()
                lossy.state = {1: 2, 3: 3, 4: 2}[transition]
                lossy.applied.append(transition)
                if ('answer', transition) in lossy.lose:
                    lossy.lose.remove(('answer', transition))
                    return lossy.unanswered()
                return _Future(ChangeState.Response(success=True))

            def remove_pending_request(self, future: _Future) -> None:
                lossy.pending.remove(future)

        assert srv in (GetState, ChangeState) and name.startswith('/planner/')
        return Client()

    def unanswered(self) -> _Future:
        future = _Future(done=False)
        self.pending.append(future)
        return future

    def destroy_client(self, client: Any) -> None:
        pass


class _Idle:
    def spin_once(self, timeout_sec: float) -> None:
        time.sleep(min(timeout_sec, 0.001))


@pytest.mark.parametrize('lose', [[], [('answer', 1)], [('request', 1)],
                                  [('answer', 3), ('request', 3)]],
                         ids=['nothing', 'configure_answer', 'configure_request',
                              'activate_answer_and_request'])
def test_a_lost_answer_or_request_is_asked_again_and_nothing_is_sent_twice(
        lose: list[tuple[str, int]], monkeypatch: pytest.MonkeyPatch) -> None:
    """A service answer lost on its way back (a client made just before the server had
    matched it: ``no answer after 30 s`` in a loaded suite run) or a lost request: the state
    is asked again and the next transition chosen from it, so each is applied once."""
    from trust_av.graph import lifecycle_client
    monkeypatch.setattr(lifecycle_client, 'ANSWER_S', 0.05)
    node = _LossyNode(lose)
    lifecycle_client.set_states(node, _Idle(), ['planner'], 'active', 5.0)
    assert node.state == 3 and node.applied == [1, 3]
    assert node.pending == []          # every unanswered request withdrawn from its client


CLEANUP, SHUTDOWN_UNCONFIGURED, SHUTDOWN_INACTIVE, SHUTDOWN_ACTIVE = 2, 5, 6, 7
FINALIZED = 4   # lifecycle_msgs/msg/State PRIMARY_STATE_FINALIZED
NAV2 = {'startup': (CONFIGURE, ACTIVATE), 'pause': (DEACTIVATE,), 'resume': (ACTIVATE,),
        'reset': (DEACTIVATE, CLEANUP),
        'shutdown': (DEACTIVATE, CLEANUP, SHUTDOWN_UNCONFIGURED)}
"""The transition sequences of nav2's lifecycle manager (nav2_lifecycle_manager
``lifecycle_manager.cpp``: startup, pause, resume, reset, shutdown), as transition ids
(``lifecycle_msgs/msg/Transition``)."""
SEQUENCES = {
    'nav2': ('startup', 'pause', 'resume', 'reset', 'startup', 'shutdown'),
    'from_active': ('startup', SHUTDOWN_ACTIVE),
    'from_inactive': (CONFIGURE, SHUTDOWN_INACTIVE),
    'from_unconfigured': (SHUTDOWN_UNCONFIGURED,),
}
"""Every nav2 sequence in one node's life, then shutdown from each primary state."""
INPUT_PERIOD_S = 0.01   # inputs at 100 Hz throughout


def wall_inputs(manager: Manager, node: str) -> Callable[[], None]:
    """Start publishing the wall-mode inputs of ``node`` at 100 Hz from the manager's
    executor, stamped now (steady car following 30 m behind a lead at 15 m/s, in ``odom``;
    for the monitor a zero plan pair); returns what stops them."""
    from nav_msgs.msg import Odometry
    from trajectory_msgs.msg import JointTrajectory

    from trust_av_common.ros.messages import odometry, trajectory
    from trust_av_common.ros.qos import topic_qos
    from trust_av_common.wall_clock import WallClockConfig

    wall = WallClockConfig(clock_mode='wall')
    if node == 'planner':
        topics = {'preceding_vehicle/odom': Odometry, 'ego/odom': Odometry}
    else:
        topics = {'ego/plan': JointTrajectory, 'ego/expected_plan': JointTrajectory}
    pubs = {t: manager.node.create_publisher(m, t, topic_qos(t, wall)) for t, m in topics.items()}

    def publish() -> None:
        ns = time.time_ns()
        t_s = time.monotonic()
        if node == 'planner':
            pubs['preceding_vehicle/odom'].publish(
                odometry(ns, 60.0 + 15.0 * t_s, 15.0, 'preceding_vehicle'))
            pubs['ego/odom'].publish(odometry(ns, 30.0 + 15.0 * t_s, 15.0, 'ego'))
        else:
            for pub in pubs.values():
                pub.publish(trajectory(ns, 0.1, frame_id='ego', accelerations=[0.0] * 30))

    timer = manager.node.create_timer(INPUT_PERIOD_S, publish)
    return timer.cancel


@pytest.mark.parametrize('sequence', sorted(SEQUENCES))
@pytest.mark.parametrize('module', ['trust_av_planner.planner_node',
                                    'trust_monitor.monitor_node'])
def test_lifecycle_manager_sequences_with_inputs_flowing(tmp_path: Path, module: str,
                                                         sequence: str) -> None:
    """A wall-mode node driven through nav2's lifecycle-manager sequences by real service
    calls while its inputs arrive at 100 Hz: every transition succeeds, the node ends
    ``finalized`` with no traceback; the planner sends exactly one hand-over command
    (``stale_decel_mps2``) per deactivation (also the one a shutdown from active makes) and
    none while inactive; the monitor publishes no trust while inactive. Before, a cleanup
    or shutdown with inputs flowing ended in ``AttributeError: ... no attribute 'latest'``
    (a message taken before the subscription was destroyed reached the released node)."""
    from geometry_msgs.msg import AccelStamped, Vector3Stamped

    from trust_av.system.config import load_run_config
    from trust_av_common.ros.messages import msg_ns
    from trust_av_common.ros.qos import topic_qos
    from trust_av_common.wall_clock import WallClockConfig

    name = 'planner' if 'planner' in module else 'trust_monitor'
    topic, msgtype = (('ego/accel_cmd', AccelStamped) if name == 'planner'
                      else ('trust_monitor/trust', Vector3Stamped))
    steps = [t for item in SEQUENCES[sequence]
             for t in (NAV2[item] if isinstance(item, str) else (item,))]
    args = ['-p', 'autostart:=false', '-p', 'clock_mode:=wall']
    if name == 'planner':
        args += ['-p', "human_odom_topic:=''", '-p', 'predictor:=ca', '-p',
                 'lead_preview:=constant_speed']   # plans from its inputs while active
    handover = load_run_config().planner.stale_decel_mps2
    with lease_domain() as domain:
        proc = start(tmp_path, domain, module, *args)
        manager = Manager(domain, name)
        try:
            manager.record(msgtype, topic, topic_qos(topic, WallClockConfig(clock_mode='wall')))
            out = manager.received[topic]
            stop_inputs = wall_inputs(manager, name)
            assert manager.state() == UNCONFIGURED
            # (deactivate asked, answered, next activate asked), ns
            inactive: list[tuple[int, int, int]] = []
            for transition in steps:
                asked = time.time_ns()
                if transition == ACTIVATE and inactive:
                    inactive[-1] = (*inactive[-1][:2], asked)
                assert manager.transition(transition), (sequence, transition)
                if transition in (DEACTIVATE, SHUTDOWN_ACTIVE):
                    inactive.append((asked, time.time_ns(), 2 ** 63))
                if transition == ACTIVATE:   # it works while active
                    seen = len(out)
                    assert manager.spin_until(lambda s=seen: len(out) >= s + 3)
                else:                        # inputs keep arriving in the new state
                    manager.spin_for(0.3)
            assert manager.state() == FINALIZED
            manager.spin_for(0.5)                     # what was in flight
            assert proc.poll() is None
            stop_inputs()
        finally:
            manager.close()
            log = stop(proc)
    assert 'AttributeError' not in log and 'Traceback' not in log, log
    deactivations = sum(t in (DEACTIVATE, SHUTDOWN_ACTIVE) for t in steps)
    assert log.count('deactivate: handed over with') == (deactivations if name == 'planner'
                                                         else 0), log
    for asked, answered, end in inactive:   # outputs until the node took the request
        after = [m for m in out if answered < msg_ns(m.header.stamp) < end]
        assert after == [], (answered, after)
        if name == 'planner':
            during = [m.accel.linear.x for m in out if asked <= msg_ns(m.header.stamp) < end]
            assert during.count(handover) == 1, (asked, during)


@pytest.mark.parametrize('module', ['trust_av_planner.planner_node',
                                    'trust_monitor.monitor_node'])
def test_parameters_are_declared_while_unconfigured(tmp_path: Path, module: str) -> None:
    """``ros2 param list``/``get`` (``rcl_interfaces`` services) on a node still
    ``unconfigured``: every parameter its configure reads is there with the value configure
    takes (the shipped file's, a ``-p`` override's); configure then keeps them."""
    from rcl_interfaces.srv import GetParameters, ListParameters

    from trust_av.system.config import load_run_config
    from trust_av_planner.nmpc import PlannerConfig
    from trust_monitor.paper_trust import TrustConfig

    name = 'planner' if 'planner' in module else 'trust_monitor'
    with lease_domain() as domain:
        proc = start(tmp_path, domain, module, '-p', 'autostart:=false', '-p',
                      'trust_initial:=5.0')
        manager = Manager(domain, name)
        try:
            listing = manager.node.create_client(ListParameters, f'/{name}/list_parameters')
            getting = manager.node.create_client(GetParameters, f'/{name}/get_parameters')
            before = set(manager.call(listing, ListParameters.Request()).result.names)
            assert manager.state() == UNCONFIGURED
            asked = ['trust_initial', 'clock_mode'] + (['alpha'] if name == 'planner' else [])
            values = manager.call(getting, GetParameters.Request(names=asked)).values
            assert manager.transition(CONFIGURE)
            after = set(manager.call(listing, ListParameters.Request()).result.names)
        finally:
            manager.close()
            stop(proc)
    fields = {f.name for f in dataclasses.fields(TrustConfig)}
    if name == 'planner':
        fields |= {f.name for f in dataclasses.fields(PlannerConfig)}
    assert fields <= before, fields - before
    assert after == before
    assert values[0].double_value == 5.0 and values[1].string_value == 'lockstep'
    if name == 'planner':
        assert values[2].double_value == load_run_config().planner.alpha
