"""The shipped trust models, registered in ``trust_av.trust_models`` (``setup.py``).

Each is a :class:`trust_monitor.model_interface.TrustModel`; equations, parameter values and
their sources are in ``docs/concepts/trust-models.md``. All are pure and deterministic.

- ``paper``: Ozkan & Ma, eqs. (9)-(11) (:mod:`trust_monitor.paper_trust`), with the
  closed-form NMPC bound :func:`~trust_monitor.paper_trust.paper_explicability_bound`.
- ``asymmetric``: the paper's update with a loss rate ``asymmetric_loss_ratio`` times its
  gain rate (trust falls faster than it rises).
- ``beta_bernoulli``: Guo & Yang (2021), trust the mean of Beta(alpha, beta) counting binary
  successes and failures, one per interaction episode of ``beta_bernoulli_episode_s``
  seconds, with separate weights and an optional forgetting factor, with its variance.
- ``optimo``: linear-Gaussian trust dynamics in the style of OPTIMo (Xu & Dudek 2015) on
  [0, 1] with a Kalman estimate and a rating observation (:meth:`OptimoModel.observe`);
  the paper's eqs. (10)-(11) are its special case inside [0, 1].

Every model reports trust on the common scale [0, 1]
(:func:`trust_monitor.model_interface.common_trust`) and declares what ratings can fit
(``fit_parameters``). Each also gives the fast path ``trajectory`` over a whole drive
(numpy; :func:`trust_monitor.model_interface.trust_trajectory`), held to its ``step``.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from trust_av_common.params import check_fields, param
from trust_av_common.registry import Component
from trust_monitor.model_interface import ClosedForm, FitParameter
from trust_monitor.paper_trust import (
    SAME_MODEL,
    TrustConfig,
    paper_explicability_bound,
    performance,
    trust_input,
    trust_step,
)

__all__ = ['ASYMMETRIC', 'BETA_BERNOULLI', 'OPTIMO', 'PAPER', 'BetaState', 'OptimoConfig',
           'OptimoModel']

EPISODE_TOLERANCE_S = 1e-9
"""An episode counts as complete this close to its length (ten 0.1 s steps sum to
0.9999999999999999 s)."""


REFERENCE_DRIVE_S = 600.0
"""The paper's US06 drive, s: the common scale of ``paper``/``asymmetric`` spans the trust
such a drive can gain or lose at most (|u_T| <= 1)."""


def paper_trust_range(config: TrustConfig) -> tuple[float, float]:
    """Trust units of eqs. (9)-(11) mapped to the common scale [0, 1]:
    ``T(0) - delta 600 s`` -> 0, ``T(0)`` -> 0.5, ``T(0) + delta 600 s`` -> 1."""
    reach = config.trust_growth_rate * REFERENCE_DRIVE_S
    return config.trust_initial - reach, config.trust_initial + reach


def _check_step(dt_s: float) -> None:
    if not (math.isfinite(dt_s) and dt_s >= 0.0):
        raise ValueError(f'dt_s must be finite and >= 0, got {dt_s}')


def _check_steps(dts_s: np.ndarray) -> None:
    """:func:`_check_step` for every step of a drive (NaN fails the first comparison)."""
    if len(dts_s) and not (dts_s.min() >= 0.0 and dts_s.max() < math.inf):
        bad = dts_s[~(np.isfinite(dts_s) & (dts_s >= 0.0))][0]
        raise ValueError(f'dt_s must be finite and >= 0, got {bad}')


def _inputs(scores: np.ndarray, threshold: float) -> np.ndarray:
    """u_T of eq. (11) for each step's E (:func:`~trust_monitor.paper_trust.trust_input` of
    :func:`~trust_monitor.paper_trust.performance`)."""
    perf: np.ndarray = 1.0 - np.tanh(scores)
    return np.where(perf >= threshold, perf, perf - 1.0)


def _accumulated(start: float, increments: np.ndarray) -> np.ndarray:
    """``start`` plus the running sum of ``increments`` (the state after each step)."""
    return start + np.cumsum(increments)


class PaperModel:
    """Eqs. (9)-(11) of Ozkan & Ma: ``T += delta dt u_T(P(E))``; the state is T."""

    name = 'paper'
    paper_bound_holds = True  # trust_bound.py's final-trust bound is derived from this update
    fit_parameters = (
        FitParameter('performance_threshold', 0.5, 0.99, 0.8, 0.1),
        FitParameter('trust_growth_rate', 0.001, 10.0, math.log(0.1), 1.0, log_scale=True,
                     identifiable=False, note='delta only scales the trust units: on the '
                     'common scale (trust_range = T(0) +- delta 600 s) it cancels'),
    )

    def __init__(self, config: TrustConfig, params: None = None) -> None:
        self.config = config
        self.closed_form_bound: ClosedForm | None = self._closed_form
        # u_T <= P <= 1 (eqs. 9, 11): trust gains at most delta per second
        self.ceiling = (config.trust_initial, config.trust_growth_rate)

    @property
    def trust_range(self) -> tuple[float, float]:
        """The common scale's 0 and 1 in trust units (:func:`paper_trust_range`)."""
        return paper_trust_range(self.config)

    def _closed_form(self, state: float, trust_min: float, steps: int,
                     dt_s: float) -> float | None:
        return paper_explicability_bound(state, trust_min, self.config, steps, dt_s)

    def initial_state(self) -> float:
        """T(0) = ``trust_initial``."""
        return self.config.trust_initial

    def step(self, state: float, score: float, dt_s: float) -> float:
        """Eq. (10) scaled by the elapsed time (:func:`~trust_monitor.paper_trust.trust_step`)."""
        _check_step(dt_s)
        return trust_step(state, score, self.config, dt_s)

    def trajectory(self, scores: np.ndarray, dts_s: np.ndarray) -> np.ndarray:
        """T after each step of a drive (the fast path of :meth:`step`)."""
        _check_steps(dts_s)
        u = _inputs(scores, self.config.performance_threshold)
        return _accumulated(self.config.trust_initial, self.config.trust_growth_rate * dts_s * u)

    def trust(self, state: float) -> float:
        """T itself."""
        return state

    def variance(self, state: float) -> float | None:
        """None: the paper's model is deterministic."""
        return None


@dataclass(frozen=True)
class AsymmetricConfig:
    """Parameters of ``asymmetric`` beyond the paper's (delta, P_thre, T(0) are shared).

    Attributes:
        asymmetric_loss_ratio: loss rate / gain rate, dimensionless (issue example: 2, trust
            falls twice as fast as it rises).
    """

    asymmetric_loss_ratio: float = param('trust loss rate as a multiple of the gain rate '
                                         'delta (asymmetric model)', low=0.0,
                                         low_inclusive=False, reason=SAME_MODEL, default=2.0,
                                         high=1000.0)

    def __post_init__(self) -> None:
        check_fields(self)


class AsymmetricModel:
    """``T += delta dt u_T`` when ``u_T >= 0`` and ``T += r delta dt u_T`` when ``u_T < 0``
    (u_T of eq. 11, r = ``asymmetric_loss_ratio``); the state is T."""

    name = 'asymmetric'
    closed_form_bound: ClosedForm | None = None
    fit_parameters = (
        PaperModel.fit_parameters[0],
        FitParameter('asymmetric_loss_ratio', 0.2, 50.0, math.log(2.0), 1.0, log_scale=True),
        PaperModel.fit_parameters[1],
    )

    def __init__(self, config: TrustConfig, params: AsymmetricConfig) -> None:
        self.config = config
        self.params = params
        # it gains as the paper's model does (u_T <= 1): at most delta per second
        self.ceiling = (config.trust_initial, config.trust_growth_rate)

    @property
    def trust_range(self) -> tuple[float, float]:
        """As ``paper``'s: T(0) -+ delta x 600 s."""
        return paper_trust_range(self.config)

    def initial_state(self) -> float:
        """T(0) = ``trust_initial``."""
        return self.config.trust_initial

    def step(self, state: float, score: float, dt_s: float) -> float:
        """One update over ``dt_s`` s."""
        _check_step(dt_s)
        u = trust_input(performance(score), self.config.performance_threshold)
        rate = self.config.trust_growth_rate * (1.0 if u >= 0.0 else
                                                self.params.asymmetric_loss_ratio)
        return state + rate * dt_s * u

    def trajectory(self, scores: np.ndarray, dts_s: np.ndarray) -> np.ndarray:
        """T after each step of a drive (the fast path of :meth:`step`)."""
        _check_steps(dts_s)
        u = _inputs(scores, self.config.performance_threshold)
        rate = self.config.trust_growth_rate * np.where(u >= 0.0, 1.0,
                                                        self.params.asymmetric_loss_ratio)
        return _accumulated(self.config.trust_initial, rate * dts_s * u)

    def trust(self, state: float) -> float:
        """T itself."""
        return state

    def variance(self, state: float) -> float | None:
        """None: deterministic."""
        return None


@dataclass(frozen=True)
class BetaBernoulliConfig:
    """Parameters of ``beta_bernoulli`` (Guo & Yang 2021; values are priors, see docs).

    Attributes:
        beta_bernoulli_alpha0: alpha of the prior Beta(alpha0, beta0), > 0.
        beta_bernoulli_beta0: beta of the prior, > 0.
        beta_bernoulli_success_weight: w_s, alpha gained per successful episode.
        beta_bernoulli_failure_weight: w_f, beta gained per failed episode.
        beta_bernoulli_episode_s: length of one interaction episode, s.
        beta_bernoulli_success_threshold: an episode is a success when its mean performance
            p_k = mean of P = 1 - tanh(E) is at least this (default: the paper's P_thre).
        beta_bernoulli_forgetting: lambda in (0, 1]: per episode the evidence gathered so
            far decays to lambda times itself (1: no forgetting, Guo & Yang's model).
    """

    beta_bernoulli_alpha0: float = param('prior alpha of the Beta trust distribution',
                                         low=0.0, low_inclusive=False, reason=SAME_MODEL,
                                         default=1.0, high=1e6)
    beta_bernoulli_beta0: float = param('prior beta of the Beta trust distribution',
                                        low=0.0, low_inclusive=False, reason=SAME_MODEL,
                                        default=1.0, high=1e6)
    beta_bernoulli_success_weight: float = param('w_s: alpha gained per successful episode',
                                                 low=0.0, reason=SAME_MODEL,
                                                 default=1.0, high=1e6)
    beta_bernoulli_failure_weight: float = param('w_f: beta gained per failed episode',
                                                 low=0.0, reason=SAME_MODEL,
                                                 default=1.0, high=1e6)
    beta_bernoulli_episode_s: float = param('length of one interaction episode', unit='s',
                                            low=0.0, low_inclusive=False, reason=SAME_MODEL,
                                            default=1.0, high=3600.0)
    beta_bernoulli_success_threshold: float = param('an episode succeeds when its mean '
                                                    'performance is at least this', low=0.0,
                                                    high=1.0, low_inclusive=False,
                                                    reason=SAME_MODEL, default=0.8)
    beta_bernoulli_forgetting: float = param('lambda: evidence kept per episode (1: no '
                                             'forgetting)', low=0.0, low_inclusive=False,
                                             high=1.0, reason=SAME_MODEL, default=1.0)

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass(frozen=True)
class BetaState:
    """Beta(alpha, beta) and the episode in progress (``elapsed_s`` s, ``performance_s`` =
    the time integral of P over it)."""

    alpha: float
    beta: float
    elapsed_s: float = 0.0
    performance_s: float = 0.0


class BetaBernoulliModel:
    """Guo & Yang (2021): each interaction episode k is a success (s_k = 1) when its mean
    performance p_k >= the threshold, else a failure; ``alpha_k = alpha0 + lambda (alpha_{k-1}
    - alpha0) + w_s s_k``, ``beta_k = beta0 + lambda (beta_{k-1} - beta0) + w_f (1 - s_k)``;
    trust = alpha / (alpha + beta) (in [0, 1]), with the Beta variance."""

    name = 'beta_bernoulli'
    closed_form_bound: ClosedForm | None = None
    rating_observation = 'direct'  # Guo & Yang: the reported trust is drawn around the mean
    fit_parameters = (
        FitParameter('beta_bernoulli_alpha0', 0.05, 50.0, math.log(1.0), 1.0, log_scale=True),
        FitParameter('beta_bernoulli_success_weight', 0.01, 20.0, math.log(1.0), 1.0,
                     log_scale=True),
        FitParameter('beta_bernoulli_failure_weight', 0.01, 50.0, math.log(3.0), 1.0,
                     log_scale=True),
        FitParameter('beta_bernoulli_forgetting', 0.5, 1.0, 0.95, 0.05),
        FitParameter('beta_bernoulli_beta0', 0.05, 50.0, 0.0, 1.0, log_scale=True,
                     identifiable=False,
                     note='trust is unchanged when alpha0, beta0, w_s and w_f are scaled '
                          'together: beta0 is held as the unit of evidence'),
    )

    def __init__(self, config: TrustConfig, params: BetaBernoulliConfig) -> None:
        self.config = config
        self.params = params

    def initial_state(self) -> BetaState:
        """The prior Beta(alpha0, beta0), no episode in progress."""
        return BetaState(self.params.beta_bernoulli_alpha0, self.params.beta_bernoulli_beta0)

    def step(self, state: BetaState, score: float, dt_s: float) -> BetaState:
        """Accumulate P over ``dt_s``; close each episode that ends within it (a step that
        spans an episode end is split there, so the update does not depend on the step)."""
        _check_step(dt_s)
        p = self.params
        perf = performance(score)
        keep = p.beta_bernoulli_forgetting
        a0, b0 = p.beta_bernoulli_alpha0, p.beta_bernoulli_beta0
        alpha, beta, elapsed, integral = (state.alpha, state.beta, state.elapsed_s,
                                          state.performance_s)
        remaining = dt_s
        while remaining > 0.0:
            take = min(remaining, p.beta_bernoulli_episode_s - elapsed)
            elapsed += take
            integral += perf * take
            remaining -= take
            if elapsed >= p.beta_bernoulli_episode_s - EPISODE_TOLERANCE_S:
                success = integral / elapsed >= p.beta_bernoulli_success_threshold
                alpha = a0 + keep * (alpha - a0) + (p.beta_bernoulli_success_weight
                                                    if success else 0.0)
                beta = b0 + keep * (beta - b0) + (0.0 if success
                                                  else p.beta_bernoulli_failure_weight)
                elapsed, integral = 0.0, 0.0
                if remaining < EPISODE_TOLERANCE_S:
                    break
        return BetaState(alpha, beta, elapsed, integral)

    def trajectory(self, scores: np.ndarray, dts_s: np.ndarray) -> np.ndarray:
        """alpha / (alpha + beta) after each step of a drive (the fast path of
        :meth:`step`): which episodes end in which step and which succeed does not depend on
        alpha0, beta0, the weights or lambda, so it is found once per drive
        (:func:`_episodes`) and the fitted parameters enter only the linear recurrence."""
        _check_steps(dts_s)
        p = self.params
        successes, closed = _episodes(scores.tobytes(), dts_s.tobytes(),
                                      p.beta_bernoulli_episode_s,
                                      p.beta_bernoulli_success_threshold)
        a0, b0 = p.beta_bernoulli_alpha0, p.beta_bernoulli_beta0
        alpha = a0 + _decaying(p.beta_bernoulli_forgetting,
                               p.beta_bernoulli_success_weight * successes)
        beta = b0 + _decaying(p.beta_bernoulli_forgetting,
                              p.beta_bernoulli_failure_weight * (1.0 - successes))
        trust: np.ndarray = (alpha / (alpha + beta))[closed]
        return trust

    def trust(self, state: BetaState) -> float:
        """The Beta mean alpha / (alpha + beta)."""
        return state.alpha / (state.alpha + state.beta)

    def variance(self, state: BetaState) -> float | None:
        """The Beta variance alpha beta / ((alpha + beta)^2 (alpha + beta + 1))."""
        total = state.alpha + state.beta
        return state.alpha * state.beta / (total * total * (total + 1.0))


def _decaying(keep: float, added: np.ndarray) -> np.ndarray:
    """``d_0 = 0, d_k = keep d_{k-1} + added_k`` for k = 1..K (the evidence beyond the prior
    after each episode; d_0 first), as ``keep^k (d + sum_j keep^-j added_j)`` over runs of
    episodes short enough that ``keep^-j`` stays below 1e300."""
    out = np.zeros(len(added) + 1)
    run = len(added) if keep >= 1.0 else max(1, int(300.0 / -math.log10(keep)))
    for start in range(0, len(added), max(run, 1)):
        chunk = added[start:start + run]
        powers = keep ** np.arange(1.0, len(chunk) + 1.0)
        out[start + 1:start + 1 + len(chunk)] = powers * (out[start] + np.cumsum(chunk / powers))
    return out


@functools.lru_cache(maxsize=4096)
def _episodes(scores: bytes, dts_s: bytes, episode_s: float,
              threshold: float) -> tuple[np.ndarray, np.ndarray]:
    """The episodes of a drive as :meth:`BetaBernoulliModel.step` closes them: 1.0 for each
    that succeeds (else 0.0), in order, and per step the number closed by its end (the same
    arithmetic as the step, so the same episodes). Keyed by the drive's bytes: a fit calls it
    with the same drive at every evaluation."""
    successes: list[float] = []
    closed = []
    elapsed, integral = 0.0, 0.0
    for score, dt in zip(np.frombuffer(scores).tolist(), np.frombuffer(dts_s).tolist(),
                         strict=True):
        perf = performance(score)
        remaining = dt
        while remaining > 0.0:
            take = min(remaining, episode_s - elapsed)
            elapsed += take
            integral += perf * take
            remaining -= take
            if elapsed >= episode_s - EPISODE_TOLERANCE_S:
                successes.append(1.0 if integral / elapsed >= threshold else 0.0)
                elapsed, integral = 0.0, 0.0
                if remaining < EPISODE_TOLERANCE_S:
                    break
        closed.append(len(successes))
    out = np.array(successes), np.array(closed, dtype=np.intp)
    for array in out:
        array.flags.writeable = False
    return out


@dataclass(frozen=True)
class OptimoConfig:
    """Parameters of ``optimo`` (trust on [0, 1]; defaults are priors of ours, see docs).

    Attributes:
        optimo_bias_rate_per_s: w_b, trust drift per second.
        optimo_performance_rate_per_s: w_p, trust per second per unit of p.
        optimo_change_gain: w_d, trust per unit change of p between steps.
        optimo_noise_std: sigma, process noise per sqrt(second), trust units.
        optimo_initial_trust: the mean of T(0), in [0, 1].
        optimo_initial_std: standard deviation of T(0), trust units.
        optimo_performance_threshold: p = P when P >= this, else P - 1 (eq. 11's input;
            0 gives p = P).
    """

    optimo_bias_rate_per_s: float = param('w_b: trust drift', unit='1/s', reason=SAME_MODEL,
                                          default=0.0, low=-1000.0, high=1000.0)
    optimo_performance_rate_per_s: float = param('w_p: trust gain per unit performance',
                                                 unit='1/s', low=0.0, reason=SAME_MODEL,
                                                 default=0.01, high=1000.0)
    optimo_change_gain: float = param('w_d: trust gain per unit change of performance',
                                      low=0.0, reason=SAME_MODEL, default=0.0, high=1000.0)
    optimo_noise_std: float = param('sigma: process noise of trust per sqrt(second)',
                                    unit='1/sqrt(s)', low=0.0, reason=SAME_MODEL, default=0.01,
                                    high=1000.0)
    optimo_initial_trust: float = param('mean of the initial trust, on [0, 1]', low=0.0,
                                        high=1.0, reason=SAME_MODEL, default=0.5)
    optimo_initial_std: float = param('standard deviation of the initial trust', low=0.0,
                                      reason=SAME_MODEL, default=0.0, high=1e6)
    optimo_performance_threshold: float = param('p = P at or above this, P - 1 below (eq. 11)',
                                                low=0.0, high=1.0, high_inclusive=False,
                                                reason=SAME_MODEL, default=0.8)

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass(frozen=True)
class GaussianState:
    """Kalman estimate of trust: mean, variance, and the last performance input (None
    before the first)."""

    mean: float
    variance: float
    last_input: float | None = None


class OptimoModel:
    """``T_k ~ N(T_{k-1} + (w_b + w_p p_k) dt + w_d (p_k - p_{k-1}), sigma^2 dt)`` with the
    mean kept in [0, 1]; the Kalman prediction propagates mean and variance, :meth:`observe`
    fuses a reported trust (a rating / 100). With w_b = 0, w_p = delta, w_d = 0, sigma = 0
    and the paper's threshold its mean is eqs. (10)-(11) while it stays inside [0, 1]."""

    name = 'optimo'
    closed_form_bound: ClosedForm | None = None
    rating_observation = 'direct'  # OPTIMo: absolute trust feedback f_k ~ N(T_k, sigma_f^2)
    fit_parameters = (
        FitParameter('optimo_performance_rate_per_s', 0.001, 0.2, math.log(0.01), 1.0,
                     log_scale=True),
        FitParameter('optimo_change_gain', 0.0, 0.5, 0.0, 0.1),
        FitParameter('optimo_initial_trust', 0.0, 1.0, 0.5, 0.25),
        FitParameter('optimo_bias_rate_per_s', -0.02, 0.02, 0.0, 0.005, identifiable=False,
                     note='ratings inform the drift under a good plan, w_b + w_p P, but '
                          'not w_b and w_p apart (their errors correlate -0.97 in the '
                          'recovery): w_b is held at its configured value (0, OPTIMo '
                          'without a bias) and w_p carries the drift'),
    )

    def __init__(self, config: TrustConfig, params: OptimoConfig) -> None:
        self.config = config
        self.params = params

    def initial_state(self) -> GaussianState:
        """N(initial trust, initial_std^2)."""
        return GaussianState(self.params.optimo_initial_trust,
                             self.params.optimo_initial_std ** 2)

    def step(self, state: GaussianState, score: float, dt_s: float) -> GaussianState:
        """Kalman prediction over ``dt_s`` s, the mean clipped to [0, 1] (the change term
        telescopes and the drift keeps its sign over a step: time-consistent)."""
        _check_step(dt_s)
        if dt_s == 0.0:
            return state
        p = self.params
        u = trust_input(performance(score), p.optimo_performance_threshold)
        change = 0.0 if state.last_input is None else u - state.last_input
        mean = (state.mean + (p.optimo_bias_rate_per_s + p.optimo_performance_rate_per_s * u)
                * dt_s + p.optimo_change_gain * change)
        return GaussianState(min(max(mean, 0.0), 1.0),
                             state.variance + p.optimo_noise_std ** 2 * dt_s, u)

    def trajectory(self, scores: np.ndarray, dts_s: np.ndarray) -> np.ndarray:
        """The mean after each step of a drive (the fast path of :meth:`step`): the drift
        and change terms at once, then the running sum kept in [0, 1]
        (:func:`_clipped_sum`). A step of no time changes nothing (not even the last
        input), as in :meth:`step`."""
        _check_steps(dts_s)
        p = self.params
        moving = dts_s > 0.0
        u, dt = _inputs(scores[moving], p.optimo_performance_threshold), dts_s[moving]
        change = np.diff(u, prepend=u[:1]) if len(u) else u
        means = _clipped_sum(p.optimo_initial_trust, (p.optimo_bias_rate_per_s
                                                      + p.optimo_performance_rate_per_s * u)
                             * dt + p.optimo_change_gain * change)
        done = np.cumsum(moving)
        return np.concatenate(([p.optimo_initial_trust], means))[done]

    def observe(self, state: GaussianState, reported: float,
                noise_variance: float) -> GaussianState:
        """Kalman update with a reported trust on [0, 1] (a rating / 100), noise variance R;
        the mean stays in [0, 1].

        Raises:
            ValueError: ``noise_variance`` is negative, or both variances are zero.
        """
        if noise_variance < 0.0 or state.variance + noise_variance <= 0.0:
            raise ValueError(f'need noise_variance >= 0 and a positive total variance, got '
                             f'{noise_variance} and {state.variance}')
        gain = state.variance / (state.variance + noise_variance)
        mean = state.mean + gain * (reported - state.mean)
        return GaussianState(min(max(mean, 0.0), 1.0), (1.0 - gain) * state.variance,
                             state.last_input)

    def trust(self, state: GaussianState) -> float:
        """The mean, in [0, 1]."""
        return state.mean

    def variance(self, state: GaussianState) -> float | None:
        """The Kalman variance."""
        return state.variance


def _clipped_sum(start: float, increments: np.ndarray) -> np.ndarray:
    """``x_0 = start, x_k = min(max(x_{k-1} + increments_k, 0), 1)`` for k = 1..K.

    In stretches: from a point of the path, the running sum clipped at one bound only has a
    closed form (Lindley's recursion: the running sum less its running extreme), and it is
    the path until it crosses the other bound; of the two one-bound paths, the one that
    crosses later is the path up to that crossing, where the path sits on the bound and a
    new stretch starts (one stretch per crossing from bound to bound, not per step).
    """
    n = len(increments)
    out = np.empty(n)
    x, k = start, 0
    while k < n:
        sums = np.cumsum(increments[k:])
        low = sums - np.minimum(-x, np.minimum.accumulate(sums))          # clipped at 0
        high = 1.0 + sums - np.maximum(1.0 - x, np.maximum.accumulate(sums))  # at 1
        over, under = np.flatnonzero(low > 1.0), np.flatnonzero(high < 0.0)
        j_low = int(over[0]) if len(over) else n - k
        j_high = int(under[0]) if len(under) else n - k
        path, j, bound = (low, j_low, 1.0) if j_low >= j_high else (high, j_high, 0.0)
        out[k:k + j] = path[:j]
        if k + j < n:
            out[k + j] = bound
        x, k = bound, k + j + 1
    return out


PAPER = Component('paper', PaperModel, None, description='Ozkan & Ma eqs. (9)-(11)')
ASYMMETRIC = Component('asymmetric', AsymmetricModel, AsymmetricConfig,
                       description='eqs. (9)-(11), trust lost faster than gained')
BETA_BERNOULLI = Component('beta_bernoulli', BetaBernoulliModel, BetaBernoulliConfig,
                           description='Guo & Yang 2021: Beta mean, per episode')
OPTIMO = Component('optimo', OptimoModel, OptimoConfig,
                   description='linear-Gaussian trust, Kalman (OPTIMo style)')
