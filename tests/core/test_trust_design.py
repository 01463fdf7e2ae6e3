"""Study designs (trust_av.study.trust_design, trust-av design-*): a design read from a drive
file, bad options refused in one line, the power analysis and the proposal's criterion on
hand-made held-out elpds (no fits run here: tests/graph/test_trust_fit.py runs a small
recovery)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from support.paths import REPO

from trust_av.cli import design
from trust_av.cli.main import build_parser
from trust_av.cli.typed_options import options_from
from trust_av.errors import TrustAvAppError
from trust_av.study.trust_design import Recovery


def options(*argv: str) -> design.DesignOptions:
    return options_from(design.DesignOptions,
                        build_parser().parse_args(['design-evaluate', *argv]))


def test_a_design_from_the_shipped_drive_file() -> None:
    shipped = design.design_of(options('--drive-file', str(REPO / 'config' / 'drive.yaml')))
    assert shipped.conditions == ('low_alpha_1', 'high_alpha_1', 'low_alpha_2',
                                  'high_alpha_2') and shipped.drives == 4
    assert shipped.rating_period_s == 2.5 and shipped.drive_s == 120
    assert shipped.planner['high_alpha_2'] == {'alpha': 1.0, 'predictor': 'ca',
                                               'perturbation': 'rough_random', 'trace': 'us06'}
    assert shipped.randomised('low_alpha_1')
    chosen = design.design_of(options('--conditions', 'rough_random,mixed_random',
                                      '--rating-period-s', '5', '--rating-span', '20,40',
                                      '--ranges', 'wide'))
    assert chosen.drive_conditions() == ['rough_random', 'mixed_random'] * 2
    assert chosen.rating_span == (20.0, 40.0) and chosen.randomised('mixed_random')
    assert chosen.true_ranges['asymmetric']['asymmetric_loss_ratio'] == (1.0, 10.0)


@pytest.mark.parametrize(('argv', 'message'), [
    (['--conditions', 'rough_randm'], 'not perturbations: rough_randm'),
    (['--rating-span', '60,20'], '--rating-span: need low,high'),
    (['--ranges', 'nowhere.json'], '--ranges nowhere.json: not benchmark, wide'),
])
def test_bad_design_options_one_line(argv: list[str], message: str) -> None:
    with pytest.raises(TrustAvAppError, match=message):
        design.design_of(options(*argv))


@pytest.mark.parametrize(('text', 'message'), [
    ('{"papr": {}}', "not registered trust models: papr (did you mean 'paper'?)"),
    ('{"paper": {"performance_treshold": [0.7, 0.9]}}',
     "paper: not a parameter paper fits: performance_treshold (did you mean "
     "'performance_threshold'?)"),
    ('{"paper": {"performance_threshold": [0.9, 0.7]}}',
     'paper.performance_threshold: [0.9, 0.7]: low must be below high'),
    ('{"paper": {"performance_threshold": [0.7, NaN]}}', 'not JSON (NaN is not a number'),
    ('{"paper": {"performance_threshold": [0.7, 5]}}',
     "paper.performance_threshold: [0.7, 5] reaches past the parameter's bounds"),
    ('{"paper": {"performance_threshold": [0.7, true]}}',
     'paper.performance_threshold: expected [low, high], two numbers, got [0.7, true]'),
    ('{"paper": [0.7, 0.9]}', 'paper: expected {parameter: [low, high]}, got list'),
    ('[]', 'expected {model: {parameter: [low, high]}}, got nothing'),
    ('{"paper": {', 'not JSON'),
])
def test_a_ranges_file_is_checked_like_every_input(tmp_path: Path, text: str,
                                                   message: str) -> None:
    """--ranges FILE: every model registered, every parameter one it fits, every range two
    finite numbers low < high inside the parameter's bounds; one line naming the file and
    the entry. A spreadsheet editor's byte-order mark is read."""
    ranges = tmp_path / 'ranges.json'
    ranges.write_text(text)
    with pytest.raises(TrustAvAppError) as raised:
        design.design_of(options('--ranges', str(ranges)))
    assert str(raised.value).startswith(f'{ranges}: ') and message in str(raised.value)
    assert '\n' not in str(raised.value)
    ranges.write_text('\ufeff{"asymmetric": {"asymmetric_loss_ratio": [1.5, 8]}}', 'utf-8')
    chosen = design.design_of(options('--ranges', str(ranges)))
    assert chosen.true_ranges == {'asymmetric': {'asymmetric_loss_ratio': (1.5, 8.0)}}


def recovery(margin: float, spread: float, count: int = 12) -> Recovery:
    rng = np.random.Generator(np.random.PCG64(0))
    rows = {'a': [{'a': 0.0, 'b': -(margin + spread * rng.standard_normal())}
                  for _ in range(count)],
            'b': [{'a': -50.0, 'b': 0.0} for _ in range(count)]}
    return Recovery(count, 4, {'a': {}, 'b': {}}, rows,
                    {'a': ['a'] * count, 'b': ['b'] * count})


def test_power_and_its_interval_follow_the_margin() -> None:
    clear, close = recovery(20.0, 5.0), recovery(1.0, 5.0)
    assert clear.needed('a', 'b') == 2 and clear.needed_interval('a', 'b') == (2, 2)
    needed = close.needed('a', 'b')
    low, high = close.needed_interval('a', 'b')
    assert needed is not None and needed > 8
    assert low is not None and low <= needed and (high is None or high >= needed)


def test_the_proposal_criterion_is_the_worst_pair() -> None:
    z, pair = design.separation(recovery(1.0, 5.0), 16)
    diff = np.array([row['a'] - row['b'] for row in recovery(1.0, 5.0).elpd['a']])
    assert pair == 'a over b'
    assert z == pytest.approx(diff.mean() / diff.std(ddof=1) * math.sqrt(16))
