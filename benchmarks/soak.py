"""Soak: a long trace through the node graph, with every node's memory sampled as it runs.

Builds a trace of at least ``--duration-s`` (default one hour of sim time) by chaining the
two commute trips (am, pm, am, ...; each trip's time shifted to follow the previous one),
runs the whole graph over it, samples the resident memory (VmRSS) of every node process
(the recorder included) at each progress report (at most twice a second of wall time), keeps
one sample per simulated minute, and reports each node's RSS at the first sample at or after
minute 5 (``--baseline-s``) and at its last sample while it ran (the recorder exits when it
holds every step: its last sample is its last progress report), and the slope of each
node's RSS over the samples from the baseline on (least squares, KB per step: a node whose
memory levels off has a slope near 0; one that grows by a fixed amount per step does not).
Writes benchmarks/results_soak.json (or --out). The target is growth < 20 MB per node.

    python benchmarks/soak.py [--duration-s 3600]
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import sys
import tempfile
import threading
from pathlib import Path

from preceding_traffic.sources import load_trace
from preceding_traffic.traces import TraceConfig, read_samples, trace_path
from trust_av.graph.orchestrator import run_graph
from trust_av.system.config import load_run_config


def chained_trace(path: Path, duration_s: float, config: TraceConfig) -> float:
    """Write am, pm, am, ... back to back (1 s between trips) until ``duration_s``."""
    rows: list[tuple[float, float]] = []
    offset = 0.0
    trips = ('commute_am', 'commute_pm')
    k = 0
    while offset < duration_s:
        times, speeds = read_samples(trace_path(trips[k % 2]), config)
        shift = offset - times[0]
        rows += [(float(t + shift), float(v)) for t, v in zip(times, speeds, strict=True)]
        offset = rows[-1][0] + 1.0
        k += 1
    path.write_text('time_s,speed_mps\n' + ''.join(f'{t!r},{v!r}\n' for t, v in rows))
    return rows[-1][0]


def node_rss_mb() -> dict[str, float]:
    """VmRSS of every child process of this one, by ROS node name."""
    out = {}
    me = os.getpid()
    for entry in Path('/proc').iterdir():
        if not entry.name.isdigit():
            continue
        try:
            ppid = int((entry / 'stat').read_text().rsplit(')', 1)[1].split()[1])
            if ppid != me:
                continue
            cmdline = (entry / 'cmdline').read_bytes().split(b'\0')
            status = (entry / 'status').read_text()
        except OSError:
            continue
        name = next((c.decode().split(':=')[1] for c in cmdline
                     if c.startswith(b'__node:=')), entry.name)
        rss = next(int(line.split()[1]) for line in status.splitlines()
                   if line.startswith('VmRSS:'))
        out[name] = rss / 1024
    return out


def slope_kb_per_step(samples: dict[int, dict[str, float]], base: int, node: str) -> float:
    """Least-squares slope of ``node``'s RSS over the samples from step ``base`` on, KB per
    step (NaN with fewer than two samples)."""
    points = [(step, rss[node]) for step, rss in sorted(samples.items())
              if step >= base and node in rss]
    if len(points) < 2:
        return float('nan')
    steps = [p[0] for p in points]
    mean_step = sum(steps) / len(steps)
    mean_mb = sum(p[1] for p in points) / len(points)
    spread = sum((x - mean_step) ** 2 for x in steps)
    if spread == 0:
        return float('nan')
    return 1024.0 * sum((x - mean_step) * (y - mean_mb) for x, y in points) / spread


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--duration-s', type=float, default=3600.0)
    parser.add_argument('--baseline-s', type=float, default=300.0,
                        help='sim time of the first memory reading (default: minute 5)')
    parser.add_argument('--out', type=Path, default=Path(__file__).parent / 'results_soak.json')
    args = parser.parse_args(argv)
    config = load_run_config()
    samples: dict[int, dict[str, float]] = {}
    last_alive: dict[str, tuple[int, float]] = {}
    lock = threading.Lock()
    with tempfile.TemporaryDirectory() as tmp:
        csv = Path(tmp) / 'soak.csv'
        end = chained_trace(csv, args.duration_s, config.trace)
        trace = load_trace(str(csv), config.planner.dt_s, config.trace)
        every = max(1, round(60.0 / trace.dt_s))
        baseline_step = round(args.baseline_s / trace.dt_s)
        due = [0, baseline_step]

        def on_step(done: int, total: int) -> None:
            rss = node_rss_mb()
            with lock:
                last_alive.update({node: (done, mb) for node, mb in rss.items()})
                if done >= min(due) or done == total:
                    samples[done] = rss
                    due[:] = [d for d in due if d > done] or [done - done % every + every]

        run = run_graph(config, str(csv), trace, Path(tmp) / 'soak',
                        on_step=on_step)
    steps = sorted(samples)
    base = next((s for s in steps if s >= baseline_step), None)
    if base is None or base == steps[-1]:
        print(f'error: no memory sample after the baseline step {baseline_step} '
              f'(samples at {steps})', file=sys.stderr)
        return 1
    last = steps[-1]
    growth = {node: last_alive[node][1] - samples[base][node] for node in samples[base]}
    slopes = {node: slope_kb_per_step(samples, base, node) for node in samples[base]}
    figures = {'date': datetime.datetime.now(datetime.UTC).isoformat(timespec='seconds'),
               'cpu_count': os.cpu_count(), 'sim_s': end, 'steps': trace.steps,
               'wall_s': run.wall_s, 'baseline_step': base, 'last_step': last,
               'rss_mb_at_baseline': samples[base],
               'rss_mb_at_end': {node: mb for node, (_, mb) in last_alive.items()},
               'last_step_sampled': {node: step for node, (step, _) in last_alive.items()},
               'growth_mb': growth, 'slope_kb_per_step': slopes,
               'samples': {str(k): v for k, v in samples.items()}}
    print(f'soak: {trace.steps} steps ({end / 60:.0f} min of sim time) in {run.wall_s:.0f} s '
          'wall')
    for node, mb in sorted(growth.items()):
        print(f'  {node:18s} RSS {samples[base][node]:7.1f} MB at step {base} -> '
              f'{last_alive[node][1]:7.1f} MB at step {last_alive[node][0]}: {mb:+.1f} MB, '
              f'slope {slopes[node]:+.3f} KB per step')
    args.out.write_text(json.dumps(figures, indent=2) + '\n')
    print(f'wrote {args.out}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
