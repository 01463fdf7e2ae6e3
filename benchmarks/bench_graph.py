"""Benchmark of the ROS 2 node graph: against its floor, real-time factor, per-step overhead.

Runs the whole graph (six processes, lock-step) on a trace and its floor
(``bench_floor.py``: the same processes, topics, QoS, chain and executor, no computation)
for as many steps, interleaved (floor, graph, floor, graph, ...; ``--repeats`` each), both
timed the same way from the ``/clock`` of every step as the orchestrator's node receives it:
steady-state ms per step (first to last ``/clock``), start-up (launch to the first) and
shutdown (last ``/clock`` until every process has stopped) apart, and CPU ms per step of
every process over the steady state. Reports medians and ranges and the ratio graph /
floor of the medians. Also the in-process loop on the same trace: per-step overhead, and
the largest difference of the first graph run's recording to it. Writes
benchmarks/results_graph.json (or --out) with the core count, date and load averages.

    python benchmarks/bench_graph.py [--trace us06] [--repeats 3] [--quick] [--rclpy-inputs]

``--rclpy-inputs``: the graph's nodes take every input as an rclpy message (rclpy's own
deserialisation) instead of reading the bytes (``trust_av_common.ros.raw_inputs``).

The floor is the lowest one: its nodes read their inputs as raw bytes, as the graph's do,
and its recorder writes uncompressed chunks, as the graph's does
(``run_floor(raw_inputs=True, compression='none')``), so that the ratio charges the graph
only with its own work. ``--floor rclpy`` compares with the floor whose nodes pay rclpy's
deserialisation (the graph's do not) and whose recorder compresses (zstd): a higher floor,
a lower ratio. The graph's extra CPU per step over the floor is printed per process, the
largest first: where the graph's own work goes.
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime
import json
import math
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from bench_floor import StepClock, describe, load, run_floor, summary

from preceding_traffic.sources import load_trace
from preceding_traffic.traces import SpeedTrace, truncate
from trust_av.graph.bag_records import records_from_bag
from trust_av.graph.orchestrator import GraphRun, run_graph
from trust_av.system.closed_loop import simulate
from trust_av.system.config import RunConfig, load_run_config
from trust_av.system.metrics import StepRecord


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


FLOORS: dict[str, dict[str, Any]] = {
    'raw': {'raw_inputs': True, 'compression': 'none'},
    'rclpy': {'raw_inputs': False, 'compression': 'zstd'},
}
"""The floors ``--floor`` chooses from (:func:`bench_floor.run_floor`'s options)."""


def extra_cpu(graph: dict[str, float], floor: dict[str, float]) -> dict[str, float]:
    """CPU ms per step the graph's processes use over the floor's, per process (the total
    last), the largest first."""
    extra = {k: graph[k] - floor.get(k, 0.0) for k in graph if k != 'total'}
    ordered = dict(sorted(extra.items(), key=lambda item: -item[1]))
    if 'total' in graph:
        ordered['total'] = graph['total'] - floor.get('total', 0.0)
    return ordered


def time_graph(config: RunConfig, trace_arg: str, trace: SpeedTrace, work: Path,
               max_steps: int) -> tuple[dict[str, Any], GraphRun]:
    """One graph run, timed as :func:`bench_floor.run_floor` times the floor."""
    clock = StepClock(trace.steps)
    run = run_graph(config, trace_arg, trace, work / 'b',
                    max_steps=max_steps, on_clock=clock.on_step)
    clock.end()
    figures = clock.figures()
    figures['bench_graph_stepping_ms_per_step'] = 1e3 * (run.wall_s - run.startup_s) / \
        trace.steps
    return figures, run


def variant(runs: list[dict[str, Any]]) -> dict[str, Any]:
    """Medians and ranges of one variant's runs."""
    cpu = [r['cpu_ms_per_step'] for r in runs if r['cpu_ms_per_step']]
    return {'steady_ms_per_step': summary([r['steady_ms_per_step'] for r in runs]),
            'startup_s': summary([r['startup_s'] for r in runs]),
            'shutdown_s': summary([r['shutdown_s'] for r in runs]),
            'cpu_ms_per_step': {k: statistics.median(c[k] for c in cpu) for k in cpu[0]}
            if cpu else {},
            'runs': runs}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--trace', default='us06')
    parser.add_argument('--quick', action='store_true',
                        help='60 steps, one run each unless --repeats (smoke run)')
    parser.add_argument('--repeats', type=int, help='runs of each, interleaved (default 3)')
    parser.add_argument('--out', type=Path,
                        default=Path(__file__).parent / 'results_graph.json')
    parser.add_argument('--rclpy-inputs', action='store_true',
                        help="the nodes read their inputs with rclpy's deserialisation")
    parser.add_argument('--floor', choices=('raw', 'rclpy'), default='raw',
                        help='raw (default): the lowest floor (raw bytes in, uncompressed '
                             'chunks); rclpy: its nodes deserialise with rclpy, zstd chunks')
    args = parser.parse_args(argv)
    if args.rclpy_inputs:
        from trust_av_common.ros.raw_inputs import INPUTS_ENV
        os.environ[INPUTS_ENV] = 'rclpy'   # the graph's node processes inherit it
    repeats = args.repeats if args.repeats is not None else 1 if args.quick else 3
    if repeats < 1:
        print(f'error: --repeats must be >= 1, got {repeats}', file=sys.stderr)
        return 2
    config = load_run_config()
    trace = load_trace(args.trace, config.planner.dt_s, config.trace)
    max_steps = 60 if args.quick else 0
    trace = truncate(trace, max_steps)
    start = time.perf_counter()
    reference = simulate(config, trace).records
    in_process_s = time.perf_counter() - start
    floor_runs: list[dict[str, Any]] = []
    graph_runs: list[dict[str, Any]] = []
    difference, recorded = math.nan, 0
    first: GraphRun | None = None
    for repeat in range(repeats):
        for name in ('floor', 'graph'):
            with tempfile.TemporaryDirectory() as tmp:
                before = load()
                if name == 'floor':
                    figures = run_floor(trace.steps, Path(tmp), **FLOORS[args.floor])
                    floor_runs.append(figures)
                else:
                    figures, run = time_graph(config, args.trace, trace, Path(tmp), max_steps)
                    graph_runs.append(figures)
                    if first is None:
                        first = run
                        records = records_from_bag(run.bag)
                        difference, recorded = max_difference(records, reference), len(records)
                figures['load_before'], figures['load_after'] = before, load()
                print(describe(f'{name} run {repeat + 1}', figures) + f' (load {before})',
                      flush=True)
    assert first is not None
    floor, graph = variant(floor_runs), variant(graph_runs)
    ratio = graph['steady_ms_per_step']['median'] / floor['steady_ms_per_step']['median']
    pairs = [g['steady_ms_per_step'] / f['steady_ms_per_step']
             for g, f in zip(graph_runs, floor_runs, strict=True)]
    cpu_ratio = (graph['cpu_ms_per_step']['total'] / floor['cpu_ms_per_step']['total']
                 if graph['cpu_ms_per_step'] and floor['cpu_ms_per_step'] else math.nan)
    steady_ms = graph['steady_ms_per_step']['median']
    extra = extra_cpu(graph['cpu_ms_per_step'], floor['cpu_ms_per_step'])
    stepping_s = first.wall_s - first.startup_s
    sim_s = trace.steps * trace.dt_s
    figures = {
        'date': datetime.datetime.now(datetime.UTC).isoformat(timespec='seconds'),
        'cpu_count': os.cpu_count(), 'trace': trace.name, 'steps': trace.steps,
        'repeats': repeats, 'load_average': load(),
        'inputs': 'rclpy' if args.rclpy_inputs else 'raw_inputs',
        'floor_kind': {'name': args.floor, **FLOORS[args.floor]},
        'extra_cpu_ms_per_step': extra,
        'ratio_graph_to_floor': ratio, 'ratio_per_pair': summary(pairs),
        'cpu_ratio_graph_to_floor': cpu_ratio,
        'graph': graph, 'floor': floor,
        'steady_real_time_factor': 1e3 * trace.dt_s / steady_ms,
        'startup_s': first.startup_s, 'stepping_s': stepping_s,
        'real_time_factor': sim_s / stepping_s,
        'graph_step_ms': 1e3 * stepping_s / trace.steps,
        'in_process_step_ms': 1e3 * in_process_s / trace.steps,
        'overhead_per_step_ms': steady_ms - 1e3 * in_process_s / trace.steps,
        'steps_recorded': recorded,
        'max_difference_to_in_process': difference,
    }
    for name, v in (('floor', floor), ('graph', graph)):
        s, st, sh = v['steady_ms_per_step'], v['startup_s'], v['shutdown_s']
        print(f"{name}: {s['median']:.2f} ms/step steady (median of {repeats}, range "
              f"{s['min']:.2f}-{s['max']:.2f}), start-up {st['median']:.2f} s, shutdown "
              f"{sh['median']:.2f} s, CPU {v['cpu_ms_per_step'].get('total', math.nan):.2f} "
              'ms/step')
    print('CPU ms per step (median), graph / floor: ' + ', '.join(
        f"{k} {graph['cpu_ms_per_step'][k]:.2f} / {floor['cpu_ms_per_step'].get(k, math.nan):.2f}"
        for k in graph['cpu_ms_per_step']))
    print(f'extra CPU ms per step over the {args.floor} floor (graph - floor, median): '
          + ', '.join(f'{k} {v:+.2f}' for k, v in extra.items()))
    print(f"graph / floor: {ratio:.2f}x (per pair {figures['ratio_per_pair']['min']:.2f}-"
          f"{figures['ratio_per_pair']['max']:.2f}), CPU {cpu_ratio:.2f}x; "
          f"{os.cpu_count()} cores, load {figures['load_average']}")
    print(f"graph on {trace.name}: {steady_ms:.2f} ms per step steady "
          f"({figures['steady_real_time_factor']:.0f}x real time) against "
          f"{figures['in_process_step_ms']:.2f} ms in-process "
          f"(overhead {figures['overhead_per_step_ms']:.2f} ms per step)")
    print(f'graph == in-process over all {recorded} steps (first run): largest difference of '
          f'any recorded state, plan, E or trust {difference:.1e}')
    args.out.write_text(json.dumps(figures, indent=2) + '\n')
    print(f'wrote {args.out}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
