"""Benchmark of ``trust-av fit-trust``: the whole command's wall and CPU time on a synthetic
study, and how far two runs' numbers are apart.

``run`` makes (once, then reads it back) a synthetic study of ``--participants``
participants, an equal share from each registered model, ``--drives`` 120 s
``rough_random`` drives each (:func:`trust_av.study.trust_recovery.synthetic_study`; a
rating at the start and every 2.5 s), runs ``trust-av fit-trust --ratings`` on it as a
child process (partial pooling on, figures on: the command as a user runs it) and prints
and writes to ``--out``/bench_fit_trust.json: wall s, CPU s (the command and its workers,
from ``wait4``), the load average before and after and the core count (the machine may be
shared: CPU s is the steadier figure).

``compare A B`` prints, for two fit-trust output directories of the same data, the largest
absolute difference of every fitted parameter (per model and parameter, over the scopes)
and of every score (elpd, rmse per scheme), and the rows only one of them has.

    python benchmarks/bench_fit_trust.py run --out DIR [--participants 24] [--drives 4]
        [--seed 0] [--table CSV] [-- extra fit-trust options, e.g. --workers 2]
    python benchmarks/bench_fit_trust.py compare DIR_A DIR_B

Not a test: nothing here asserts a speed.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any


def make_study(path: Path, participants: int, drives: int, seed: int) -> None:
    """The synthetic ratings table (``participants`` split evenly over the models)."""
    from trust_av.study.trust_recovery import synthetic_study, write_ratings_table
    from trust_av.system.config import load_run_config
    from trust_av_common.registry import names
    from trust_monitor.model_interface import TRUST_MODELS

    models = list(names(TRUST_MODELS))
    per_model = max(1, participants // len(models))
    people = synthetic_study(load_run_config(), models, per_model, drives, seed=seed)
    write_ratings_table(path, people)


def run(args: argparse.Namespace) -> int:
    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    table = args.table or out / f'ratings_{args.participants}x{args.drives}_seed{args.seed}.csv'
    if not table.exists():
        start = time.perf_counter()
        make_study(table, args.participants, args.drives, args.seed)
        print(f'made {table} in {time.perf_counter() - start:.0f} s', flush=True)
    command = [sys.executable, '-m', 'trust_av.cli', 'fit-trust', '--ratings', str(table), '--out',
               str(out / 'fit_trust'), *args.extra]
    load_before = os.getloadavg()
    start = time.monotonic()
    proc = subprocess.Popen(command)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.monotonic() - start
    code = os.waitstatus_to_exitcode(status)
    figures: dict[str, Any] = {
        'command': ' '.join(command), 'exit_code': code,
        'participants': args.participants, 'drives': args.drives, 'seed': args.seed,
        'wall_s': round(wall, 1), 'cpu_s': round(usage.ru_utime + usage.ru_stime, 1),
        'cores': os.cpu_count(), 'load_before': [round(v, 2) for v in load_before],
        'load_after': [round(v, 2) for v in os.getloadavg()],
        'date': time.strftime('%Y-%m-%d %H:%M:%S', time.gmtime())}
    (out / 'bench_fit_trust.json').write_text(json.dumps(figures, indent=1) + '\n')
    print(f"fit-trust {args.participants} x {args.drives}: wall {wall:.1f} s, CPU "
          f"{figures['cpu_s']:.1f} s, {figures['cores']} cores, load "
          f"{figures['load_before']} -> {figures['load_after']}; exit {code}")
    return code


def _rows(path: Path) -> list[dict[str, str]]:
    with path.open(newline='') as handle:
        return list(csv.DictReader(handle))


def _differences(a: dict[tuple[str, ...], float], b: dict[tuple[str, ...], float],
                 group: int) -> tuple[dict[tuple[str, ...], float], list[tuple[str, ...]]]:
    """Largest |a - b| per key prefix of ``group`` fields; keys only one side has."""
    out: dict[tuple[str, ...], float] = {}
    for key in a.keys() & b.keys():
        d = abs(a[key] - b[key]) if math.isfinite(a[key]) or math.isfinite(b[key]) else 0.0
        out[key[:group]] = max(out.get(key[:group], 0.0), d if math.isfinite(d) else math.inf)
    return out, sorted(a.keys() ^ b.keys())


def compare(args: argparse.Namespace) -> int:
    fits = [{(r['model'], r['kind'], r['parameter'], r['scope']): float(r['value'])
             for r in _rows(d / 'fits.csv')} for d in (args.a, args.b)]
    scores = {}
    for name, d in (('a', args.a), ('b', args.b)):
        scores[name] = {(r['scheme'], r['model'], column, r['scope']): float(r[column])
                        for r in _rows(d / 'scores.csv') for column in ('elpd', 'rmse')}
    pooling = [{(r['model'], r['kind'], r['parameter'], r['scope']): float(r['value'])
                for r in _rows(d / 'partial_pooling.csv')}
               for d in (args.a, args.b) if (d / 'partial_pooling.csv').exists()]
    report: dict[str, Any] = {}
    for title, pair, group in (('fits.csv', fits, 3), ('scores.csv', list(scores.values()), 3),
                               ('partial_pooling.csv', pooling, 3)):
        if len(pair) != 2:
            continue
        diff, only = _differences(pair[0], pair[1], group)
        report[title] = {' '.join(k): v for k, v in sorted(diff.items())}
        print(f'== {title}: largest |A - B| per model, kind/scheme, parameter/column')
        for key, value in sorted(diff.items()):
            print(f'  {" ".join(key):70s} {value:.3g}')
        if only:
            print(f'  rows in one only: {len(only)} (e.g. {" ".join(only[0])})')
            report[title + ' rows in one only'] = len(only)
    if args.json is not None:
        args.json.write_text(json.dumps(report, indent=1) + '\n')
    return 0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    sub = parser.add_subparsers(dest='what', required=True)
    timed = sub.add_parser('run', help='time fit-trust on a synthetic study')
    timed.add_argument('--out', type=Path, required=True)
    timed.add_argument('--participants', type=int, default=24)
    timed.add_argument('--drives', type=int, default=4)
    timed.add_argument('--seed', type=int, default=0)
    timed.add_argument('--table', type=Path, default=None,
                       help='a ratings table to fit instead (made when it does not exist)')
    timed.add_argument('extra', nargs='*', help='more fit-trust options (after --)')
    both = sub.add_parser('compare', help="two fit-trust outputs' largest differences")
    both.add_argument('a', type=Path)
    both.add_argument('b', type=Path)
    both.add_argument('--json', type=Path, default=None)
    args = parser.parse_args()
    if args.what == 'run':
        if args.participants < 1 or args.drives < 1:
            print('need --participants >= 1 and --drives >= 1', file=sys.stderr)
            return 2
        return run(args)
    return compare(args)


if __name__ == '__main__':
    sys.exit(main())
