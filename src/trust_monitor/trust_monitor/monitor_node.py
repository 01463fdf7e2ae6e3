"""``trust_monitor`` node: E, P and trust from the observed plan and the expected plan.

Subscribes ``ego/plan`` and ``ego/expected_plan`` (paired by header stamp), publishes
``trust_monitor/trust`` (``geometry_msgs/Vector3Stamped``: x = E, y = P, z = trust after
the step; ``frame_id`` empty, the three numbers are not a spatial vector), stamped like the
plans. Topic names are relative (the node's namespace). Parameters: the trust model's
(``config/trust_av.yaml``) and ``dt_s``. Trust is per second: each plan's update is scaled by
the time it is applied for, ``dt_s`` in lock-step (one step = eq. 10 exactly). The expected
plan is read on the plan's times (both carry ``time_from_start``).

``clock_mode: wall``: the latest plan and expected plan are scored once, as soon as both
carry the same, new stamp (checked on every arrival and on a wall-clock timer at
``control_rate_hz``), and the trust is stamped with the current time; the update is scaled
by the time since the previously scored plan (at most ``input_timeout_s``; for the first
after an activation, the time since the activation, at most one control period). Trust
counts from the activation: plans stamped before it (kept while inactive) are not scored,
so a drive that activates the monitor at its start (``trust-av drive``) gets trust for
the drive's time only. Loop jitter as in the planner.

Every plan is checked where it enters (:func:`trust_av_common.envelope.trajectory_problem`:
1 to ``input_points_max`` points, each with an acceleration within
+-``input_accel_abs_max_mps2``, on increasing times, valid stamps): one that is not is
dropped, counted and named on ``/diagnostics`` (a log line at most once a second), and no
pair is scored until that plan's next usable message.
"""

from __future__ import annotations

import functools
import sys
import time

import numpy as np
from geometry_msgs.msg import Vector3Stamped
from trajectory_msgs.msg import JointTrajectory

from trust_av_common.envelope import InputRanges, trajectory_problem
from trust_av_common.grids import hold_at
from trust_av_common.lifecycle import LifecycleConfig
from trust_av_common.lockstep import StepBuffer
from trust_av_common.ros import diagnostics as diag
from trust_av_common.ros.lifecycle import ManagedNode
from trust_av_common.ros.messages import msg_ns, trajectory_times, trajectory_values, vector3_bytes
from trust_av_common.ros.parameters import (
    declare_component_params,
    declare_config,
    predeclare,
    predeclare_component,
)
from trust_av_common.ros.qos import topic_qos
from trust_av_common.ros.raw_inputs import subscribe
from trust_av_common.ros.spin import WallLoop, now_ns, spin_node
from trust_av_common.topics import NO_FRAME
from trust_av_common.wall_clock import NS_PER_S, LatestInputs, WallClockConfig
from trust_monitor.model_interface import TRUST_MODELS, build_trust_model
from trust_monitor.paper_trust import MonitorConfig, TrustConfig, TrustEstimator

__all__ = ['main']


class MonitorNode(ManagedNode):
    """Thin adapter over :class:`trust_monitor.paper_trust.TrustEstimator`, a managed node
    (:mod:`trust_av_common.ros.lifecycle`): ``configure`` builds the estimator, trust is
    published only while active."""

    task = 'trust'
    idle = 'inactive: not publishing trust (waiting for activate)'

    def __init__(self) -> None:
        super().__init__('trust_monitor')
        self.lifecycle = declare_config(self, LifecycleConfig)
        # declared now, read and checked at configure: `ros2 param` sees them unconfigured
        for cls in (TrustConfig, MonitorConfig, WallClockConfig, InputRanges):
            predeclare(self, cls)
        predeclare_component(self, TRUST_MODELS, 'trust_model')

    def build(self) -> None:
        """``configure``: parameters, the trust estimator, the publisher, the subscriptions.

        Raises:
            ParamsError: a refused parameter value.
        """
        trust = declare_config(self, TrustConfig)
        self.estimator = TrustEstimator(trust, build_trust_model(
            trust, declare_component_params(self, TRUST_MODELS, trust.trust_model)))
        self.step_s = declare_config(self, MonitorConfig).dt_s
        self.clock = declare_config(self, WallClockConfig)
        self.wall = self.clock.wall
        self.ranges = declare_config(self, InputRanges)
        self.refused_now: dict[str, str] = {}   # plan kind -> why its newest was refused
        self.buffer = StepBuffer(['plan', 'expected'])
        self.latest = LatestInputs(['plan', 'expected'])
        self.scored_ns: int | None = None
        self.active_ns = 0      # wall mode: when the monitor was last activated
        self.scored = 0
        self.estimate: tuple[float, float, float] | None = None   # E, P, trust of the last
        self.pub = self.create_lifecycle_publisher(Vector3Stamped, 'trust_monitor/trust',
                                         topic_qos('trust_monitor/trust', self.clock))
        self.trust_bytes = vector3_bytes(NO_FRAME)
        callback = self.on_latest if self.clock.wall else self.on_input
        for name, topic in (('plan', 'ego/plan'), ('expected', 'ego/expected_plan')):
            subscribe(self, JointTrajectory, topic, functools.partial(callback, name),
                      topic_qos(topic, self.clock), readers=not self.wall)
        self.loop = WallLoop(self, self.clock, self.wall_step) if self.clock.wall else None
        self.ready_line = f'ready ({self.clock.clock_mode})'

    def on_latest(self, name: str, msg: JointTrajectory) -> None:
        """Wall mode: keep the latest plan of each kind and score a new pair as soon as it
        is complete (on the tick alone, a tick that fell just before the planner's publish
        found nothing new, and under load whole seconds went unscored). None once released."""
        if not self.configured or self.refused(name, msg):
            return
        self.latest.put(name, time.monotonic_ns(), msg)
        self.wall_step()

    def wall_step(self) -> None:
        """Wall mode: score the latest plan pair once, stamped now (only while active)."""
        if not self.active or not self.check_clock() or self.refused_now:
            return
        plan, expected = self.latest.get('plan'), self.latest.get('expected')
        if plan is None or expected is None:
            return
        ns = msg_ns(plan.header.stamp)
        if ns != msg_ns(expected.header.stamp) or ns == self.scored_ns or ns < self.active_ns:
            return
        if self.scored_ns is None or self.scored_ns < self.active_ns:
            dt_s = min(1.0 / self.clock.control_rate_hz, (ns - self.active_ns) / NS_PER_S)
        else:
            dt_s = min(max(ns - self.scored_ns, 0) / NS_PER_S, self.clock.input_timeout_s)
        self.scored_ns = ns
        self.publish(now_ns(self), plan, expected, dt_s)

    def refused(self, name: str, msg: JointTrajectory) -> bool:
        """Check a plan: a refused one is counted and named (:meth:`ManagedNode.refuse`),
        and no pair is scored until that plan's next usable message."""
        r = self.ranges
        problem = trajectory_problem(msg, 'accelerations', -r.input_accel_abs_max_mps2,
                                     r.input_accel_abs_max_mps2, r.input_points_max)
        if problem:
            self.refused_now[name] = problem
            self.refuse(name, 'ego/plan' if name == 'plan' else 'ego/expected_plan', problem)
            return True
        self.refused_now.pop(name, None)
        return False

    def release(self) -> None:
        """``cleanup``/``shutdown``: drop the estimator and the step buffers."""
        for name in ('estimator', 'buffer', 'latest'):
            self.__dict__.pop(name, None)

    def health(self) -> tuple[int, str, dict[str, str]]:
        """``/diagnostics`` (:meth:`ManagedNode.diagnose`): plan pairs scored since configure,
        the last E, P and trust, the plans' ages (wall mode)."""
        values = {'scored': str(self.scored)}
        if self.estimate is not None:
            values.update(zip(('explicability', 'performance', 'trust'),
                              map(repr, self.estimate), strict=True))
        if self.wall:
            mono = time.monotonic_ns()
            for name in self.latest.names:
                values[f'input_age_{name}_s'] = diag.age(mono, self.latest.received(name))
        return diag.OK, 'publishing trust', values

    def on_input(self, name: str, msg: JointTrajectory) -> None:
        """Store a plan; when both plans of a step are there, score them (only while
        active: while inactive they wait for :meth:`resume`; none once released)."""
        if not self.configured or self.refused(name, msg):
            return
        ns = msg_ns(msg.header.stamp)
        self.buffer.put(name, ns, msg)
        if self.active and self.buffer.ready(ns):
            self.score(ns)

    def score(self, ns: int) -> None:
        """Lock-step: score the plan pair of step ``ns`` and publish the trust."""
        items = self.buffer.pop(ns)
        self.publish(ns, items['plan'], items['expected'], self.step_s)

    def resume(self) -> None:
        """``activate``: in wall mode, trust counts from now; in lock-step, score the plan
        pairs that came while inactive."""
        if self.wall:
            self.active_ns = now_ns(self)
        else:
            for ns in list(self.buffer.ready_stamps(['plan', 'expected'])):
                self.score(ns)

    def publish(self, ns: int, plan: JointTrajectory, expected: JointTrajectory,
                dt_s: float) -> None:
        """One trust step (the plan applied for ``dt_s`` seconds) from a plan pair, published
        stamped ``ns``; the expected plan is read on the plan's times."""
        values = trajectory_values(plan, 'accelerations')
        times = trajectory_times(plan)
        step_s = float(times[1] - times[0]) if len(times) > 1 else self.step_s
        held = hold_at(np.array(trajectory_times(expected)),
                       np.array(trajectory_values(expected, 'accelerations')), step_s,
                       len(values))
        estimate = self.estimator.step(values, held.tolist(), dt_s)
        self.scored += 1
        self.estimate = (estimate.explicability, estimate.performance, estimate.trust)
        self.pub.publish(self.trust_bytes.render(ns, estimate.explicability,
                                                 estimate.performance, estimate.trust))


def main(args: list[str] | None = None) -> int:
    """Entry point of ``ros2 run trust_monitor monitor``."""
    return spin_node(MonitorNode, args)


if __name__ == '__main__':
    sys.exit(main())
