"""How close the human follower comes to the AV in the paper sweep and in a driver population.

Usage::

    python scripts/follower_safety.py [--params-file FILE] [--driver-fit FIT] [--drivers K]
        [--alphas 0,0.25,0.5,0.75,1] [--population-alphas 0.5] [--predictors ca,gru]
        [--workers 2] [--json OUT]

For every case (us06 and nycc x predictor x alpha, the in-process closed loop of
``trust-av simulate`` / ``study.sweep.run_case``) it records the human's smallest gap, the
number of steps whose human gap is below d_s - ``safety_gap_margin_m`` (and below 2 m and
0 m), when the first of them happens and the AV's own smallest gap; then the same for K
drivers drawn from ``--driver-fit`` (``study.population.population_cases``: per-driver fits when
the file has them). Prints Markdown tables and writes JSON. The figures of
docs/DRIVER_IRL.md, "Closed-loop safety", come from this script.
"""

from __future__ import annotations

import argparse
import concurrent.futures
import json
from pathlib import Path
from typing import Any

from preceding_traffic.sources import load_trace
from trust_av.study.population import population_cases
from trust_av.study.sweep import Case
from trust_av.system.closed_loop import simulate
from trust_av.system.config import load_run_config

TRACES = ('us06', 'nycc')


def run(case: Case, params_file: str | None) -> dict[str, Any]:
    """One closed loop; the human's gap statistics."""
    overrides: dict[str, dict[str, Any]] = {
        'planner': {'alpha': case.alpha, 'predictor': case.predictor}}
    if case.driver_params:
        overrides['human_driver'] = dict(case.driver_params)
    config = load_run_config([params_file] if params_file else [], overrides)
    trace = load_trace(case.trace, config.planner.dt_s, config.trace)
    records = simulate(config, trace).records
    limit = config.min_safe_gap_m
    below = [r for r in records if r.human_gap_m < limit]
    return {'case': case.label, 'steps': len(records), 'limit_m': limit,
            'min_human_gap_m': min(r.human_gap_m for r in records),
            'min_av_gap_m': min(r.av_gap_m for r in records),
            'human_steps_below_limit': len(below),
            'human_steps_below_2m': sum(r.human_gap_m < 2.0 for r in records),
            'human_collisions': sum(r.human_gap_m <= 0.0 for r in records),
            'av_steps_below_limit': sum(r.av_gap_m < limit for r in records),
            'below_limit_at_s': [round(r.t_s, 1) for r in below][:20],
            'below_limit_speed_mps': [round(r.human_speed_mps, 1) for r in below][:20],
            'driver_fallback_steps': sum(not r.driver_success for r in records),
            'final_trust': records[-1].trust}


def main() -> None:
    """Run the cases, print tables, write JSON."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--params-file', default=None)
    parser.add_argument('--driver-fit', type=Path, default=None)
    parser.add_argument('--drivers', type=int, default=0)
    parser.add_argument('--alphas', default='0,0.25,0.5,0.75,1')
    parser.add_argument('--population-alphas', default='0.5')
    parser.add_argument('--predictors', default='ca,gru')
    parser.add_argument('--workers', type=int, default=2)
    parser.add_argument('--json', type=Path, default=None)
    args = parser.parse_args()
    predictors = args.predictors.split(',')
    sweep = [Case(t, p, float(a)) for t in TRACES for p in predictors
             for a in args.alphas.split(',')]
    population: list[Case] = []
    if args.drivers:
        base = [Case(t, 'ca', float(a)) for t in TRACES for a in args.population_alphas.split(',')]
        population = population_cases(base, args.drivers, 1, args.driver_fit) \
            if args.driver_fit else population_cases(base, args.drivers, 1)
    with concurrent.futures.ProcessPoolExecutor(args.workers) as pool:
        results = list(pool.map(run, sweep + population,
                                [args.params_file] * (len(sweep) + len(population))))
    header = ('| case | min human gap (m) | steps below d_s - margin | below 2 m | collisions '
              '| min AV gap (m) | driver fallbacks | first times below (s) |\n'
              '| --- | --- | --- | --- | --- | --- | --- | --- |')
    print(header)
    for r in results:
        print(f'| {r["case"]} | {r["min_human_gap_m"]:.3f} | {r["human_steps_below_limit"]} '
              f'| {r["human_steps_below_2m"]} | {r["human_collisions"]} | '
              f'{r["min_av_gap_m"]:.3f} | {r["driver_fallback_steps"]} | '
              f'{r["below_limit_at_s"][:6]} |')
    for name, part in (('sweep', results[:len(sweep)]), ('population', results[len(sweep):])):
        if part:
            print(f'{name}: {len(part)} runs, {sum(r["steps"] for r in part)} steps; smallest '
                  f'human gap {min(r["min_human_gap_m"] for r in part):.3f} m; steps below '
                  f'd_s - margin {sum(r["human_steps_below_limit"] for r in part)} in '
                  f'{sum(r["human_steps_below_limit"] > 0 for r in part)} runs; below 2 m '
                  f'{sum(r["human_steps_below_2m"] for r in part)}; collisions '
                  f'{sum(r["human_collisions"] for r in part)}; AV below d_s - margin '
                  f'{sum(r["av_steps_below_limit"] for r in part)}')
    if args.json is not None:
        args.json.write_text(json.dumps({'params_file': args.params_file,
                                         'driver_fit': str(args.driver_fit),
                                         'runs': results}, indent=1))


if __name__ == '__main__':
    main()
