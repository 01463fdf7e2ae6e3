"""Benchmark of the bag writer alone: CPU time per recorded step, and of finishing a bag.

Records ``--steps`` lock-step steps of ``--topics`` topics (one ``nav_msgs/msg/Odometry``
each per step, about as many bytes as the graph's largest messages) with
:class:`~trust_av.graph.bag_writer.BagWriter` into a temporary directory, ``--repeats``
times: process CPU microseconds per step (``write`` of every topic + ``end_step``: one MCAP
chunk through to the file), milliseconds to ``finish`` (summary, metadata.yaml) and the bag's
size. Prints medians and ranges; writes benchmarks/results_bag_writer.json (or ``--out``)
with the core count, date and load averages.

    python benchmarks/bench_bag_writer.py [--steps 6000] [--topics 12] [--repeats 5]

``--memory``: the writer's memory over a long recording instead. Two child processes each
record ``--steps`` steps (36,000 = an hour at 10 Hz is the figure to run) of ``--topics``
topics, one with the writer's split (``MAX_CHUNKS_PER_FILE``, or ``--max-chunks-per-file``)
and one without (a single file), sampling their resident memory (VmRSS) every 500 steps;
prints the least-squares slope over the second half of the recording (KB per step: a writer
that levels off is near 0) and the growth from the first sample; writes
benchmarks/results_bag_writer_memory.json (or ``--out``).
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import statistics
import struct
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from preceding_traffic.bags import ODOMETRY, TYPESTORE, odometry_messages
from trust_av.graph.bag_writer import MAX_CHUNKS_PER_FILE, BagWriter, qos_profile

MEMORY_SAMPLE_STEPS = 500


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


def rss_kb() -> int:
    """This process's resident memory, kB (VmRSS of /proc/self/status)."""
    status = Path('/proc/self/status').read_text()
    return int(next(line.split()[1] for line in status.splitlines()
                    if line.startswith('VmRSS:')))


def memory_once(directory: Path, steps: int, topics: int, max_chunks: int) -> dict[str, Any]:
    """One recording's memory: (step, VmRSS kB) every MEMORY_SAMPLE_STEPS steps."""
    names = [f'/t{number}/odom' for number in range(topics)]
    (_ns, template), = odometry_messages(np.array([10.0]), np.array([0.0]), 'odom', 'ego')
    message = bytearray(TYPESTORE.serialize_cdr(template, ODOMETRY))
    writer = BagWriter(directory / 'bag', max_chunks_per_file=max_chunks)
    qos = qos_profile(reliable=True, transient_local=False, depth=10)
    for name in names:
        writer.add_topic(name, ODOMETRY, qos)
    samples = []
    for step in range(steps):
        stamp_ns = 10**10 + step * 10**8                # 10 Hz
        struct.pack_into('<iI', message, 4, stamp_ns // 10**9, stamp_ns % 10**9)
        for name in names:
            writer.write(name, memoryview(message))
        if not writer.end_step():
            raise SystemExit(f'error: {writer.disk_full}')
        if step % MEMORY_SAMPLE_STEPS == 0:
            samples.append((step, rss_kb()))
    files = len(writer.files)
    writer.finish()
    return {'samples': samples, 'files': files, 'max_chunks_per_file': max_chunks}


def memory(args: argparse.Namespace) -> int:
    """Both recordings, each in its own process; print and write the slopes (the soak's
    least-squares slope, over the second half of the samples)."""
    from soak import slope_kb_per_step  # benchmarks/, beside this script

    results: dict[str, Any] = {'steps': args.steps, 'topics': args.topics,
                               'cpu_count': os.cpu_count(),
                               'date': datetime.datetime.now(datetime.UTC).isoformat()}
    for label, max_chunks in (('split', args.max_chunks_per_file),
                              ('one file', args.steps + 1)):
        done = subprocess.run([sys.executable, __file__, '--memory-child', str(max_chunks),
                               '--steps', str(args.steps), '--topics', str(args.topics)],
                              capture_output=True, text=True, check=False)
        if done.returncode != 0:
            print(done.stderr, end='', file=sys.stderr)
            return done.returncode
        run = json.loads(done.stdout)
        samples = run['samples']
        run['slope_kb_per_step'] = slope_kb_per_step(
            {step: {'writer': kb / 1024} for step, kb in samples},
            samples[len(samples) // 2][0], 'writer')
        run['growth_mb'] = (max(kb for _, kb in samples) - samples[0][1]) / 1024
        results[label] = run
        print(f'{label:9s} ({run["files"]} file{"s" if run["files"] != 1 else ""}, '
              f'{max_chunks} chunks per file): slope over the second half '
              f'{run["slope_kb_per_step"]:.3f} kB/step, peak growth {run["growth_mb"]:.1f} MB '
              f'over {args.steps} steps', flush=True)
    out = args.out or Path(__file__).parent / 'results_bag_writer_memory.json'
    out.write_text(json.dumps(results, indent=1) + '\n')
    print(f'wrote {out}')
    return 0


def spread(values: list[float]) -> dict[str, float]:
    return {'median': statistics.median(values), 'min': min(values), 'max': max(values)}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--steps', type=int, default=6000)
    parser.add_argument('--topics', type=int, default=12)
    parser.add_argument('--repeats', type=int, default=5)
    parser.add_argument('--out', type=Path, default=None,
                        help='the JSON to write (default: benchmarks/results_bag_writer.json, '
                             'with --memory results_bag_writer_memory.json)')
    parser.add_argument('--memory', action='store_true',
                        help="the writer's memory over a long recording, split and not")
    parser.add_argument('--max-chunks-per-file', type=int, default=MAX_CHUNKS_PER_FILE,
                        help='with --memory: the split (default: %(default)s)')
    parser.add_argument('--memory-child', type=int, default=0, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if min(args.steps, args.topics, args.repeats, args.max_chunks_per_file) < 1:
        print('error: --steps, --topics, --repeats and --max-chunks-per-file must be >= 1',
              file=sys.stderr)
        return 2
    if args.memory_child:
        with tempfile.TemporaryDirectory() as tmp:
            print(json.dumps(memory_once(Path(tmp), args.steps, args.topics,
                                         args.memory_child)))
        return 0
    if args.memory:
        return memory(args)
    args.out = args.out or Path(__file__).parent / 'results_bag_writer.json'
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
