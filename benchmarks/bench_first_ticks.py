"""The planner's first ticks in wall mode against its control period.

A freshly built planner (:class:`trust_av_planner.planner.AvPlanner`, as the planner node
builds it in wall mode: NMPC on the control period's grid, CPU budget on) plans from a steady
car-following situation, tick after tick; each tick's wall time is measured from the call to
its plan. The first ticks include what the solver does only once (CasADi/QP set-up on the
first solves), which is what a lifecycle ``configure`` that warms the solver would take off
the control loop. Prints the first ticks and the steady ones against the period and writes
benchmarks/results_first_ticks.json (or --out). Not a test: timings are noisy.

    python benchmarks/bench_first_ticks.py [--rate-hz 10] [--ticks 30] [--predictor ca]
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime
import json
import os
import statistics
import sys
import time
from pathlib import Path

from trust_av.system.config import load_run_config
from trust_av_common.kinematics import VehicleState
from trust_av_planner.planner import AvPlanner


def first_ticks(rate_hz: float, ticks: int, predictor: str) -> list[float]:
    """Wall time of each of the first ``ticks`` plans of a fresh planner, ms."""
    config = load_run_config()
    planner_config = dataclasses.replace(config.planner, predictor=predictor,
                                         lead_preview='constant_speed')
    period_s = 1.0 / rate_hz
    planner = AvPlanner(planner_config, config.trust, config.shared.vehicle_length_m,
                        period_s=period_s, cpu_budget=True)
    times_ms = []
    for k in range(ticks):
        t_s = k * period_s
        lead = VehicleState(40.0 + 15.0 * t_s, 15.0)
        av = VehicleState(15.0 * t_s, 15.0)
        human = VehicleState(-30.0 + 15.0 * t_s, 15.0)
        start = time.perf_counter()
        planner.step(lead, None, av, human, 0.5, t_s)
        times_ms.append(1e3 * (time.perf_counter() - start))
    return times_ms


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--rate-hz', type=float, default=10.0)
    parser.add_argument('--ticks', type=int, default=30)
    parser.add_argument('--predictor', default='ca')
    parser.add_argument('--out', type=Path,
                        default=Path(__file__).parent / 'results_first_ticks.json')
    args = parser.parse_args(argv)
    if args.rate_hz <= 0 or args.ticks < 10:
        print('error: --rate-hz must be > 0 and --ticks >= 10', file=sys.stderr)
        return 2
    times_ms = first_ticks(args.rate_hz, args.ticks, args.predictor)
    period_ms = 1e3 / args.rate_hz
    steady = times_ms[5:]
    figures = {
        'date': datetime.datetime.now(datetime.UTC).isoformat(timespec='seconds'),
        'cpu_count': os.cpu_count(), 'load_average': os.getloadavg(),
        'rate_hz': args.rate_hz, 'period_ms': period_ms, 'predictor': args.predictor,
        'ticks_ms': times_ms, 'first_ms': times_ms[0],
        'steady_median_ms': statistics.median(steady), 'steady_max_ms': max(steady),
        'ticks_over_period': [k for k, t in enumerate(times_ms) if t > period_ms],
    }
    print(f"first tick {times_ms[0]:.1f} ms, then {', '.join(f'{t:.1f}' for t in times_ms[1:5])}"
          f" ms; ticks 5+: median {figures['steady_median_ms']:.2f} ms, max "
          f"{figures['steady_max_ms']:.2f} ms; period {period_ms:g} ms; over the period: "
          f"{figures['ticks_over_period'] or 'none'} (load {figures['load_average']})")
    args.out.write_text(json.dumps(figures, indent=2) + '\n')
    print(f'wrote {args.out}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
