"""The reproduce sweep: cases, cache and resume, executors, tables, improvement maths."""

from __future__ import annotations

import io
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
from support.study import InlineExecutor

from trust_av.study import population, sweep, tables
from trust_av.study.paper_results import TABLE_II_TAC_GRU_US06, TABLE_III_TAC_CA_US06
from trust_av.study.sweep import Case
from trust_av.system.config import DEFAULT_PARAMS_FILE, load_run_config


@pytest.fixture
def short_trace(tmp_path: Path) -> str:
    path = tmp_path / 'short.csv'
    speeds = [min(t, 12) if t < 25 else max(12 - 2 * (t - 25), 0) for t in range(40)]
    path.write_text('time_s,speed_mps\n' + ''.join(f'{t},{v}\n' for t, v in enumerate(speeds)))
    return str(path)


def test_improvement_maths() -> None:
    assert tables.improvement_percent('final_trust', 44.36, 53.402) == pytest.approx(20.383,
                                                                                      abs=1e-3)
    assert tables.improvement_percent('rmse_mps2', 0.518, 0.353) == pytest.approx(31.85,
                                                                                    abs=1e-2)


def test_cache_resumes_and_reruns_only_changes(tmp_path: Path, short_trace: str) -> None:
    cases = sweep.sweep_cases([short_trace], ['ca'], [0.0, 1.0])
    first = InlineExecutor()
    results = sweep.run_sweep(cases, DEFAULT_PARAMS_FILE, tmp_path, first)
    assert first.ran == cases and set(results) == set(cases)
    again = InlineExecutor()
    cached = sweep.run_sweep(cases, DEFAULT_PARAMS_FILE, tmp_path, again)
    assert again.ran == []
    assert cached[cases[1]]['metrics'] == results[cases[1]]['metrics']
    # A different params file is a different key: everything runs again.
    changed = tmp_path / 'changed.yaml'
    changed.write_text(DEFAULT_PARAMS_FILE.read_text().replace('explicability_scale: 0.005',
                                                               'explicability_scale: 0.006'))
    third = InlineExecutor()
    sweep.run_sweep(cases, changed, tmp_path, third)
    assert third.ran == cases


def test_local_executor_equals_inline(tmp_path: Path, short_trace: str) -> None:
    cases = sweep.sweep_cases([short_trace], ['ca'], [0.0, 0.5, 1.0])
    pooled = sweep.run_sweep(cases, DEFAULT_PARAMS_FILE, tmp_path / 'a',
                                 sweep.LocalExecutor(2))
    inline = sweep.run_sweep(cases, DEFAULT_PARAMS_FILE, tmp_path / 'b', InlineExecutor())
    for case in cases:
        assert pooled[case]['trust'] == inline[case]['trust']
        assert pooled[case]['metrics'] == inline[case]['metrics']


def test_ray_executor_runs_the_same_sweep(tmp_path: Path, short_trace: str) -> None:
    ray = pytest.importorskip('ray', reason='ray is pinned in requirements.txt; the venv has it')
    assert ray is not None
    cases = sweep.sweep_cases([short_trace], ['ca'], [0.0, 1.0])
    with_ray = sweep.run_sweep(cases, DEFAULT_PARAMS_FILE, tmp_path / 'ray',
                                   sweep.RayExecutor(num_cpus=2))
    inline = sweep.run_sweep(cases, DEFAULT_PARAMS_FILE, tmp_path / 'in', InlineExecutor())
    for case in cases:
        assert with_ray[case]['metrics'] == inline[case]['metrics']


def test_failing_case_names_itself(tmp_path: Path) -> None:
    from trust_av.errors import TrustAvAppError
    with pytest.raises(TrustAvAppError, match=r'case .*missing\.csv/TAC-CA/alpha=0 failed'):
        sweep.run_sweep([Case(str(tmp_path / 'missing.csv'), 'ca', 0.0)],
                            DEFAULT_PARAMS_FILE, tmp_path, sweep.LocalExecutor(1))


def test_tables_from_results() -> None:
    def fake(trust: float, score: float, rmse: float) -> dict[str, Any]:
        return {'metrics': {'final_trust': trust, 'mean_explicability': score,
                            'rmse_mps2': rmse}}
    results = {Case('us06', 'ca', a): fake(40 + 10 * a, 0.06 - 0.03 * a, 0.7 - 0.2 * a)
               for a in sweep.ALPHAS}
    header, rows = tables.alpha_table(results, 'us06', 'ca', None)
    assert header[:4] == ['alpha', 'final trust', 'mean E', 'RMSE (m/s^2)']
    assert rows[-1] == ['max improvement', '25.00 %', '50.00 %', '28.57 %']
    header, rows = tables.improvement_table(results, ['us06'], ['ca'])
    assert rows[0][:3] == ['TAC-CA', 'us06', '25.00 %']
    assert rows[0][-1] == '0.84, 0.89, 0.98'   # ours / paper (29.88, 56.37, 29.22)


def test_paper_rows_carry_their_trust_bound() -> None:
    """Beside each paper row: T_M >= delta M (1 - 5.919 mean E); Table II at alpha = 0 (mean
    E 0.038 over 600 steps) needs 46.50 but prints 44.36; Table III at alpha = 0 (0.065)
    allows 36.92 and prints 38.141."""
    results = {Case('us06', p, a): {'metrics': {'final_trust': 50.0, 'mean_explicability': 0.01,
                                                'rmse_mps2': 0.5 - 0.1 * a}}
               for p in ('gru', 'ca') for a in sweep.ALPHAS}
    trust = load_run_config().trust
    header, rows = tables.alpha_table(results, 'us06', 'gru', TABLE_II_TAC_GRU_US06,
                                      (600, trust))
    assert header[-1] == tables.BOUND_HEADER
    assert rows[0][-1] == '46.50 (44.36 unattainable)'
    assert all('unattainable' in row[-1] for row in rows[:-1])
    _, rows = tables.alpha_table(results, 'us06', 'ca', TABLE_III_TAC_CA_US06, (600, trust))
    assert rows[0][-1] == '36.92 (38.141 attainable)'
    assert rows[-1][-1] == ''


def test_profile_and_params_file_exclude_each_other(tmp_path: Path) -> None:
    proc = subprocess.run([sys.executable, '-m', 'trust_av.cli', 'reproduce',
                           '--profile', 'as_reported', '--params-file',
                           str(DEFAULT_PARAMS_FILE), '--results-dir', str(tmp_path)],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    assert '--profile and --params-file both choose the parameters' in proc.stderr


def test_reproduce_command_writes_tables_and_figures(tmp_path: Path) -> None:
    proc = subprocess.run([sys.executable, '-m', 'trust_av.cli', 'reproduce',
                           '--traces', 'nycc', '--predictors', 'ca', '--results-dir',
                           str(tmp_path), '--no-progress', '--workers', '2'],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    for name in ('table_IV_max_improvements.md', 'table_IV_max_improvements.csv',
                 'figure_2_speed_profiles.png', 'all_runs.csv'):
        assert (tmp_path / name).stat().st_size > 0, name
    assert 'TAC-CA nycc: ok' in proc.stdout
    assert (tmp_path / 'figure_2_speed_profiles.png').read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'


@pytest.mark.slow
def test_graph_sweep_equals_in_process_sweep(tmp_path: Path) -> None:
    """``reproduce --graph``: every case through the ROS 2 node graph, numbers as in-process.

    Two cases (NYCC, TAC-CA, alpha 0 and 1, the sweep's ends) of 15 steps on two pooled
    workers: two graphs of six processes each run at once, each on its own ROS domain. (It
    ran all five alphas: three more graph starts of the same code path, about 12 s of CPU;
    graph == in-process at alpha 0.5 is test_graph.py's, for every component
    test_component_contract.py's.)
    """
    steps = 15
    alphas = (0.0, 1.0)
    proc = subprocess.run([sys.executable, '-m', 'trust_av.cli', 'reproduce',
                           '--traces', 'nycc', '--predictors', 'ca', '--alphas',
                           ','.join(f'{a:g}' for a in alphas), '--graph', '--max-steps',
                           str(steps), '--results-dir', str(tmp_path / 'graph'),
                           '--no-progress', '--workers', '2'],
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert '2 cases (graph)' in proc.stdout
    bags = {b.name for b in (tmp_path / 'graph' / 'graph_bags').glob('*/metadata.yaml')
            for b in [b.parent]}
    assert bags == {f'nycc_ca_alpha{a:g}' for a in alphas}
    cases = sweep.sweep_cases(['nycc'], ['ca'], alphas)
    # The same sweep again: read from the graph cache, and in-process with the same steps.
    graph = sweep.run_sweep(cases, DEFAULT_PARAMS_FILE, tmp_path / 'graph',
                                InlineExecutor(), runner='graph', max_steps=steps)
    inline = InlineExecutor()
    in_process = sweep.run_sweep(cases, DEFAULT_PARAMS_FILE, tmp_path / 'in',
                                     inline, max_steps=steps)
    assert inline.ran == cases
    for case in cases:
        assert graph[case]['runner'] == 'graph'
        assert len(graph[case]['trust']) == steps
        assert graph[case]['trust'] == pytest.approx(in_process[case]['trust'], abs=1e-9)
        for name, value in in_process[case]['metrics'].items():
            assert graph[case]['metrics'][name] == pytest.approx(value, abs=1e-9), name


def test_run_settings_are_checked() -> None:
    from trust_av.errors import TrustAvAppError
    with pytest.raises(TrustAvAppError, match=r"runner must be one of .*'rviz'"):
        sweep.RunSettings(runner='rviz')
    with pytest.raises(TrustAvAppError, match='max_steps must be >= 0, got -1'):
        sweep.RunSettings(max_steps=-1)


def test_population_cases_are_seeded_and_named() -> None:
    """From a fit without per-driver fits (the cautious driver's driver_fit.yaml): W drawn
    from its per-pair weights, tau_H its pooled one."""
    from human_driver_sim.population import CAUTIOUS_FIT_FILE, fitted_time_headway_s
    cases = sweep.sweep_cases(['us06'], ['gru'], [0.0, 1.0])
    first = population.population_cases(cases, 3, seed=4, driver_fit=CAUTIOUS_FIT_FILE)
    again = population.population_cases(cases, 3, seed=4, driver_fit=CAUTIOUS_FIT_FILE)
    other = population.population_cases(cases, 3, seed=5, driver_fit=CAUTIOUS_FIT_FILE)
    assert first == again and first != other
    assert len(first) == 6 and [c.driver for c in first] == [1, 2, 3, 1, 2, 3]
    # The same driver k for every alpha, so improvements over alpha = 0 are per driver.
    assert first[0].driver_params == first[3].driver_params
    params = dict(first[0].driver_params)
    assert params['weight_acceleration'] == 1.0 and len(params) == 5
    assert params['time_headway_s'] == fitted_time_headway_s(CAUTIOUS_FIT_FILE) == pytest.approx(
        1.2715, abs=1e-3)
    assert first[1].label == 'us06/TAC-GRU/alpha=0/driver=2'
    assert first[4].base == Case('us06', 'gru', 1.0)
    from trust_av.errors import TrustAvAppError
    with pytest.raises(TrustAvAppError, match='number of drivers must be >= 1, got 0'):
        population.population_cases(cases, 0, seed=1)


def test_population_tables_give_mean_and_95_percent_interval() -> None:
    def fake(trust: float, score: float, rmse: float) -> dict[str, Any]:
        return {'metrics': {'final_trust': trust, 'mean_explicability': score,
                            'rmse_mps2': rmse}, 'time_s': [0.0, 1.0], 'trust': [0.0, trust]}
    results = {}
    for driver, offset in ((1, 0.0), (2, 2.0)):
        for a in sweep.ALPHAS:
            case = Case('us06', 'ca', a, driver, (('weight_relative_distance', 0.01 * driver),))
            results[case] = fake(40 + 10 * a + offset, 0.06 - 0.03 * a, 0.7 - 0.2 * a)
    _, rows = tables.population_alpha_table(results, 'us06', 'ca', None)
    # Trust at alpha = 0: drivers 40 and 42 -> mean 41, half-width t(1) * 1 = 12.706.
    assert rows[0][1] == '41.000 ± 12.706'
    assert rows[0][3] == '0.700 ± 0.000'
    # Max trust improvement per driver: 25 % and 23.81 %; E and RMSE the same for both.
    assert rows[-1][2:] == ['50.00 ± 0.00 %', '28.57 ± 0.00 %']
    assert rows[-1][1].startswith('24.40 ± 7.5')
    mean = population.population_mean(results)
    assert mean[Case('us06', 'ca', 1.0)]['metrics']['final_trust'] == pytest.approx(51.0)
    assert mean[Case('us06', 'ca', 1.0)]['trust'] == pytest.approx([0.0, 51.0])


def test_reproduce_with_a_driver_population(tmp_path: Path) -> None:
    proc = subprocess.run([sys.executable, '-m', 'trust_av.cli', 'reproduce',
                           '--traces', 'nycc', '--predictors', 'gru', '--drivers', '2',
                           '--max-steps', '40', '--results-dir', str(tmp_path),
                           '--no-progress', '--workers', '2'],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert '10 cases (in-process)' in proc.stdout
    assert 'a population of 2 drivers, seed 1' in proc.stdout
    rows = (tmp_path / 'all_runs.csv').read_text().splitlines()
    assert rows[0].startswith('trace,predictor,trust_model,driver_model,alpha,driver,'
                              'weight_acceleration,')
    assert sorted({r.split(',')[5] for r in rows[1:]}) == ['1', '2']
    table = (tmp_path / 'table_IV_max_improvements.md').read_text()
    assert table.count(' ± ') == 3
    bad = subprocess.run([sys.executable, '-m', 'trust_av.cli', 'reproduce',
                          '--drivers', '-1', '--results-dir', str(tmp_path)],
                         capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2 and '--drivers must be >= 0, got -1' in bad.stderr


def test_the_population_draws_from_the_shipped_per_driver_fits(tmp_path: Path) -> None:
    """``--drivers K``: K drivers drawn from the per-driver fits of driver_fit_caution.yaml (the
    shipped driver's fit: d_s and a_extra per driver too); ``--profile human_cautious`` draws
    from driver_fit.yaml's per-pair weights and keeps the worst-case bound."""
    import yaml

    from human_driver_sim.population import (
        CAUTIOUS_FIT_FILE,
        DRIVER_FIT_FILE,
        sample_driver_params,
    )

    def runs(out: Path, *args: str) -> list[dict[str, str]]:
        proc = subprocess.run([sys.executable, '-m', 'trust_av.cli', 'reproduce',
                               *args, '--traces', 'nycc', '--predictors', 'ca', '--drivers', '2',
                               '--alphas', '0,1', '--max-steps', '15', '--results-dir', str(out),
                               '--no-progress', '--workers', '2'],
                              capture_output=True, text=True, timeout=300)
        assert proc.returncode == 0, proc.stderr[-3000:]
        rows = [r.split(',') for r in (out / 'all_runs.csv').read_text().splitlines()]
        return [dict(zip(rows[0], row, strict=True)) for row in rows[1:]]

    per_driver = list(yaml.safe_load(DRIVER_FIT_FILE.read_text())['per_driver'].values())
    drawn = sample_driver_params(per_driver, 2, seed=1)
    shipped = runs(tmp_path / 'shipped')
    assert len(shipped) == 4
    for row in shipped:
        driver = drawn[int(row['driver']) - 1]
        for name in ('desired_standstill_gap_m', 'av_extra_decel_mps2', 'time_headway_s'):
            assert float(row[name]) == pytest.approx(driver[name]), name
        assert row['cautious'] == 'False'
    cautious = runs(tmp_path / 'cautious', '--profile', 'human_cautious')
    pooled_tau = yaml.safe_load(CAUTIOUS_FIT_FILE.read_text())['pooled']['time_headway_s']
    for row in cautious:
        assert float(row['time_headway_s']) == pytest.approx(pooled_tau)
        assert row['cautious'] == 'True'


def reproduce(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, '-m', 'trust_av.cli', 'reproduce',
                           '--no-progress', *args], capture_output=True, text=True,
                          timeout=600, stdin=subprocess.DEVNULL)


def test_study_of_any_registered_parts(tmp_path: Path, short_trace: str) -> None:
    """A predictor the paper did not print (cv) on US06 and on a CSV, two followers, two
    alphas: every run is one row of the tidy table, the paper's tables hold only the paper's
    cases (no KeyError ('cv', 'us06')), and from Python the same table is a DataFrame."""
    import pandas as pd

    from trust_av.study.frame import study

    out = tmp_path / 'study'
    proc = reproduce('--traces', f'us06,{short_trace}', '--predictors', 'cv,ca',
                     '--alphas', '0,1', '--driver-models', 'mpc,idm', '--max-steps', '4',
                     '--results-dir', str(out), '--workers', '2')
    assert proc.returncode == 0, proc.stderr[-3000:]
    runs = pd.read_csv(out / 'all_runs.csv', keep_default_na=False)
    assert len(runs) == 16
    assert list(runs.columns[:6]) == ['trace', 'predictor', 'trust_model', 'driver_model',
                                      'alpha', 'driver']
    assert {'final_trust', 'mean_explicability', 'rmse_mps2', 'idm_time_headway_s',
            'runner', 'max_steps'} <= set(runs.columns)
    settings = set(zip(runs.predictor, runs.driver_model, runs.alpha, strict=True))
    assert settings == {(p, d, a) for p in ('ca', 'cv') for d in ('idm', 'mpc')
                        for a in (0.0, 1.0)}
    assert (runs[runs.driver_model == 'mpc'].idm_time_headway_s == '').all()
    table = (out / 'table_IV_max_improvements.csv').read_text().splitlines()
    cv_us06 = next(r for r in table if r.startswith('TAC-CV,us06,'))
    assert cv_us06.endswith('—,—,—,—')      # the paper printed no TAC-CV
    assert (out / 'table_III_tac_ca_us06.md').exists()
    assert not (out / 'table_II_tac_gru_us06.md').exists()
    inline = InlineExecutor()
    frame = study(['us06', short_trace], ['cv', 'ca'], [0.0, 1.0],
                  driver_models=['mpc', 'idm'], results_dir=out, executor=inline, max_steps=4)
    assert inline.ran == []                 # every case came from the cache
    # the same table: the CSV read back equals the DataFrame written and read back alike
    pd.testing.assert_frame_equal(pd.read_csv(out / 'all_runs.csv'),
                                  pd.read_csv(io.StringIO(frame.to_csv(index=False))))


def test_params_files_layer_in_reproduce(tmp_path: Path, short_trace: str) -> None:
    """``--params-file A --params-file B`` layers B over A over the shipped file, as in run
    and simulate (it used to read B alone)."""
    first, second = tmp_path / 'a.yaml', tmp_path / 'b.yaml'
    first.write_text('/**/planner:\n  ros__parameters:\n    explicability_scale: 0.02\n')
    second.write_text('/**:\n  ros__parameters:\n    epsilon_mps2: 3.0\n')
    proc = reproduce('--params-file', str(first), '--params-file', str(second), '--traces',
                     short_trace, '--predictors', 'ca', '--alphas', '0', '--max-steps', '3',
                     '--results-dir', str(tmp_path / 'out'), '--workers', '1')
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert ('epsilon_mps2 = 3, performance_threshold = 0.8, explicability_scale = 0.02'
            in proc.stdout)


def test_unregistered_names_are_refused_in_one_line(tmp_path: Path) -> None:
    for option, value, message in (('--predictors', 'ca,nope', 'unknown predictor(s) nope;'),
                                   ('--driver-models', 'nope', 'unknown driver model(s)'),
                                   ('--trust-models', 'nope', 'unknown trust model(s)'),
                                   ('--alphas', '0,2', 'alpha must be in [0, 1]')):
        proc = reproduce(option, value, '--results-dir', str(tmp_path))
        assert proc.returncode == 2, proc.stderr
        assert message in proc.stderr and 'Traceback' not in proc.stderr, proc.stderr
