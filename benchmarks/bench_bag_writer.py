"""Benchmark of the bag writer alone: CPU time per recorded step, and of finishing a bag.

Records ``--steps`` lock-step steps of ``--topics`` topics (one ``nav_msgs/msg/Odometry``
each per step, about as many bytes as the graph's largest messages) with
:class:`~trust_av.graph.bag_writer.BagWriter` into a temporary directory, ``--repeats``
times: process CPU microseconds per step (``write`` of every topic + ``end_step``: one MCAP
chunk through to the file), milliseconds to ``finish`` (summary, metadata.yaml) and the bag's
size. Prints medians and ranges; writes benchmarks/results_bag_writer.json (or ``--out``)
with the core count, date and load averages.

    python benchmarks/bench_bag_writer.py [--steps 6000] [--topics 12] [--repeats 5]
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
from typing import Any

import numpy as np

from preceding_traffic.bags import ODOMETRY, TYPESTORE, odometry_messages
from trust_av.graph.bag_writer import BagWriter, qos_profile


def run_once(directory: Path, steps: int, topics: int) -> dict[str, float]:
    """Record one bag; CPU µs per step, ms to finish, MiB written."""
    names = [f'/t{number}/odom' for number in range(topics)]
    times_s = 10.0 + 0.1 * np.arange(steps)
    messages = [bytes(TYPESTORE.serialize_cdr(msg, ODOMETRY)) for _ns, msg in
                odometry_messages(times_s, times_s - 10.0, 'odom', 'ego')]
    bag = directory / 'bag'
    writer = BagWriter(bag)
    qos = qos_profile(reliable=True, transient_local=False, depth=10)
    for name in names:
        writer.add_topic(name, ODOMETRY, qos)
    start = time.process_time()
    for step in range(steps):
        for name in names:
            writer.write(name, messages[step])
        if not writer.end_step():
            raise SystemExit(f'error: {writer.disk_full}')
    recorded = time.process_time() - start
    start = time.process_time()
    writer.finish()
    finished = time.process_time() - start
    size = sum(path.stat().st_size for path in bag.iterdir())
    return {'cpu_us_per_step': recorded / steps * 1e6, 'finish_ms': finished * 1e3,
            'bag_mib': size / 2**20}


def spread(values: list[float]) -> dict[str, float]:
    return {'median': statistics.median(values), 'min': min(values), 'max': max(values)}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--steps', type=int, default=6000)
    parser.add_argument('--topics', type=int, default=12)
    parser.add_argument('--repeats', type=int, default=5)
    parser.add_argument('--out', type=Path,
                        default=Path(__file__).parent / 'results_bag_writer.json')
    args = parser.parse_args(argv)
    if args.steps < 1 or args.topics < 1 or args.repeats < 1:
        print('error: --steps, --topics and --repeats must be >= 1', file=sys.stderr)
        return 2
    runs: list[dict[str, float]] = []
    for repeat in range(args.repeats):
        with tempfile.TemporaryDirectory() as tmp:
            runs.append(run_once(Path(tmp), args.steps, args.topics))
        print(f'run {repeat + 1}: {runs[-1]["cpu_us_per_step"]:.1f} µs CPU per step, finish '
              f'{runs[-1]["finish_ms"]:.1f} ms, {runs[-1]["bag_mib"]:.2f} MiB', flush=True)
    figures: dict[str, Any] = {key: spread([run[key] for run in runs])
                               for key in ('cpu_us_per_step', 'finish_ms', 'bag_mib')}
    per_step = figures['cpu_us_per_step']
    print(f'bag writer: {per_step["median"]:.1f} µs CPU per step of {args.topics} topics '
          f'(median of {args.repeats}, range {per_step["min"]:.1f}-{per_step["max"]:.1f}), '
          f'finish {figures["finish_ms"]["median"]:.1f} ms, '
          f'{figures["bag_mib"]["median"]:.2f} MiB for {args.steps} steps')
    results = {'steps': args.steps, 'topics': args.topics, 'repeats': args.repeats,
               'figures': figures, 'runs': runs, 'cpu_count': os.cpu_count(),
               'date': datetime.datetime.now(datetime.UTC).isoformat(),
               'load': os.getloadavg()}
    args.out.write_text(json.dumps(results, indent=2) + '\n')
    print(f'wrote {args.out}')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
