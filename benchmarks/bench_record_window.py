"""Benchmark of the recorder's back-pressure: the graph with and without the window.

Runs the whole graph on a trace, interleaved (window, none, window, none, ...; ``--repeats``
each): ``window`` is what ``trust-av run`` does (the step authority runs at most
``recorder_window_steps`` ahead of the recorder's acknowledgement,
trust_av_common.record_window); ``none`` sets the window to 0 (no waiting, the recorder
may fall behind and lose messages). Timed from the ``/clock`` of every step as this
process's node receives it: steady-state ms per step, first to last ``/clock``. Prints the
medians and ranges and writes benchmarks/results_record_window.json (or ``--out``).

    python benchmarks/bench_record_window.py [--trace us06] [--repeats 5]
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

from preceding_traffic.sources import load_trace
from trust_av.graph import orchestrator
from trust_av.system.config import load_run_config
from trust_av_common.record_window import window_steps


def steady_ms_per_step(window: bool, trace_name: str) -> float:
    """One graph run; its steady-state ms per step (first to last ``/clock``)."""
    config = load_run_config()
    trace = load_trace(trace_name, config.planner.dt_s, config.trace)
    orchestrator.window_steps = window_steps if window else (lambda: 0)  # type: ignore[assignment]
    stamps: list[float] = []
    with tempfile.TemporaryDirectory() as tmp:
        orchestrator.run_graph(config, trace_name, trace, Path(tmp) / 'bag',
                               on_clock=lambda _step: stamps.append(time.perf_counter()))
    return (stamps[-1] - stamps[0]) / (len(stamps) - 1) * 1e3


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--trace', default='us06')
    parser.add_argument('--repeats', type=int, default=5, help='runs of each, interleaved')
    parser.add_argument('--out', type=Path,
                        default=Path(__file__).parent / 'results_record_window.json')
    args = parser.parse_args(argv)
    if args.repeats < 1:
        print(f'error: --repeats must be >= 1, got {args.repeats}', file=sys.stderr)
        return 2
    runs: dict[str, list[float]] = {'window': [], 'none': []}
    for repeat in range(args.repeats):
        for name in runs:
            runs[name].append(steady_ms_per_step(name == 'window', args.trace))
            print(f'{name} run {repeat + 1}: {runs[name][-1]:.2f} ms/step steady', flush=True)
    figures = {
        'date': datetime.datetime.now(datetime.UTC).isoformat(timespec='seconds'),
        'cores': os.cpu_count(), 'load': os.getloadavg(), 'trace': args.trace,
        'window_steps': window_steps(),
        **{name: {'median_ms_per_step': statistics.median(values), 'min': min(values),
                  'max': max(values), 'runs': values} for name, values in runs.items()},
    }
    ratio = figures['window']['median_ms_per_step'] / figures['none']['median_ms_per_step']
    figures['ratio_window_to_none'] = ratio
    for name in runs:
        f = figures[name]
        print(f"{name}: {f['median_ms_per_step']:.2f} ms/step (median of {args.repeats}, "
              f"range {f['min']:.2f}-{f['max']:.2f})")
    print(f'window / none: {ratio:.2f}x; {os.cpu_count()} cores, load {os.getloadavg()}')
    args.out.write_text(json.dumps(figures, indent=1) + '\n')
    print(f'wrote {args.out}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
