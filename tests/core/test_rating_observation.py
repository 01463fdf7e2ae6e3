"""The observation model from trust to ratings, censored at the scale's ends (Tobit): its
likelihood is a probability distribution over the ratings, its fit is the maximum of that
likelihood (checked against scipy's general-purpose optimiser, not against itself), and it
recovers the noise the Gaussian fit underestimates when ratings pile up at 100.

Floating point: the asserted tolerances are far above any CPU's rounding differences."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import integrate, optimize

from trust_monitor.rating_observation import (
    MIN_RATING_STD,
    Observation,
    fit_observation,
    log_density,
)


def _ratings(trust: np.ndarray, obs: Observation, seed: int) -> np.ndarray:
    """Whole ratings in 0-100, as a participant gives them."""
    rng = np.random.Generator(np.random.PCG64(seed))
    latent = 100.0 * obs.mean(trust) + 100.0 * obs.s * rng.standard_normal(len(trust))
    out: np.ndarray = np.clip(np.round(latent), 0.0, 100.0)
    return out


@pytest.mark.parametrize('mean', [2.0, 50.0, 97.0])
def test_the_likelihood_of_a_rating_is_a_distribution_over_the_scale(mean: float) -> None:
    """Mass at 0, density inside, mass at 100: together one, for a mean near either end."""
    obs = Observation(mean / 100.0, 0.0, 0.06)
    trust = np.zeros(1)
    inside, _ = integrate.quad(lambda r: math.exp(log_density(obs, trust, np.array([r]))[0]),
                               0.0, 100.0, points=[mean], limit=200)
    ends = np.exp(log_density(obs, np.zeros(2), np.array([0.0, 100.0]))).sum()
    assert inside + ends == pytest.approx(1.0, abs=1e-8)


def _scipy_fit(kind: str, trust: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """The maximum log-likelihood and s found by L-BFGS-B over (a, b, log s), many starts."""
    def nll(p: np.ndarray) -> float:
        a, b, s = (0.0, 1.0, math.exp(p[0])) if kind == 'direct' else (p[0], p[1],
                                                                       math.exp(p[2]))
        return -float(log_density(Observation(a, b, s), trust, 100.0 * y).sum())

    best = None
    starts = ([[math.log(s)] for s in (0.01, 0.05, 0.2)] if kind == 'direct' else
              [[a, b, math.log(s)] for a in (0.0, 0.5) for b in (0.0, 1.0) for s in (0.02, 0.1)])
    bounds = ([(math.log(MIN_RATING_STD), 2.0)] if kind == 'direct' else
              [(-5.0, 5.0), (0.0, 10.0), (math.log(MIN_RATING_STD), 2.0)])
    for x0 in starts:
        result = optimize.minimize(nll, np.array(x0, float), method='L-BFGS-B', bounds=bounds,
                                   options={'ftol': 1e-14, 'gtol': 1e-9, 'maxiter': 5000})
        if best is None or result.fun < best.fun:
            best = result
    assert best is not None
    return -float(best.fun), math.exp(float(best.x[-1]))


@pytest.mark.parametrize(('kind', 'truth', 'seed'), [
    ('linear', Observation(0.3, 0.9, 0.05), 1),     # many at 100
    ('linear', Observation(0.02, 0.3, 0.06), 2),    # many at 0
    ('linear', Observation(-0.1, 1.2, 0.08), 3),    # both ends
    ('linear', Observation(0.95, 0.0, 0.05), 4),     # flat, at 100: the maximum on b = 0
    ('direct', Observation(0.0, 1.0, 0.12), 5),
    ('linear', Observation(0.5, 0.6, 0.001), 6),    # the maximum on s = MIN_RATING_STD
])
def test_the_fit_is_the_maximum_of_the_censored_likelihood(kind: str, truth: Observation,
                                                            seed: int) -> None:
    trust = np.random.Generator(np.random.PCG64(seed)).uniform(0.0, 1.0, 150)
    ratings = _ratings(trust, truth, seed)
    assert ((ratings == 0) | (ratings == 100)).sum() >= 10          # the case under test
    y = ratings / 100.0
    fitted = fit_observation(kind, trust, y)
    ours = float(log_density(fitted, trust, ratings).sum())
    theirs, s = _scipy_fit(kind, trust, y)
    assert ours >= theirs - 1e-6                      # nothing scipy finds is higher
    assert fitted.s == pytest.approx(s, rel=1e-3)
    assert fitted.b >= 0.0
    # the start changes the iterations, not the maximum
    far = fit_observation(kind, trust, y, Observation(0.9, 0.1, 0.3))
    assert (far.a, far.b, far.s) == pytest.approx((fitted.a, fitted.b, fitted.s), abs=1e-6)


def test_without_ratings_at_an_end_the_fit_is_least_squares() -> None:
    """No censored rating: the Gaussian likelihood, maximised in closed form."""
    trust = np.linspace(0.0, 1.0, 60)
    ratings = _ratings(trust, Observation(0.2, 0.5, 0.05), 7)
    assert ratings.min() > 0 and ratings.max() < 100
    y = ratings / 100.0
    fitted = fit_observation('linear', trust, y)
    b, a = np.polyfit(trust, y, 1)
    assert (fitted.a, fitted.b) == pytest.approx((a, b), abs=1e-12)
    assert fitted.s == pytest.approx(float(np.std(y - a - b * trust)), abs=1e-12)


def test_ratings_piled_at_100_are_fitted_as_cut_not_as_given() -> None:
    """Two fifths of the ratings at 100: least squares takes the cut ratings at face value
    and flattens the slope; the censored fit finds the slope and noise that made them."""
    trust = np.random.Generator(np.random.PCG64(11)).uniform(0.0, 1.0, 400)
    truth = Observation(0.65, 0.6, 0.05)
    ratings = _ratings(trust, truth, 11)
    assert 0.3 < float(np.mean(ratings == 100)) < 0.5
    y = ratings / 100.0
    fitted = fit_observation('linear', trust, y)
    naive_b = float(np.polyfit(trust, y, 1)[0])
    assert naive_b < 0.75 * truth.b                    # what the Gaussian fit did
    assert fitted.b == pytest.approx(truth.b, rel=0.1)
    assert fitted.a == pytest.approx(truth.a, abs=0.02)
    assert fitted.s == pytest.approx(truth.s, rel=0.1)


def test_all_ratings_at_100_keep_the_least_squares_values() -> None:
    """No maximum exists (the mean runs off to infinity): the fit stays finite."""
    trust = np.linspace(0.0, 1.0, 20)
    fitted = fit_observation('linear', trust, np.ones(20))
    assert (fitted.a, fitted.b, fitted.s) == (1.0, 0.0, MIN_RATING_STD)
    assert np.isfinite(log_density(fitted, trust, np.full(20, 100.0))).all()
