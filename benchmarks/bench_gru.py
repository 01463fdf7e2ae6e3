"""Benchmark of the GRU plan estimator: inference time per control step.

Feeds the observations of a US06 TAC-GRU closed loop to the shipped predictor and times
``observe`` + ``predict`` (one control step's work) after the warm-up. Writes
benchmarks/results_gru.json (or --out).

    python benchmarks/bench_gru.py [--quick]
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

from preceding_traffic.sources import load_trace
from preceding_traffic.traces import truncate
from trust_av.system.closed_loop import simulate
from trust_av.system.config import load_run_config
from trust_av_common.kinematics import VehicleState
from trust_av_planner.planner import make_predictor, observe


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--quick', action='store_true', help='60 steps, 1 repeat')
    parser.add_argument('--repeats', type=int, default=5)
    parser.add_argument('--out', type=Path, default=Path(__file__).parent / 'results_gru.json')
    args = parser.parse_args(argv)
    config = load_run_config(overrides={'planner': {'predictor': 'gru'}})
    trace = load_trace('us06', config.planner.dt_s, config.trace)
    if args.quick:
        trace, args.repeats = truncate(trace, 60), 1
    records = simulate(config, trace).records
    length, cap = config.shared.vehicle_length_m, config.planner.time_headway_cap_s
    observations = [observe(VehicleState(r.av_position_m, r.av_speed_mps),
                            VehicleState(r.human_position_m, r.human_speed_mps),
                            r.av_accel_mps2, length, cap) for r in records]
    times = []
    for _ in range(args.repeats):
        predictor = make_predictor(config.planner)
        for k, obs in enumerate(observations):
            start = time.perf_counter()
            predictor.observe(obs)
            predictor.predict()
            if k >= 10:
                times.append(time.perf_counter() - start)
    ms = np.array(times) * 1e3
    figures = {'date': datetime.datetime.now(datetime.UTC).isoformat(timespec='seconds'),
               'cpu_count': os.cpu_count(), 'steps_timed': len(times),
               'inference_ms': {'p50': float(np.percentile(ms, 50)),
                                'p99': float(np.percentile(ms, 99)), 'max': float(ms.max())}}
    inf = figures['inference_ms']
    print(f"GRU inference per control step (observe + predict, numpy): p50 {inf['p50']:.3f} ms, "
          f"p99 {inf['p99']:.3f} ms, max {inf['max']:.3f} ms over {len(times)} steps")
    args.out.write_text(json.dumps(figures, indent=2) + '\n')
    print(f'wrote {args.out}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
