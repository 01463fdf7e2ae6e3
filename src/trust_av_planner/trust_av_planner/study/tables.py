"""The paper's tables from a sweep's results: Tables II/III (one trace and predictor over
alpha, ours beside the paper's), Table IV (maximum improvements), their driver-population
versions (mean and 95 % confidence interval over drivers), and CSV/Markdown writing."""

from __future__ import annotations

import csv
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from trust_av_planner.study.paper_results import MAX_IMPROVEMENT_PERCENT
from trust_av_planner.study.stats import mean_ci95
from trust_av_planner.study.sweep import ALPHAS, METRICS, Case, by_driver
from trust_monitor.common.output_files import replacing
from trust_monitor.trust_bound import row_bound
from trust_monitor.trust_model import TrustConfig

BOUND_HEADER = 'least final trust eqs. 9-11 allow for the paper mean E'
"""Column beside each paper row: the bound T_M >= T_0 + delta M (1 - c mean E) of
:func:`trust_monitor.trust_bound.row_bound`, and whether the printed final trust reaches it."""


def paper_bound_cell(final_trust: float, mean_score: float, steps: int,
                     trust: TrustConfig) -> str:
    """The bound for one printed paper row, e.g. ``46.50 (44.36 unattainable)``.

    Args:
        final_trust: the paper's printed final trust.
        mean_score: the paper's printed mean E.
        steps: trust updates over the trace (M).
        trust: the trust model's parameters (delta, P_thre, T(0)).
    """
    bound = row_bound(final_trust, mean_score, steps, trust.trust_growth_rate,
                      trust.performance_threshold, trust.trust_initial)
    verdict = 'attainable' if bound.attainable else 'unattainable'
    return f'{bound.bound:.2f} ({final_trust:g} {verdict})'


def improvement_percent(metric: str, base: float, value: float) -> float:
    """Improvement of ``value`` over ``base`` (trust up, E and RMSE down), percent; NaN when
    ``base`` is 0 (a relative change from nothing, e.g. trust still at T(0) = 0 after a
    few steps of ``reproduce --max-steps``)."""
    if base == 0.0:
        return math.nan
    if metric == 'final_trust':
        return 100.0 * (value - base) / abs(base)
    return 100.0 * (base - value) / base


def max_improvements(results: dict[Case, dict[str, Any]], trace: str,
                     predictor: str) -> tuple[float, float, float]:
    """Largest improvement over alpha = 0 among the alphas, for each metric (Tables II-IV)."""
    by_alpha = {c.alpha: r['metrics'] for c, r in results.items()
                if c.trace == trace and c.predictor == predictor}
    base = by_alpha[0.0]
    out = []
    for metric in METRICS:
        changes = [improvement_percent(metric, base[metric], m[metric])
                   for a, m in by_alpha.items() if a > 0.0]
        defined = [change for change in changes if not math.isnan(change)]
        out.append(max(defined) if defined else math.nan)
    return out[0], out[1], out[2]


def write_rows(path: Path, header: Sequence[str], rows: Sequence[Sequence[object]]) -> None:
    """Write a CSV and a Markdown table with the same content (``path`` without suffix)."""
    lines = ['| ' + ' | '.join(header) + ' |', '|' + '---|' * len(header)]
    lines += ['| ' + ' | '.join(str(v) for v in row) + ' |' for row in rows]
    with replacing(path.with_suffix('.csv'), path.with_suffix('.md')) as (csv_path, md_path):
        with csv_path.open('w', newline='') as handle:
            writer = csv.writer(handle)
            writer.writerow(header)
            writer.writerows(rows)
        md_path.write_text('\n'.join(lines) + '\n')


def alpha_table(results: dict[Case, dict[str, Any]], trace: str, predictor: str,
                paper: dict[float, tuple[float, float, float]] | None,
                bound: tuple[int, TrustConfig] | None = None
                ) -> tuple[list[str], list[list[object]]]:
    """Table II/III layout: per alpha our three metrics (and the paper's), then max improvement.

    Args:
        results: the sweep's results.
        trace: the trace of the table.
        predictor: the predictor of the table.
        paper: the paper's rows by alpha (final trust, mean E, RMSE), or None.
        bound: (steps, trust parameters) to print beside each paper row the least final
            trust eqs. (9)-(11) allow for its mean E (:func:`paper_bound_cell`), or None.
    """
    header = ['alpha', 'final trust', 'mean E', 'RMSE (m/s^2)']
    if paper is not None:
        header += ['paper final trust', 'paper mean E', 'paper RMSE (m/s^2)']
        if bound is not None:
            header.append(BOUND_HEADER)
    rows: list[list[object]] = []
    for alpha in ALPHAS:
        m = results[Case(trace, predictor, alpha)]['metrics']
        row: list[object] = [f'{alpha:g}', f"{m['final_trust']:.3f}",
                             f"{m['mean_explicability']:.4f}", f"{m['rmse_mps2']:.3f}"]
        if paper is not None:
            row += [f'{v:g}' for v in paper[alpha]]
            if bound is not None:
                row.append(paper_bound_cell(paper[alpha][0], paper[alpha][1], *bound))
        rows.append(row)
    ours = max_improvements(results, trace, predictor)
    summary: list[object] = ['max improvement', *(f'{v:.2f} %' for v in ours)]
    if paper is not None:
        summary += [f'{v:.2f} %' for v in MAX_IMPROVEMENT_PERCENT[(predictor, trace)]]
        if bound is not None:
            summary.append('')
    rows.append(summary)
    return header, rows


def improvement_table(results: dict[Case, dict[str, Any]], traces: Sequence[str],
                      predictors: Sequence[str]) -> tuple[list[str], list[list[object]]]:
    """Table IV layout: maximum improvements per predictor and trace, ours beside the paper's."""
    header = ['predictor', 'trace', 'final trust', 'mean E', 'RMSE', 'paper final trust',
              'paper mean E', 'paper RMSE', 'ratio ours/paper (trust, E, RMSE)']
    rows: list[list[object]] = []
    for predictor in predictors:
        for trace in traces:
            ours = max_improvements(results, trace, predictor)
            paper = MAX_IMPROVEMENT_PERCENT[(predictor, trace)]
            ratios = ', '.join(f'{o / p:.2f}' for o, p in zip(ours, paper, strict=True))
            rows.append([f'TAC-{predictor.upper()}', trace, *[f'{v:.2f} %' for v in ours],
                         *[f'{v:.2f} %' for v in paper], ratios])
    return header, rows


def _cell(values: Sequence[float], digits: int, suffix: str = '') -> str:
    """Mean ± 95 % CI of the defined values (an improvement over a zero base is NaN), or
    ``n/a`` when none is."""
    defined = [value for value in values if not math.isnan(value)]
    if not defined:
        return 'n/a'
    mean, half = mean_ci95(defined)
    return f'{mean:.{digits}f} ± {half:.{digits}f}{suffix}'


def population_alpha_table(results: dict[Case, dict[str, Any]], trace: str, predictor: str,
                           paper: dict[float, tuple[float, float, float]] | None,
                           bound: tuple[int, TrustConfig] | None = None
                           ) -> tuple[list[str], list[list[object]]]:
    """Table II/III with a driver population: mean ± 95 % CI over drivers in every cell.

    The maximum improvement is computed per driver (against that driver's alpha = 0), then
    summarised the same way. ``bound`` as in :func:`alpha_table`.
    """
    drivers = by_driver(results)
    header = ['alpha', 'final trust', 'mean E', 'RMSE (m/s^2)']
    if paper is not None:
        header += ['paper final trust', 'paper mean E', 'paper RMSE (m/s^2)']
        if bound is not None:
            header.append(BOUND_HEADER)
    rows: list[list[object]] = []
    for alpha in ALPHAS:
        per = [d[Case(trace, predictor, alpha)]['metrics'] for d in drivers.values()]
        row: list[object] = [f'{alpha:g}', _cell([m['final_trust'] for m in per], 3),
                             _cell([m['mean_explicability'] for m in per], 4),
                             _cell([m['rmse_mps2'] for m in per], 3)]
        if paper is not None:
            row += [f'{v:g}' for v in paper[alpha]]
            if bound is not None:
                row.append(paper_bound_cell(paper[alpha][0], paper[alpha][1], *bound))
        rows.append(row)
    improvements = [max_improvements(d, trace, predictor) for d in drivers.values()]
    summary: list[object] = ['max improvement', *(_cell([imp[i] for imp in improvements], 2,
                                                        ' %') for i in range(3))]
    if paper is not None:
        summary += [f'{v:.2f} %' for v in MAX_IMPROVEMENT_PERCENT[(predictor, trace)]]
        if bound is not None:
            summary.append('')
    rows.append(summary)
    return header, rows


def population_improvement_table(results: dict[Case, dict[str, Any]], traces: Sequence[str],
                                 predictors: Sequence[str]
                                 ) -> tuple[list[str], list[list[object]]]:
    """Table IV with a driver population: per-driver maximum improvements, mean ± 95 % CI."""
    drivers = by_driver(results)
    header = ['predictor', 'trace', 'final trust', 'mean E', 'RMSE', 'paper final trust',
              'paper mean E', 'paper RMSE', 'ratio of means ours/paper (trust, E, RMSE)']
    rows: list[list[object]] = []
    for predictor in predictors:
        for trace in traces:
            improvements = [max_improvements(d, trace, predictor) for d in drivers.values()]
            means = [float(np.nanmean([imp[i] for imp in improvements]))
                     if any(not math.isnan(imp[i]) for imp in improvements) else math.nan
                     for i in range(3)]
            paper = MAX_IMPROVEMENT_PERCENT[(predictor, trace)]
            ratios = ', '.join(f'{o / p:.2f}' for o, p in zip(means, paper, strict=True))
            rows.append([f'TAC-{predictor.upper()}', trace,
                         *[_cell([imp[i] for imp in improvements], 2, ' %') for i in range(3)],
                         *[f'{v:.2f} %' for v in paper], ratios])
    return header, rows
