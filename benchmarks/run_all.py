"""Run every benchmark and write benchmarks/results.json plus a Markdown summary.

    python benchmarks/run_all.py [--quick]

Each part runs as its own process, so its peak memory (max RSS, from ``wait4``) is its own:

- ``core``: bench_core.py, NMPC solve times against the Opti + IPOPT baseline, closed-loop
  steps per second;
- ``gru``: bench_gru.py, GRU inference per control step (when the GRU predictor exists);
- ``graph``: bench_graph.py, the ROS 2 graph against its floor (ms per step of both, the
  ratio) and its real-time factor (when the graph exists);
- ``sweep``: ``trust-av reproduce`` from an empty cache, then again from the cache.

Nothing here asserts a speed: timings are noisy. The numbers go in the issue notes.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent


def run_measured(command: list[str]) -> tuple[int, float, float, str]:
    """Run ``command``; return (exit code, wall s, peak RSS MB of it and its children, stdout)."""
    start = time.monotonic()
    with tempfile.TemporaryFile('w+') as out:
        proc = subprocess.Popen(command, stdout=out, stderr=subprocess.STDOUT, text=True)
        _, status, usage = os.wait4(proc.pid, 0)
        proc.returncode = os.waitstatus_to_exitcode(status)
        out.seek(0)
        text = out.read()
    return proc.returncode, time.monotonic() - start, usage.ru_maxrss / 1024, text


def part(name: str, command: list[str], json_path: Path | None) -> dict[str, Any]:
    """Run one benchmark part and collect its figures."""
    print(f'== {name}: {" ".join(command)}', flush=True)
    code, wall, rss, text = run_measured(command)
    print(text, end='' if text.endswith('\n') else '\n')
    figures: dict[str, Any] = {'exit_code': code, 'wall_s': wall, 'peak_rss_mb': rss}
    if code != 0:
        raise SystemExit(f'benchmark part {name} failed with exit code {code}')
    if json_path is not None and json_path.exists():
        figures['figures'] = json.loads(json_path.read_text())
    return figures


def markdown(results: dict[str, Any]) -> str:
    """A short human summary of results.json."""
    lines = [f"# Benchmarks ({results['date']}, {results['cpu_count']} cores)", '',
             '| figure | value |', '|---|---|']
    core = results['parts']['core']['figures']
    base = core['baseline']
    lines += [
        f"| NMPC solve in the US06 loop p50 / p99 / max | {core['nmpc_solve_ms']['p50']:.3f} / "
        f"{core['nmpc_solve_ms']['p99']:.3f} / {core['nmpc_solve_ms']['max']:.3f} ms |",
        f"| same inputs, whole solve() call p50 / p99 | {base['ours_ms']['p50']:.3f} / "
        f"{base['ours_ms']['p99']:.3f} ms |",
        f"| baseline Opti + IPOPT p50 / p99 | {base['baseline_ipopt_ms']['p50']:.3f} / "
        f"{base['baseline_ipopt_ms']['p99']:.3f} ms |",
        f"| speed-up at p99 | {base['speedup_p99']:.1f}x |",
        f"| largest plan difference to the baseline | "
        f"{base['max_plan_difference_mps2']:.1e} m/s^2 |",
        f"| in-process closed loop | {core['closed_loop_steps_per_s']['median']:.0f} steps/s |",
    ]
    for name, part_figures in results['parts'].items():
        lines.append(f"| {name}: wall time, peak RSS | {part_figures['wall_s']:.1f} s, "
                     f"{part_figures['peak_rss_mb']:.0f} MB |")
    sweep = results['parts'].get('sweep')
    if sweep is not None:
        lines.append(f"| reproduce sweep ({sweep['cases']} runs): fresh / cached | "
                     f"{sweep['wall_s']:.1f} s / {sweep['cached_wall_s']:.1f} s |")
    graph = results['parts'].get('graph', {}).get('figures')
    if graph and 'ratio_graph_to_floor' in graph:
        g, f = graph['graph']['steady_ms_per_step'], graph['floor']['steady_ms_per_step']
        lines.append(f"| graph / floor, steady ms per step (median of {graph['repeats']} each, "
                     f"{graph['steps']} steps) | {graph['ratio_graph_to_floor']:.2f}x: "
                     f"{g['median']:.2f} ({g['min']:.2f}-{g['max']:.2f}) / {f['median']:.2f} "
                     f"({f['min']:.2f}-{f['max']:.2f}) ms |")
    for name in ('gru', 'graph'):
        figures = results['parts'].get(name, {}).get('figures')
        if figures:
            lines.append(f'| {name} figures | `{json.dumps(figures)[:300]}` |')
    return '\n'.join(lines) + '\n'


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--quick', action='store_true',
                        help='tiny inputs (a smoke run, as the test suite does)')
    parser.add_argument('--out', type=Path, default=HERE / 'results.json')
    args = parser.parse_args(argv)
    python = sys.executable
    work = Path(tempfile.mkdtemp(prefix='trust-av-bench-'))
    results: dict[str, Any] = {
        'date': datetime.datetime.now(datetime.UTC).isoformat(timespec='seconds'),
        'cpu_count': os.cpu_count(), 'quick': args.quick, 'parts': {}}
    core_args = ['--steps', '30', '--repeats', '1'] if args.quick else []
    results['parts']['core'] = part('core', [python, str(HERE / 'bench_core.py'), *core_args,
                                             '--out', str(work / 'core.json')],
                                    work / 'core.json')
    for name in ('gru', 'graph'):
        script = HERE / f'bench_{name}.py'
        if script.exists():
            extra = ['--quick'] if args.quick else []
            results['parts'][name] = part(name, [python, str(script), *extra, '--out',
                                                 str(work / f'{name}.json')],
                                          work / f'{name}.json')
        else:
            print(f'== {name}: {script.name} not present, skipped')
    sweep_cmd = [python, '-m', 'trust_av.cli', 'reproduce', '--no-progress',
                 '--results-dir', str(work / 'sweep')]
    if args.quick:
        sweep_cmd += ['--traces', 'nycc', '--predictors', 'ca']
    sweep = part('sweep', sweep_cmd, None)
    cached = part('sweep (cached)', sweep_cmd, None)
    sweep['cached_wall_s'] = cached['wall_s']
    sweep['cases'] = sum(1 for _ in (work / 'sweep' / 'cache').glob('*.json'))
    results['parts']['sweep'] = sweep
    args.out.write_text(json.dumps(results, indent=2) + '\n')
    summary = args.out.with_suffix('.md')
    summary.write_text(markdown(results))
    print(f'\nwrote {args.out} and {summary}\n')
    print(summary.read_text())
    return 0


if __name__ == '__main__':
    sys.exit(main())
