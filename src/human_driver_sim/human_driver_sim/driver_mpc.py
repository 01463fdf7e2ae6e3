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

from human_driver_sim import longitudinal
from human_driver_sim.solver import sqp_options
from trust_monitor.params import require

LOG = logging.getLogger(__name__)

FEATURE_NAMES = ('acceleration', 'desired_speed', 'relative_speed', 'relative_distance')


@dataclass(frozen=True)
class DriverConfig:
    """Parameters of the driver MPC."""

    dt_s: float
    horizon_steps: int
    standstill_gap_m: float
    speed_min_mps: float
    speed_max_mps: float
    weight_acceleration: float
    weight_desired_speed: float
    weight_relative_speed: float
    weight_relative_distance: float
    time_headway_s: float
    accel_min_mps2: float
    accel_max_mps2: float
    gap_slack_weight: float
    solver_max_iter: int
    fallback_gap_gain_per_s2: float
    fallback_speed_gain_per_s: float
    desired_standstill_gap_m: float
    """d_s inside the relative-distance feature f_rd (fitted, docs/DRIVER_IRL.md), m; the
    gap constraint d_H >= ``standstill_gap_m`` (the paper's safety d_s) is separate."""

    def __post_init__(self) -> None:
        require(self.dt_s > 0.0, f'dt_s must be > 0, got {self.dt_s}')
        require(1 <= self.horizon_steps <= 50,
                f'horizon_steps must be in [1, 50], got {self.horizon_steps}')
        for name in ('weight_acceleration', 'weight_desired_speed', 'weight_relative_speed',
                     'weight_relative_distance'):
            require(getattr(self, name) >= 0.0, f'{name} must be >= 0, got {getattr(self, name)}')
        require(self.weight_acceleration > 0.0, 'weight_acceleration must be > 0 (regularity)')
        require(0.0 <= self.speed_min_mps < self.speed_max_mps,
                f'need 0 <= speed_min_mps < speed_max_mps, got {self.speed_min_mps}, '
                f'{self.speed_max_mps}')
        require(self.accel_min_mps2 < 0.0 < self.accel_max_mps2,
                'need accel_min_mps2 < 0 < accel_max_mps2')
        require(self.gap_slack_weight > 0.0, 'gap_slack_weight must be > 0')
        require(self.solver_max_iter >= 1, 'solver_max_iter must be >= 1')
        require(self.desired_standstill_gap_m >= 0.0,
                f'desired_standstill_gap_m must be >= 0, got {self.desired_standstill_gap_m}')

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
    av_speeds = longitudinal.lead_speeds(av_speed_mps, expected_mps2, dt_s)
    gaps, speeds = longitudinal.rollout(gap_m, speed_mps, av_speeds, accels_mps2, dt_s)
    av_next = [s + a * dt_s for s, a in zip(av_speeds, expected_mps2, strict=True)]
    f_a = sum(a * a for a in accels_mps2)
    f_ds = sum((v - desired_speed_mps) ** 2 for v in speeds)
    f_rs = sum((vr - v) ** 2 for vr, v in zip(av_next, speeds, strict=True))
    f_rd = sum((d - standstill_gap_m - time_headway_s * v) ** 2
               for d, v in zip(gaps, speeds, strict=True))
    return [f_a, f_ds, f_rs, f_rd]


@dataclass(frozen=True)
class DriverResult:
    """Outcome of one driver MPC step (see :class:`trust_av_planner.nmpc.PlanResult`)."""

    plan_mps2: np.ndarray
    status: str
    success: bool
    iterations: int
    solve_time_s: float


class DriverMpc:
    """The human follower's MPC; build once, call :meth:`solve` every step."""

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
                         standstill_gap_m=config.desired_standstill_gap_m,
                         time_headway_s=config.time_headway_s,
                         desired_speed_mps=config.speed_max_mps)
        cost = ca.dot(weights, ca.vertcat(*feats)) + config.gap_slack_weight * ca.sum1(slack)
        av_speeds = longitudinal.lead_speeds(av_speed0, e_list, config.dt_s)
        gaps, speeds = longitudinal.rollout(gap0, speed0, av_speeds, u_list, config.dt_s)
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

    def solve(self, gap_m: float, speed_mps: float, av_speed_mps: float,
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
        av_speeds = longitudinal.lead_speeds(av_speed_mps, list(expected_mps2), c.dt_s)
        plan = np.asarray(longitudinal.hold_gap_plan(
            gap_m, speed_mps, av_speeds, dt_s=c.dt_s, standstill_gap_m=c.standstill_gap_m,
            time_headway_s=c.time_headway_s, gap_gain_per_s2=c.fallback_gap_gain_per_s2,
            speed_gain_per_s=c.fallback_speed_gain_per_s, accel_min_mps2=c.accel_min_mps2,
            accel_max_mps2=c.accel_max_mps2, speed_min_mps=c.speed_min_mps,
            speed_max_mps=c.speed_max_mps))
        LOG.debug('driver MPC fallback (%s)', stats['return_status'])
        self._previous = None
        return DriverResult(plan, f'fallback: {stats["return_status"]}', False, iterations,
                            elapsed)
