"""Benchmark of the pure core: NMPC solve time and in-process closed-loop speed on US06.

Prints the figures and writes them to benchmarks/results_core.json (or --out). Not a test:
timings are noisy, so nothing here asserts a speed.

    python benchmarks/bench_core.py [--repeats 3] [--trace us06] [--alpha 0.5]
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

import numpy as np

from preceding_traffic.traces import load_trace
from trust_av_planner.config import load_run_config
from trust_av_planner.simulate import simulate


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--trace', default='us06')
    parser.add_argument('--alpha', type=float, default=0.5)
    parser.add_argument('--repeats', type=int, default=3, help='closed loops to time')
    parser.add_argument('--steps', type=int, default=0, help='limit steps (0: whole trace)')
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
    nmpc = np.array(solve_times) * 1e3
    driver = np.array(driver_times) * 1e3
    figures = {
        'date': datetime.datetime.now(datetime.UTC).isoformat(timespec='seconds'),
        'cpu_count': os.cpu_count(),
        'trace': trace.name, 'steps': trace.steps, 'alpha': args.alpha,
        'repeats': args.repeats,
        'nmpc_solve_ms': {'p50': float(np.percentile(nmpc, 50)),
                          'p99': float(np.percentile(nmpc, 99)), 'max': float(nmpc.max())},
        'driver_solve_ms': {'p50': float(np.percentile(driver, 50)),
                            'p99': float(np.percentile(driver, 99)),
                            'max': float(driver.max())},
        'closed_loop_steps_per_s': {'median': float(np.median(rates)),
                                    'min': float(np.min(rates))},
        'peak_rss_mb': resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
        'metrics': vars(result.metrics),
    }
    print(f"NMPC solve time on {trace.name} (alpha {args.alpha}): "
          f"p50 {figures['nmpc_solve_ms']['p50']:.3f} ms, "
          f"p99 {figures['nmpc_solve_ms']['p99']:.3f} ms, "
          f"max {figures['nmpc_solve_ms']['max']:.3f} ms")
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
