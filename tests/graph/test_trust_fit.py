"""Drives in which trust moves, the trust-model fit and its recovery of known participants."""

from __future__ import annotations

import csv
import dataclasses
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from support.contract import GRAPH_STEPS, cli, trace_csv
from support.graph import assert_records_equal  # the graph == in-process comparison

from preceding_traffic.sources import load_trace
from preceding_traffic.traces import truncate
from trust_av.drive.study import conditions_from
from trust_av.drive.trust_fit_data import read_ratings_table
from trust_av.study.trust_design import Design, recover
from trust_av.study.trust_recovery import drive_scores, make_participant
from trust_av.system.closed_loop import simulate
from trust_av.system.config import load_run_config
from trust_av.system.outputs import MARKER, marked_outputs
from trust_av_common.params import ParamsError
from trust_av_planner.perturbations import LIBRARY, Perturbation, schedule
from trust_monitor.model_interface import fit_parameters
from trust_monitor.paper_trust import performance
from trust_monitor.trust_fit import (
    RatedDrive,
    fit,
    held_out,
    model_spec,
    model_trust,
)

__all__ = ['trace_csv']


CONFIG = load_run_config()


@pytest.fixture(scope='module')
def scores() -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """(times, E) of 120 s in-process drives under three conditions."""
    return {c: drive_scores(CONFIG, c, 3) for c in ('none', 'late_brake', 'mixed_random')}


def test_random_conditions_are_seeded_and_spaced() -> None:
    one, again, other = (schedule('mixed_random', s) for s in (1, 1, 2))
    assert one == again and one != other
    starts = [e.start_s for e in one]
    assert np.all(np.diff(starts) >= 15.0) and starts[0] >= 10.0 and starts[-1] <= 110.0
    with pytest.raises(ValueError, match='perturbation must be one of'):
        schedule('sudden_stop')


def test_a_cap_applies_inside_its_window_only() -> None:
    brake = Perturbation('late_brake', 0, accel_min_mps2=-2.0)   # -3 clipped to the bound
    plan = np.array([0.5, 0.5, 0.5])
    assert np.array_equal(brake.apply(plan, 19.0, 1.0), plan)
    assert np.array_equal(brake.apply(plan, 20.0, 1.0), [-2.0, 0.5, 0.5])
    assert np.array_equal(brake.apply(plan, 20.0, 0.5), [-2.0, -2.0, 0.5])
    assert Perturbation('headway_change', 0, -3.0).headway_s(39.0) == 0.0
    assert Perturbation('headway_change', 0, -3.0).headway_s(40.0) == 1.0


def test_the_planner_parameter_and_the_study_conditions_are_checked() -> None:
    with pytest.raises(ParamsError, match='perturbation'):
        load_run_config([], {'planner': {'perturbation': 'sudden_stop'}})
    base = {'condition_names': ['a', 'b'], 'condition_alphas': [0.0, 1.0],
            'condition_predictors': ['ca', 'ca'], 'condition_traces': ['us06', 'us06']}
    assert [c.perturbation for c in conditions_from(base, 'f')] == ['none', 'none']
    chosen = conditions_from({**base, 'condition_perturbations': ['late_brake', 'none']}, 'f')
    assert [c.perturbation for c in chosen] == ['late_brake', 'none']
    with pytest.raises(ParamsError, match="condition 'a': perturbation must be one of"):
        conditions_from({**base, 'condition_perturbations': ['x', 'none']}, 'f')
    with pytest.raises(ParamsError, match='condition_perturbations must be an array'):
        conditions_from({**base, 'condition_perturbations': ['none']}, 'f')


def test_trust_moves_only_in_a_perturbed_drive(
        scores: dict[str, tuple[np.ndarray, np.ndarray]]) -> None:
    """Without a perturbation no plan falls below P_thre; with one some do, and the AV
    keeps its gap (the events are short enough to recover from)."""
    low = {c: int(sum(performance(e) < 0.8 for e in s[1])) for c, s in scores.items()}
    assert low['none'] == 0 and low['late_brake'] >= 3 and low['mixed_random'] >= 3
    for condition in LIBRARY:
        cfg = dataclasses.replace(CONFIG, planner=dataclasses.replace(
            CONFIG.planner, perturbation=condition, perturbation_seed=7))
        run = simulate(cfg, dataclasses.replace(load_trace('us06', 1.0, cfg.trace),
                                                step_limit=120))
        assert min(r.av_gap_m for r in run.records) >= CONFIG.min_safe_gap_m, condition


def test_graph_applies_the_perturbation_as_in_process(tmp_path: Path, trace_csv: Path) -> None:
    """The perturbation is in the planner core: ``trust-av run`` (the node graph) equals the
    in-process loop through a late brake at 20 s."""
    from trust_av.graph.bag_records import records_from_bag

    params = tmp_path / 'late.yaml'
    params.write_text('/**/planner:\n  ros__parameters:\n    perturbation: late_brake\n')
    config = load_run_config([params])
    trace = truncate(load_trace(str(trace_csv), config.planner.dt_s, config.trace),
                     GRAPH_STEPS)
    reference = simulate(config, trace).records
    assert reference[20].av_accel_mps2 == -3.0 and reference[19].av_accel_mps2 != -3.0
    bag = tmp_path / 'run'
    proc = cli('run', '--trace', str(trace_csv), '--params-file', str(params),
               '--max-steps', str(GRAPH_STEPS), '--bag', str(bag), '--no-plot',
               '--no-progress', cwd=tmp_path)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert len(reference) == GRAPH_STEPS
    assert_records_equal(records_from_bag(bag), reference)


def test_a_model_without_a_declaration_takes_part() -> None:
    class Plain:
        name = 'plain'

    assert fit_parameters(Plain()) == ()          # type: ignore[arg-type]
    assert all(p.prior_std > 0 for name in ('paper', 'asymmetric', 'beta_bernoulli', 'optimo')
               for p in model_spec(CONFIG.trust, name).parameters)


def test_rating_at_a_time_reads_the_steps_completed_by_then() -> None:
    drive = RatedDrive('p', 'd', np.array([0.0, 1.0, 2.0]), np.array([0.0, 0.0, 0.0]),
                       np.array([0.5, 1.0, 3.0]), np.array([50.0, 50.0, 50.0]))
    model = model_spec(CONFIG.trust, 'optimo').build({})
    every, at = model_trust(model, drive, every_step=True)
    assert at[0] == 0.5 and at[1] == every[0] and at[2] == every[2] == pytest.approx(0.53)


def test_fit_recovers_a_known_participant(
        scores: dict[str, tuple[np.ndarray, np.ndarray]]) -> None:
    """Ratings from OPTIMo (2 points of noise): the fit finds its initial trust and its
    drift in good stretches, w_p (w_b is declared not identifiable and held at 0:
    docs/tutorials/fit-trust-models.md), and held out it beats the paper's model."""
    spec = model_spec(CONFIG.trust, 'optimo')
    rng = np.random.Generator(np.random.PCG64(1))
    data = [(c, *scores[c]) for c in ('late_brake', 'mixed_random')]
    who = make_participant(spec, 'p', data, rng, noise=2.0)
    fitted = fit(spec, who.drives)
    true, got = who.theta, fitted.theta
    assert got['optimo_initial_trust'] == pytest.approx(true['optimo_initial_trust'], abs=0.03)
    assert 'optimo_bias_rate_per_s' not in got and fitted.fixed['optimo_bias_rate_per_s'] == 0.0
    rate = 'optimo_performance_rate_per_s'
    assert got[rate] == pytest.approx(true[rate], rel=0.1)
    assert fitted.observation.s == pytest.approx(0.02, rel=0.5)
    paper = model_spec(CONFIG.trust, 'paper')
    own = held_out(spec, [[d] for d in who.drives], 'lodo')
    other = held_out(paper, [[d] for d in who.drives], 'lodo')
    assert own.elpd > other.elpd


def test_small_recovery() -> None:
    """The suite's version of benchmarks/bench_trust_recovery.py: 3 participants x 2
    drives of 60 s of two models; each model's participants are best fitted by their own
    model."""
    result = recover(CONFIG, ['beta_bernoulli', 'optimo'],
                     Design(drives=2, drive_s=60, participants=3), seed=2)
    assert {t: sum(row.values()) for t, row in result.confusion.items()} == \
        {'beta_bernoulli': 3, 'optimo': 3}
    assert result.confusion['beta_bernoulli']['beta_bernoulli'] >= 2
    assert result.confusion['optimo']['optimo'] >= 2
    r = result.parameter_r({m: model_spec(CONFIG.trust, m) for m in result.elpd})
    assert r['beta_bernoulli']['beta_bernoulli_beta0'] is None   # declared unidentifiable


def test_a_design_evaluated_on_workers_equals_one_process(tmp_path: Path) -> None:
    """`design-evaluate --workers 2` runs its drives and fits on the study's worker pool
    (study/workers.py) and prints what one process prints, with no worker's traceback
    (a fork pool's workers, ended at its close, raised the command's own stop signal)."""
    argv = ('design-evaluate', '--conditions', 'rough_random', '--drives', '2',
            '--drive-s', '20', '--participants', '3', '--models', 'paper,optimo')
    runs = [cli(*argv, '--workers', n, cwd=tmp_path) for n in ('1', '2')]
    for run in runs:
        assert run.returncode == 0, run.stderr
        assert 'Traceback' not in run.stdout + run.stderr
        assert '6/6 participants fitted' in run.stdout

    def result(text: str) -> str:
        return text[text.index('confusion'):text.rindex('wall')]
    assert result(runs[0].stdout) == result(runs[1].stdout)


def write_table(path: Path, rows: list[dict[str, object]]) -> Path:
    with path.open('w', newline='') as handle:
        writer = csv.DictWriter(handle, ['participant', 'drive', 't_s', 'explicability',
                                         'rating'])
        writer.writeheader()
        writer.writerows(rows)
    return path


def table_rows(scores: dict[str, tuple[np.ndarray, np.ndarray]]) -> list[dict[str, object]]:
    spec = model_spec(CONFIG.trust, 'beta_bernoulli')
    rng = np.random.Generator(np.random.PCG64(4))
    rows: list[dict[str, object]] = []
    for who in ('a', 'b'):
        p = make_participant(spec, who, [(c, *scores[c]) for c in ('late_brake',
                                                                   'mixed_random')], rng)
        for d in p.drives:
            rows += [{'participant': who, 'drive': d.drive, 't_s': t, 'explicability': e,
                      'rating': ''} for t, e in zip(d.times_s, d.scores, strict=True)]
            rows += [{'participant': who, 'drive': d.drive, 't_s': t, 'explicability': '',
                      'rating': r} for t, r in zip(d.rating_times_s, d.ratings, strict=True)]
    return rows


def test_fit_trust_from_a_ratings_table(tmp_path: Path,
                                        scores: dict[str, tuple[np.ndarray, np.ndarray]]
                                        ) -> None:
    table = write_table(tmp_path / 'ratings.csv', table_rows(scores))
    assert [d.drive for d in read_ratings_table(table)] == ['late_brake', 'mixed_random'] * 2
    out = tmp_path / 'fit'
    proc = subprocess.run([sys.executable, '-m', 'trust_av.cli', 'fit-trust',
                           '--ratings', str(table), '--out', str(out),
                           '--models', 'paper,beta_bernoulli'],
                          capture_output=True, text=True, timeout=600, check=False)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    with (out / 'comparison.csv').open() as handle:
        rows = list(csv.DictReader(handle))
    assert {(r['scope'], r['scheme']) for r in rows} == {
        ('a', 'leave_one_drive_out'), ('b', 'leave_one_drive_out'),
        ('pooled', 'leave_one_participant_out')}
    pooled = [r for r in rows if r['scope'] == 'pooled']
    assert {r['model'] for r in pooled} == {'paper', 'beta_bernoulli'}  # best first:
    assert float(pooled[0]['elpd_diff']) == 0.0 and float(pooled[0]['elpd_diff_se']) == 0.0
    assert float(pooled[1]['elpd_diff']) < 0.0 and float(pooled[1]['elpd_diff_se']) > 0.0
    assert float(pooled[1]['elpd']) < float(pooled[0]['elpd'])
    for scope in ('a', 'b', 'pooled'):     # one preferred model per scope, by the named rule
        marked = [r for r in rows if r['scope'] == scope]
        assert sorted(r['preferred'] for r in marked) == ['0', '1']
        assert {r['rule'] for r in marked} == {'parsimony_1se'}
    chosen = next(r['model'] for r in pooled if r['preferred'] == '1')
    assert f'preferred leave_one_participant_out: {chosen}' in proc.stdout
    assert 'preferred leave_one_drive_out: ' in proc.stdout and 'parsimony rule' in proc.stdout
    assert {r['parameters'] for r in pooled} == {'4', '5'}   # a, b, s counted for paper
    assert 'parameters counted: beta_bernoulli 5, paper 4' in proc.stdout
    with (out / 'adequacy.csv').open() as handle:
        checks = list(csv.DictReader(handle))
    assert {(r['participant'], r['model'], r['statistic']) for r in checks} == {
        (p, m, s) for p in 'ab' for m in ('paper', 'beta_bernoulli')
        for s in ('residual_lag1', 'interval_90')}
    assert {r['adequate'] for r in checks} <= {'true', 'false'}
    for p in 'ab':              # the summary says what adequacy.csv says, per participant
        fits = any(all(r['adequate'] == 'true' for r in checks
                       if r['participant'] == p and r['model'] == m)
                   for m in ('paper', 'beta_bernoulli'))
        assert (f'\n{p}: fitted adequately by' in proc.stdout) is fits
        assert (f'none of the registered models fits {p}: ' in proc.stdout) is not fits
    assert 'fit-trust: fits: 14/14 in ' in proc.stderr   # the progress, counted in fits
    fits = (out / 'fits.csv').read_text()
    assert 'pooled,beta_bernoulli,beta_bernoulli_failure_weight' in fits
    assert 'beta_bernoulli_beta0' in fits and ',fixed' in fits
    assert (out / 'participant_a.png').stat().st_size > 10_000
    # one set: every file named in the command's marker, nothing left beside it
    names = {p.name for p in out.iterdir()} - {MARKER}
    assert set(marked_outputs(out) or []) == names >= {'fits.csv', 'comparison.csv'}
    assert 'trust-av fit-trust --ratings' in (out / MARKER).read_text()
    assert sorted(p.name for p in tmp_path.iterdir()) == ['fit', 'ratings.csv']


@pytest.mark.parametrize(('content', 'message'), [
    ('participant,drive,t_s\na,d,0\n', 'missing column(s) explicability, rating'),
    ('participant,drive,t_s,explicability,rating\na,d,x,0.1,\n', 't_s: not a number'),
    ('participant,drive,t_s,explicability,rating\na,d,0,1.5,\na,d,1,0.1,50\n',
     ':2: column explicability: 1.5 is outside [0, 1]'),
    ('participant,drive,t_s,explicability,rating\na,d,0,0.1,\na,d,1,0.1,\n',
     'no drive has a rating'),
])
def test_bad_ratings_table_one_line_exit_2(tmp_path: Path, content: str, message: str) -> None:
    table = tmp_path / 'bad.csv'
    table.write_text(content)
    proc = subprocess.run([sys.executable, '-m', 'trust_av.cli', 'fit-trust',
                           '--ratings', str(table), '--out', str(tmp_path / 'o')],
                          capture_output=True, text=True, timeout=120, check=False)
    assert proc.returncode == 2 and proc.stderr.count('\n') == 1, proc.stderr
    assert message in proc.stderr


def test_unknown_model_one_line_exit_2(tmp_path: Path) -> None:
    proc = subprocess.run([sys.executable, '-m', 'trust_av.cli', 'fit-trust',
                           '--ratings', str(tmp_path / 'none.csv'), '--out', str(tmp_path),
                           '--models', 'paper,nope'],
                          capture_output=True, text=True, timeout=120, check=False)
    assert proc.returncode == 2 and 'not registered: nope' in proc.stderr


def test_a_study_is_read_from_its_drive_bags(tmp_path: Path,
                                             monkeypatch: pytest.MonkeyPatch) -> None:
    """Practice drives and earlier attempts are left out; E is recomputed from the recorded
    plans with the run's eps; ratings (x in [0, 1] on driver/rating) come back as 0-100."""
    from trust_av.drive import bag_data
    from trust_av.drive.trust_fit_data import read_study
    from trust_av.drive.trust_rating import DriveSeries
    from trust_monitor.paper_trust import explicability

    for name in ('drive_01_practice', 'drive_02_calm', 'drive_02_calm.attempt1',
                 'drive_03_brake'):
        (tmp_path / 'p7' / name).mkdir(parents=True)
        (tmp_path / 'p7' / name / 'metadata.yaml').write_text('x: 1\n')
    plans = [[0.0, 0.0, 0.0], [-3.0, 0.0, 0.0], [0.5, 0.5, 0.5]]
    expected = [[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.5, 0.5, 0.5]]

    def fake(bag: Path) -> bag_data.DriveBag:
        series = DriveSeries(np.array([0.0, 1.0, 2.0]), plans, expected, np.zeros(3))
        return bag_data.DriveBag(Path(bag), {'trust_av.participant': 'p7'}, series,
                                 np.array([1.5]), np.array([0.42]), [], {})

    monkeypatch.setattr(bag_data, 'read_drive', fake)
    drives = read_study(tmp_path, 6.0)
    assert [(d.participant, d.drive) for d in drives] == [('p7', 'drive_02_calm'),
                                                        ('p7', 'drive_03_brake')]
    assert drives[0].scores[1] == explicability(plans[1], expected[1], 6.0) > 0.05
    assert drives[0].scores[0] == drives[0].scores[2] == 0.0
    assert drives[0].ratings.tolist() == [42.0]
