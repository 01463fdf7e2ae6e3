"""The planner node's view of its wall-mode inputs: each message checked where it enters
(:mod:`trust_av_common.envelope`; a refused one makes its input stale), why the required
inputs cannot be used now, and the stale-input policy (:meth:`PlannerInputs.hold`; its log: one
line per reason, then throttled).
:class:`~trust_av_planner.planner_node.PlannerNode` is built on it."""

from __future__ import annotations

import re
import time

import numpy as np
from geometry_msgs.msg import Vector3Stamped
from nav_msgs.msg import Odometry
from trajectory_msgs.msg import JointTrajectory

from trust_av_common.envelope import (
    InputRanges,
    odometry_problem,
    trajectory_problem,
    vector_problem,
)
from trust_av_common.frames import FrameConfig, position_frame_problem
from trust_av_common.health import SolveRecord
from trust_av_common.kinematics import VehicleState
from trust_av_common.ros.lifecycle import ManagedNode
from trust_av_common.wall_clock import LatestInputs, WallClockConfig
from trust_av_planner.nmpc import PlannerConfig
from trust_av_planner.planner import AvPlanner

__all__ = ['STALE_DETAIL', 'PlannerInputs', 'vehicle']

STALE_DETAIL = re.compile(r" \((?:[^()]|\([^()]*\))*\)| in '[^']*'")
"""The details of a stale-input reason (an input's age, a refused value, its frame): a
change in them alone is not logged again."""


def vehicle(msg: Odometry) -> VehicleState:
    """Odometry to the core's vehicle state."""
    return VehicleState(float(msg.pose.pose.position.x), float(msg.twist.twist.linear.x))


class PlannerInputs(ManagedNode):
    """The input side of the planner node (its attributes are set by its ``build``)."""

    ranges: InputRanges
    clock: WallClockConfig
    frames: FrameConfig
    latest: LatestInputs
    required: list[str]
    missed: dict[str, int]
    refused_now: dict[str, str]
    topics: dict[str, str]
    stale_logged: str
    stale_reason: str
    config: PlannerConfig
    planner: AvPlanner
    record: SolveRecord
    has_human: bool

    def publish(self, ns: int, plan: np.ndarray, expected: np.ndarray, accel_mps2: float,
                trust: float, *, status: str, ok: bool, extra: dict[str, str],
                error: bool = False) -> None:
        """The step's outputs (:meth:`PlannerNode.publish
        <trust_av_planner.planner_node.PlannerNode.publish>`)."""
        raise NotImplementedError


    def input_problem(self, name: str, msg: Odometry | JointTrajectory | Vector3Stamped) -> str:
        """Why a message of input ``name`` cannot be used ('' if it can), from what the
        planner reads of it (:mod:`trust_av_common.envelope`)."""
        r = self.ranges
        if name == 'preview':
            return trajectory_problem(msg, 'velocities', r.input_speed_min_mps,
                                      r.input_speed_max_mps, r.input_points_max)
        if name == 'trust':
            return vector_problem(msg, r.input_trust_abs_max)
        return odometry_problem(msg, r)

    def refused(self, name: str, msg: Odometry | JointTrajectory | Vector3Stamped) -> bool:
        """Check a message of input ``name``: a refused one is counted and named
        (:meth:`ManagedNode.refuse`), and the input is stale until its next usable
        message."""
        problem = self.input_problem(name, msg)
        if problem:
            self.refused_now[name] = problem
            self.refuse(name, self.topics[name], problem)
            return True
        self.refused_now.pop(name, None)
        return False

    def problems(self, now_mono_ns: int) -> str:
        """Wall mode: why the required inputs cannot be used ('' when they can)."""
        missed = [n for n in self.required if n in self.missed]
        polled = self.latest.problems(now_mono_ns, self.clock.input_timeout_s, self.required)
        event = f'deadline missed (QoS event): {", ".join(missed)}' if missed else ''
        frames = '' if polled else self.frame_problem(
            [n for n in self.required if n in ('traffic', 'ego', 'human')])
        refused = ', '.join(f'{n} ({self.refused_now[n]})' for n in self.required
                            if n in self.refused_now)
        refused = f'refused: {refused}' if refused else ''
        return '; '.join(p for p in (refused, event, polled, frames) if p)

    def frame_problem(self, names: list[str]) -> str:
        """Why the positions of the latest ``names`` odometry cannot be compared ('' if
        they can: one world-fixed frame)."""
        latest = {n: self.latest.get(n) for n in names}
        return position_frame_problem(
            {n: m.header.frame_id for n, m in latest.items() if m is not None}, self.frames)

    def log_stale(self, why: str, accel: float) -> None:
        """The stale-input log: one line when the reason changes (which inputs are missing,
        stale, refused or in other frames; their ages, values and frames aside), then at most
        one every 10 s while it lasts."""
        key = STALE_DETAIL.sub('', why)
        if key != self.stale_logged:
            self.stale_logged = key
            self.get_logger().error(f'stale inputs ({why}): commanding {accel:g} m/s^2 until '
                                    'they are fresh')
        else:
            self.get_logger().error(f'still stale ({why}): commanding {accel:g} m/s^2',
                                    throttle_duration_sec=10.0)

    def hold(self, ns: int, t_s: float, why: str, human: Odometry | None, trust: float) -> None:
        """The stale-input policy: command ``stale_decel_mps2``, status ERROR with the reason;
        the plan estimator keeps observing and the plans are published (the monitor scores
        them: trust goes on)."""
        ego_fresh = not self.latest.problems(time.monotonic_ns(), self.clock.input_timeout_s,
                                             ['ego']) and not {'ego'} & (self.missed.keys()
                                                                     | self.refused_now.keys())
        ego = self.latest.get('ego') if ego_fresh else None
        accel = self.config.stale_decel_mps2
        plan, expected = self.planner.hold(accel, None if ego is None else vehicle(ego),
                                           None if human is None else vehicle(human), t_s)
        self.record.stale()
        if why != self.stale_reason:
            self.log_stale(why, accel)
            self.stale_reason = why
            self.diagnostics.changed()
        self.publish(ns, plan, expected, accel, trust, status='stale_inputs', ok=False,
                     extra={'reason': why, 'fallback': 'True', 'success': 'False'},
                     error=True)
