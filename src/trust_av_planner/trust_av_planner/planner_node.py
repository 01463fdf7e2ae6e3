"""``planner`` node (``ros2 run trust_av_planner planner``): the trust-aware AV planner.

Subscribes the preceding vehicle's odometry and speed preview, the ego and human odometry and
the monitor's trust; per step (inputs paired by header stamp) it runs
:class:`trust_av_planner.planner.AvPlanner` (plan estimator + NMPC) and publishes the plan, the
expected plan (``JointTrajectory``), the acceleration command (``AccelStamped``), all three in
the AV's body frame (the ``child_frame_id`` of its odometry: ``ego`` in the simulated graph;
``base_frame_id``, default ``base_link``, before the first), the solver status
(``DiagnosticArray``) and the three vehicles' markers (``vehicle_markers``, each in its
vehicle's frame). Topic names are relative (the node's namespace). Parameters: the ``planner``
section of ``config/trust_av.yaml``.

``clock_mode: wall`` (real-vehicle mode, docs/operations/real-vehicle.md): a steady-clock timer
at ``control_rate_hz`` plans from the LATEST inputs (sensor-data QoS; with
``input_deadline_qos`` a QoS deadline of ``input_timeout_s``), the NMPC predicting on the
control period's grid; outputs are stamped with the current time. While the lead or ego
odometry (or a recorded preview) is missing, older than ``input_timeout_s``, past its deadline,
or in frames it cannot relate (positions along the road need one world-fixed frame,
``odom_frame_id`` or ``map_frame_id``), it commands ``stale_decel_mps2`` with status ERROR
naming why; it plans again as soon as they are usable. The human odometry is used when fresh
(an empty ``human_odom_topic`` needs an estimator without the ``follower_state`` need, such as
CA or CV). With ``use_sim_time`` true it does not command at all and its status and
``/diagnostics`` say why (:meth:`ManagedNode.clock_problem
<trust_av_common.ros.lifecycle.ManagedNode.clock_problem>`). Trust: the latest estimate,
``trust_initial`` before the first. ``alpha``, ``trust_min`` and ``solver_cpu_budget_s`` can be
changed with ``ros2 param set`` (from the next tick).

Input messages are checked where they enter (:mod:`trust_av_planner.ros.planner_inputs`: a
refused one is counted and its input stale; lock-step: the step waits); every command passes
the :class:`~trust_av_common.envelope.CommandEnvelope` last (docs/operations/real-vehicle.md).
"""

from __future__ import annotations

import functools
import sys
import time
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import AccelStamped, Vector3Stamped
from nav_msgs.msg import Odometry
from trajectory_msgs.msg import JointTrajectory
from visualization_msgs.msg import MarkerArray

from trust_av_common import registry
from trust_av_common.envelope import (
    CommandEnvelope,
    EnvelopeConfig,
    InputRanges,
)
from trust_av_common.frames import FrameConfig, body_frame
from trust_av_common.grids import interp_at
from trust_av_common.health import Report, SolveRecord, age
from trust_av_common.lifecycle import LifecycleConfig
from trust_av_common.lockstep import StepBuffer
from trust_av_common.ros.messages import (
    TrajectoryBytes,
    VehicleMarkers,
    accel_command_bytes,
    diagnostics,
    msg_ns,
    trajectory_times,
    trajectory_values,
)
from trust_av_common.ros.parameters import (
    declare_component_params,
    declare_config,
    predeclare,
    predeclare_component,
)
from trust_av_common.ros.qos import input_events, topic_qos
from trust_av_common.ros.raw_inputs import subscribe
from trust_av_common.ros.spin import WallLoop, now_ns, spin_node
from trust_av_common.ros.tuning import Tunable, enable_tuning
from trust_av_common.wall_clock import NS_PER_S, LatestInputs, WallClockConfig
from trust_av_planner.errors import TrustAvPlannerError
from trust_av_planner.nmpc import BOUND_TOLERANCE, PlannerConfig
from trust_av_planner.planner import AvPlanner
from trust_av_planner.planner_params import PlannerTopics, SharedConfig, check_control_rate
from trust_av_planner.predictors import PREDICTORS
from trust_av_planner.ros.planner_inputs import PlannerInputs, vehicle
from trust_monitor.model_interface import TRUST_MODELS, build_trust_model
from trust_monitor.paper_trust import TrustConfig

__all__ = ['WARM_UP', 'PlannerNode', 'main']

WARM_UP = True
"""Wall mode: ``configure`` warms the outputs and the NMPC (:meth:`PlannerNode.warm_up`);
False only for the cold case of benchmarks/bench_lifecycle.py."""
WARM_UP_SOLVES = 3  # solves of the NMPC at ``configure`` in wall mode
STEP_INPUTS = ('traffic', 'preview', 'ego', 'human')
TABLE_TOPIC = {'traffic': 'preceding_vehicle/odom', 'preview': 'preceding_vehicle/speed_preview',
               'ego': 'ego/odom', 'human': 'human/odom', 'trust': 'trust_monitor/trust'}
"""Input -> the topic-table row whose QoS it uses (its actual name may be remapped)."""


class PlannerNode(PlannerInputs):
    """Thin adapter over :class:`~trust_av_planner.planner.AvPlanner`, a managed node:
    ``configure`` builds and warms it, ``activate`` starts outputs, ``deactivate`` hands over."""

    user_errors = (ValueError, TrustAvPlannerError)
    task = 'trust_aware_nmpc'
    idle = 'inactive: not commanding (waiting for activate)'

    def __init__(self) -> None:
        super().__init__('planner')
        self.lifecycle = declare_config(self, LifecycleConfig)
        self.tuning = False
        # declared now, read and checked at configure: `ros2 param` sees them unconfigured
        for cls in (PlannerConfig, TrustConfig, SharedConfig, WallClockConfig, PlannerTopics,
                    FrameConfig, InputRanges, EnvelopeConfig,
                    *(c.config_type for c in registry.components(PREDICTORS)
                      if c.config_type is not None)):
            predeclare(self, cls)
        predeclare_component(self, TRUST_MODELS, 'trust_model')

    def build(self) -> None:
        """``configure``: parameters, core (warmed in wall mode), publishers, subscriptions.

        Raises:
            ParamsError: a refused parameter value.
            TrustAvPlannerError: a trust model wall mode cannot mirror.
            ValueError: an empty ``human_odom_topic`` where the follower is needed.
        """
        self.config = declare_config(self, PlannerConfig)
        trust = declare_config(self, TrustConfig)
        shared = declare_config(self, SharedConfig)
        self.clock = declare_config(self, WallClockConfig)
        topics = declare_config(self, PlannerTopics)
        self.frames = declare_config(self, FrameConfig)
        self.ranges = declare_config(self, InputRanges)
        envelope = declare_config(self, EnvelopeConfig)
        # Every registered plan estimator's parameters are declared (and checked), the
        # chosen one's are used: as trust-av's node_components reads the section.
        params: dict[str, object] = {c.name: declare_config(self, c.config_type)
                  for c in registry.components(PREDICTORS)
                  if c.config_type is not None}
        wall = self.wall = self.clock.wall
        if wall:
            check_control_rate(self.config, self.clock.control_rate_hz)
        self.trust_model = build_trust_model(
            trust, declare_component_params(self, TRUST_MODELS, trust.trust_model))
        # The trust topic carries E and T. A model whose state is T takes it from there; a
        # model with more state (Beta counts, a Kalman variance) is mirrored: in lock-step
        # the planner steps the same model with the E the monitor scored and publishes, over
        # the same dt_s, so its state is the monitor's (checked against T each step).
        self.mirror = not isinstance(self.trust_model.initial_state(), float)
        self.trust_state = self.trust_model.initial_state()
        if self.mirror and wall:
            raise TrustAvPlannerError(f'trust model {trust.trust_model!r} has a state beyond '
                                      'the trust value the trust topic carries: wall mode '
                                      'runs models whose state is T (paper, asymmetric); '
                                      'use clock_mode lockstep or run it in-process')
        self.planner = AvPlanner(self.config, trust, shared.vehicle_length_m,
                                 period_s=1.0 / self.clock.control_rate_hz if wall else None,
                                 cpu_budget=wall, trust_model=self.trust_model,
                                 predictor_params=params.get(self.config.predictor))
        self.trust_initial = trust.trust_initial
        self.previous_ns: int | None = None
        self.buffer = StepBuffer([*STEP_INPUTS, 'trust'])
        self.latest = LatestInputs([*STEP_INPUTS, 'trust'])
        self.has_human = bool(topics.human_odom_topic)
        if not self.has_human and (not wall or self.planner.needs_follower):
            raise ValueError('parameter human_odom_topic: may be empty only with '
                             'clock_mode wall and a predictor that does not need the '
                             f'follower state ({self.config.predictor} does)'
                             if self.planner.needs_follower else
                             'parameter human_odom_topic: may be empty only with clock_mode '
                             'wall')
        recorded = self.config.lead_preview == 'recorded'
        self.required = ['traffic', 'preview', 'ego'] if recorded else ['traffic', 'ego']
        if self.planner.needs_follower:
            # the estimator's inputs include the follower's gap and speed: without a fresh
            # human odometry it cannot predict, so the stale-input policy applies
            self.required.append('human')
        self.missed: dict[str, int] = {}  # input -> deadline events since its last message
        self.record = SolveRecord(self.trust_initial)   # for /diagnostics
        self.stale_reason = ''
        self.stale_logged = ''   # the last stale reason logged, without the inputs' ages
        self.refused_now: dict[str, str] = {}  # input -> why its newest message was refused
        self.period_s = 1.0 / self.clock.control_rate_hz if wall else self.config.dt_s
        self.envelope = CommandEnvelope(self.config.accel_min_mps2, self.config.accel_max_mps2,
                                        envelope.command_jerk_max_mps3 if wall else None,
                                        self.config.stale_decel_mps2)
        self.frame = ''
        self.set_frame(self.frames.base_frame_id)
        self.markers = VehicleMarkers(shared.vehicle_length_m)
        self.make_publishers()
        inputs = self.subscribe_inputs(topics, recorded, wall)
        self.loop = WallLoop(self, self.clock, self.wall_step) if wall else None
        if not self.tuning:   # once: the values it guards stay declared across cleanup
            enable_tuning(self, [Tunable(PlannerConfig, lambda: self.config, self.retune)], wall)
            self.tuning = True
        warm = self.warm_up() if wall and WARM_UP else ''

        mode = f'wall clock at {self.clock.control_rate_hz:g} Hz' if wall else 'lock-step'
        step_s, steps = self.planner.grid
        self.ready_line = (f'ready ({mode}): predictor {self.config.predictor}, alpha '
                           f'{self.config.alpha:g}, prediction grid {steps} x {step_s:g} s, '
                           f'lead preview {self.config.lead_preview}, inputs '
                           f'{", ".join(t for _, _, t in inputs if t)}{warm}')


    def make_publishers(self) -> None:
        """The planner's lifecycle publishers (plan, expected plan, command, status, markers)."""
        def publisher(msgtype: type, topic: str) -> Any:   # rclpy's method is unannotated
            return self.create_lifecycle_publisher(msgtype, topic, topic_qos(topic, self.clock))
        self.pub_plan = publisher(JointTrajectory, 'ego/plan')
        self.pub_expected = publisher(JointTrajectory, 'ego/expected_plan')
        self.pub_accel = publisher(AccelStamped, 'ego/accel_cmd')
        self.pub_status = publisher(DiagnosticArray, 'ego/planner_status')
        self.pub_markers = publisher(MarkerArray, 'vehicle_markers')

    def subscribe_inputs(self, topics: PlannerTopics, recorded: bool,
                         wall: bool) -> tuple[tuple[str, type, str], ...]:
        """Subscribe every input that has a topic (the preview only where it is used); the
        inputs as (name, type, topic), an empty topic for one not subscribed."""
        inputs = (('traffic', Odometry, topics.lead_odom_topic),
                  ('preview', JointTrajectory,
                   topics.lead_preview_topic if recorded or not wall else ''),
                  ('ego', Odometry, topics.ego_odom_topic),
                  ('human', Odometry, topics.human_odom_topic),
                  ('trust', Vector3Stamped, topics.trust_topic))
        callback = self.on_latest if wall else self.on_input
        self.topics = {name: topic for name, _, topic in inputs}
        for name, msgtype, topic in inputs:
            if topic:
                subscribe(
                    self, msgtype, topic, functools.partial(callback, name),
                    topic_qos(TABLE_TOPIC[name], self.clock), readers=not wall,
                    event_callbacks=input_events(self, name, self.missed, self.clock) if wall
                    else None)
        return inputs

    def warm_up(self) -> str:
        """Take the first-use costs off the first active tick: the output templates of the
        body frame (made by :meth:`set_frame`; a plan's template deserialises the message
        once per byte to find its exact length, about 170 ms for 30 points, which was most
        of the 150-220 ms first tick; benchmarks/bench_lifecycle.py) and the NMPC's first
        solves, on a steady car-following state, after which its warm start is forgotten.
        Only the NMPC is stepped: the plan estimator sees nothing. Lock-step runs are not
        warmed (no deadline; their numbers stay those of the in-process loop).

        Returns:
            The log's note: solves and the first and last solve times.
        """
        times = self.planner.warm_up(WARM_UP_SOLVES, self.trust_model.initial_state())
        return (f'; solver warmed: {len(times)} solves, {1e3 * times[0]:.1f} ms then '
                f'{1e3 * times[-1]:.1f} ms')

    def handover(self) -> None:
        """``deactivate``: one last command, ``stale_decel_mps2`` (the stale-input
        deceleration, :class:`~trust_av_planner.nmpc.PlannerConfig`), stamped now in the
        AV's frame; then the outputs stop until ``activate``."""
        accel = self.envelope.command(self.config.stale_decel_mps2, self.period_s, stop=True)
        self.pub_accel.publish(self.command_bytes.render(now_ns(self), accel))
        self.get_logger().info(f'deactivate: handed over with {accel:g} m/s^2')

    def release(self) -> None:
        """``cleanup``/``shutdown``: drop the core and the step buffers."""
        for name in ('planner', 'buffer', 'latest', 'markers'):
            self.__dict__.pop(name, None)
        self.refused_now = {}

    def set_frame(self, frame: str) -> None:
        """The frame_id of the plans and the command from now on (the AV's body frame)."""
        if frame != self.frame:
            self.frame = frame
            self.plan_bytes = TrajectoryBytes('accelerations', frame)
            self.command_bytes = accel_command_bytes(frame)
            if self.wall and WARM_UP:   # the templates are made now, not on the next tick
                step_s, steps = self.planner.grid
                self.plan_bytes.render(0, step_s, [0.0] * steps)

    def retune(self, config: PlannerConfig) -> None:
        """A validated run-time parameter change: effective at the next tick (kept for the
        next ``configure`` while unconfigured)."""
        if 'planner' in self.__dict__:
            self.planner.retune(config)
        self.config = config

    def on_latest(self, name: str, msg: Odometry | JointTrajectory | Vector3Stamped) -> None:
        """Wall mode: keep the latest message of each input with its receive time (also
        while inactive: the first active tick has fresh inputs; none once released); a
        refused one is not kept (:meth:`refused`)."""
        if not self.configured or self.refused(name, msg):
            return
        self.latest.put(name, time.monotonic_ns(), msg)
        self.missed.pop(name, None)
        if name == 'ego':
            self.set_frame(body_frame(msg.child_frame_id, self.frames))

    def wall_step(self) -> None:
        """Wall mode: one planning step from the latest inputs, stamped now; the stale-input
        deceleration while a required input is missing or stale. Only while active."""
        if not self.active:
            return
        if not self.check_clock():   # no command: its stamp would be wrong; the status says why
            self.pub_status.publish(diagnostics(
                time.time_ns(), 'trust_aware_nmpc', False, 'not_running',
                {'reason': self.blocked, 'commanding': 'False'}, error=True))
            return
        ns, mono = now_ns(self), time.monotonic_ns()
        t_s = mono / NS_PER_S
        why = self.problems(mono)
        human_ok = self.has_human and 'human' not in self.refused_now and not self.latest.problems(
            mono, self.clock.input_timeout_s, ['human']) and not self.frame_problem(
            ['ego', 'human'])
        human = self.latest.get('human') if human_ok else None
        trust_msg = None if 'trust' in self.refused_now else self.latest.get('trust')
        trust = self.trust_initial if trust_msg is None else float(trust_msg.vector.z)
        if why:
            self.hold(ns, t_s, why, human, trust)
            return
        if self.stale_reason:
            self.get_logger().info('inputs fresh again: planning resumed')
            self.stale_reason = self.stale_logged = ''
            self.diagnostics.changed()
        items: dict[str, object] = {name: self.latest.get(name) for name in self.required}
        items.setdefault('preview', None)
        items['human'] = human
        self.plan(ns, items, trust, t_s)

    def health(self) -> Report:
        """``/diagnostics`` (:meth:`ManagedNode.diagnose`): :meth:`SolveRecord.report
        <trust_av_common.health.SolveRecord.report>`, with the input ages in wall mode."""
        mono = time.monotonic_ns()
        ages = {name: age(mono, self.latest.received(name)) for name in self.latest.names
                if self.wall and (name != 'human' or self.has_human)}
        level, message, values = self.record.report(self.stale_reason,
                                                    self.config.stale_decel_mps2, ages)
        return level, message, {**values, **self.envelope.values()}

    def on_input(self, name: str, msg: Odometry | JointTrajectory | Vector3Stamped) -> None:
        """Store an input; plan every step whose inputs are complete, in order (only while
        active: while inactive the lock-step chain waits, its inputs kept for
        :meth:`resume`; none once released)."""
        if not self.configured or self.refused(name, msg):
            return
        self.buffer.put(name, msg_ns(msg.header.stamp), msg)
        if name == 'ego':
            self.set_frame(body_frame(msg.child_frame_id, self.frames))
        if self.active:
            self.try_plan()

    def resume(self) -> None:
        """``activate``: the command envelope starts afresh; in lock-step, plan the steps
        whose inputs came while inactive."""
        self.envelope.reset()
        if not self.wall:
            self.try_plan()

    def try_plan(self) -> None:
        """Plan the next step if its inputs (and the previous step's trust) are in."""
        for ns in self.buffer.ready_stamps(STEP_INPUTS):
            if self.previous_ns is not None and not self.buffer.ready(self.previous_ns,
                                                                      ['trust']):
                return
            if self.previous_ns is None:
                state: object = self.trust_state
            else:
                msg = self.buffer.take('trust', self.previous_ns)
                state = self.trust_input(msg.vector.x, msg.vector.z)  # type: ignore[attr-defined]
            items = self.buffer.pop(ns)
            if self.config.lead_preview != 'recorded':
                items['preview'] = None
            self.plan(ns, items, state, None)
            self.previous_ns = ns

    def trust_input(self, score: float, trust: float) -> object:
        """The trust model's state after the monitor's step with E = ``score`` that gave
        T = ``trust`` (T itself, or the mirrored state).

        Raises:
            TrustAvPlannerError: the mirrored trust is not the monitor's (another model or
                step: the constraint would use the wrong state).
        """
        if not self.mirror:
            return float(trust)
        self.trust_state = self.trust_model.step(self.trust_state, float(score),
                                                 self.config.dt_s)
        mirrored = self.trust_model.trust(self.trust_state)
        if abs(mirrored - trust) > 1e-9 * (1.0 + abs(trust)):
            raise TrustAvPlannerError(f"mirrored trust {mirrored!r} is not the monitor's "
                                      f'{trust!r}: the planner and the monitor must run the '
                                      'same trust model and step')
        return self.trust_state

    def plan(self, ns: int, items: dict[str, object], state: object,
             t_s: float | None) -> None:
        """One planning step and its four outputs (``state``: the trust model's state; for
        a model whose state is T, T itself)."""
        trust = float(self.trust_model.trust(state))
        step_s, steps = self.planner.grid
        preview = None
        if items['preview'] is not None:
            msg: JointTrajectory = items['preview']
            preview = interp_at(np.array(trajectory_times(msg)),
                                np.array(trajectory_values(msg, 'velocities')), step_s, steps)
        out = self.planner.step(vehicle(items['traffic']), preview,
                                vehicle(items['ego']),
                                None if items['human'] is None
                                else vehicle(items['human']),
                                state, t_s)
        result = out.result
        self.record.solved(result.solve_time_s, result.fallback, result.status)
        self.publish(ns, result.plan_mps2, out.expected_mps2, float(result.plan_mps2[0]), trust,
                     status=result.status,
                     ok=result.success and not result.gap_bounds_relaxed,
                     extra={'success': str(result.success), 'fallback': str(result.fallback),
                            'gap_bounds_relaxed': str(result.gap_bounds_relaxed),
                            'iterations': str(result.iterations),
                            'solve_time_s': repr(result.solve_time_s),
                            'explicability_max': repr(result.explicability_max),
                            'gap_m': repr(out.gap_m)})
        if result.fallback:
            self.get_logger().warning(f'NMPC fallback: {result.status}',
                                      throttle_duration_sec=5.0)

    def publish(self, ns: int, plan: np.ndarray, expected: np.ndarray, accel_mps2: float,
                trust: float, *, status: str, ok: bool, extra: dict[str, str],
                error: bool = False) -> None:
        """The vehicles' markers, then the step's four outputs (they complete its recorded
        chunk), stamped ``ns``; plans on the prediction grid, in the AV's frame."""
        step_s = self.planner.grid[0]
        requested = accel_mps2
        accel_mps2 = self.envelope.command(requested, self.period_s)
        plan = self.envelope.plan(plan, accel_mps2, BOUND_TOLERANCE)
        if accel_mps2 != requested:   # NaN too
            extra = {**extra, 'command_requested_mps2': repr(requested)}
        self.record.published(trust, accel_mps2)
        self.pub_markers.publish(self.markers.update(ns))
        self.pub_plan.publish(self.plan_bytes.render(ns, step_s, plan.tolist()))
        self.pub_expected.publish(self.plan_bytes.render(ns, step_s, expected.tolist()))
        self.pub_accel.publish(self.command_bytes.render(ns, accel_mps2))
        self.pub_status.publish(diagnostics(ns, 'trust_aware_nmpc', ok, status,
                                            {'status': status, **extra, 'trust': repr(trust),
                                             'command_mps2': repr(accel_mps2)}, error=error))


def main(args: list[str] | None = None) -> int:
    """Entry point of ``ros2 run trust_av_planner planner``."""
    return spin_node(PlannerNode, args, user_errors=(ValueError, TrustAvPlannerError))


if __name__ == '__main__':
    sys.exit(main())
