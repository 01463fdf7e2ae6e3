"""Every trace of a study gets its own per-alpha table (every metric, every trust model and
follower an axis) and its trust figure: from ``trust-av reproduce`` on a user's trace and
from :func:`trust_av.study.frame.study`."""

from __future__ import annotations

import csv
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
from support.study import InlineExecutor

from trust_av.study import sweep, trace_reports
from trust_av.study.sweep import Case
from trust_av.system.config import DEFAULT_PARAMS_FILE
from trust_av_common.registry import names
from trust_monitor.model_interface import TRUST_MODELS

MODELS = ('paper', 'beta_bernoulli')


@pytest.fixture
def user_trace(tmp_path: Path) -> Path:
    """A user's trace: a stop and go, 40 s."""
    path = tmp_path / 'my drive.csv'
    speeds = [min(t, 12) if t < 25 else max(12 - 2 * (t - 25), 0) for t in range(40)]
    path.write_text('time_s,speed_mps\n' + '\n'.join(f'{t},{v}' for t, v in
                                                      enumerate(speeds)) + '\n')
    return path


def read_csv(path: Path) -> list[dict[str, str]]:
    with path.open(newline='') as handle:
        return list(csv.DictReader(handle))


def test_registered_models_are_the_test_models() -> None:
    assert set(MODELS) <= set(names(TRUST_MODELS))


def test_reproduce_on_a_user_trace_writes_its_table_and_figure(tmp_path: Path,
                                                               user_trace: Path) -> None:
    """Two trust models x two followers x two alphas on a CSV: 8 rows in the trace's tidy
    table, each axis as it ran; the Markdown holds every combination; the improvement
    table has one row per combination; the figure is a PNG."""
    out = tmp_path / 'study'
    proc = subprocess.run(
        [sys.executable, '-m', 'trust_av.cli', 'reproduce', '--no-progress',
         '--traces', str(user_trace), '--predictors', 'ca', '--alphas', '0,1',
         '--trust-models', ','.join(MODELS), '--driver-models', 'mpc,idm',
         '--max-steps', '6', '--results-dir', str(out), '--workers', '1'],
        capture_output=True, text=True, timeout=600, stdin=subprocess.DEVNULL)
    assert proc.returncode == 0, proc.stderr[-3000:]
    folder = out / 'by_trace' / 'my_drive'
    assert 'by_trace' in proc.stdout
    assert ("Tables II-IV and Figure 3 are the paper's: 2 of 8 cases, the params file's "
            'follower mpc and trust model paper') in proc.stdout
    rows = read_csv(folder / 'by_alpha.csv')
    assert len(rows) == 8
    assert {(r['trust_model'], r['driver_model'], r['alpha']) for r in rows} == {
        (m, d, a) for m in MODELS for d in ('mpc', 'idm') for a in ('0.0', '1.0')}
    assert {'steps', 'final_trust', 'final_trust_common', 'mean_explicability', 'rmse_mps2',
            'min_av_gap_m', 'min_human_gap_m', 'fallback_steps', 'driver_fallback_steps',
            'unsafe_steps', 'collision'} <= set(rows[0])
    assert all(r['steps'] == '6' for r in rows)
    assert all(0.0 <= float(r['final_trust_common']) <= 1.0 for r in rows)
    # the paper model's trust is in its own units (T(0) + delta t), its common value is not
    paper = next(r for r in rows if r['trust_model'] == 'paper')
    assert float(paper['final_trust']) != pytest.approx(float(paper['final_trust_common']))
    markdown = (folder / 'by_alpha.md').read_text()
    for model in MODELS:
        for follower in ('mpc', 'idm'):
            assert markdown.count(f'| ca | {model} | {follower} |') == 3   # 2 alphas + best
    improvements = read_csv(folder / 'improvements.csv')
    assert len(improvements) == 4
    assert (folder / 'trust.png').read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'
    # all_runs.csv holds the same runs (the per-trace table drops none)
    assert len(read_csv(out / 'all_runs.csv')) == 8


def test_study_writes_the_same_per_trace_outputs(tmp_path: Path, user_trace: Path) -> None:
    """study(), over a shipped trace and a CSV: one folder per trace with all four files;
    a population's Markdown shows mean ± CI and the number of drivers."""
    from trust_av.study.frame import study

    out = tmp_path / 'py'
    frame = study(['nycc', str(user_trace)], ['ca'], [0.0, 0.5], trust_models=MODELS,
                  results_dir=out, executor=InlineExecutor(), max_steps=4)
    assert len(frame) == 8
    for folder in ('nycc', 'my_drive'):
        for name in trace_reports.FILES:
            assert (out / 'by_trace' / folder / name).is_file(), (folder, name)
    rows = read_csv(out / 'by_trace' / 'nycc' / 'by_alpha.csv')
    assert {r['trust_model'] for r in rows} == set(MODELS)


def test_a_population_is_summarised_per_cell(tmp_path: Path, user_trace: Path) -> None:
    """Two drivers of the same case: one Markdown row per case with mean ± CI over them."""
    base = sweep.sweep_cases([str(user_trace)], ['ca'], [0.0, 1.0])
    cases = [Case(c.trace, c.predictor, c.alpha, driver=k) for c in base for k in (1, 2)]
    results: dict[Case, dict[str, Any]] = {}
    for case in cases:
        result = sweep.run_case(case, DEFAULT_PARAMS_FILE, sweep.RunSettings(max_steps=4))
        result['metrics']['final_trust'] += case.driver      # two drivers that differ
        results[case] = result
    trace_reports.write_trace_reports(tmp_path, cases, results, DEFAULT_PARAMS_FILE)
    markdown = (tmp_path / 'by_trace' / 'my_drive' / 'by_alpha.md').read_text()
    assert 'mean ± 95 % confidence interval' in markdown
    row = next(line for line in markdown.splitlines()
               if line.startswith('| ca | paper | mpc | 0 | 2 |'))      # 2 drivers
    assert '| 4 ± 0 |' in row and row.count(' ± ') >= 5
    assert len(read_csv(tmp_path / 'by_trace' / 'my_drive' / 'by_alpha.csv')) == 4


def test_folder_names_are_unique_and_safe() -> None:
    assert trace_reports.trace_folders(['us06', 'a/x y.csv', 'b/x y.csv', 'c/x_y.csv']) == {
        'us06': 'us06', 'a/x y.csv': 'x_y', 'b/x y.csv': 'x_y_2', 'c/x_y.csv': 'x_y_3'}
