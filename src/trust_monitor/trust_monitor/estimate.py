"""Offline trust estimation: a CSV of observed plans in, a CSV of E, P and trust out.

Input columns: ``t`` (s), ``plan_0 .. plan_{N-1}`` (the AV's plan, m/s^2) and
``expected_0 .. expected_{N-1}`` (the plan the human expects, m/s^2), one row per control
step in time order. Output columns: ``t, E, P, trust`` (trust after the step's update).
"""

from __future__ import annotations

import argparse
import csv
import math
import sys
from collections.abc import Sequence
from pathlib import Path

from trust_monitor.common.params import build_config, node_params, read_params_file
from trust_monitor.errors import TrustMonitorError
from trust_monitor.trust_model import TrustConfig, TrustEstimator

DEFAULT_PARAMS = Path(__file__).resolve().parent / 'config' / 'trust_av.yaml'


class EstimateError(TrustMonitorError):
    """The plans CSV is malformed; the message names the file, row and problem."""


def estimate_csv(in_path: Path, out_path: Path, config: TrustConfig) -> int:
    """Run the trust estimator over a plans CSV and write the estimates.

    Returns:
        The number of rows written.

    Raises:
        EstimateError: missing columns, non-numeric or non-finite values, time not increasing.
    """
    try:
        handle = in_path.open(newline='')
    except OSError as err:
        raise EstimateError(f'{in_path}: cannot open ({err.strerror})') from err
    with handle:
        reader = csv.DictReader(handle)
        header = reader.fieldnames or []
        plan_cols = sorted((c for c in header if c.startswith('plan_')),
                           key=lambda c: int(c.split('_')[1]))
        exp_cols = [c.replace('plan_', 'expected_') for c in plan_cols]
        missing = [c for c in ['t', *exp_cols] if c not in header]
        if not plan_cols or missing:
            raise EstimateError(f'{in_path}: header needs t, plan_0.., expected_0..; '
                                f'missing {missing or ["plan_0"]}')
        estimator = TrustEstimator(config)
        rows_out: list[Sequence[float]] = []
        last_t = -math.inf
        for line, row in enumerate(reader, start=2):
            try:
                values = [float(row[c]) for c in ['t', *plan_cols, *exp_cols]]
            except (TypeError, ValueError) as err:
                raise EstimateError(f'{in_path}:{line}: not a number ({err})') from err
            if not all(math.isfinite(v) for v in values):
                raise EstimateError(f'{in_path}:{line}: NaN or infinite value')
            t = values[0]
            if t <= last_t:
                raise EstimateError(f'{in_path}:{line}: time {t} does not increase')
            last_t = t
            n = len(plan_cols)
            est = estimator.step(values[1:1 + n], values[1 + n:])
            rows_out.append((t, est.explicability, est.performance, est.trust))
    with out_path.open('w', newline='') as out:
        writer = csv.writer(out)
        writer.writerow(['t', 'E', 'P', 'trust'])
        writer.writerows([[repr(v) for v in r] for r in rows_out])
    return len(rows_out)


def main(argv: list[str] | None = None) -> int:
    """Command line entry point ``trust-monitor-estimate``."""
    parser = argparse.ArgumentParser(
        prog='trust-monitor-estimate',
        description="Estimate the human follower's trust from observed AV plans and expected "
                    'plans (Ozkan & Ma, eqs. 8-11). Input CSV columns: t, plan_0..plan_{N-1}, '
                    'expected_0..expected_{N-1}; output CSV columns: t, E, P, trust.')
    parser.add_argument('input', type=Path, help='CSV of observed plans')
    parser.add_argument('-o', '--output', type=Path, required=True, help='CSV to write')
    parser.add_argument('--params-file', type=Path, default=DEFAULT_PARAMS,
                        help='ROS 2 params file with the trust parameters (default: %(default)s)')
    args = parser.parse_args(argv)
    try:
        config = build_config(TrustConfig,
                              node_params(read_params_file(args.params_file), 'trust_monitor'))
        count = estimate_csv(args.input, args.output, config)
    except TrustMonitorError as err:
        print(f'trust-monitor-estimate: error: {err}', file=sys.stderr)
        return 2
    print(f'wrote {count} rows to {args.output}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
