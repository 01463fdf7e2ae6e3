"""Command lines: trust-av simulate and trust-monitor-estimate, run as a user would."""

from __future__ import annotations

import csv
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import closed_loop


def trust_av(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, '-m', 'trust_av_planner.cli', *args],
                          capture_output=True, text=True, timeout=300)


@pytest.fixture
def short_trace(tmp_path: Path) -> Path:
    path = tmp_path / 'ramp.csv'
    rows = [f'{t},{min(t * 1.5, 15.0) if t < 30 else max(15.0 - (t - 30) * 2, 0.0)}'
            for t in range(60)]
    path.write_text('time_s,speed_mps\n' + '\n'.join(rows) + '\n')
    return path


def test_simulate_prints_metrics_and_writes_table(short_trace: Path, tmp_path: Path) -> None:
    out = tmp_path / 'run.csv'
    proc = trust_av('simulate', '--trace', str(short_trace), '--alpha', '0.5', '--out', str(out),
                    '--no-progress')
    assert proc.returncode == 0, proc.stderr
    assert 'final trust' in proc.stdout and 'mean explicability E' in proc.stdout
    with out.open() as handle:
        rows = list(csv.DictReader(handle))
    assert len(rows) == 59
    assert {'av_plan_mps2_0', 'expected_plan_mps2_2', 'trust', 'solver_status'} <= set(rows[0])


@pytest.mark.parametrize(('args', 'message'), [
    (['--alpha', '1.5'], 'alpha must be in [0, 1]'),
    (['--predictor', 'magic'], "invalid choice: 'magic'"),
    (['--trace', '/no/such/trace.csv'], '/no/such/trace.csv: cannot open trace'),
    (['--params-file', '/no/such.yaml'], '/no/such.yaml: cannot read params file'),
])
def test_bad_arguments_give_one_clear_line(args: list[str], message: str) -> None:
    proc = trust_av('simulate', '--no-progress', *args)
    assert proc.returncode == 2
    assert message in proc.stderr
    assert 'Traceback' not in proc.stderr


def test_help_explains() -> None:
    proc = trust_av('simulate', '--help')
    assert proc.returncode == 0 and '--alpha' in proc.stdout and 'explicability' in proc.stdout


def test_offline_estimator_matches_the_loop(tmp_path: Path) -> None:
    """trust-monitor-estimate on the loop's observed plans gives the loop's E and trust."""
    records = closed_loop('us06', 0.5).records[:200]
    plans = tmp_path / 'plans.csv'
    with plans.open('w', newline='') as handle:
        writer = csv.writer(handle)
        writer.writerow(['t', *(f'plan_{k}' for k in range(3)),
                         *(f'expected_{k}' for k in range(3))])
        for r in records:
            writer.writerow([r.t_s, *map(repr, r.av_plan_mps2), *map(repr, r.expected_plan_mps2)])
    out = tmp_path / 'trust.csv'
    proc = subprocess.run([sys.executable, '-m', 'trust_monitor.estimate', str(plans), '-o',
                           str(out)], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    with out.open() as handle:
        rows = list(csv.DictReader(handle))
    assert len(rows) == len(records)
    for row, r in zip(rows, records, strict=True):
        assert float(row['E']) == r.explicability
        assert float(row['trust']) == r.trust


def test_offline_estimator_names_bad_row(tmp_path: Path) -> None:
    plans = tmp_path / 'plans.csv'
    plans.write_text('t,plan_0,expected_0\n0,0.1,0.2\n1,nan,0.2\n')
    proc = subprocess.run([sys.executable, '-m', 'trust_monitor.estimate', str(plans), '-o',
                           str(tmp_path / 'o.csv')], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2
    assert f'{plans}:3: NaN or infinite value' in proc.stderr


@pytest.mark.parametrize(('body', 'message'), [
    ('', 'header needs t, plan_0.., expected_0..'),
    ('t,a,b\n0,1,2\n', 'header needs t, plan_0.., expected_0..'),
    ('t,plan_0,expected_0\n1,0.1,0.2\n1,0.1,0.2\n', ':3: time 1.0 does not increase'),
    ('t,plan_0,expected_0\n0,fast,0.2\n', ':2: not a number'),
])
def test_offline_estimator_rejects_bad_files(tmp_path: Path, body: str, message: str) -> None:
    plans = tmp_path / 'plans.csv'
    plans.write_text(body)
    out = tmp_path / 'o.csv'
    proc = subprocess.run([sys.executable, '-m', 'trust_monitor.estimate', str(plans), '-o',
                           str(out)], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2 and message in proc.stderr
    assert proc.stderr.count('\n') == 1 and not out.exists()
