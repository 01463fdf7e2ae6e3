"""Driver in the loop, pure parts: the follower's reaction to a lost participant, the
questionnaire's scoring, the ratings-vs-models comparison, counterbalancing, sessions
(resume, withdrawal), the settings file and the page protocol. No ROS, no browser."""

from __future__ import annotations

import dataclasses
import itertools
import json
import math
from pathlib import Path

import numpy as np
import pytest

from human_driver_sim.follower_plant import (
    BRAKE,
    COAST,
    HOLD,
    WAITING,
    FollowerConfig,
    applied_accel,
)
from trust_av.drive.server import parse_message
from trust_av.drive.sessions import (
    ABANDONED,
    DONE,
    PRACTICE,
    Condition,
    DriveRecord,
    SessionError,
    balanced_latin_square_row,
    drive_dir,
    enrol,
    load_session,
    save_session,
)
from trust_av.drive.study import (
    DriveConfig,
    load_drive_settings,
    summary_csv,
)
from trust_av.drive.trust_rating import (
    DriveSeries,
    RatingError,
    compare,
    questionnaire_score,
    registered_models,
)
from trust_av.drive.withdrawal import withdraw
from trust_av.system.config import DEFAULT_PARAMS_FILE
from trust_av_common.params import ParamsError
from trust_av_common.registry import names
from trust_monitor.model_interface import TRUST_MODELS, UnitTrust, unit_trust
from trust_monitor.paper_trust import TrustConfig, TrustEstimator

CONFIG = FollowerConfig(input_timeout_s=0.5, coast_s=1.0, fallback_brake_mps2=-2.0)
CONDITIONS = [Condition('a', 0.0, 'ca', 'us06'), Condition('b', 0.5, 'ca', 'us06'),
              Condition('c', 1.0, 'ca', 'us06'), Condition('d', 1.0, 'gru', 'us06')]


@pytest.mark.parametrize(('command', 'since', 'expected'), [
    (None, 0.0, (0.0, WAITING)),
    (1.0, 0.0, (1.0, HOLD)),
    (1.0, 0.5, (1.0, HOLD)),              # a late sample is jitter, not a lost participant
    (1.0, 0.51, (0.0, COAST)),
    (-3.0, 1.5, (0.0, COAST)),
    (1.0, 1.51, (-2.0, BRAKE)),
    (9.0, 0.1, (2.5, HOLD)),              # clipped to full gas
    (-9.0, 0.1, (-6.0, HOLD)),            # and to full brake
])
def test_follower_holds_then_coasts_then_brakes(command: float | None, since: float,
                                                expected: tuple[float, str]) -> None:
    assert applied_accel(CONFIG, command, since) == expected


def test_follower_settings_are_checked() -> None:
    with pytest.raises(ParamsError, match='fallback_brake_mps2'):
        FollowerConfig(fallback_brake_mps2=0.5)


def test_questionnaire_reverses_the_distrust_items() -> None:
    # full trust: distrust items 1-5 answered 1 (not at all), trust items 6-12 answered 7
    assert questionnaire_score([1] * 5 + [7] * 7) == 1.0
    assert questionnaire_score([7] * 5 + [1] * 7) == 0.0
    assert questionnaire_score([4] * 12) == 0.5
    # item 1 alone moves the score down when it rises (it is reversed)
    assert questionnaire_score([7] + [4] * 11) < questionnaire_score([4] * 12)
    assert questionnaire_score([4] * 11 + [7]) > questionnaire_score([4] * 12)


@pytest.mark.parametrize(('answers', 'message'), [
    ([4] * 11, '12 items'), ([4] * 11 + [8], 'jian_12'), ([0] + [4] * 11, 'jian_01'),
    ([4.5] + [4] * 11, 'jian_01'), ([True] + [4] * 11, 'jian_01')])
def test_questionnaire_refuses_bad_answers(answers: list[int], message: str) -> None:
    with pytest.raises(RatingError, match=message):
        questionnaire_score(answers)


def _series(times: np.ndarray) -> DriveSeries:
    return DriveSeries(times, [[0.0, 0.0]] * len(times), [[0.0, 0.0]] * len(times),
                       np.full(len(times), np.nan))


def test_comparison_finds_rmse_correlation_and_the_lag() -> None:
    times = np.arange(0.0, 60.0, 0.1)

    def wave(series: DriveSeries) -> list[UnitTrust]:
        return [UnitTrust(v) for v in 0.5 + 0.3 * np.sin(series.times_s / 5.0)]

    rating_times = np.arange(5.0, 60.0, 2.0)
    lagged = 0.5 + 0.3 * np.sin((rating_times - 3.0) / 5.0)   # the person answers 3 s late
    [same], = [compare(rating_times, 0.5 + 0.3 * np.sin(rating_times / 5.0), _series(times),
                       [('wave', wave)])]
    assert same.rmse < 0.01 and same.correlation > 0.99 and same.best_lag_s == 0.0
    [late] = compare(rating_times, lagged, _series(times), [('wave', wave)], max_lag_s=6.0)
    assert late.best_lag_s == pytest.approx(3.0) and late.rmse_at_best_lag < 0.01
    assert late.rmse > 0.1
    [flat] = compare([1.0, 2.0], [0.2, 0.4], _series(times), [('flat', lambda s: [
        UnitTrust(0.3)] * len(s.times_s))])
    assert flat.rmse == pytest.approx(0.1) and math.isnan(flat.correlation)


def test_comparison_refuses_no_ratings() -> None:
    with pytest.raises(RatingError, match='at least one rating'):
        compare([], [], _series(np.arange(3.0)), [])


def test_paper_model_is_the_trust_estimator_over_the_plans() -> None:
    config = TrustConfig(epsilon_mps2=6.0, trust_growth_rate=0.1, performance_threshold=0.8,
                         trust_initial=0.0)
    times = np.array([0.0, 0.1, 0.3])
    plans, expected = [[1.0, 0.0], [0.5, 0.5], [-1.0, 0.0]], [[1.0, 0.0], [0.0, 0.5],
                                                               [1.0, 2.0]]
    series = DriveSeries(times, plans, expected, np.full(3, np.nan))
    estimator = TrustEstimator(config)
    by_hand = [unit_trust(estimator.model, estimator.step(p, e, dt).trust)
               for p, e, dt in zip(plans, expected, [0.1, 0.2, 0.0], strict=True)]
    # every registered trust model is compared; 'paper' gives the monitor's own trust, on
    # the common scale (its raw units beside ratings on [0, 1] gave RMSE 7.01)
    models = dict(registered_models(config))
    assert set(models) == set(names(TRUST_MODELS)) >= {'paper', 'asymmetric', 'optimo'}
    np.testing.assert_allclose(models['paper'](series), by_hand)


@pytest.mark.parametrize('n', [1, 2, 3, 4, 5, 6])
def test_latin_square_is_balanced(n: int) -> None:
    rows = [balanced_latin_square_row(n, r) for r in range(n if n % 2 == 0 else 2 * n)]
    for row in rows:
        assert sorted(row) == list(range(n))
    for position in range(n):               # every condition in every position equally often
        counts = np.bincount([row[position] for row in rows], minlength=n)
        assert len(set(counts)) == 1
    pairs = [(row[i], row[i + 1]) for row in rows for i in range(n - 1)]
    for pair in itertools.permutations(range(n), 2):   # each ordered neighbour pair equally
        assert pairs.count(pair) == pairs.count((0, 1)) if n > 1 else True


def test_sessions_are_counterbalanced_resumed_and_withdrawn(tmp_path: Path) -> None:
    first = enrol(tmp_path, 'P01', CONDITIONS)
    second = enrol(tmp_path, 'P02', CONDITIONS)
    assert (first.row, second.row) == (0, 1)
    assert first.order != second.order and sorted(first.order) == ['a', 'b', 'c', 'd']
    assert first.next_condition() == PRACTICE
    first.drives.append(DriveRecord(1, PRACTICE, 'x', DONE, 1))
    first.practice_done = True
    first.drives.append(DriveRecord(2, first.order[0], 'y', ABANDONED, 2))
    save_session(tmp_path, first)
    resumed = enrol(tmp_path, 'P01', CONDITIONS)     # after a crash: the same session
    assert resumed.row == 0 and resumed.next_condition() == first.order[0]
    assert load_session(tmp_path, 'P01') == resumed
    bag = drive_dir(tmp_path, 'P01', 2, 'a')
    bag.mkdir(parents=True)
    again = drive_dir(tmp_path, 'P01', 2, 'a')       # an earlier attempt is kept aside
    assert again == bag and not again.exists() and bag.with_name(bag.name + '.attempt1').is_dir()
    assert withdraw(tmp_path, 'P01') and not (tmp_path / 'P01').exists()
    assert not withdraw(tmp_path, 'P01')
    assert enrol(tmp_path, 'P03', CONDITIONS).row == 2   # the counter holds no ids
    counter = json.loads((tmp_path / 'study.json').read_text())
    assert counter['enrolled'] == 3 and sorted(counter) == ['enrolled', 'study']
    assert 'P01' not in (tmp_path / 'study.json').read_text()


def test_participants_who_enrol_at_once_get_a_row_each(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Eight participants enrol at the same instant (threads; each waits 20 ms between
    reading the counter and writing it back, where two lab machines on one shared study folder
    would interleave): eight rows, and the counter at eight."""
    import threading
    import time

    from trust_av.drive import sessions
    real = sessions._study_record

    def slow_record(study: Path) -> tuple[int, str]:
        record = real(study)
        time.sleep(0.02)
        return record
    monkeypatch.setattr(sessions, '_study_record', slow_record)
    enrol(tmp_path, 'P00', CONDITIONS)       # the study's id is written once, before the race
    start = threading.Barrier(8)
    rows: dict[str, int] = {}

    def one(participant: str) -> None:
        start.wait()
        rows[participant] = enrol(tmp_path, participant, CONDITIONS).row
    threads = [threading.Thread(target=one, args=(f'P{k:02d}',)) for k in range(1, 9)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert sorted(rows.values()) == list(range(1, 9)), rows
    assert json.loads((tmp_path / 'study.json').read_text())['enrolled'] == 9


@pytest.mark.parametrize('bad', ['', 'Jane Doe', '../x', 'a' * 33, '-x'])
def test_participant_ids_are_pseudonyms(tmp_path: Path, bad: str) -> None:
    with pytest.raises(SessionError, match='participant id'):
        enrol(tmp_path, bad, CONDITIONS)


def test_changed_conditions_refuse_to_resume(tmp_path: Path) -> None:
    enrol(tmp_path, 'P01', CONDITIONS)
    with pytest.raises(SessionError, match='their session has conditions'):
        enrol(tmp_path, 'P01', CONDITIONS[:2])


def test_shipped_drive_settings_load() -> None:
    drive, follower, conditions = load_drive_settings(DEFAULT_PARAMS_FILE.with_name(
        'drive.yaml'))
    assert drive == DriveConfig(drive_duration_s=120.0, rating_mode='continuous',
                                rating_period_s=2.5)
    assert follower == FollowerConfig()
    assert [c.name for c in conditions] == ['low_alpha_1', 'high_alpha_1', 'low_alpha_2',
                                            'high_alpha_2']
    assert {c.perturbation for c in conditions} == {'rough_random'}


@pytest.mark.parametrize(('text', 'message'), [
    ('rating_period_s: 0.5', 'rating_period_s must be in \\[1, 3600\\]'),
    ('rating_mode: slider', "rating_mode must be one of \\['prompt', 'continuous'\\], got 'sl"),
    ('colour: red', 'unknown parameter'),
    ('condition_alphas: [0.0]', 'arrays of one length'),
    ('condition_alphas: [0.0, 2.0, 0.0, 1.0]', 'alpha must be in'),
    # a condition name is part of its drives' folder names: never a path, never empty
    ("condition_names: ['../../outside', b, c, d]", "condition name '../../outside'"),
    ("condition_names: ['', b, c, d]", "condition name ''"),
    ('condition_names: [low_alpha, low_alpha, c, d]', "'low_alpha' is listed twice"),
    ('condition_names: [practice, b, c, d]', "condition name 'practice'"),
    ('condition_names: [1, 2, 3, 4]', 'condition name 1'),
    ('condition_traces: [7, 8, 9, 10]', 'condition_traces holds 7'),
])
def test_bad_drive_settings_are_named(tmp_path: Path, text: str, message: str) -> None:
    lines = DEFAULT_PARAMS_FILE.with_name('drive.yaml').read_text().splitlines()
    key = text.split(':')[0]
    kept = [line for line in lines if not line.strip().startswith(key + ':')]
    path = tmp_path / 'drive.yaml'
    path.write_text('\n'.join([*kept, f'    {text}']) + '\n')
    with pytest.raises(ParamsError, match=message):
        load_drive_settings(path)


def test_every_seed_the_settings_accept_gives_every_drive_a_valid_seed(tmp_path: Path) -> None:
    """Drive k's seed is the study's + k modulo 2**32 (the perturbation seed's range): the
    largest seed the settings accept once failed at drive 1, after enrolment, using up
    the participant's counterbalancing row at every retry."""
    import dataclasses

    from trust_av.drive.study import next_drive
    from trust_av.system.config import load_run_config

    session = enrol(tmp_path, 'P01', CONDITIONS, practice=False)
    top = DriveConfig(seed=2**32 - 1).seed
    seed = next_drive(tmp_path, session, {c.name: c for c in CONDITIONS}, top)[4]
    planner = load_run_config(()).planner        # as the session loop sets it per drive
    assert seed == 0 and dataclasses.replace(planner, perturbation_seed=seed)
    assert next_drive(tmp_path, session, {}, 41)[4] == 42
    with pytest.raises(ParamsError, match='seed must be in'):
        DriveConfig(seed=2**32)


def test_one_live_session_per_participant(tmp_path: Path,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    """A second `trust-av drive` (or a withdrawal) for a participant whose session is live
    is refused in one line naming the first's pid, before anything is served or written."""
    import os

    from trust_av.cli.main import main
    from trust_av.drive.sessions import participant_lock

    enrol(tmp_path, 'P01', CONDITIONS)
    before = sorted(p.name for p in tmp_path.rglob('*'))
    with participant_lock(tmp_path, 'P01'):           # the first session
        for extra in ([], ['--withdraw', '--yes']):
            assert main(['drive', '--study', str(tmp_path), '--participant', 'P01',
                         '--port', '0', *extra]) == 2
            err = capsys.readouterr().err
            assert err.count('\n') == 1 and 'participant P01 already has a live session' in err
            assert f'pid {os.getpid()}' in err and str(tmp_path / 'P01.lock') in err
    assert sorted(p.name for p in tmp_path.rglob('*')) == before


def test_summary_table_has_one_row_per_drive(tmp_path: Path) -> None:
    session = enrol(tmp_path, 'P01', CONDITIONS, practice=False)
    session.drives.append(DriveRecord(1, 'a', 'P01/drive_01_a', DONE, 1,
                                      {'alpha': 0.0, 'ratings': 4, 'latency_p99_ms': 21.5}))
    lines = summary_csv(session).splitlines()
    assert lines[0].startswith('drive,condition,alpha') and len(lines) == 2
    assert lines[1].startswith('1,a,0.0,') and ',21.5,' in lines[1]


def test_page_messages_are_checked() -> None:
    assert parse_message('{"type": "input", "seq": 1}')['seq'] == 1
    for bad in ('[1]', '{"type": "shutdown"}', '{}'):
        with pytest.raises(ValueError, match='not a page message'):
            parse_message(bad)


def test_drive_demonstrations_hold_out_whole_participants() -> None:
    from human_driver_sim.car_following import FollowingPair
    from trust_av.drive.bag_data import DriveBagError, split_by_participant

    def pair(person: str, k: int) -> FollowingPair:
        one = np.ones(3)
        return FollowingPair(f'd{k}:{person}', 1.0, one, one, one, 'drive', f'd{k}{person}',
                             f'drive:{person}')
    pairs = [pair(p, k) for p in ('P1', 'P2', 'P3', 'P4') for k in range(2)]
    split = split_by_participant(pairs)
    assert {p.driver for p in split.train} == {'drive:P1', 'drive:P4'}
    assert {p.driver for p in split.validation} == {'drive:P2'}
    assert {p.driver for p in split.test} == {'drive:P3'}
    split = split_by_participant([pair('P1', k) for k in range(4)])
    assert [len(part) for part in split] == [2, 1, 1]
    names = [{p.name for p in part} for part in split]
    assert not (names[0] & names[1] or names[0] & names[2] or names[1] & names[2])
    with pytest.raises(DriveBagError, match='at least three drives'):
        split_by_participant([pair('P1', 0), pair('P1', 1)])


def test_fit_driver_refuses_a_study_without_complete_drives(tmp_path: Path) -> None:
    from trust_av.drive.bag_data import DriveBagError, drive_bag_pairs
    with pytest.raises(DriveBagError, match='no complete drive'):
        drive_bag_pairs(tmp_path, 1.0, 4.5)


@pytest.mark.parametrize(('args', 'message'), [
    (['--participant', 'Jane Doe'], 'participant id'),
    (['--participant', 'P01', '--drive-file', 'missing.yaml'], 'missing.yaml'),
    (['--participant', 'P01', '--port', '70000'], '--port must be in'),
])
def test_bad_drive_input_is_one_line_and_writes_nothing(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], args: list[str],
        message: str) -> None:
    from trust_av.cli.main import main
    study = tmp_path / 'study'
    args = [a if a != 'missing.yaml' else str(tmp_path / a) for a in args]
    assert main(['drive', '--study', str(study), *args]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith('trust-av drive: error:') and message in err and '\n' not in err
    assert not study.exists()


def test_a_taken_port_is_one_line_and_enrols_nobody(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    import socket

    from trust_av.cli.main import main
    with socket.socket() as taken:
        taken.bind(('127.0.0.1', 0))
        taken.listen()
        port = taken.getsockname()[1]
        study = tmp_path / 'study'
        assert main(['drive', '--study', str(study), '--participant', 'P01', '--port',
                     str(port)]) == 2
    err = capsys.readouterr().err
    assert 'cannot serve on 127.0.0.1' in err and not study.exists()


def test_withdrawal_from_the_command_line(tmp_path: Path,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    from trust_av.cli.main import main
    enrol(tmp_path, 'P07', CONDITIONS)
    assert main(['drive', '--study', str(tmp_path), '--participant', 'P07', '--withdraw',
                 '--yes']) == 0
    assert not (tmp_path / 'P07').exists()
    assert 'every file trust-av wrote deleted' in capsys.readouterr().out


def test_every_model_s_live_trust_is_on_the_common_scale() -> None:
    """What a drive records on /driver/model_trust: each registered model's trust after
    each plan pair, mapped to [0, 1] by the model's declared ``trust_range`` (the paper's
    model: T(0) +- delta * 600 s), not in the model's own units."""
    from trust_av.drive.link import ModelTrust
    from trust_av.system.config import load_run_config
    from trust_monitor.model_interface import make_trust_model

    config = load_run_config()
    live = ModelTrust(config.trust, dict(config.trust_model_params))
    paper = TrustEstimator(config.trust, make_trust_model(config.trust,
                                                          dict(config.trust_model_params)))
    plan, expected = [0.5, 0.0, -0.5], [0.4, 0.0, -0.4]
    for k in range(5):
        assert live.add('plan', k * 10**9, plan) is None        # waits for its pair
        trust = live.add('expected', k * 10**9, expected)
        assert trust is not None and len(trust) == len(names(TRUST_MODELS))
        assert all(0.0 <= value <= 1.0 for value in trust), trust
        paper.step(plan, expected, 0.1 if k == 0 else 1.0)   # its first pair: the 10 Hz period
    low, high = paper.model.trust_range
    assert trust[live.names.index('paper')] == pytest.approx(
        (paper.trust - low) / (high - low), abs=1e-12)
    assert paper.trust > 0.3      # five steps of growth: the own scale is not the common one


def test_a_session_tells_its_page_and_gate_how_the_study_rates() -> None:
    """The shipped study rates continuously: its gate takes the scale's moves and the page is
    told so (with the kept position, for a reopened tab); a prompted study's gate refuses
    them."""
    from trust_av.drive.gate import DRIVING, READY
    from trust_av.drive.run_session import page_hello, page_link

    drive, follower, _ = load_drive_settings(DEFAULT_PARAMS_FILE.with_name('drive.yaml'))
    link = page_link(drive, follower, 10.0)
    assert page_hello(link, drive, follower, 10.0, 'P01')['rating_mode'] == 'continuous'
    link.gate.set_phase(READY)
    assert link.gate.trust({'value': 64}, 0) == 64.0
    link.gate.set_phase(DRIVING)
    hello = page_hello(link, drive, follower, 10.0, 'P01')
    assert hello['scale'] == 64.0 and hello['accel_min_mps2'] == follower.accel_min_mps2
    prompted = dataclasses.replace(drive, rating_mode='prompt')
    link = page_link(prompted, follower, 10.0)
    assert page_hello(link, prompted, follower, 10.0, 'P01')['rating_mode'] == 'prompt'
    assert link.gate.trust({'value': 64}, 0) is None
