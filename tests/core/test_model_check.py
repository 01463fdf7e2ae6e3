"""Model checking (trust_monitor.model_check) and the preference rule of fit-trust: a model
whose residuals wander is rejected, one that generated the ratings is not; held-out intervals
too narrow are rejected; stacking weights; every fitted parameter is counted, and a few
ratings prefer nothing. Pure numerics on hand-made drives and fits (no optimiser runs)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from trust_av.cli import fit_trust
from trust_av.system.config import load_run_config
from trust_monitor import model_check
from trust_monitor.rating_observation import Observation
from trust_monitor.trust_fit import (
    Fit,
    RatedDrive,
    Score,
    model_spec,
    model_trust,
    preferred,
)

TRUST = load_run_config().trust


def drives(rng: np.random.Generator, count: int = 4) -> list[RatedDrive]:
    """Drives of 120 one-second steps with random E, a rating every 2.5 s (filled later)."""
    out = []
    for k in range(count):
        times = np.arange(120.0)
        scores = np.clip(rng.uniform(0.4, 1.0, 120), 0.0, 1.0)
        rating_times = np.arange(0.0, 121.0, 2.5)
        out.append(RatedDrive('p', f'd{k}', times, scores, rating_times,
                              np.zeros(len(rating_times))))
    return out


def rated(spec_name: str, theta: dict[str, float], obs: Observation, wander: float,
          seed: int) -> tuple[list[RatedDrive], Fit]:
    """Ratings of ``spec_name`` with ``theta`` through ``obs`` plus 5-point noise and, when
    ``wander`` > 0, a random walk of that many points per rating; the fit is the truth."""
    rng = np.random.Generator(np.random.PCG64(seed))
    spec = model_spec(TRUST, spec_name)
    model = spec.build(theta)
    out = []
    for d in drives(rng):
        mean = 100.0 * obs.mean(model_trust(model, d)[1])
        walk = np.cumsum(rng.normal(0.0, wander, len(mean))) if wander else 0.0
        ratings = np.clip(np.round(mean + walk + rng.normal(0.0, 5.0, len(mean))), 0, 100)
        out.append(RatedDrive(d.participant, d.drive, d.times_s, d.scores, d.rating_times_s,
                              ratings))
    return out, Fit(spec_name, dict(theta), obs, 0.0, sum(len(d.ratings) for d in out), 0)


def test_lag1_counts_pairs_within_a_drive_only() -> None:
    residuals = np.array([1.0, 1.0, 1.0, -1.0, -1.0, -1.0])
    assert model_check.lag1(residuals, np.array([0, 0, 0, 1, 1, 1])) == pytest.approx(4 / 6)
    alternating = np.array([1.0, -1.0, 1.0, -1.0, 1.0, -1.0])
    assert model_check.lag1(alternating, np.zeros(6)) == pytest.approx(-5 / 6)
    assert math.isnan(float(model_check.lag1(residuals, np.arange(6))))   # no pairs


def test_the_generating_model_passes_and_a_wandering_participant_fails() -> None:
    spec = model_spec(TRUST, 'optimo')
    theta = {p.name: p.low + 0.4 * (p.high - p.low) if not p.log_scale else
             math.exp(p.prior_mean) for p in spec.parameters}
    obs = Observation(0.0, 1.0, 0.05)
    data, truth = rated('optimo', theta, obs, 0.0, seed=1)
    checks = model_check.check_model('p', spec, truth, data, None)
    assert [c.statistic for c in checks] == ['residual_lag1']
    assert checks[0].adequate and abs(checks[0].value) < 0.2
    data, truth = rated('optimo', theta, obs, 2.0, seed=1)
    checks = model_check.check_model('p', spec, truth, data, None)
    assert not checks[0].adequate and checks[0].value > 0.3 and checks[0].p_value < 0.001
    assert model_check.adequate(checks) == {'optimo': False}
    text = model_check.misfit_text(checks)
    assert text.startswith('residuals correlated, lag-1 0.') and 'p < 0.001' in text


def test_held_out_intervals_too_narrow_are_rejected() -> None:
    rng = np.random.Generator(np.random.PCG64(3))
    spec = model_spec(TRUST, 'optimo')
    theta = {p.name: math.exp(p.prior_mean) if p.log_scale else p.prior_mean
             for p in spec.parameters}
    data, truth = rated('optimo', theta, Observation(0.0, 1.0, 0.05), 0.0, seed=2)
    n = sum(len(d.ratings) for d in data)
    for spread, ok in ((5.0, True), (10.0, False)):
        errors = rng.normal(0.0, spread, n)
        held = Score('optimo', 'leave_one_drive_out', -0.5 * (errors / 5.0) ** 2, errors,
                     np.full(n, 5.0))
        check = model_check.check_model('p', spec, truth, data, held)[1]
        assert check.statistic == 'interval_90' and check.adequate is ok, check
    assert 0.85 < model_check.check_model('p', spec, truth, data, Score(
        'optimo', 'x', np.zeros(n), rng.normal(0.0, 5.0, n), np.full(n, 5.0)))[1].value < 0.95


def test_stacking_weights() -> None:
    good, bad = np.full(100, -1.0), np.full(100, -9.0)
    one = model_check.stacking_weights({'a': Score('a', 's', good, good),
                                        'b': Score('b', 's', bad, bad)})
    assert one['a'] > 0.99 and one['b'] < 0.01
    half = model_check.stacking_weights({
        'a': Score('a', 's', np.r_[good[:50], bad[:50]], good),
        'b': Score('b', 's', np.r_[bad[:50], good[:50]], good)})
    assert half['a'] == pytest.approx(0.5, abs=0.01) and sum(half.values()) == \
        pytest.approx(1.0)


def test_every_fitted_parameter_is_counted() -> None:
    specs = {m: model_spec(TRUST, m) for m in ('paper', 'asymmetric', 'optimo',
                                               'beta_bernoulli')}
    counts = {m: model_check.parameter_count(s) for m, s in specs.items()}
    assert counts == {m: len(s.parameters) + (3 if s.observation == 'linear' else 1)
                      for m, s in specs.items()}
    assert counts == {'paper': 4, 'asymmetric': 5, 'optimo': 4, 'beta_bernoulli': 5}
    # optimo's elpd within one SE of asymmetric's: the simpler by every parameter wins
    # (by the model's own parameters alone, 2 against 3, asymmetric was the simpler)
    rng = np.random.Generator(np.random.PCG64(0))
    base = rng.normal(-3.0, 0.5, 200)
    scores = [Score('asymmetric', 's', base + rng.normal(0.01, 0.5, 200), base),
              Score('optimo', 's', base, base)]
    assert preferred(scores, counts) == 'optimo'
    assert preferred(scores, {m: len(s.parameters) for m, s in specs.items()}) == 'asymmetric'


def test_few_ratings_prefer_nothing() -> None:
    rng = np.random.Generator(np.random.PCG64(0))
    sizes = {'paper': 5, 'beta_bernoulli': 5}
    few = rng.normal(-3.0, 1.0, 16)
    rows = fit_trust._rows('P1', [Score('paper', 's', few, few),
                                  Score('beta_bernoulli', 's', few - 50.0, few)], sizes)
    assert {r['evidence'] for r in rows} == {'not enough data'}
    assert [r['preferred'] for r in rows] == [0, 0]
    many = rng.normal(-3.0, 1.0, 200)
    rows = fit_trust._rows('P1', [Score('paper', 's', many, many),
                                  Score('beta_bernoulli', 's', many - 1.0, many)], sizes)
    assert rows[0]['model'] == 'paper' and rows[0]['preferred'] == 1
    assert {r['evidence'] for r in rows} == {'clear'} and rows[0]['parameters'] == 5
