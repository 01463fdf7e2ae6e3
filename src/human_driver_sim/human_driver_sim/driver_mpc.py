"""MPC model of the human driver following the AV, eq. (13) of Ozkan & Ma.

The driver minimises ``W^T sum_k f(x^k, u^k, u_R^H,k)`` over its own accelerations, where
the AV ahead is predicted with the plan the human *expects*, u_R^H (not the AV's true plan).
Features (our definitions, docs/MODEL.md), summed over the predicted steps k = 1..N::

    f_a  = (u_H^{k-1})^2                        acceleration, (m/s^2)^2
    f_ds = (v_H^k - v_max)^2                    desired speed = the speed limit, (m/s)^2
    f_rs = (v_R^k - v_H^k)^2                    relative speed to the AV, (m/s)^2
    f_rd = (d_H^k - d_s - tau_H v_H^k)^2        relative distance to the desired gap, m^2

subject to ``v_min <= v_H^k <= v_max``, ``u_min <= u_H <= u_max`` and ``d_H^k >= d_s``; the
gap bound is softened by an exact L1 penalty (``gap_slack_weight``) so that the problem is
always feasible even when the AV brakes harder than expected.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np

from trust_monitor.common import kinematics
from trust_monitor.common.params import check_fields, control_step_param, param, require
from trust_monitor.common.solver import sqp_options

LOG = logging.getLogger(__name__)

FEATURE_NAMES = ('acceleration', 'desired_speed', 'relative_speed', 'relative_distance')


@dataclass(frozen=True)
class DriverConfig:
    """Parameters of the driver MPC."""

    dt_s: float = control_step_param()
    horizon_steps: int = param('prediction horizon N', unit='steps', low=1, high=50)
    standstill_gap_m: float = param('standstill gap d_s: the bound d_H >= d_s', unit='m')
    speed_min_mps: float = param('lower speed bound', unit='m/s', low=0.0)
    speed_max_mps: float = param('upper speed bound (the orchestrator passes max(v_PT))',
                                 unit='m/s')
    weight_acceleration: float = param('driver feature weight: acceleration', low=0.0,
                                       low_inclusive=False)
    weight_desired_speed: float = param('driver feature weight: desired speed', low=0.0)
    weight_relative_speed: float = param('driver feature weight: relative speed', low=0.0)
    weight_relative_distance: float = param('driver feature weight: relative distance',
                                            low=0.0)
    time_headway_s: float = param("human's time headway tau_H in the relative-distance "
                                  'feature', unit='s')
    accel_min_mps2: float = param("human's lower acceleration bound", unit='m/s^2', high=0.0,
                                  high_inclusive=False)
    accel_max_mps2: float = param("human's upper acceleration bound", unit='m/s^2', low=0.0,
                                  low_inclusive=False)
    gap_slack_weight: float = param('penalty weight on violating the driver gap bound', low=0.0,
                                    low_inclusive=False)
    solver_max_iter: int = param('SQP iterations before the step falls back', low=1)
    fallback_gap_gain_per_s2: float = param('gap gain of the fallback controller',
                                            unit='1/s^2')
    fallback_speed_gain_per_s: float = param('speed gain of the fallback controller',
                                             unit='1/s')

    def __post_init__(self) -> None:
        check_fields(self)
        require(self.speed_min_mps < self.speed_max_mps,
                f'need 0 <= speed_min_mps < speed_max_mps, got {self.speed_min_mps}, '
                f'{self.speed_max_mps}')

    @property
    def weights(self) -> np.ndarray:
        """W in the order of :data:`FEATURE_NAMES`."""
        return np.array([self.weight_acceleration, self.weight_desired_speed,
                         self.weight_relative_speed, self.weight_relative_distance])


def features(gap_m: Any, speed_mps: Any, av_speed_mps: Any, accels_mps2: Sequence[Any],
             expected_mps2: Sequence[Any], *, dt_s: float, standstill_gap_m: float,
             time_headway_s: float, desired_speed_mps: float) -> list[Any]:
    """The four summed features of eq. (13) (floats or CasADi expressions).

    Args:
        gap_m: human's gap to the AV, m.
        speed_mps: human's speed, m/s.
        av_speed_mps: AV's speed, m/s.
        accels_mps2: human's plan, N values.
        expected_mps2: the AV plan the human expects, N values.
    """
    av_speeds = kinematics.lead_speeds(av_speed_mps, expected_mps2, dt_s)
    gaps, speeds = kinematics.rollout(gap_m, speed_mps, av_speeds, accels_mps2, dt_s)
    av_next = [s + a * dt_s for s, a in zip(av_speeds, expected_mps2, strict=True)]
    f_a = sum(a * a for a in accels_mps2)
    f_ds = sum((v - desired_speed_mps) ** 2 for v in speeds)
    f_rs = sum((vr - v) ** 2 for vr, v in zip(av_next, speeds, strict=True))
    f_rd = sum((d - standstill_gap_m - time_headway_s * v) ** 2
               for d, v in zip(gaps, speeds, strict=True))
    return [f_a, f_ds, f_rs, f_rd]


@dataclass(frozen=True)
class DriverResult:
    """Outcome of one driver MPC step (the same fields as the AV's ``PlanResult``)."""

    plan_mps2: np.ndarray
    status: str
    success: bool
    iterations: int
    solve_time_s: float


class DriverMpc:
    """The human follower's MPC; build once, call :meth:`step` every step."""

    def __init__(self, config: DriverConfig) -> None:
        self.config = config
        n = config.horizon_steps
        u = ca.SX.sym('u', n)
        slack = ca.SX.sym('slack', n)
        gap0, speed0, av_speed0 = ca.SX.sym('gap0'), ca.SX.sym('speed0'), ca.SX.sym('av_speed0')
        expected = ca.SX.sym('expected', n)
        weights = ca.SX.sym('weights', len(FEATURE_NAMES))
        u_list = [u[k] for k in range(n)]
        e_list = [expected[k] for k in range(n)]
        feats = features(gap0, speed0, av_speed0, u_list, e_list, dt_s=config.dt_s,
                         standstill_gap_m=config.standstill_gap_m,
                         time_headway_s=config.time_headway_s,
                         desired_speed_mps=config.speed_max_mps)
        cost = ca.dot(weights, ca.vertcat(*feats)) + config.gap_slack_weight * ca.sum1(slack)
        av_speeds = kinematics.lead_speeds(av_speed0, e_list, config.dt_s)
        gaps, speeds = kinematics.rollout(gap0, speed0, av_speeds, u_list, config.dt_s)
        g = ca.vertcat(*[gaps[k] + slack[k] for k in range(n)], *speeds)
        self._lbg = np.concatenate([np.full(n, config.standstill_gap_m),
                                    np.full(n, config.speed_min_mps)])
        self._ubg = np.concatenate([np.full(n, np.inf), np.full(n, config.speed_max_mps)])
        self._lbx = np.concatenate([np.full(n, config.accel_min_mps2), np.zeros(n)])
        self._ubx = np.concatenate([np.full(n, config.accel_max_mps2), np.full(n, np.inf)])
        self._solver = ca.nlpsol('driver_mpc', 'sqpmethod',
                                 {'x': ca.vertcat(u, slack), 'f': cost, 'g': g,
                                  'p': ca.vertcat(gap0, speed0, av_speed0, expected, weights)},
                                 sqp_options(config.solver_max_iter))
        self._previous: np.ndarray | None = None

    def reset(self) -> None:
        """Forget the warm start."""
        self._previous = None

    def step(self, gap_m: float, speed_mps: float, av_speed_mps: float,
             expected_mps2: np.ndarray) -> DriverResult:
        """Plan the human's next N accelerations against the expected AV plan.

        Args:
            gap_m: gap from the human's front bumper to the AV's rear bumper, m.
            speed_mps: human's speed, m/s.
            av_speed_mps: AV's current speed, m/s.
            expected_mps2: the AV plan the human expects, N values, m/s^2.
        """
        c, n = self.config, self.config.horizon_steps
        guess = np.zeros(2 * n)
        if self._previous is not None:
            guess[:n] = np.concatenate([self._previous[1:], self._previous[-1:]])
        params = np.concatenate([[gap_m, speed_mps, av_speed_mps], expected_mps2, c.weights])
        start = time.perf_counter()
        sol = self._solver(x0=guess, p=params, lbx=self._lbx, ubx=self._ubx, lbg=self._lbg,
                           ubg=self._ubg)
        elapsed = time.perf_counter() - start
        stats = self._solver.stats()
        iterations = int(stats.get('iter_count', 0))
        if stats['success']:
            plan = np.asarray(sol['x']).ravel()[:n]
            self._previous = plan
            return DriverResult(plan, str(stats['return_status']), True, iterations, elapsed)
        av_speeds = kinematics.lead_speeds(av_speed_mps, list(expected_mps2), c.dt_s)
        plan = np.asarray(kinematics.hold_gap_plan(
            gap_m, speed_mps, av_speeds, dt_s=c.dt_s, standstill_gap_m=c.standstill_gap_m,
            time_headway_s=c.time_headway_s, gap_gain_per_s2=c.fallback_gap_gain_per_s2,
            speed_gain_per_s=c.fallback_speed_gain_per_s, accel_min_mps2=c.accel_min_mps2,
            accel_max_mps2=c.accel_max_mps2, speed_min_mps=c.speed_min_mps,
            speed_max_mps=c.speed_max_mps))
        LOG.debug('driver MPC fallback (%s)', stats['return_status'])
        self._previous = None
        return DriverResult(plan, f'fallback: {stats["return_status"]}', False, iterations,
                            elapsed)
