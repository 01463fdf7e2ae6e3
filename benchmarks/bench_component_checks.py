"""Benchmark of the per-step checks of the components' outputs against a step of the loop.

Every step the loop checks what its components give it
(:mod:`trust_av_common.component_checks`): the plan estimator's prediction
(``planner.CheckedPredictor``), the follower's result (``followers.CheckedFollower``), the
trust model's trust and variance (``paper_trust.TrustEstimator``) and the NMPC's E_max with
the trust it starts from (``model_interface.CheckedBound``); each call into a component goes
through ``call``. This runs the in-process loop over a shipped trace and times its steps;
then it times, per step, those checked wrappers around stand-in components that hand back
what the real ones gave in that step, against the same stand-ins called directly: the
difference is what the checks add to a step (the budget: under 2 % of it).

Times are the CPU time of this thread (``time.thread_time``), not the wall clock: on a
shared machine the wall clock counts the time other processes ran, which is most of it.

Prints the figures and writes them to benchmarks/results_component_checks.json (or --out).
Not a test: timings are noisy, so nothing here asserts a speed.

    python benchmarks/bench_component_checks.py [--trace us06] [--steps 120] [--repeats 200]
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from pathlib import Path
from typing import Any

import numpy as np

from human_driver_sim.driver_mpc import DriverResult
from human_driver_sim.followers import CheckedFollower
from preceding_traffic.traces import truncate
from trust_av.system.closed_loop import ClosedLoop, control_trace
from trust_av.system.config import load_run_config
from trust_av_planner.planner import CheckedPredictor
from trust_av_planner.predictors import Observation
from trust_monitor.model_interface import CheckedBound, explicability_bound
from trust_monitor.paper_trust import TrustEstimator, explicability, performance


class Stand:
    """A stand-in for every kind of component: it hands back ``value`` (set per step)."""

    name = 'stand'
    closed_form_bound: Any = None

    def __init__(self) -> None:
        self.value: Any = None
        self.closed_form_bound = lambda state, trust_min, steps, dt_s: self.value

    def reset(self) -> None:
        pass

    def observe(self, observation: Any) -> None:
        pass

    def predict(self) -> Any:
        return self.value

    def step(self, *args: Any) -> Any:
        return self.value if len(args) == 4 else args[0]

    def initial_state(self) -> float:
        return 0.5

    def trust(self, state: Any) -> float:
        return 0.5

    def variance(self, state: Any) -> float | None:
        return None


def per_step_s(config: Any, outputs: list[tuple[np.ndarray, DriverResult, float]],
               checked: bool, repeats: int) -> float:
    """Seconds per step of the component calls of a step, checked or direct."""
    predictor, follower, trust_model = Stand(), Stand(), Stand()
    seen = Observation(20.0, 0.5, 1.5, 0.3)
    wrapped_predictor = CheckedPredictor(predictor, config.planner)
    wrapped_follower = CheckedFollower(follower, config.follower.driver_model, config.driver)
    estimator = TrustEstimator(config.trust, trust_model)
    bound = CheckedBound(trust_model, config.trust.trust_model)
    n = config.planner.horizon_steps
    start = time.thread_time()
    for _ in range(repeats):
        for expected, result, e_max in outputs:
            predictor.value, follower.value = expected, result
            trust_model.value = e_max
            if checked:
                wrapped_predictor.observe(seen)
                wrapped_predictor.predict()
                bound(0.5, 0.4, n, 1.0)
                estimator.step(expected, expected, 1.0)
                wrapped_follower.step(20.0, 10.0, 10.5, expected)
            else:
                predictor.observe(seen)
                predictor.predict()
                explicability_bound(trust_model, 0.5, 0.4, n, 1.0)
                explicability(list(expected), list(expected), config.trust.epsilon_mps2)
                performance(0.0)
                state = trust_model.step(0.5, 0.1, 1.0)
                trust_model.trust(state)
                trust_model.variance(state)
                follower.step(20.0, 10.0, 10.5, expected)
    return (time.thread_time() - start) / (repeats * len(outputs))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--trace', default='us06', help='a shipped trace or a CSV')
    parser.add_argument('--steps', type=int, default=120, help='steps of the loop timed')
    parser.add_argument('--repeats', type=int, default=200,
                        help='times the checks of every step are replayed')
    parser.add_argument('--out', type=Path,
                        default=Path(__file__).with_name('results_component_checks.json'))
    args = parser.parse_args(argv)
    config = load_run_config(overrides={'preceding_traffic': {'trace': args.trace}})
    trace = truncate(control_trace(config), args.steps)
    loop = ClosedLoop(config, trace)
    step_s, records = [], []
    while not loop.done:
        start = time.thread_time()
        records.append(loop.step())
        step_s.append(time.thread_time() - start)
    n = loop.config.planner.horizon_steps
    outputs = [(np.array(r.expected_plan_mps2[:n]),
                DriverResult(np.array(r.human_plan_mps2), r.driver_status,
                             bool(r.driver_success), int(r.solver_iterations),
                             r.driver_solve_time_s),
                r.explicability_max if 0.0 <= r.explicability_max < 1.0 else 1.0)
               for r in records]
    direct = min(per_step_s(loop.config, outputs, False, args.repeats) for _ in range(3))
    checked = min(per_step_s(loop.config, outputs, True, args.repeats) for _ in range(3))
    checks_s = checked - direct
    step_median = statistics.median(step_s)
    figures = {'trace': trace.name, 'steps': len(records), 'repeats': args.repeats,
               'step_ms_median': 1e3 * step_median,
               'component_calls_direct_us_per_step': 1e6 * direct,
               'component_calls_checked_us_per_step': 1e6 * checked,
               'checks_us_per_step': 1e6 * checks_s,
               'checks_percent_of_step': 100.0 * checks_s / step_median}
    print(f'{trace.name}, {len(records)} steps: a step of the in-process loop takes '
          f'{figures["step_ms_median"]:.2f} ms (median); its output checks '
          f'{figures["checks_us_per_step"]:.1f} us = '
          f'{figures["checks_percent_of_step"]:.3f} % of a step (budget: 2 %)')
    args.out.write_text(json.dumps(figures, indent=2) + '\n')
    print(f'wrote {args.out}')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
