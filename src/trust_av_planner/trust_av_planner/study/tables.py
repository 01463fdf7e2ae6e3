"""The paper's tables from a sweep's results: Tables II/III (one trace and predictor over
alpha, ours beside the paper's), Table IV (maximum improvements), their driver-population
versions (mean and 95 % confidence interval over drivers), and CSV/Markdown writing."""

from __future__ import annotations

import csv
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from trust_av_planner.study.paper_results import MAX_IMPROVEMENT_PERCENT
from trust_av_planner.study.stats import mean_ci95
from trust_av_planner.study.sweep import ALPHAS, METRICS, Case, by_driver


def improvement_percent(metric: str, base: float, value: float) -> float:
    """Improvement of ``value`` over ``base`` (trust up, E and RMSE down), percent."""
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
        out.append(max(improvement_percent(metric, base[metric], m[metric])
                       for a, m in by_alpha.items() if a > 0.0))
    return out[0], out[1], out[2]


def write_rows(path: Path, header: Sequence[str], rows: Sequence[Sequence[object]]) -> None:
    """Write a CSV and a Markdown table with the same content (``path`` without suffix)."""
    with path.with_suffix('.csv').open('w', newline='') as handle:
        writer = csv.writer(handle)
        writer.writerow(header)
        writer.writerows(rows)
    lines = ['| ' + ' | '.join(header) + ' |', '|' + '---|' * len(header)]
    lines += ['| ' + ' | '.join(str(v) for v in row) + ' |' for row in rows]
    path.with_suffix('.md').write_text('\n'.join(lines) + '\n')


def alpha_table(results: dict[Case, dict[str, Any]], trace: str, predictor: str,
                paper: dict[float, tuple[float, float, float]] | None
                ) -> tuple[list[str], list[list[object]]]:
    """Table II/III layout: per alpha our three metrics (and the paper's), then max improvement."""
    header = ['alpha', 'final trust', 'mean E', 'RMSE (m/s^2)']
    if paper is not None:
        header += ['paper final trust', 'paper mean E', 'paper RMSE (m/s^2)']
    rows: list[list[object]] = []
    for alpha in ALPHAS:
        m = results[Case(trace, predictor, alpha)]['metrics']
        row: list[object] = [f'{alpha:g}', f"{m['final_trust']:.3f}",
                             f"{m['mean_explicability']:.4f}", f"{m['rmse_mps2']:.3f}"]
        if paper is not None:
            row += [f'{v:g}' for v in paper[alpha]]
        rows.append(row)
    ours = max_improvements(results, trace, predictor)
    summary: list[object] = ['max improvement', *(f'{v:.2f} %' for v in ours)]
    if paper is not None:
        summary += [f'{v:.2f} %' for v in MAX_IMPROVEMENT_PERCENT[(predictor, trace)]]
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
    mean, half = mean_ci95(values)
    return f'{mean:.{digits}f} ± {half:.{digits}f}{suffix}'


def population_alpha_table(results: dict[Case, dict[str, Any]], trace: str, predictor: str,
                           paper: dict[float, tuple[float, float, float]] | None
                           ) -> tuple[list[str], list[list[object]]]:
    """Table II/III with a driver population: mean ± 95 % CI over drivers in every cell.

    The maximum improvement is computed per driver (against that driver's alpha = 0), then
    summarised the same way.
    """
    drivers = by_driver(results)
    header = ['alpha', 'final trust', 'mean E', 'RMSE (m/s^2)']
    if paper is not None:
        header += ['paper final trust', 'paper mean E', 'paper RMSE (m/s^2)']
    rows: list[list[object]] = []
    for alpha in ALPHAS:
        per = [d[Case(trace, predictor, alpha)]['metrics'] for d in drivers.values()]
        row: list[object] = [f'{alpha:g}', _cell([m['final_trust'] for m in per], 3),
                             _cell([m['mean_explicability'] for m in per], 4),
                             _cell([m['rmse_mps2'] for m in per], 3)]
        if paper is not None:
            row += [f'{v:g}' for v in paper[alpha]]
        rows.append(row)
    improvements = [max_improvements(d, trace, predictor) for d in drivers.values()]
    summary: list[object] = ['max improvement', *(_cell([imp[i] for imp in improvements], 2,
                                                        ' %') for i in range(3))]
    if paper is not None:
        summary += [f'{v:.2f} %' for v in MAX_IMPROVEMENT_PERCENT[(predictor, trace)]]
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
            means = [float(np.mean([imp[i] for imp in improvements])) for i in range(3)]
            paper = MAX_IMPROVEMENT_PERCENT[(predictor, trace)]
            ratios = ', '.join(f'{o / p:.2f}' for o, p in zip(means, paper, strict=True))
            rows.append([f'TAC-{predictor.upper()}', trace,
                         *[_cell([imp[i] for imp in improvements], 2, ' %') for i in range(3)],
                         *[f'{v:.2f} %' for v in paper], ratios])
    return header, rows
