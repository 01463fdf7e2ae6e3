"""MPC model of the human driver following the AV, eq. (13) of Ozkan & Ma.

The driver minimises ``W^T sum_k f(x^k, u^k, u_R^H,k)`` over its own accelerations, where
the AV ahead is predicted with the plan the human *expects*, u_R^H (not the AV's true plan).
Features (our definitions, docs/MODEL.md), summed over the predicted steps k = 1..N::

    f_a  = (u_H^{k-1})^2                        acceleration, (m/s^2)^2
    f_ds = (v_H^k - v_max)^2                    desired speed = the speed limit, (m/s)^2
    f_rs = (v_R^k - v_H^k)^2                    relative speed to the AV, (m/s)^2
    f_rd = (d_H^k - d_s - tau_H v_H^k)^2        relative distance to the desired gap, m^2

subject to ``v_min <= v_H^k <= v_max``, ``u_min <= u_H <= u_max`` and the HARD gap bound
``d_H^k >= d_s`` (eq. 13) for k = 2..N: the next gap d_H^1 follows from today's speeds and
no plan can change it, so the bound applies from the first step the plan acts on. For the
gap bound (only; the cost keeps the expected plan) the human allows for the AV braking
harder than expected, in one of two ways (:meth:`DriverMpc.bound_av_accels`):

* ``cautious`` (the worst case): the AV at min(u_R^H,k, ``assumed_av_accel_min_mps2``) at
  every step (the AV's braking bound, as in Gipps' 1981 car-following model);
* fitted caution: the AV at min(u_R^H,k, 0) - ``av_extra_decel_mps2`` (a_extra >= 0, fitted
  to human drivers, docs/DRIVER_IRL.md): the expected plan's braking, never its
  acceleration, plus a margin the human keeps for the unexpected;

the AV's speed never below 0. When no plan meets the bound (even the hardest braking plan does
not), the human brakes as hard as it can and the step counts as a driver fallback
(docs/MODEL.md, "The human's safety gap").
"""

from __future__ import annotations

import logging
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np

from trust_av_common import kinematics
from trust_av_common.params import check_fields, control_step_param, param, require
from trust_av_common.registry import Component
from trust_av_common.solver import qp_options, solve

__all__ = ['COMPONENT', 'DriverConfig', 'DriverMpc', 'DriverResult', 'bound_av_accels', 'features']

LOG = logging.getLogger(__name__)

FEATURE_NAMES = ('acceleration', 'desired_speed', 'relative_speed', 'relative_distance')
BOUND_FEASIBILITY_TOLERANCE_M = 1e-6
"""The gap bound counts as feasible when the hardest braking plan misses it by at most this, m
(rounding); within it the bound is lowered to what braking reaches."""


@dataclass(frozen=True)
class DriverConfig:
    """Parameters of the driver MPC.

    Attributes:
        assumed_av_accel_min_mps2: for the gap bound d_H^k >= d_s the human predicts the AV
            at min(expected acceleration, this) at every step: the AV may brake this hard
            whatever the human expects, m/s^2 (<= 0; Table I's u_R,min = -3 by default).
            Used when ``cautious``.
        cautious: True, the worst-case bound above; False, the fitted caution.
        av_extra_decel_mps2: a_extra >= 0, m/s^2: with ``cautious`` False the gap bound
            predicts the AV at min(expected, 0) - a_extra at every step.
    """

    dt_s: float = control_step_param()
    horizon_steps: int = param('prediction horizon N', unit='steps', low=1, high=50)
    standstill_gap_m: float = param('standstill gap d_s: the bound d_H >= d_s', unit='m',
                                     low=0.0, high=1000.0)
    speed_min_mps: float = param('lower speed bound', unit='m/s', low=0.0, high=100.0)
    speed_max_mps: float = param('upper speed bound (the orchestrator passes max(v_PT))',
                                 unit='m/s', low=0.0, high=100.0)
    weight_acceleration: float = param('driver feature weight: acceleration', low=0.0,
                                       low_inclusive=False, high=1e6)
    weight_desired_speed: float = param('driver feature weight: desired speed', low=0.0,
                                        high=1e6)
    weight_relative_speed: float = param('driver feature weight: relative speed', low=0.0,
                                         high=1e6)
    weight_relative_distance: float = param('driver feature weight: relative distance',
                                            low=0.0, high=1e6)
    time_headway_s: float = param("human's time headway tau_H in the relative-distance "
                                  'feature', unit='s', low=0.0, high=100.0)
    accel_min_mps2: float = param("human's lower acceleration bound", unit='m/s^2', low=-100.0,
                                  high=0.0, high_inclusive=False)
    accel_max_mps2: float = param("human's upper acceleration bound", unit='m/s^2', low=0.0,
                                  low_inclusive=False, high=100.0)
    solver_max_iter: int = param('QP (DAQP active-set) iterations before the step falls back',
                                 low=1, high=10_000)
    fallback_gap_gain_per_s2: float = param('gap gain of the fallback controller',
                                            unit='1/s^2', low=0.0, high=1000.0)
    fallback_speed_gain_per_s: float = param('speed gain of the fallback controller',
                                             unit='1/s', low=0.0, high=1000.0)
    desired_standstill_gap_m: float = param(
        'the d_s inside the relative-distance feature f_rd, fitted to human drivers '
        '(docs/DRIVER_IRL.md); the hard gap bound uses standstill_gap_m', unit='m', low=0.0,
        high=1000.0)
    assumed_av_accel_min_mps2: float = param(
        "the AV's braking the human allows for in its gap bound: it plans d_H >= d_s against "
        "the AV at min(expected, this) at every step (Gipps 1981); the AV's u_R,min",
        unit='m/s^2', low=-100.0, high=0.0, default=-3.0)
    cautious: bool = param(
        'true: the gap bound assumes the AV brakes at min(expected, assumed_av_accel_min_mps2) '
        '(the worst case, never below d_s); false: at min(expected, 0) - av_extra_decel_mps2 '
        '(the fitted caution of a human driver)', default=True)
    av_extra_decel_mps2: float = param(
        "fitted caution a_extra: with cautious false, the braking beyond the expected plan's "
        "that the human's gap bound allows for", unit='m/s^2', low=0.0, high=6.0, default=0.0)

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


def bound_av_accels(config: DriverConfig, expected_mps2: np.ndarray) -> np.ndarray:
    """The AV accelerations the human's gap bound is planned against, m/s^2.

    ``cautious``: min(expected, ``assumed_av_accel_min_mps2``); otherwise
    min(expected, 0) - ``av_extra_decel_mps2``. Works elementwise on any shape.

    Args:
        config: The driver's parameters.
        expected_mps2: The AV plan the human expects (any shape), m/s^2.
    """
    expected = np.asarray(expected_mps2, dtype=float)
    if config.cautious:
        return np.asarray(np.minimum(expected, config.assumed_av_accel_min_mps2), dtype=float)
    return np.asarray(np.minimum(expected, 0.0) - config.av_extra_decel_mps2, dtype=float)


SOLVED = 'Solve_Succeeded'
"""The status of a solved step (the word of CasADi's SQP, which the AV planner reports)."""
DAQP_EXIT_FLAGS = {-1: 'infeasible', -2: 'cycling', -3: 'unbounded', -4: 'iteration limit'}
"""DAQP's failure exit flags (``include/constants.h`` of darnstrom/daqp: EXIT_INFEASIBLE,
EXIT_CYCLE, EXIT_UNBOUNDED, EXIT_ITERLIMIT); 1 and 2 are (soft) optimal."""


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
        gap0, speed0, av_speed0 = ca.SX.sym('gap0'), ca.SX.sym('speed0'), ca.SX.sym('av_speed0')
        expected = ca.SX.sym('expected', n)
        weights = ca.SX.sym('weights', len(FEATURE_NAMES))
        cautious = ca.SX.sym('cautious_av_speeds', n)
        u_list = [u[k] for k in range(n)]
        e_list = [expected[k] for k in range(n)]
        feats = features(gap0, speed0, av_speed0, u_list, e_list, dt_s=config.dt_s,
                         standstill_gap_m=config.desired_standstill_gap_m,
                         time_headway_s=config.time_headway_s,
                         desired_speed_mps=config.speed_max_mps)
        cost = ca.dot(weights, ca.vertcat(*feats))
        # The gap bound against the cautious AV prediction; d^1 is fixed, so k = 2..N.
        gaps, speeds = kinematics.rollout(gap0, speed0, [cautious[k] for k in range(n)],
                                            u_list, config.dt_s)
        g = ca.vertcat(*gaps[1:], *speeds)
        self._lbg = np.concatenate([np.full(n - 1, config.standstill_gap_m),
                                    np.full(n, config.speed_min_mps)])
        self._ubg = np.concatenate([np.full(n - 1, np.inf), np.full(n, config.speed_max_mps)])
        self._lbx = np.full(n, config.accel_min_mps2)
        self._ubx = np.full(n, config.accel_max_mps2)
        self._solver = ca.qpsol('driver_mpc', 'daqp',
                                {'x': u, 'f': cost, 'g': g,
                                 'p': ca.vertcat(gap0, speed0, av_speed0, expected, weights,
                                                 cautious)},
                                qp_options(config.solver_max_iter))

    def reset(self) -> None:
        """Nothing to forget: each step is one QP solve from its inputs alone (DAQP takes no
        starting point; over 2,876 random states a different ``x0`` changed no plan's bits)."""

    def cautious_av_speeds(self, av_speed_mps: float,
                           expected_mps2: Sequence[float] | np.ndarray) -> np.ndarray:
        """AV speeds at steps 0..N-1 that the gap bound is planned against, m/s.

        The AV accelerates at :func:`bound_av_accels` at every step and never reverses.
        """
        c = self.config
        speeds = [max(float(av_speed_mps), 0.0)]
        for accel in bound_av_accels(c, np.asarray(expected_mps2, dtype=float))[:-1]:
            speeds.append(max(speeds[-1] + float(accel) * c.dt_s, 0.0))
        return np.array(speeds)

    def braking_plan(self, speed_mps: float) -> np.ndarray:
        """The hardest braking plan (:func:`kinematics.hardest_plan`): u_min at every step,
        never below ``speed_min_mps``; the gap bound is feasible exactly when it meets it."""
        c = self.config
        return np.array(kinematics.hardest_plan(speed_mps, c.horizon_steps, c.dt_s,
                                                c.accel_min_mps2, c.accel_max_mps2,
                                                c.speed_min_mps, braking=True))

    def _meet_bound(self, plan_mps2: np.ndarray, gap_m: float, speed_mps: float,
                    cautious_mps: np.ndarray, bounds_m: np.ndarray) -> np.ndarray:
        """The QP's plan with each acceleration lowered just enough that the gaps d^2..d^N
        meet ``bounds_m`` exactly.

        The QP meets its constraints only to its tolerance (measured: 5e-8 m/s^2 of creep per
        step while stopped behind a stopped AV, 1e-6 m below d_s after 20 s); u^k first acts
        on d^{k+2}, and lowering it raises every later gap.
        """
        dt = self.config.dt_s
        plan = plan_mps2.copy()
        for k in range(len(plan) - 1):
            gaps, _ = kinematics.rollout(gap_m, speed_mps, list(cautious_mps), list(plan), dt)
            shortfall = bounds_m[k] - gaps[k + 1]
            if shortfall > 0.0:
                plan[k] -= shortfall / dt ** 2
        return plan

    def step(self, gap_m: float, speed_mps: float, av_speed_mps: float,
             expected_mps2: np.ndarray) -> DriverResult:
        """Plan the human's next N accelerations against the expected AV plan.

        When the gap bound cannot be met (:meth:`braking_plan` misses it by more than
        :data:`BOUND_FEASIBILITY_TOLERANCE_M`), the result is the braking plan with status
        ``fallback: gap_bound_infeasible``; when the solver fails, the fallback controller
        :func:`kinematics.hold_gap_plan` against the cautious AV prediction. Both have
        ``success`` False (counted as driver fallbacks). A solved plan is corrected to meet
        the bound exactly (:meth:`_meet_bound`).

        Args:
            gap_m: gap from the human's front bumper to the AV's rear bumper, m.
            speed_mps: human's speed, m/s.
            av_speed_mps: AV's current speed, m/s.
            expected_mps2: the AV plan the human expects, N values, m/s^2.
        """
        c, n = self.config, self.config.horizon_steps
        cautious = self.cautious_av_speeds(av_speed_mps, expected_mps2)
        start = time.perf_counter()
        braking = self.braking_plan(speed_mps)
        reach, _ = kinematics.rollout(gap_m, speed_mps, list(cautious), list(braking), c.dt_s)
        if min(reach[1:], default=np.inf) < c.standstill_gap_m - BOUND_FEASIBILITY_TOLERANCE_M:
            LOG.debug('driver gap bound infeasible: braking plan reaches %.3f m', min(reach[1:]))
            return DriverResult(braking, 'fallback: gap_bound_infeasible', False, 0,
                                time.perf_counter() - start)
        lbg = self._lbg.copy()
        lbg[:n - 1] = np.minimum(lbg[:n - 1], reach[1:])
        params = np.concatenate([[gap_m, speed_mps, av_speed_mps], expected_mps2, c.weights,
                                 cautious])
        sol = solve(self._solver, p=params, lbx=self._lbx, ubx=self._ubx, lbg=lbg,
                    ubg=self._ubg)
        elapsed = time.perf_counter() - start
        stats = self._solver.stats()
        iterations = 1                      # one QP solve (DAQP does not report its count)
        if stats['success']:
            plan = self._meet_bound(np.asarray(sol['x']).ravel(), gap_m, speed_mps, cautious,
                                    lbg[:n - 1])
            return DriverResult(plan, SOLVED, True, iterations, elapsed)
        plan = np.asarray(kinematics.hold_gap_plan(
            gap_m, speed_mps, list(cautious), dt_s=c.dt_s, standstill_gap_m=c.standstill_gap_m,
            time_headway_s=c.time_headway_s, gap_gain_per_s2=c.fallback_gap_gain_per_s2,
            speed_gain_per_s=c.fallback_speed_gain_per_s, accel_min_mps2=c.accel_min_mps2,
            accel_max_mps2=c.accel_max_mps2, speed_min_mps=c.speed_min_mps,
            speed_max_mps=c.speed_max_mps))
        flag = stats['return_status']
        status = f'DAQP {DAQP_EXIT_FLAGS.get(flag, "failed")} (exit flag {flag})'
        LOG.debug('driver MPC fallback (%s)', status)
        return DriverResult(plan, f'fallback: {status}', False, iterations, elapsed)


def build(config: DriverConfig, params: None) -> DriverMpc:
    """The fitted MPC follower: its weights are the ``human_driver`` section's
    (:class:`DriverConfig`), so it declares no parameters of its own."""
    return DriverMpc(config)


COMPONENT = Component(
    name='mpc', factory=build,
    description='MPC follower of eq. (13) with the IRL-fitted feature weights (the paper)')
"""Registered as ``mpc`` in ``trust_av.drivers`` (human_driver_sim's setup.py)."""
