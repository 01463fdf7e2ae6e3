"""Benchmark of the ROS 2 node graph: real-time factor and per-step overhead.

Runs the whole graph (six processes, lock-step) on a trace and the in-process loop on the
same trace, and reports: start-up time, stepping wall time, real-time factor (sim seconds
per wall second while stepping), per-step overhead of the graph over the in-process loop,
and the whole command's wall time. Writes benchmarks/results_graph.json (or --out).

    python benchmarks/bench_graph.py [--trace us06] [--quick]
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime
import json
import math
import os
import sys
import tempfile
import time
from pathlib import Path

from preceding_traffic.sources import load_trace
from preceding_traffic.traces import truncate
from trust_av_planner.graph.bag_records import records_from_bag
from trust_av_planner.graph.orchestrator import run_graph
from trust_av_planner.system.closed_loop import simulate
from trust_av_planner.system.config import DEFAULT_PARAMS_FILE, load_run_config
from trust_av_planner.system.metrics import StepRecord


def max_difference(recorded: list[StepRecord], reference: list[StepRecord]) -> float:
    """Largest absolute difference of any numeric field (solve times excluded); inf when
    the step counts or a status differ."""
    if len(recorded) != len(reference):
        return math.inf
    worst = 0.0
    for a, b in zip(recorded, reference, strict=True):
        for field in dataclasses.fields(StepRecord):
            x, y = getattr(a, field.name), getattr(b, field.name)
            if 'solve_time' in field.name:
                continue
            if isinstance(y, tuple):
                worst = max(worst, *(abs(p - q) for p, q in zip(x, y, strict=True)))
            elif isinstance(y, float):
                worst = max(worst, abs(x - y))
            elif x != y:
                return math.inf
    return worst


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--trace', default='us06')
    parser.add_argument('--quick', action='store_true', help='60 steps only (smoke run)')
    parser.add_argument('--out', type=Path,
                        default=Path(__file__).parent / 'results_graph.json')
    args = parser.parse_args(argv)
    config = load_run_config()
    trace = load_trace(args.trace, config.planner.dt_s, config.trace)
    max_steps = 60 if args.quick else 0
    trace = truncate(trace, max_steps)
    start = time.perf_counter()
    reference = simulate(config, trace).records
    in_process_s = time.perf_counter() - start
    with tempfile.TemporaryDirectory() as tmp:
        start = time.perf_counter()
        run = run_graph(config, args.trace, trace, DEFAULT_PARAMS_FILE, Path(tmp) / 'b.mcap',
                        max_steps=max_steps)
        total_s = time.perf_counter() - start
        recorded = records_from_bag(run.bag)
    difference = max_difference(recorded, reference)
    stepping_s = run.wall_s - run.startup_s
    sim_s = trace.steps * trace.dt_s
    figures = {
        'date': datetime.datetime.now(datetime.UTC).isoformat(timespec='seconds'),
        'cpu_count': os.cpu_count(), 'trace': trace.name, 'steps': trace.steps,
        'startup_s': run.startup_s, 'stepping_s': stepping_s, 'total_s': total_s,
        'real_time_factor': sim_s / stepping_s,
        'graph_step_ms': 1e3 * stepping_s / trace.steps,
        'in_process_step_ms': 1e3 * in_process_s / trace.steps,
        'overhead_per_step_ms': 1e3 * (stepping_s - in_process_s) / trace.steps,
        'steps_recorded': len(recorded),
        'max_difference_to_in_process': difference,
    }
    print(f'graph on {trace.name} ({trace.steps} steps): start-up {run.startup_s:.1f} s, '
          f'stepping {stepping_s:.2f} s, total {total_s:.1f} s')
    print(f"real-time factor {figures['real_time_factor']:.0f}x while stepping; "
          f"{figures['graph_step_ms']:.2f} ms per step against "
          f"{figures['in_process_step_ms']:.2f} ms in-process "
          f"(overhead {figures['overhead_per_step_ms']:.2f} ms per step)")
    print(f'graph == in-process over all {len(recorded)} steps: largest difference of any '
          f'recorded state, plan, E or trust {difference:.1e}')
    args.out.write_text(json.dumps(figures, indent=2) + '\n')
    print(f'wrote {args.out}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
