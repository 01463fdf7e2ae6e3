"""Partial pooling of per-participant trust fits: the population's center is the pooled fit,
its spread the participants' own estimates around it; a participant's shrunk fit lies
toward the center; ``trust-av fit-trust`` writes and scores it."""

from __future__ import annotations

import csv
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from trust_av.drive.trust_fit_pooling import (
    MIN_SPREAD,
    PARTICIPANT_FOLDS,
    SCHEME,
    Population,
    held_out_partial,
    partial_fits,
    participant_folds,
    population,
    shrunk,
)
from trust_av.study.trust_recovery import synthetic_study, write_ratings_table
from trust_av.study.workers import call_runner
from trust_av.system.config import load_run_config
from trust_monitor.trust_fit import Fit, Observation, by_participant, fit, model_spec


def search(p, value: float) -> float:  # type: ignore[no-untyped-def]
    return ((math.log(value) if p.log_scale else value) - p.prior_mean) / p.prior_std


def at(spec, z: dict[str, float]) -> dict[str, float]:  # type: ignore[no-untyped-def]
    """Parameter values at search units ``z`` (prior SDs from the declared prior mean)."""
    out = {}
    for p in spec.parameters:
        x = p.prior_mean + p.prior_std * z[p.name]
        out[p.name] = math.exp(x) if p.log_scale else x
    return out


def fitted(theta: dict[str, float]) -> Fit:
    return Fit('optimo', theta, Observation(0.0, 1.0, 0.05), 0.0, 10, 1)


@pytest.fixture(scope='module')
def spec():  # type: ignore[no-untyped-def]
    return model_spec(load_run_config().trust, 'optimo')


@pytest.fixture(scope='module')
def people():  # type: ignore[no-untyped-def]
    """Three synthetic optimo participants, two 60 s drives each (rating noise included)."""
    return synthetic_study(load_run_config(), ['optimo'], per_model=3, drives=2, steps=60)


def test_center_is_the_pooled_fit_and_spread_the_rms_deviation(spec) -> None:  # type: ignore[no-untyped-def]
    names = [p.name for p in spec.parameters]
    assert len(names) >= 2
    pooled = fitted(at(spec, dict.fromkeys(names, 0.2)))
    first, second = names[0], names[1]
    own = {'a': fitted(at(spec, {**dict.fromkeys(names, 0.2), first: 0.5})),
           'b': fitted(at(spec, {**dict.fromkeys(names, 0.2), first: -0.1,
                                  second: 5.0}))}
    result = population(spec, pooled, own)
    assert result.center == pytest.approx(pooled.theta)
    assert result.spread[first] == pytest.approx(0.3)          # sqrt((0.3^2 + 0.3^2) / 2)
    assert result.spread[second] == 1.0                        # never wider than the prior
    assert all(result.spread[n] == MIN_SPREAD for n in names[2:])  # all at the center
    assert result.participants == 2
    with pytest.raises(Exception, match='at least two participants'):
        population(spec, pooled, {'a': own['a']})


def test_shrunk_prior_is_centred_on_the_population(spec) -> None:  # type: ignore[no-untyped-def]
    names = [p.name for p in spec.parameters]
    center = at(spec, dict.fromkeys(names, 0.7))
    prior = shrunk(spec, Population('optimo', center, dict.fromkeys(names, 0.25), 3))
    for before, after in zip(spec.parameters, prior.parameters, strict=True):
        assert search(after, center[after.name]) == pytest.approx(0.0)
        assert after.prior_std == pytest.approx(0.25 * before.prior_std)
        assert (after.low, after.high, after.log_scale) == (before.low, before.high,
                                                           before.log_scale)


def test_a_participant_is_pulled_toward_the_population(spec, people) -> None:  # type: ignore[no-untyped-def]
    """Each shrunk fit is nearer the pooled fit than the participant's own fit (summed
    squared distance in prior SDs), and nearer still under a narrow population."""
    groups = by_participant([d for who in people for d in who.drives])
    own = {who: fit(spec, drives) for who, drives in groups.items()}
    pooled = fit(spec, [d for drives in groups.values() for d in drives])

    def distance(theta: dict[str, float]) -> float:
        return sum((search(p, theta[p.name]) - search(p, pooled.theta[p.name])) ** 2
                   for p in spec.parameters)

    result, partial = partial_fits(spec, groups, own, pooled)
    assert set(partial) == set(groups)
    assert sum(distance(partial[w].theta) for w in groups) < sum(distance(own[w].theta)
                                                                 for w in groups)
    narrow = shrunk(spec, Population('optimo', result.center,
                                     dict.fromkeys(result.spread, MIN_SPREAD), 3))
    tight = {w: fit(narrow, drives) for w, drives in groups.items()}
    assert sum(distance(tight[w].theta) for w in groups) < sum(distance(partial[w].theta)
                                                               for w in groups)
    score = held_out_partial(spec, groups, own, next(iter(groups)))
    assert score.scheme == SCHEME and len(score.pointwise) == sum(
        len(d.ratings) for d in groups[next(iter(groups))])
    assert np.all(np.isfinite(score.pointwise))
    with pytest.raises(Exception, match='at least 3 participants'):
        held_out_partial(spec, dict(list(groups.items())[:2]), own, next(iter(groups)))


def test_fit_trust_writes_and_scores_partial_pooling(tmp_path: Path, people) -> None:  # type: ignore[no-untyped-def]
    table = tmp_path / 'ratings.csv'
    write_ratings_table(table, people)
    out = tmp_path / 'fit'
    command = [sys.executable, '-m', 'trust_av.cli', 'fit-trust', '--ratings',
               str(table), '--models', 'paper,optimo', '--no-figures']
    proc = subprocess.run([*command, '--out', str(out)], capture_output=True, text=True,
                          timeout=600, check=False)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    with (out / 'partial_pooling.csv').open() as handle:
        rows = list(csv.DictReader(handle))
    kinds = {(r['scope'], r['model'], r['kind']) for r in rows}
    for model in ('paper', 'optimo'):
        assert ('population', model, 'center') in kinds
        assert ('population', model, 'spread') in kinds
        for who in ('optimo_00', 'optimo_01', 'optimo_02'):
            assert (who, model, 'observation') in kinds
    spreads = [float(r['value']) for r in rows if r['kind'] == 'spread']
    assert all(MIN_SPREAD <= s <= 1.0 for s in spreads)
    with (out / 'comparison.csv').open() as handle:
        scored = {(r['scope'], r['scheme']) for r in csv.DictReader(handle)}
    assert {(w, SCHEME) for w in ('optimo_00', 'optimo_01', 'optimo_02')} <= scored
    assert f'all {SCHEME}' in proc.stdout      # summed over the participants
    bare = tmp_path / 'bare'
    proc = subprocess.run([*command, '--out', str(bare), '--no-partial-pooling'],
                          capture_output=True, text=True, timeout=600, check=False)
    assert proc.returncode == 0, proc.stderr
    assert not (bare / 'partial_pooling.csv').exists()
    assert SCHEME not in (bare / 'comparison.csv').read_text()


def test_participants_are_dealt_into_at_most_eight_folds() -> None:
    """Up to eight participants each is a fold (leave one participant out); beyond, eight
    folds dealt round-robin in order, every participant in exactly one."""
    assert participant_folds(['a', 'b', 'c']) == [['a'], ['b'], ['c']]
    names = [f'p{i:02d}' for i in range(24)]
    folds = participant_folds(names)
    assert len(folds) == PARTICIPANT_FOLDS == 8
    assert folds[0] == ['p00', 'p08', 'p16'] and folds[7] == ['p07', 'p15', 'p23']
    assert sorted(n for fold in folds for n in fold) == names
    with pytest.raises(ValueError, match='at least one fold'):
        participant_folds(names, 0)


def test_calls_give_the_same_results_here_and_on_a_pool() -> None:
    """The runner fit-trust uses: in this process and on two worker processes, the same
    result per key, progress reported to the total."""
    calls = {k: (math.hypot, (float(k), 2.0)) for k in range(6)}
    seen: list[tuple[int, int]] = []
    with call_runner(1) as run:
        here = run(calls, lambda done, total: seen.append((done, total)))
    with call_runner(2) as run:
        pooled = run(calls, None)
    assert here == pooled == {k: math.hypot(k, 2.0) for k in range(6)}
    assert seen[-1] == (6, 6) and len(seen) == 6
