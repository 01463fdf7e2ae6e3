"""Definitions of E, RMSE and the expectation tried for the 1 Hz vs 10 Hz comparison
(docs/MODEL.md and docs/RESULTS.md, "Control rate"): the in-process loop at 1 Hz and at a
faster rate, with one piece of the faster loop replaced, and every score computed from the
same records. Prints one Markdown row per case: 1 Hz / fast value (change) of each score.

A measurement tool, not a planner option: a variant swaps a function or attribute of the
loop for this process only. Variants (join with ``+``):

- ``main``: the shipped loop (1 s estimator samples aligned to the run's whole seconds);
- ``sliding``: the 1 s samples end at every tick (no expectation age), both estimators;
- ``ca-every-tick``: the CA estimator fed every tick (the latest tick's acceleration held);
- ``mean-e``: E on the 1 s means of the plan and the expectation, in the NMPC and the
  monitor (the 1 s grid is the identity);
- ``held-lead``: the lead's speed held between its 1 s samples (the 1 Hz loop's lead),
  instead of interpolated;
- ``model-step``: the NMPC on the paper's 1 s grid at the faster rate (``prediction_grid:
  model_step``, sampled-data control);
- ``blocked-commands``: the NMPC on the control period's grid, its plan held in the 1 s blocks
  of the expectation (the first block is the rest of the current second): the AV plans in the
  steps in which the human forms the expectation, and is still checked every period.

Scores from the records: ``E`` and ``RMSE`` (the definitions of the metrics), ``E@points``
(plan and expectation compared at k * dt_s only), ``E@1s-means`` (their 1 s means),
``E@whole-s`` (the mean of E over the steps at whole seconds only), ``RMSE@points`` (the
expectation at k * dt_s against the command executed then), ``RMSE@1s-means`` (1 s means of
the expectation against 1 s means of what was executed).

Usage: python scripts/rate_variants.py sliding [--rate-hz 10] [--traces us06] [--max-steps-s S]
"""

from __future__ import annotations

import argparse
import dataclasses
import math
from collections.abc import Callable
from typing import Any

import casadi as ca
import numpy as np

from preceding_traffic.traces import SpeedTrace, truncate
from trust_av.system.closed_loop import control_trace, simulate
from trust_av.system.config import RunConfig, load_run_config
from trust_av.system.metrics import StepRecord, expectation_errors, ticks_per_model_step
from trust_av_common import kinematics
from trust_av_common.solver import nmpc_solver_options
from trust_av_planner import nmpc, planner
from trust_av_planner.predictors.ca import ConstantAccelerationPredictor
from trust_av_planner.preview import hold_on_grid
from trust_monitor import paper_trust as trust_model

VARIANTS = ('main', 'sliding', 'ca-every-tick', 'mean-e', 'held-lead', 'model-step',
            'blocked-commands')
SCORES = ('trust', 'E', 'E@points', 'E@1s-means', 'E@whole-s', 'RMSE', 'RMSE@points',
          'RMSE@1s-means')


def _one_second_means(values: list[Any], ticks: int) -> list[Any]:
    """Means over consecutive blocks of ``ticks`` values (floats or CasADi symbols)."""
    out = []
    for start in range(0, len(values), ticks):
        total = values[start]
        for value in values[start + 1:start + ticks]:
            total = total + value
        out.append(total / ticks)
    return out


def _mean_e(score: Callable[..., Any], horizon_steps: int) -> Callable[..., Any]:
    """E on the 1 s means of both plans (a plan on the model grid is left as it is)."""
    def scored(plan: Any, expected: Any, epsilon_mps2: float) -> Any:
        plan, expected = list(plan), list(expected)
        if len(plan) == horizon_steps or len(plan) % horizon_steps:
            return score(plan, expected, epsilon_mps2)
        ticks = len(plan) // horizon_steps
        return score(_one_second_means(plan, ticks), _one_second_means(expected, ticks),
                     epsilon_mps2)
    return scored


class _BlockedSolver:
    """The NMPC's solver with its plan held in the expectation's 1 s blocks: it takes and
    returns the plan on the prediction grid, so :meth:`TrustAwareNmpc.step` (warm start,
    bound check, fallback) is unchanged."""

    def __init__(self, owner: nmpc.TrustAwareNmpc) -> None:
        c, n, dt = owner.config, owner.steps, owner.grid_step_s
        blocks = c.horizon_steps
        w, mapping = ca.SX.sym('w', blocks), ca.SX.sym('blocks', n, blocks)
        u = ca.mtimes(mapping, w)
        gap0, speed0 = ca.SX.sym('gap0'), ca.SX.sym('speed0')
        lead, expected, alpha = ca.SX.sym('lead', n), ca.SX.sym('expected', n), ca.SX.sym('a')
        plan = [u[k] for k in range(n)]
        gaps, speeds = kinematics.rollout(gap0, speed0, [lead[k] for k in range(n)], plan, dt)
        tracking = sum((c.standstill_gap_m + c.time_headway_s * speeds[k] - gaps[k]) ** 2
                       for k in range(n)) * (c.horizon_steps / n)
        score = trust_model.explicability(plan, [expected[k] for k in range(n)],
                                          owner.trust.epsilon_mps2)
        self.solver = ca.nlpsol('blocked_nmpc', 'sqpmethod', {
            'x': w, 'f': tracking / c.tracking_cost_scale_m2 + alpha * score
            / c.explicability_scale, 'g': ca.vertcat(*gaps[1:], *speeds, score),
            'p': ca.vertcat(gap0, speed0, lead, expected, alpha, ca.reshape(mapping, -1, 1))},
            nmpc_solver_options(c.solver_max_iter, blocks))
        self.owner, self.age_s = owner, 0.0

    def matrix(self) -> np.ndarray:
        """Which block each point of the prediction grid belongs to, at the current age."""
        o = self.owner
        blocks = o.config.horizon_steps
        index = hold_on_grid(np.arange(blocks, dtype=float), o.config.dt_s, o.grid_step_s,
                             o.steps, self.age_s).astype(int)
        out = np.zeros((o.steps, blocks))
        out[np.arange(o.steps), index] = 1.0
        return out

    def __call__(self, x0: np.ndarray, p: np.ndarray, **bounds: Any) -> dict[str, Any]:
        mapping = self.matrix()
        first = mapping.argmax(axis=0)  # the first point of each block (0 if unused)
        sol = self.solver(x0=np.asarray(x0)[first], p=np.concatenate(
            [np.asarray(p).ravel(), mapping.ravel(order='F')]), **bounds)
        return {'x': mapping @ np.asarray(sol['x']).ravel(), 'f': sol['f']}

    def stats(self) -> dict[str, Any]:
        return self.solver.stats()  # type: ignore[no-any-return]


def apply_variant(parts: set[str], config: RunConfig) -> None:
    """Replace the pieces named in ``parts`` for this process.

    Raises:
        SystemExit: an unknown variant.
    """
    unknown = parts - set(VARIANTS)
    if unknown:
        raise SystemExit(f'unknown variant(s) {", ".join(sorted(unknown))}; known: '
                         f'{", ".join(VARIANTS)}')
    shipped_init = planner.AvPlanner.__init__

    def init(self: planner.AvPlanner, *args: Any, **kwargs: Any) -> None:
        shipped_init(self, *args, **kwargs)
        if self.sampler is None:
            return
        if 'ca-every-tick' in parts and isinstance(self.predictor,
                                                   ConstantAccelerationPredictor):
            self.sampler = None  # observed every tick, its plan held from now
        elif 'sliding' in parts:
            self.sampler.aligned = False
        if 'blocked-commands' in parts:
            self.nmpc._solver = _BlockedSolver(self.nmpc)  # type: ignore[assignment]

    planner.AvPlanner.__init__ = init  # type: ignore[method-assign]
    if 'blocked-commands' in parts:
        shipped_expect = planner.AvPlanner.expect

        def expect(self: planner.AvPlanner, *args: Any) -> tuple[np.ndarray, float]:
            expected, age_s = shipped_expect(self, *args)
            if isinstance(self.nmpc._solver, _BlockedSolver):
                self.nmpc._solver.age_s = age_s
            return expected, age_s

        planner.AvPlanner.expect = expect  # type: ignore[method-assign,assignment]
    if 'mean-e' in parts:
        scored = _mean_e(trust_model.explicability, config.planner.horizon_steps)
        nmpc.explicability = scored  # type: ignore[assignment]
        trust_model.explicability = scored  # type: ignore[assignment]


def loop_trace(config: RunConfig, rate_hz: float, parts: set[str],
               max_steps_s: float) -> SpeedTrace:
    """The trace at ``rate_hz``: interpolated, or (``held-lead``) the 1 s samples held."""
    trace = control_trace(config, rate_hz)
    if 'held-lead' in parts and rate_hz != 1.0:
        ticks = ticks_per_model_step(1.0 / rate_hz, config.planner.dt_s)
        base = control_trace(config, 1.0)
        held = np.repeat(base.speeds_mps, ticks)[:trace.speeds_mps.size]
        trace = dataclasses.replace(trace, speeds_mps=held)
    if max_steps_s:
        trace = truncate(trace, round(max_steps_s * rate_hz))
    return trace


def scores(records: list[StepRecord], ticks: int, epsilon_mps2: float,
           plan_step_s: float | None = None) -> dict[str, float]:
    """Every score of :data:`SCORES` from one run's records (``ticks`` per model step; plans
    on the grid of ``plan_step_s``, None = the control period)."""
    executed = np.array([r.av_accel_mps2 for r in records])
    per_point = 1 if plan_step_s is not None else ticks  # plan points per model step
    stride = ticks // per_point  # control steps per plan point
    e_points, e_means, at_points, at_means = [], [], [], []
    for t, r in enumerate(records):
        plan, expected = np.array(r.av_plan_mps2), np.array(r.expected_plan_mps2)
        e_points.append(trust_model.explicability(plan[::per_point].tolist(),
                                                  expected[::per_point].tolist(), epsilon_mps2))
        e_means.append(trust_model.explicability(
            _one_second_means(plan.tolist(), per_point),
            _one_second_means(expected.tolist(), per_point), epsilon_mps2))
        for k in range(0, expected.size, per_point):
            if t + k * stride + ticks <= executed.size:
                at_points.append(expected[k] - executed[t + k * stride])
                at_means.append(expected[k:k + per_point].mean()
                                - executed[t + k * stride:t + k * stride + ticks].mean())
    errors = expectation_errors(records, plan_step_s).tolist()

    def rms(values: list[float]) -> float:
        return math.sqrt(float(np.mean(np.square(values))))

    return {'trust': records[-1].trust,
            'E': float(np.mean([r.explicability for r in records])),
            'E@points': float(np.mean(e_points)), 'E@1s-means': float(np.mean(e_means)),
            'E@whole-s': float(np.mean([r.explicability for r in records[::ticks]])),
            'RMSE': rms(errors), 'RMSE@points': rms(at_points), 'RMSE@1s-means': rms(at_means)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('variant', help=f'one of {", ".join(VARIANTS)}, or several joined '
                                        'with +')
    parser.add_argument('--rate-hz', type=float, default=10.0)
    parser.add_argument('--traces', default='us06,commute_am')
    parser.add_argument('--predictors', default='ca,gru')
    parser.add_argument('--alphas', default='0,1')
    parser.add_argument('--max-steps-s', type=float, default=0.0,
                        help='only the first S seconds of each trace (0: all)')
    args = parser.parse_args()
    parts = set(args.variant.split('+')) - {'main'}
    print(f'| case ({args.variant}, 1 / {args.rate_hz:g} Hz) | ' + ' | '.join(SCORES)
          + ' | fallbacks / unsafe steps |')
    print('|---|' + '---|' * len(SCORES) + '---|')
    applied = False
    for trace in args.traces.split(','):
        for predictor in args.predictors.split(','):
            for alpha in (float(a) for a in args.alphas.split(',')):
                grid = {'prediction_grid': 'model_step'} if 'model-step' in parts else {}
                config = load_run_config(overrides={
                    'planner': {'alpha': alpha, 'predictor': predictor, **grid},
                    'preceding_traffic': {'trace': trace}})
                if not applied:
                    apply_variant(parts, config)
                    applied = True
                ticks = ticks_per_model_step(1.0 / args.rate_hz, config.planner.dt_s)
                one = simulate(config, loop_trace(config, 1.0, parts, args.max_steps_s))
                fast = simulate(config, loop_trace(config, args.rate_hz, parts,
                                                   args.max_steps_s))
                eps = config.trust.epsilon_mps2
                s1 = scores(one.records, 1, eps)
                sf = scores(fast.records, ticks, eps, fast.plan_step_s)
                cells = [f'{s1[k]:.5g} / {sf[k]:.5g} ({100 * (sf[k] - s1[k]) / s1[k]:+.1f} %)'
                         for k in SCORES]
                m = fast.metrics
                print(f'| {trace} {predictor} {alpha:g} | ' + ' | '.join(cells)
                      + f' | {m.fallback_steps} / {m.unsafe_steps} |', flush=True)


if __name__ == '__main__':
    main()
