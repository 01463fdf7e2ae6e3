"""Benchmark of the pure core: NMPC solve time against a plain baseline, closed-loop speed.

1. Runs the in-process closed loop on US06 (``--repeats`` times): steps per second, and our
   NMPC's and the driver MPC's solve times as the loop saw them.
2. Replays the inputs of every NMPC call of that loop (gap, speed, preview, expected plan,
   trust bound) into our solver and into the baseline built here, in the same process:
   CasADi ``Opti`` + IPOPT with default options (``nmpc_reference.ReferenceNmpc``). Reports
   both solve-time distributions, the speed-up at p99, and the largest plan difference.

3. Runs the loop once more at ``--rate-hz`` (default 10 Hz: the NMPC on the 0.1 s grid, 30
   steps, DAQP) and reports its solve times, the figure real-vehicle mode needs.

Prints the figures and writes them to benchmarks/results_core.json (or --out). Not a test:
timings are noisy, so nothing here asserts a speed.

    python benchmarks/bench_core.py [--repeats 3] [--trace us06] [--alpha 0.5] [--rate-hz 10]
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime
import json
import os
import resource
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
from nmpc_reference import compare_on_records  # beside this script

from preceding_traffic.sources import load_trace
from preceding_traffic.traces import SpeedTrace, truncate
from trust_av.system.closed_loop import SimResult, control_trace, simulate
from trust_av.system.config import RunConfig, load_run_config


def percentiles_ms(seconds: list[float]) -> dict[str, float]:
    """p50, p99 and max of durations, in ms."""
    ms = np.asarray(seconds) * 1e3
    return {'p50': float(np.percentile(ms, 50)), 'p99': float(np.percentile(ms, 99)),
            'max': float(ms.max())}


def replay_against_baseline(config: RunConfig, trace: SpeedTrace,
                            result: SimResult) -> dict[str, Any]:
    """Our NMPC and the Opti + IPOPT baseline on the inputs of every step of ``result``."""
    comparison = compare_on_records(config, trace, result.records)
    ours_p = percentiles_ms(comparison.ours_s)
    base_p = percentiles_ms(comparison.reference_s)
    return {'ours_ms': ours_p, 'baseline_ipopt_ms': base_p,
            'speedup_p99': base_p['p99'] / ours_p['p99'],
            'speedup_p50': base_p['p50'] / ours_p['p50'],
            'max_plan_difference_mps2': comparison.max_plan_difference_mps2,
            'steps_compared': len(comparison.plan_differences_mps2),
            'baseline_failures': comparison.reference_failures}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--trace', default='us06')
    parser.add_argument('--alpha', type=float, default=0.5)
    parser.add_argument('--repeats', type=int, default=3, help='closed loops to time')
    parser.add_argument('--steps', type=int, default=0, help='limit steps (0: whole trace)')
    parser.add_argument('--rate-hz', type=float, default=10.0,
                        help='control rate of the extra loop timed at it (default: %(default)s)')
    parser.add_argument('--out', type=Path, default=Path(__file__).parent / 'results_core.json')
    args = parser.parse_args(argv)

    config = load_run_config()
    config = dataclasses.replace(config, planner=dataclasses.replace(config.planner,
                                                                     alpha=args.alpha))
    trace = load_trace(args.trace, config.planner.dt_s, config.trace)
    if args.steps:
        trace = dataclasses.replace(trace, speeds_mps=trace.speeds_mps[:args.steps + 1])
    solve_times, driver_times, rates = [], [], []
    for _ in range(args.repeats):
        start = time.perf_counter()
        result = simulate(config, trace)
        elapsed = time.perf_counter() - start
        rates.append(len(result.records) / elapsed)
        solve_times += [r.solve_time_s for r in result.records]
        driver_times += [r.driver_solve_time_s for r in result.records]
    baseline = replay_against_baseline(config, trace, result)
    on_trace = dataclasses.replace(config, trace=dataclasses.replace(config.trace,
                                                                     trace=args.trace))
    rate_trace = truncate(control_trace(on_trace, args.rate_hz),
                          round(trace.steps * trace.dt_s * args.rate_hz))
    at_rate = simulate(config, rate_trace)
    figures = {
        'date': datetime.datetime.now(datetime.UTC).isoformat(timespec='seconds'),
        'cpu_count': os.cpu_count(),
        'trace': trace.name, 'steps': trace.steps, 'alpha': args.alpha,
        'repeats': args.repeats,
        'nmpc_solve_ms': percentiles_ms(solve_times),
        'driver_solve_ms': percentiles_ms(driver_times),
        'closed_loop_steps_per_s': {'median': float(np.median(rates)),
                                    'min': float(np.min(rates))},
        'baseline': baseline,
        'rate_hz': args.rate_hz,
        'nmpc_solve_ms_at_rate': percentiles_ms([r.solve_time_s for r in at_rate.records]),
        'fallback_steps_at_rate': at_rate.metrics.fallback_steps,
        'peak_rss_mb': resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
        'metrics': vars(result.metrics),
    }
    nm, b = figures['nmpc_solve_ms'], baseline
    print(f"NMPC solve time in the {trace.name} loop (alpha {args.alpha}): "
          f"p50 {nm['p50']:.3f} ms, p99 {nm['p99']:.3f} ms, max {nm['max']:.3f} ms")
    print(f"replayed inputs, whole solve() call, ours: p50 {b['ours_ms']['p50']:.3f} ms, "
          f"p99 {b['ours_ms']['p99']:.3f} ms; baseline Opti+IPOPT: "
          f"p50 {b['baseline_ipopt_ms']['p50']:.3f} ms, "
          f"p99 {b['baseline_ipopt_ms']['p99']:.3f} ms; speed-up at p99 {b['speedup_p99']:.1f}x")
    print(f"largest plan difference to the baseline: {b['max_plan_difference_mps2']:.2e} m/s^2 "
          f"over {b['steps_compared']} steps")
    nr = figures['nmpc_solve_ms_at_rate']
    print(f"NMPC solve time at {args.rate_hz:g} Hz ({len(at_rate.records)} ticks, "
          f"{figures['fallback_steps_at_rate']} fallbacks): p50 {nr['p50']:.3f} ms, "
          f"p99 {nr['p99']:.3f} ms, max {nr['max']:.3f} ms")
    print(f"driver MPC solve time: p50 {figures['driver_solve_ms']['p50']:.3f} ms, "
          f"p99 {figures['driver_solve_ms']['p99']:.3f} ms")
    print(f"in-process closed loop: {figures['closed_loop_steps_per_s']['median']:.0f} steps/s "
          f"(median of {args.repeats}; {os.cpu_count()} cores)")
    print(f"peak RSS {figures['peak_rss_mb']:.0f} MB")
    args.out.write_text(json.dumps(figures, indent=2) + '\n')
    print(f'wrote {args.out}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
