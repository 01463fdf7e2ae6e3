"""Offline trust estimation: a CSV of observed plans in, a CSV of E, P and trust out.

Input: UTF-8 CSV with columns ``t`` (s), ``plan_0 .. plan_{N-1}`` (the AV's plan, m/s^2)
and ``expected_0 .. expected_{N-1}`` (the plan the human expects, m/s^2), one row per
control step in time order; other columns are ignored. Plans are accelerations: a value
outside +-:data:`MAX_ACCEL_MPS2` is refused (no vehicle accelerates at 10 g; far larger
values would overflow eq. (8)). Output: ``t, E, P, trust`` (trust after the step's update),
and ``trust_variance`` when the trust model has an uncertainty, written only when every row
is valid and every estimate finite.

The trust model is the registered one the params files' ``trust_model`` names (or
``--trust-model``), with its own parameters from the same files
(:mod:`trust_monitor.model_interface`).

Parameters: the trust monitor's, from the shipped params file with every ``--params-file``
layered over it, read by rcl's rules as the ``trust_monitor`` node reads them.
"""

from __future__ import annotations

import argparse
import csv
import math
import os
import re
import stat
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any, TextIO

from trust_av_common.errors import TrustAvError, one_line
from trust_av_common.input_files import bounded_lines, not_regular
from trust_av_common.lifecycle import LifecycleConfig
from trust_av_common.output_files import cannot_write, link_refused, odd_path, replacing
from trust_av_common.param_layers import layer_files, layered_params, read_layers
from trust_av_common.params import build_config, check_known
from trust_av_common.rcl_values import ParsedParams
from trust_av_common.registry import names
from trust_av_common.wall_clock import WallClockConfig
from trust_monitor.errors import TrustMonitorError
from trust_monitor.model_interface import (
    TRUST_MODELS,
    TrustModel,
    make_trust_model,
    trust_model_config_types,
)
from trust_monitor.paper_trust import TrustConfig, TrustEstimator

__all__ = ['EstimateError', 'build_parser', 'estimate_csv', 'main']

MAX_ACCEL_MPS2 = 100.0
"""Largest plan acceleration magnitude accepted, m/s^2 (about 10 g)."""
MAX_LINE_CHARS = 65536
"""Longest line of a plans CSV."""
_COLUMN = re.compile(r'(plan|expected)_(\d+)')


class EstimateError(TrustMonitorError):
    """The plans CSV is malformed; the message names the file, row and problem."""


def plan_columns(path: Path, header: Sequence[str]) -> tuple[list[str], list[str]]:
    """The plan and expected-plan columns of a header, in horizon order.

    Raises:
        EstimateError: no ``t``, no ``plan_0``, a ``plan_``/``expected_`` column whose suffix
            is not an index, indices that are not 0..N-1, or a different number of plan and
            expected columns.
    """
    found: dict[str, dict[int, str]] = {'plan': {}, 'expected': {}}
    for name in header:
        if not name.startswith(('plan_', 'expected_')):
            continue
        match = _COLUMN.fullmatch(name)
        if match is None or (len(match.group(2)) > 1 and match.group(2).startswith('0')):
            shown = name if len(name) <= 40 else name[:37] + '...'
            raise EstimateError(f'{path}:1: column {shown!r} is not plan_<k> or expected_<k> '
                                'with k = 0, 1, ...')
        found[match.group(1)][int(match.group(2))] = name
    plans, expected = found['plan'], found['expected']
    if 't' not in header or not plans:
        raise EstimateError(f'{path}: header needs t, plan_0.., expected_0..; missing '
                            f'{"t" if "t" not in header else "plan_0"}')
    for kind, columns in found.items():
        if sorted(columns) != list(range(len(columns))):
            raise EstimateError(f'{path}:1: {kind} columns must be {kind}_0..{kind}_'
                                f'{len(columns) - 1} without gaps')
    if len(plans) != len(expected):
        raise EstimateError(f'{path}:1: {len(plans)} plan columns but {len(expected)} expected '
                            'columns (both are the same horizon)')
    return [plans[k] for k in range(len(plans))], [expected[k] for k in range(len(expected))]


def _rows(path: Path, handle: TextIO, config: TrustConfig,
          model: TrustModel | None) -> list[tuple[float, ...]]:
    reader = csv.reader(bounded_lines(handle, path, MAX_LINE_CHARS, EstimateError))
    header = next(reader, None)
    if header is None:
        raise EstimateError(f'{path}: header needs t, plan_0.., expected_0..; the file is empty')
    if len(set(header)) != len(header):
        raise EstimateError(f'{path}:1: a column name appears twice')
    plan_cols, exp_cols = plan_columns(path, header)
    index = {name: i for i, name in enumerate(header)}
    wanted = [index[c] for c in ['t', *plan_cols, *exp_cols]]
    n = len(plan_cols)
    estimator = TrustEstimator(config, model)
    rows: list[tuple[float, ...]] = []
    last_t = -math.inf
    for line, row in enumerate(reader, start=2):
        if not row:
            continue
        if len(row) != len(header):
            raise EstimateError(f'{path}:{line}: expected {len(header)} values, got {len(row)}')
        values = []
        for i in wanted:
            try:
                values.append(float(row[i]))
            except ValueError as err:
                raise EstimateError(f'{path}:{line}: {header[i]} is not a number') from err
        if not all(math.isfinite(v) for v in values):
            raise EstimateError(f'{path}:{line}: NaN or infinite value')
        for name, value in zip([*plan_cols, *exp_cols], values[1:], strict=True):
            if abs(value) > MAX_ACCEL_MPS2:
                raise EstimateError(f'{path}:{line}: {name} = {value:g} m/s^2 is outside '
                                    f'+-{MAX_ACCEL_MPS2:g} m/s^2')
        t = values[0]
        if t <= last_t:
            raise EstimateError(f'{path}:{line}: time {t} does not increase')
        last_t = t
        est = estimator.step(values[1:1 + n], values[1 + n:])
        row_out: tuple[float, ...] = (t, est.explicability, est.performance, est.trust)
        if est.variance is not None:
            row_out = (*row_out, est.variance)
        if not all(math.isfinite(v) for v in row_out):
            raise EstimateError(f'{path}:{line}: the estimate is not finite (E, P, trust = '
                                f'{row_out[1]}, {row_out[2]}, {row_out[3]}); check the trust '
                                'parameters')
        rows.append(row_out)
    return rows


def check_output(out_path: Path) -> None:
    """Refuse an output path that cannot be written, before any work.

    Raises:
        EstimateError: an odd path (a NUL or newline in it, ``.``), a symbolic link, a
            directory, or a parent that is missing or not a directory.
    """
    odd = odd_path(out_path)
    if odd is not None:
        raise EstimateError(f'-o {str(out_path)!r}: {odd}')
    refused = link_refused(out_path)
    if refused is not None:
        raise EstimateError(f'-o {out_path}: {refused}')
    if out_path.is_dir():
        raise EstimateError(f'{out_path}: is a directory; -o needs a file name')
    parent = out_path.parent
    if not parent.is_dir():
        raise EstimateError(f'{out_path}: no such directory {parent}')
    problem = cannot_write(out_path, parent)
    if problem is not None:
        raise EstimateError(f'{out_path}: {problem}')


def estimate_csv(in_path: Path, out_path: Path, config: TrustConfig,
                 model: TrustModel | None = None) -> int:
    """Run the trust estimator over a plans CSV and write the estimates.

    Args:
        in_path: the plans CSV.
        out_path: the estimates CSV to write.
        config: the shared trust parameters (eps, ``trust_model``).
        model: the trust model (None: ``config.trust_model`` with default parameters).

    The output is written to a temporary file beside ``out_path`` and renamed, so a failure
    leaves no partial file.

    Returns:
        The number of rows written.

    Raises:
        EstimateError: unreadable, not UTF-8 or not CSV, bad columns, non-numeric,
            non-finite or out-of-range values, time not increasing, a non-finite estimate.
        OutputFileError: the output cannot be written (the file there before is kept).
    """
    check_output(out_path)
    kind = not_regular(in_path)
    if kind is not None:                # checked before opening: a FIFO blocks the open
        raise EstimateError(f'{in_path}: not a regular file ({kind})')
    try:
        handle = in_path.open(newline='', encoding='utf-8-sig')
    except OSError as err:
        raise EstimateError(f'{in_path}: cannot open ({err.strerror})') from err
    with handle:
        if not stat.S_ISREG(os.fstat(handle.fileno()).st_mode):
            raise EstimateError(f'{in_path}: not a regular file')
        try:
            rows = _rows(in_path, handle, config, model)
        except UnicodeDecodeError as err:
            raise EstimateError(f'{in_path}: not UTF-8 text (expected a CSV)') from err
        except csv.Error as err:
            raise EstimateError(f'{in_path}: not CSV text ({err})') from err
    with replacing(out_path) as (temporary,), temporary.open('w', newline='') as out:
        writer = csv.writer(out)
        writer.writerow(['t', 'E', 'P', 'trust', 'trust_variance'][:len(rows[0]) if rows
                                                                   else 4])
        writer.writerows([[repr(v) for v in r] for r in rows])
    return len(rows)


def trust_setup(params_files: Sequence[Path], trust_model: str | None = None,
                ) -> tuple[TrustConfig, TrustModel]:
    """The trust monitor's configuration and its trust model, as the ``trust_monitor``
    node in namespace ``/`` gets them.

    Args:
        params_files: params files over the shipped one, in order.
        trust_model: a registered model name over the files' ``trust_model`` (None: the
            files').

    Raises:
        ParamsError: an unknown parameter, a bad value (one line).
        RegistryError: the model is not registered.
    """
    layers: list[ParsedParams] = read_layers(layer_files(params_files))
    for layer in layers:
        for section, section_values in layer.items():
            if section.rstrip('/').rsplit('/', 1)[-1] == 'trust_monitor':
                check_known(section_values, TrustConfig, WallClockConfig, LifecycleConfig,
                            *trust_model_config_types(),
                            where=f'{layer.where}: section {section}')
    values: dict[str, Any] = dict(layered_params(layers, '/trust_monitor'))
    if trust_model is not None:
        values['trust_model'] = trust_model
    config = build_config(TrustConfig, values)
    return config, make_trust_model(config, values)


def build_parser() -> argparse.ArgumentParser:
    """The ``trust-monitor-estimate`` parser (also the source of its reference page)."""
    parser = argparse.ArgumentParser(
        prog='trust-monitor-estimate',
        description="Estimate the human follower's trust from observed AV plans and expected "
                    'plans (Ozkan & Ma, eqs. 8-11). Input CSV columns: t, plan_0..plan_{N-1}, '
                    'expected_0..expected_{N-1} (m/s^2, within +-100); output CSV columns: t, '
                    'E, P, trust. Exit codes: 0 done, 2 bad input (one line).')
    parser.add_argument('input', type=Path, help='CSV of observed plans')
    parser.add_argument('-o', '--output', type=Path, required=True, help='CSV to write')
    parser.add_argument('--params-file', type=Path, action='append', default=[],
                        help='ROS 2 params file over the shipped config/trust_av.yaml '
                             '(repeatable: later files over earlier ones)')
    parser.add_argument('--trust-model', default=None,
                        help="registered trust model, over the params files' trust_model "
                             f'(registered: {", ".join(names(TRUST_MODELS))})')
    return parser


def main(argv: list[str] | None = None) -> int:
    """Command line entry point ``trust-monitor-estimate``."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        count = estimate_csv(args.input, args.output,
                             *trust_setup(args.params_file, args.trust_model))
    except TrustAvError as err:
        print(f'trust-monitor-estimate: error: {one_line(err)}', file=sys.stderr)
        return 2
    print(f'wrote {count} rows to {args.output}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
