"""The paper's tables from a sweep's results: Tables II/III (one trace and predictor over
alpha, ours beside the paper's), Table IV (maximum improvements), their driver-population
versions (mean and 95 % confidence interval over drivers), and CSV/Markdown writing.

Any case lays out: a (predictor, trace) the paper did not print gets empty paper cells
(:data:`NO_VALUE`), an alpha axis without 0 or without a larger alpha no improvements."""

from __future__ import annotations

import csv
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from trust_av.study.paper_results import MAX_IMPROVEMENT_PERCENT
from trust_av.study.population import by_driver
from trust_av.study.sweep import METRICS, Case
from trust_av_common.output_files import replacing
from trust_av_common.stats import mean_ci95
from trust_monitor.final_trust_bound import row_bound
from trust_monitor.paper_trust import TrustConfig

__all__ = ['BOUND_HEADER', 'alpha_table', 'improvement_percent', 'improvement_table',
           'population_alpha_table', 'population_improvement_table', 'write_rows']

NO_VALUE = '—'
"""A cell with nothing to show (no paper value for the case, no improvement over alpha 0)."""

BOUND_HEADER = 'least final trust eqs. 9-11 allow for the paper mean E'
"""Column beside each paper row: the bound T_M >= T_0 + delta M (1 - c mean E) of
:func:`trust_monitor.final_trust_bound.row_bound`, and whether the printed final trust
reaches it."""


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
    ``base`` is 0 (no relative change to give)."""
    if base == 0.0:
        return math.nan
    if metric == 'final_trust':
        return 100.0 * (value - base) / abs(base)
    return 100.0 * (base - value) / base


def alphas_of(results: dict[Case, dict[str, Any]], trace: str, predictor: str) -> list[float]:
    """The alphas the results hold for ``trace`` and ``predictor``, in order."""
    return sorted({c.alpha for c in results if c.trace == trace and c.predictor == predictor})


def max_improvements(results: dict[Case, dict[str, Any]], trace: str,
                     predictor: str) -> tuple[float, float, float] | None:
    """Largest improvement over alpha = 0 among the alphas, for each metric (Tables II-IV);
    None when the results hold no alpha = 0 or no larger alpha for the case."""
    by_alpha = {c.alpha: r['metrics'] for c, r in results.items()
                if c.trace == trace and c.predictor == predictor}
    base = by_alpha.get(0.0)
    if base is None or not any(a > 0.0 for a in by_alpha):
        return None
    out = []
    for metric in METRICS:
        values = [improvement_percent(metric, base[metric], m[metric])
                  for a, m in by_alpha.items() if a > 0.0]
        out.append(max((v for v in values if not math.isnan(v)), default=math.nan))
    return out[0], out[1], out[2]


def write_rows(path: Path, header: Sequence[str], rows: Sequence[Sequence[object]],
               note: str = '') -> None:
    """Write a CSV and a Markdown table with the same content (``path`` without suffix);
    ``note`` (a truncated run says so) is a paragraph above the Markdown table."""
    lines = [f'**{note}**', ''] if note else []
    lines += ['| ' + ' | '.join(header) + ' |', '|' + '---|' * len(header)]
    lines += ['| ' + ' | '.join(str(v) for v in row) + ' |' for row in rows]
    with replacing(path.with_suffix('.csv'), path.with_suffix('.md')) as (csv_path, md_path):
        with csv_path.open('w', newline='') as handle:
            writer = csv.writer(handle)
            writer.writerow(header)
            writer.writerows(rows)
        md_path.write_text('\n'.join(lines) + '\n')


def _percent(values: Sequence[float] | None) -> list[str]:
    if values is None:
        return [NO_VALUE] * 3
    return [NO_VALUE if math.isnan(v) else f'{v:.2f} %' for v in values]


def _ratios(ours: Sequence[float] | None, paper: tuple[float, float, float] | None) -> str:
    if ours is None or paper is None:
        return NO_VALUE
    return ', '.join(NO_VALUE if math.isnan(o) else f'{o / p:.2f}'
                     for o, p in zip(ours, paper, strict=True))


def _paper_cells(paper: dict[float, tuple[float, float, float]], alpha: float,
                 bound: tuple[int, TrustConfig] | None) -> list[object]:
    """The paper's row at ``alpha`` (and its bound), or empty cells if it printed none."""
    if alpha not in paper:
        return [NO_VALUE] * (4 if bound is not None else 3)
    cells: list[object] = [f'{v:g}' for v in paper[alpha]]
    if bound is not None:
        cells.append(paper_bound_cell(paper[alpha][0], paper[alpha][1], *bound))
    return cells


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
    for alpha in alphas_of(results, trace, predictor):
        m = results[Case(trace, predictor, alpha)]['metrics']
        row: list[object] = [f'{alpha:g}', f"{m['final_trust']:.3f}",
                             f"{m['mean_explicability']:.4f}", f"{m['rmse_mps2']:.3f}"]
        if paper is not None:
            row += _paper_cells(paper, alpha, bound)
        rows.append(row)
    summary: list[object] = ['max improvement',
                             *_percent(max_improvements(results, trace, predictor))]
    if paper is not None:
        summary += _percent(MAX_IMPROVEMENT_PERCENT.get((predictor, trace)))
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
            paper = MAX_IMPROVEMENT_PERCENT.get((predictor, trace))
            rows.append([f'TAC-{predictor.upper()}', trace, *_percent(ours), *_percent(paper),
                         _ratios(ours, paper)])
    return header, rows


def _cell(values: Sequence[float], digits: int, suffix: str = '') -> str:
    values = [v for v in values if not math.isnan(v)]
    if not values:
        return NO_VALUE
    mean, half = mean_ci95(values)
    if math.isnan(half):
        return f'{mean:.{digits}f}{suffix} (n = 1)'
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
    for alpha in alphas_of(results, trace, predictor):
        per = [d[Case(trace, predictor, alpha)]['metrics'] for d in drivers.values()]
        row: list[object] = [f'{alpha:g}', _cell([m['final_trust'] for m in per], 3),
                             _cell([m['mean_explicability'] for m in per], 4),
                             _cell([m['rmse_mps2'] for m in per], 3)]
        if paper is not None:
            row += _paper_cells(paper, alpha, bound)
        rows.append(row)
    summary: list[object] = ['max improvement', *_improvement_cells(
        [max_improvements(d, trace, predictor) for d in drivers.values()])]
    if paper is not None:
        summary += _percent(MAX_IMPROVEMENT_PERCENT.get((predictor, trace)))
        if bound is not None:
            summary.append('')
    rows.append(summary)
    return header, rows


def _improvement_cells(improvements: Sequence[tuple[float, float, float] | None]) -> list[str]:
    """Per-driver maximum improvements as mean ± 95 % CI cells (empty without any)."""
    known = [imp for imp in improvements if imp is not None]
    if not known:
        return [NO_VALUE] * 3
    return [_cell([imp[i] for imp in known], 2, ' %') for i in range(3)]


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
            known = [imp for imp in improvements if imp is not None]
            means = ([float(np.mean([imp[i] for imp in known])) for i in range(3)]
                     if known else None)
            paper = MAX_IMPROVEMENT_PERCENT.get((predictor, trace))
            rows.append([f'TAC-{predictor.upper()}', trace, *_improvement_cells(improvements),
                         *_percent(paper), _ratios(means, paper)])
    return header, rows
