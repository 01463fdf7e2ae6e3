"""Per-trace results of any study: every metric per alpha with every axis kept, and trust over
time per trust model and alpha on the common scale.

``trust-av reproduce`` and :func:`trust_av.study.frame.study` write, for every trace
of the study (shipped, CSV or bag alike), into ``<results>/by_trace/<trace>/``:

- ``by_alpha.csv``: tidy, one row per run: trace, plan estimator, trust model, follower,
  driver, alpha, every metric of the run, its final trust on the common scale
  (``final_trust_common``) and its collision (``none`` or the line naming it);
- ``by_alpha.md``: the same readable: one row per plan estimator x trust model x follower x
  alpha (a driver population: mean ± 95 % confidence interval over drivers per cell), then
  the largest improvement over alpha = 0 of each combination;
- ``improvements.csv``: that improvement, tidy (per driver);
- ``trust.png``: trust over time on the common scale [0, 1], one panel per trust model
  (columns) and plan estimator x follower (rows; a single row wraps two panels wide), one
  line per alpha.

The model and follower names are the ones each run ran with (the params file's choice
resolved), so no axis is folded into another: a study of three trust models has three
columns of panels and three rows per alpha.
"""

from __future__ import annotations

import csv
import math
import re
import textwrap
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from trust_av.study.plots import pyplot, save_figure
from trust_av.study.sweep import METRICS, Case, ParamsFiles, case_config
from trust_av.study.tables import NO_VALUE, max_improvements
from trust_av_common.output_files import replacing, write_text
from trust_av_common.stats import mean_ci95
from trust_monitor.model_interface import TrustModel, unit_trust

__all__ = ['FILES', 'trace_folders', 'trace_paths', 'write_trace_reports']

FILES = ('by_alpha.csv', 'by_alpha.md', 'improvements.csv', 'trust.png')
"""The files written for each trace, in ``<results>/by_trace/<trace>/``."""
AXES = ('predictor', 'trust_model', 'driver_model')
"""The axes besides trace, alpha and driver; each is a column of every table."""
HEADERS = {'predictor': 'plan estimator', 'trust_model': 'trust model',
           'driver_model': 'follower', 'alpha': 'α', 'drivers': 'drivers',
           'steps': 'steps', 'final_trust': 'final trust',
           'final_trust_common': 'final trust (common scale)',
           'mean_explicability': 'mean E', 'rmse_mps2': 'RMSE (m/s²)',
           'min_av_gap_m': 'min AV gap (m)', 'min_human_gap_m': 'min human gap (m)',
           'fallback_steps': 'NMPC fallback steps',
           'driver_fallback_steps': 'driver fallback steps', 'unsafe_steps': 'unsafe steps',
           'collision': 'collision'}
DIGITS = {'final_trust': 3, 'final_trust_common': 4, 'mean_explicability': 4,
          'rmse_mps2': 3, 'min_av_gap_m': 2, 'min_human_gap_m': 2}
"""Decimals shown in the Markdown table (counts are whole numbers)."""


def trace_folders(traces: Sequence[str]) -> dict[str, str]:
    """Each trace's folder name under ``by_trace/``: its name or file stem, with characters
    other than letters, digits, ``._-`` replaced, made unique (``_2``, ...) in study order."""
    out: dict[str, str] = {}
    for trace in traces:
        base = re.sub(r'[^A-Za-z0-9._-]', '_', Path(trace).stem or trace) or 'trace'
        name, k = base, 1
        while name in out.values():
            k += 1
            name = f'{base}_{k}'
        out[trace] = name
    return out


def trace_paths(results_dir: Path, traces: Sequence[str]) -> dict[str, list[Path]]:
    """The files :func:`write_trace_reports` writes for each trace."""
    return {trace: [results_dir / 'by_trace' / folder / name for name in FILES]
            for trace, folder in trace_folders(traces).items()}


@dataclass(frozen=True)
class Scale:
    """A trust model's own units mapped to the common scale by the one conversion
    (:func:`~trust_monitor.model_interface.unit_trust`)."""

    model: TrustModel

    def common(self, trust: Sequence[float] | np.ndarray) -> np.ndarray:
        """``trust`` (the model's readings) on the common scale [0, 1]."""
        return np.array([unit_trust(self.model, value) for value in np.asarray(trust, float)])


def scales(cases: Sequence[Case], params_file: ParamsFiles) -> dict[str, Scale]:
    """The common-scale mapping of each trust model of the cases ('' = the params file's),
    from the model as configured (its declared ``trust_range``)."""
    out = {}
    for case in cases:
        if case.trust_model not in out:
            out[case.trust_model] = Scale(case_config(case, params_file).trust_model())
    return out


def run_rows(cases: Sequence[Case], results: dict[Case, dict[str, Any]],
             scale: dict[str, Scale]) -> list[dict[str, Any]]:
    """One tidy row per case: the axes as they ran, every metric, the final trust on the
    common scale, the collision."""
    rows = []
    for case in cases:
        result = results[case]
        settings = result['settings']
        trust = result['metrics']['final_trust']
        rows.append({'trace': case.trace, **{axis: settings[axis] for axis in AXES},
                     'driver': case.driver, 'alpha': case.alpha, **result['metrics'],
                     'final_trust_common': float(scale[case.trust_model].common([trust])[0]),
                     'collision': result.get('collision') or 'none'})
    return rows


def _cell(values: Sequence[Any], digits: int | None) -> str:
    """One value, or mean ± 95 % CI of a population's values."""
    numbers = [float(v) for v in values if not (isinstance(v, float) and math.isnan(v))]
    if not numbers:
        return NO_VALUE
    def fmt(value: float) -> str:
        return f'{value:.{digits}f}' if digits is not None else f'{value:g}'

    if len(numbers) == 1:
        return fmt(numbers[0])
    mean, half = mean_ci95(numbers)
    return f'{fmt(mean)} ± {fmt(half)}'


def combination(row: dict[str, Any]) -> tuple[str, str, str]:
    """A row's (plan estimator, trust model, follower)."""
    return row['predictor'], row['trust_model'], row['driver_model']


def alpha_markdown(trace: str, rows: Sequence[dict[str, Any]],
                   improvements: Sequence[dict[str, Any]], note: str = '') -> str:
    """The readable per-alpha table of one trace, then the largest improvements."""
    metrics = [key for key in rows[0] if key not in ('trace', *AXES, 'driver', 'alpha',
                                                        'collision', 'final_trust_common')]
    if 'final_trust' in metrics:     # the common scale beside the model's own units
        metrics.insert(metrics.index('final_trust') + 1, 'final_trust_common')
    groups: dict[tuple[Any, ...], list[dict[str, Any]]] = {}
    for row in rows:
        groups.setdefault((*combination(row), row['alpha']), []).append(row)
    population = any(len(members) > 1 for members in groups.values())
    header = [HEADERS.get(k, k) for k in (*AXES, 'alpha')]
    header += ['drivers'] if population else []
    header += [HEADERS.get(m, m) for m in metrics] + ['collision']
    lines = [f'# {Path(trace).name}: every metric per α', '']
    if note:
        lines += [f'**{note}**', '']
    if population:
        lines += ['Each cell: mean ± 95 % confidence interval over the drivers.', '']
    lines += ['| ' + ' | '.join(header) + ' |', '|' + '---|' * len(header)]
    for (predictor, trust_model, driver_model, alpha), members in groups.items():
        crashed = [m['collision'] for m in members if m['collision'] != 'none']
        cells = [predictor, trust_model, driver_model, f'{alpha:g}']
        cells += [str(len(members))] if population else []
        cells += [_cell([m[k] for m in members], DIGITS.get(k)) for k in metrics]
        cells.append(f'{len(crashed)} of {len(members)}' if population and crashed
                     else (crashed[0] if crashed else 'none'))
        lines.append('| ' + ' | '.join(cells) + ' |')
    lines += ['', '## Largest improvement over α = 0', '',
              'Final trust up, mean E and RMSE down, in percent of the α = 0 run with the same '
              f'plan estimator, trust model, follower and driver ({NO_VALUE}: no α = 0 or no '
              'larger α in the study).', '']
    header = [HEADERS[k] for k in AXES] + [HEADERS[m] for m in METRICS]
    lines += ['| ' + ' | '.join(header) + ' |', '|' + '---|' * len(header)]
    by_combination: dict[tuple[str, str, str], list[dict[str, Any]]] = {}
    for row in improvements:
        by_combination.setdefault(combination(row), []).append(row)
    for key, members in by_combination.items():
        cells = [*key, *(_cell([m[f'{metric}_improvement_percent'] for m in members], 2)
                         for metric in METRICS)]
        lines.append('| ' + ' | '.join(c if c == NO_VALUE else
                                       (f'{c} %' if i >= len(AXES) else c)
                                       for i, c in enumerate(cells)) + ' |')
    return '\n'.join(lines) + '\n'


def improvement_rows(cases: Sequence[Case], results: dict[Case, dict[str, Any]]
                     ) -> list[dict[str, Any]]:
    """The largest improvement over alpha = 0 of every (trace, plan estimator, trust model,
    follower, driver): one tidy row each (NaN where there is none)."""
    groups: dict[tuple[Any, ...], dict[Case, dict[str, Any]]] = {}
    for case in cases:
        key = (case.trace, case.predictor, case.trust_model, case.driver_model, case.driver)
        groups.setdefault(key, {})[case] = results[case]
    rows = []
    for (trace, predictor, _, _, driver), members in groups.items():
        settings = next(iter(members.values()))['settings']
        best = max_improvements(members, trace, predictor)
        values = best if best is not None else (math.nan,) * len(METRICS)
        rows.append({'trace': trace, **{axis: settings[axis] for axis in AXES},
                     'driver': driver,
                     **{f'{m}_improvement_percent': v
                        for m, v in zip(METRICS, values, strict=True)}})
    return rows


def write_csv(path: Path, rows: Sequence[dict[str, Any]]) -> None:
    """Tidy CSV, whole or not at all; columns in first-seen order."""
    columns = list(dict.fromkeys(key for row in rows for key in row))
    with replacing(path) as (target,), target.open('w', newline='') as handle:
        writer = csv.DictWriter(handle, fieldnames=columns, restval='')
        writer.writeheader()
        writer.writerows(rows)


def trust_figure(trace: str, cases: Sequence[Case], results: dict[Case, dict[str, Any]],
                 scale: dict[str, Scale], path: Path, note: str = '') -> None:
    """Trust over time on the common scale: a panel per trust model (columns) and per plan
    estimator x follower (rows), a line per alpha (a driver population: the mean over its
    drivers)."""
    series: dict[tuple[str, str], dict[str, dict[float, list[np.ndarray]]]] = {}
    times: dict[tuple[str, str, str, float], list[float]] = {}
    models: list[str] = []
    for case in cases:
        result = results[case]
        settings = result['settings']
        row_key = (settings['predictor'], settings['driver_model'])
        model = settings['trust_model']
        if model not in models:
            models.append(model)
        common = scale[case.trust_model].common(result['trust'])
        series.setdefault(row_key, {}).setdefault(model, {}).setdefault(
            case.alpha, []).append(common)
        times[(*row_key, model, case.alpha)] = result['time_s']
    alphas = sorted({case.alpha for case in cases})
    plt = pyplot()
    rows = list(series)
    panels = [(row_key, model) for row_key in rows for model in models]
    # a panel per model and plan estimator x follower; one such row wraps two panels wide
    columns = len(models) if len(rows) > 1 else min(len(models), 2)
    lines = math.ceil(len(panels) / columns)
    fig, axes = plt.subplots(lines, columns, squeeze=False, sharex=True, sharey=True,
                             figsize=(4.6 * columns + 0.6, 2.8 * lines + 0.9))
    colors = plt.get_cmap('viridis')
    for index, (row_key, model) in enumerate(panels):
        ax = axes[index // columns, index % columns]
        for alpha, members in sorted(series[row_key].get(model, {}).items()):
            length = min(len(m) for m in members)
            mean = np.mean([m[:length] for m in members], axis=0)
            t = times[(*row_key, model, alpha)][:length]
            k = alphas.index(alpha)
            label = f'α = {alpha:g}' + (f' (mean of {len(members)})'
                                        if len(members) > 1 else '')
            ax.plot(t, mean, color=colors(k / max(len(alphas) - 1, 1)), linewidth=1.1,
                    label=label)
        ax.set_title(f'{model} | TAC-{row_key[0].upper()} | follower {row_key[1]}',
                     fontsize=9)
        ax.grid(alpha=0.3)
        if index % columns == 0:
            ax.set_ylabel('trust, common scale')
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=7, loc='lower right')
    for ax in axes[-1, :]:
        ax.set_xlabel('time (s)')
    for index in range(len(panels), lines * columns):     # an odd panel count leaves one
        axes[index // columns, index % columns].set_visible(False)
    width = max(60, int(14 * (4.6 * columns + 0.6)))    # characters the figure holds
    fig.suptitle(f'{Path(trace).name}: trust over time per trust model and α (common scale [0, 1])'
                 + (f'\n{textwrap.fill(note, width)}' if note else ''), fontsize=10)
    fig.tight_layout()
    save_figure(fig, path, dpi=100)
    plt.close(fig)


def write_trace_reports(results_dir: Path, cases: Sequence[Case],
                        results: dict[Case, dict[str, Any]], params_file: ParamsFiles,
                        note: str = '') -> list[Path]:
    """Write every trace's tables and figure (module docstring); return the files written.

    Args:
        results_dir: the study's results directory.
        cases: the study's cases, in table order.
        results: their results (:func:`~trust_av.study.sweep.run_sweep`).
        params_file: the params file(s) the study ran with (for each trust model's scale).
        note: a line every table and figure carries (a truncated run says so).
    """
    traces = list(dict.fromkeys(case.trace for case in cases))
    scale = scales(cases, params_file)
    written = []
    for trace, paths in trace_paths(Path(results_dir), traces).items():
        own = [case for case in cases if case.trace == trace]
        rows = run_rows(own, results, scale)
        improvements = improvement_rows(own, results)
        csv_path, md_path, improvements_path, figure_path = paths
        csv_path.parent.mkdir(parents=True, exist_ok=True)
        write_csv(csv_path, rows)
        write_text(md_path, alpha_markdown(trace, rows, improvements, note))
        write_csv(improvements_path, improvements)
        trust_figure(trace, own, results, scale, figure_path, note)
        written += paths
    return written
