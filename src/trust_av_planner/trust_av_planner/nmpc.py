"""Trust-aware nonlinear MPC of the automated vehicle, eq. (12) of Ozkan & Ma.

Decision: the plan u_R^0..u_R^{N-1} (m/s^2). For the predicted states k = 1..N (the ones
the plan influences)::

    min  sum_k (d_s + tau v^k - d^k)^2 / tracking_cost_scale_m2
         + alpha * E(u, u^H) / explicability_scale
    s.t. d_min <= d^k <= d_max,  v_min <= v^k <= v_max,  u_min <= u^k <= u_max,
         E(u, u^H) <= E_max(T)                     (the trust constraint T^k >= T_min)

with the dynamics of :mod:`trust_av_common.kinematics` and E of
:func:`trust_monitor.paper_trust.explicability` (each written once). The trust constraint is
the exact smooth equivalent of propagating the trust model's update over the horizon: the
largest admissible E of :func:`trust_monitor.model_interface.explicability_bound` (a closed
form for ``paper``, a bisection on their own update for the others).

The NLP is built once (CasADi SX, ``sqpmethod`` with the ``qrqp`` active-set QP solver),
warm-started from the shifted previous plan. A solve that fails, that (against the wall
clock only: ``cpu_budget``) uses more thread CPU time than ``solver_cpu_budget_s``, or whose
plan breaks a bound by more than :data:`BOUND_TOLERANCE`, is replaced by the documented
fallback plan (:func:`trust_av_common.kinematics.hold_gap_plan`), reported in the status.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import time
from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np

from trust_av_common import kinematics, registry
from trust_av_common.params import (
    PARAM_METADATA_KEY,
    check_fields,
    control_step_param,
    param,
    require,
)
from trust_av_common.solver import nmpc_solver_options, solve
from trust_av_planner import perturbations
from trust_av_planner.plan_result import PlanResult
from trust_av_planner.predictors import PREDICTORS
from trust_monitor.model_interface import CheckedBound, TrustModel, make_trust_model
from trust_monitor.paper_trust import TrustConfig, explicability

__all__ = ['BOUND_TOLERANCE', 'LEAD_PREVIEWS', 'PlanResult', 'PlannerConfig', 'TrustAwareNmpc',
           'prediction_grid']

LOG = logging.getLogger(__name__)

LEAD_PREVIEWS = ('recorded', 'constant_speed', 'constant_acceleration')
"""Where the lead's speed over the horizon comes from (parameter ``lead_preview``)."""

PREDICTION_GRIDS = ('control_period', 'model_step')
"""The NMPC's prediction grid (parameter ``prediction_grid``, :func:`prediction_grid`)."""

MAX_GRID_STEPS = 300
"""Largest prediction grid (steps) the NMPC is built with."""

BOUND_TOLERANCE = 1e-6
"""Largest bound violation (m, m/s, m/s^2 or E) accepted from the solver."""

STATIONARY_STATUS = 'Search_Direction_Becomes_Too_Small'
"""SQP stopped because its step vanished: the iterate cannot move. Accepted when it passes the
bound check (it happens at standstill at d_min, where the feasible set shrinks to one point and
the active gap and speed bounds have opposite gradients); otherwise the step falls back."""

BUILT = 'built into the NMPC at start-up'
SAFETY = 'a safety bound: fixed while the vehicle drives'
ESTIMATOR = 'the plan estimator and its history are built at start-up'


@dataclass(frozen=True)
class PlannerConfig:
    """Parameters of the AV's NMPC (Table I and docs/MODEL.md).

    ``read_only=False`` marks the parameters a running node (wall mode) lets a test driver
    change with ``set_parameters``; every other one says why it is fixed.
    """

    dt_s: float = control_step_param("model step: the paper's 1 s grid of the plan estimator "
                                     'and the horizon',
                                     reason='the prediction grid and the estimator are built at '
                                            'start-up')
    horizon_steps: int = param('prediction horizon N in model steps (horizon = N dt_s)',
                               unit='steps', low=1, high=50, reason=BUILT)
    standstill_gap_m: float = param('standstill gap d_s', unit='m', low=0.0, high=1000.0,
                                     reason=BUILT)
    time_headway_s: float = param('desired time headway tau_R of the CTH policy', unit='s',
                                  low=0.0, high=100.0, reason=BUILT)
    gap_min_m: float = param('minimum gap to the preceding traffic d_R,min', unit='m', low=0.0,
                             high=10_000.0, reason=SAFETY)
    gap_max_m: float = param('maximum gap to the preceding traffic d_R,max', unit='m',
                             low=0.0, high=10_000.0, reason=SAFETY)
    speed_min_mps: float = param('lower speed bound', unit='m/s', low=0.0, high=100.0,
                                 reason=SAFETY)
    speed_max_mps: float = param('upper speed bound (the orchestrator passes max(v_PT))',
                                 unit='m/s', low=0.0, high=100.0, reason=SAFETY)
    accel_min_mps2: float = param('lower acceleration bound u_R,min', unit='m/s^2', low=-100.0,
                                  high=0.0, high_inclusive=False, reason=SAFETY)
    accel_max_mps2: float = param('upper acceleration bound u_R,max', unit='m/s^2', low=0.0,
                                  low_inclusive=False, high=100.0, reason=SAFETY)
    trust_min: float = param('minimum trust T_min over the horizon, eq. (12)', low=-1e6,
                             high=1e6, read_only=False)
    alpha: float = param('relative weight of explicability in the cost, eq. (4)', low=0.0,
                         high=1.0, read_only=False)
    tracking_cost_scale_m2: float = param('scale of the CTH tracking cost', unit='m^2', low=0.0,
                                          low_inclusive=False, high=1e12, reason=BUILT)
    explicability_scale: float = param('scale of the explicability cost', low=0.0,
                                       low_inclusive=False, high=1e12, reason=BUILT)
    solver_max_iter: int = param('SQP iterations before the step falls back', low=1,
                                 high=10_000, reason=BUILT)
    solver_cpu_budget_s: float = param('wall mode: CPU time per solve before the step falls '
                                       'back', unit='s', low=0.0, low_inclusive=False,
                                       high=60.0, read_only=False)
    fallback_gap_gain_per_s2: float = param('gap gain of the fallback controller',
                                            unit='1/s^2', low=0.0, high=1000.0, reason=SAFETY)
    fallback_speed_gain_per_s: float = param('speed gain of the fallback controller',
                                             unit='1/s', low=0.0, high=1000.0, reason=SAFETY)
    predictor: str = param('estimator of the plan the human expects: a registered plan '
                           'estimator (entry-point group trust_av.predictors)',
                           reason=ESTIMATOR)
    time_headway_cap_s: float = param('cap of the time headway d_H / v_H when the human is '
                                      'stopped', unit='s', low=0.0, low_inclusive=False,
                                      high=1000.0, reason=ESTIMATOR)
    lead_preview: str = param("the lead's speed over the horizon: the recorded preview topic, "
                              'or built from its odometry (constant speed or constant '
                              'acceleration)', choices=LEAD_PREVIEWS, default='recorded',
                              reason='selects the input topics at start-up')
    lead_accel_window_s: float = param("constant_acceleration: the lead's acceleration is its "
                                       'speed change over this window', unit='s', low=0.0,
                                       low_inclusive=False, high=3600.0, default=1.0,
                                       reason=SAFETY)
    prediction_grid: str = param('NMPC grid: control_period (N = horizon / period) or '
                                 'model_step (dt_s, sampled-data control)',
                                 choices=PREDICTION_GRIDS, default='control_period',
                                 reason=BUILT)
    stale_decel_mps2: float = param('wall mode: acceleration commanded while an input is '
                                    'missing or stale (>= accel_min_mps2)', unit='m/s^2',
                                    low=-100.0, high=0.0, high_inclusive=False, default=-2.0,
                                    reason=SAFETY)
    perturbation: str = perturbations.CONDITION_PARAM
    perturbation_seed: int = perturbations.SEED_PARAM

    def __post_init__(self) -> None:
        check_fields(self)
        require(self.gap_min_m < self.gap_max_m,
                f'need 0 <= gap_min_m < gap_max_m, got {self.gap_min_m}, {self.gap_max_m}')
        require(self.speed_min_mps < self.speed_max_mps,
                f'need 0 <= speed_min_mps < speed_max_mps, got {self.speed_min_mps}, '
                f'{self.speed_max_mps}')
        predictors = registry.names(PREDICTORS)
        require(self.predictor in predictors,
                registry.not_one_of('predictor', self.predictor, predictors))
        require(self.stale_decel_mps2 >= self.accel_min_mps2, 'stale_decel_mps2 must be >= '
                f'accel_min_mps2 = {self.accel_min_mps2:g}, got {self.stale_decel_mps2:g}')

    @property
    def horizon_s(self) -> float:
        """Length of the prediction horizon, s."""
        return self.horizon_steps * self.dt_s


def prediction_grid(config: PlannerConfig, period_s: float | None = None) -> tuple[float, int]:
    """The NMPC's prediction grid (step in s, number of steps) at a control period
    ``period_s`` (None = ``dt_s``, lock-step).

    ``control_period``: the plan is predicted on the control period's grid over the same
    horizon in seconds, N = round(horizon_s / period) (at the paper's 1 s period exactly
    ``dt_s`` and ``horizon_steps``). ``model_step``: sampled-data control over the 1 s grid
    whatever the period.

    Raises:
        ValueError: the period is not > 0, is longer than ``dt_s`` (the estimators take a
            sample every model step), or the grid would have more than
            :data:`MAX_GRID_STEPS` steps.
    """
    if period_s is None:
        return config.dt_s, config.horizon_steps
    if not period_s > 0.0:
        raise ValueError(f'control period must be > 0 s, got {period_s}')
    if period_s > config.dt_s * (1.0 + 1e-12):
        raise ValueError(f'a {period_s:g} s control period is longer than the model step dt_s '
                         f'= {config.dt_s:g} s, which the plan estimators sample: use a rate '
                         f'of at least {1.0 / config.dt_s:g} Hz')
    if config.prediction_grid == 'model_step':
        return config.dt_s, config.horizon_steps
    if abs(period_s - config.dt_s) <= 1e-12 * config.dt_s:
        return config.dt_s, config.horizon_steps
    steps = max(1, round(config.horizon_s / period_s))
    if steps > MAX_GRID_STEPS:
        raise ValueError(f'a {config.horizon_s:g} s horizon at a {period_s:g} s period needs '
                         f'{steps} steps (at most {MAX_GRID_STEPS}); lower the control rate '
                         'or use prediction_grid model_step')
    return period_s, steps


class TrustAwareNmpc:
    """The AV's trust-aware NMPC; build once, call :meth:`step` every step.

    Args:
        config: the planner's parameters.
        trust: the trust model (its per-second rule bounds E over the horizon).
        period_s: the control period, s (None = ``dt_s``): the prediction grid is
            :func:`prediction_grid`.
        cpu_budget: a solve over ``solver_cpu_budget_s`` of thread CPU time falls back (wall
            clock). Off in lock-step and in-process runs, whose results must not depend on
            timing (docs/MODEL.md): ``solver_max_iter`` alone bounds the work there.

    Attributes:
        grid_step_s: step of the prediction grid, s.
        steps: number of predicted steps N on that grid.
    """

    def __init__(self, config: PlannerConfig, trust: TrustConfig,
                 period_s: float | None = None, *, cpu_budget: bool = False,
                 trust_model: TrustModel | None = None) -> None:
        self.config = config
        self.trust = trust
        self.trust_model = make_trust_model(trust) if trust_model is None else trust_model
        self.e_max_of = CheckedBound(self.trust_model, trust.trust_model)
        self.cpu_budget = cpu_budget
        self.grid_step_s, self.steps = prediction_grid(config, period_s)
        n, dt = self.steps, self.grid_step_s
        u = ca.SX.sym('u', n)
        gap0, speed0 = ca.SX.sym('gap0'), ca.SX.sym('speed0')
        lead = ca.SX.sym('lead', n)
        expected = ca.SX.sym('expected', n)
        alpha = ca.SX.sym('alpha')
        gaps, speeds = kinematics.rollout(gap0, speed0, [lead[k] for k in range(n)],
                                            [u[k] for k in range(n)], dt)
        tracking = sum((config.standstill_gap_m + config.time_headway_s * speeds[k] - gaps[k])
                       ** 2 for k in range(n))
        if n != config.horizon_steps:
            # The same cost per second of horizon on a finer grid (a Riemann sum of the gap
            # error over the horizon): the trade-off against E does not depend on the rate.
            tracking = tracking * (config.horizon_steps / n)
        score = explicability([u[k] for k in range(n)], [expected[k] for k in range(n)],
                              trust.epsilon_mps2)
        cost = (tracking / config.tracking_cost_scale_m2
                + alpha * score / config.explicability_scale)
        params = ca.vertcat(gap0, speed0, lead, expected, alpha)
        # d^1 does not depend on the plan: a constant row would break the QP's constraint
        # qualification, so it only enters the bounds of the later gaps
        # (:meth:`_reachable_gap_bounds`).
        constraints = ca.vertcat(*gaps[1:], *speeds, score)
        self._solver = ca.nlpsol('trust_aware_nmpc', 'sqpmethod',
                                 {'x': u, 'p': params, 'f': cost, 'g': constraints},
                                 nmpc_solver_options(config.solver_max_iter, n))
        self._lower = np.concatenate([np.full(n, config.gap_min_m),
                                      np.full(n, config.speed_min_mps), [-np.inf]])
        self._upper = np.concatenate([np.full(n, config.gap_max_m),
                                      np.full(n, config.speed_max_mps), [np.inf]])
        self._previous: np.ndarray | None = None

    def retune(self, config: PlannerConfig) -> None:
        """Take new values of the run-time parameters (``read_only=False``) from the next
        step on.

        Raises:
            ValueError: ``config`` differs in a parameter the NMPC was built with.
        """
        fixed = [f.name for f in dataclasses.fields(PlannerConfig)
                 if f.metadata[PARAM_METADATA_KEY].read_only
                 and getattr(config, f.name) != getattr(self.config, f.name)]
        if fixed:
            raise ValueError(f'read-only parameter(s) changed: {", ".join(fixed)}')
        self.config = config

    def reset(self) -> None:
        """Forget the warm start."""
        self._previous = None

    def bounds(self, explicability_max: float) -> tuple[np.ndarray, np.ndarray]:
        """Bounds of the constraint vector (gaps d^1..d^N, speeds v^1..v^N, E)."""
        upper = self._upper.copy()
        upper[-1] = explicability_max
        return self._lower, upper

    def step(self, gap_m: float, speed_mps: float, lead_speeds_mps: np.ndarray,
             expected_mps2: np.ndarray, trust: Any) -> PlanResult:
        """Plan the next N accelerations.

        Args:
            gap_m: gap to the preceding traffic, m.
            speed_mps: AV speed, m/s.
            lead_speeds_mps: preview of the preceding traffic's speed on the prediction
                grid, N values, m/s.
            expected_mps2: the plan the human expects u_R^H on the prediction grid, N
                values, m/s^2.
            trust: the trust model's current state (for ``paper``: T(t) itself).

        Returns:
            The plan and the solver's report; never raises for an infeasible problem.
        """
        c, n, dt = self.config, self.steps, self.grid_step_s
        e_max = self.e_max_of(trust, c.trust_min, n, dt)
        params = np.concatenate([[gap_m, speed_mps], lead_speeds_mps, expected_mps2, [c.alpha]])
        if e_max is None:
            return self._fallback(gap_m, speed_mps, lead_speeds_mps, 'trust below T_min',
                                  -1.0, 0, 0.0)
        e_max = min(e_max, 1.0)  # E < 1 always: larger bounds are inactive
        if self._previous is None:
            guess = np.zeros(n)
        else:
            guess = np.concatenate([self._previous[1:], self._previous[-1:]])
        lbg, ubg = self.bounds(e_max)
        low, high, note = self._reachable_gap_bounds(lbg, ubg, gap_m, speed_mps, lead_speeds_mps)
        # The bounds of (12) first, unless no plan can meet them (then the reachable ones); the
        # reachable ones again when (12) fails a rounding error short of them.
        tries = [(low, high)] if note else [(lbg, ubg)]
        if not note and (low is not lbg or high is not ubg):
            tries.append((low, high))
        start, cpu_start = time.perf_counter(), time.thread_time()
        iterations = 0
        for lower, upper in tries:
            sol, stats, used = self._solve(guess, params, lower, upper)
            iterations += used
            plan = np.asarray(sol['x']).ravel()
            solved = stats['success'] or stats['return_status'] == STATIONARY_STATUS
            violation = (self._violation(plan, gap_m, speed_mps, lead_speeds_mps, expected_mps2,
                                         lower, upper) if solved else math.inf)
            if violation <= BOUND_TOLERANCE:
                break
        elapsed, cpu = time.perf_counter() - start, time.thread_time() - cpu_start
        if self.cpu_budget and cpu > c.solver_cpu_budget_s:
            return self._fallback(gap_m, speed_mps, lead_speeds_mps,
                                  f'CPU budget exceeded ({cpu * 1e3:.3f} ms > '
                                  f'{c.solver_cpu_budget_s * 1e3:.3f} ms)', e_max, iterations,
                                  elapsed)
        if not solved:
            return self._fallback(gap_m, speed_mps, lead_speeds_mps,
                                  str(stats['return_status']), e_max, iterations, elapsed)
        if violation > BOUND_TOLERANCE:
            return self._fallback(gap_m, speed_mps, lead_speeds_mps,
                                  f'bound violated by {violation:.2e}', e_max, iterations,
                                  elapsed)
        self._previous = plan
        return PlanResult(plan, str(stats['return_status']) + note, True, iterations, elapsed,
                          e_max, float(sol['f']), gap_bounds_relaxed=bool(note))

    def _solve(self, guess: np.ndarray, params: np.ndarray, lower: np.ndarray,
               upper: np.ndarray) -> tuple[Any, dict[str, Any], int]:
        """One solve with these constraint bounds, retried cold when a warm start fails:
        the solution, the solver's stats and the SQP iterations of both calls."""
        c = self.config
        sol = solve(self._solver, x0=guess, p=params, lbx=c.accel_min_mps2,
                    ubx=c.accel_max_mps2, lbg=lower[1:], ubg=upper[1:])
        stats = self._solver.stats()
        iterations = int(stats.get('iter_count', 0))
        if not stats['success'] and self._previous is not None:
            # A warm start can stall SQP on degenerate corners (standstill at d_min): retry cold.
            sol = solve(self._solver, x0=np.zeros(self.steps), p=params, lbx=c.accel_min_mps2,
                        ubx=c.accel_max_mps2, lbg=lower[1:], ubg=upper[1:])
            stats = self._solver.stats()
            iterations += int(stats.get('iter_count', 0))
        return sol, stats, iterations

    def _reachable_gap_bounds(self, lower: np.ndarray, upper: np.ndarray, gap_m: float,
                              speed_mps: float, lead_speeds_mps: np.ndarray
                              ) -> tuple[np.ndarray, np.ndarray, str]:
        """``lower``/``upper`` with the gap bounds some plan meets
        (:func:`kinematics.reachable_gap_bounds`: stopped short of d_s, a cut-in, a lead far
        ahead), and a note for the status ('' when they are d_min and d_max to within
        :data:`BOUND_TOLERANCE`). The same objects when nothing changes."""
        c, n = self.config, self.steps
        low, high = kinematics.reachable_gap_bounds(
            c.gap_min_m, c.gap_max_m, gap_m, speed_mps, lead_speeds_mps.tolist(),
            self.grid_step_s, c.accel_min_mps2, c.accel_max_mps2, c.speed_min_mps,
            c.speed_max_mps)
        if min(low) >= c.gap_min_m and max(high) <= c.gap_max_m:
            return lower, upper, ''
        lower, upper = lower.copy(), upper.copy()
        lower[:n], upper[:n] = low, high
        if (min(low) >= c.gap_min_m - BOUND_TOLERANCE
                and max(high) <= c.gap_max_m + BOUND_TOLERANCE):
            return lower, upper, ''  # a rounding error (a stop that crept 1e-7 m too far)
        return lower, upper, (f' (gap bounds relaxed to what the vehicle can reach: '
                              f'{min(low):.3f} to {max(high):.3f} m)')

    def _violation(self, plan: np.ndarray, gap_m: float, speed_mps: float,
                   lead_speeds_mps: np.ndarray, expected_mps2: np.ndarray, lower: np.ndarray,
                   upper: np.ndarray) -> float:
        c = self.config
        accels = plan.tolist()
        gaps, speeds = kinematics.rollout(gap_m, speed_mps, lead_speeds_mps.tolist(), accels,
                                            self.grid_step_s)
        score = explicability(accels, expected_mps2.tolist(), self.trust.epsilon_mps2)
        values = gaps + speeds + [score]
        worst = max(max(lo - x, x - up) for lo, x, up in zip(lower, values, upper, strict=True))
        worst_accel = max(max(c.accel_min_mps2 - a, a - c.accel_max_mps2) for a in accels)
        return float(max(0.0, worst, worst_accel))

    def _fallback(self, gap_m: float, speed_mps: float, lead_speeds_mps: np.ndarray, reason: str,
                  e_max: float, iterations: int, elapsed: float) -> PlanResult:
        c = self.config
        plan = np.asarray(kinematics.hold_gap_plan(
            gap_m, speed_mps, list(lead_speeds_mps), dt_s=self.grid_step_s,
            standstill_gap_m=c.standstill_gap_m, time_headway_s=c.time_headway_s,
            gap_gain_per_s2=c.fallback_gap_gain_per_s2,
            speed_gain_per_s=c.fallback_speed_gain_per_s, accel_min_mps2=c.accel_min_mps2,
            accel_max_mps2=c.accel_max_mps2, speed_min_mps=c.speed_min_mps,
            speed_max_mps=c.speed_max_mps))
        LOG.debug('NMPC fallback (%s) at gap %.2f m, speed %.2f m/s', reason, gap_m, speed_mps)
        self._previous = None
        return PlanResult(plan, f'fallback: {reason}', False, iterations, elapsed, e_max)

