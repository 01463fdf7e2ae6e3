"""The person's trust and the models' trust, pure part: the post-drive questionnaire's score
and the comparison of in-drive ratings with every trust model.

Questionnaire: the 12-item "trust between people and automation" scale of Jian, Bisantz and
Drury (2000), "Foundations for an empirically determined scale of trust in automated
systems", International Journal of Cognitive Ergonomics 4(1), 53-71, answered on a 7-point
scale (1 not at all, 7 extremely). Items 1-5 measure distrust and are reverse-scored
(8 - answer); the score is the mean of the 12 scored items mapped from [1, 7] to [0, 1],
the scale of the monitor's trust.

Comparison: each in-drive rating (0-100, mapped to [0, 1]) at its wall time against each
model's trust series at that time minus a lag (the person may answer late): RMSE and
Pearson correlation at lag 0 and the lag in [0, max_lag_s] with the smallest RMSE. Both
sides are on the common scale [0, 1]: a model's trust enters only as
:class:`~trust_monitor.model_interface.UnitTrust` (its own units converted once, by
:func:`~trust_monitor.model_interface.unit_trust`); a raw reading is refused.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from trust_av_common.errors import TrustAvError
from trust_monitor.model_interface import UnitTrust, common_trust
from trust_monitor.paper_trust import TrustConfig, TrustEstimator

__all__ = ['ITEM_NAMES', 'JIAN_ITEMS', 'SCORE_NAME', 'Agreement', 'DriveSeries', 'RatingError',
           'TrustModel', 'agreement_lines', 'compare', 'questionnaire_score',
           'registered_models']

JIAN_ITEMS = (
    'The system is deceptive.',
    'The system behaves in an underhanded manner.',
    "I am suspicious of the system's intent, action, or outputs.",
    'I am wary of the system.',
    "The system's actions will have a harmful or injurious outcome.",
    'I am confident in the system.',
    'The system provides security.',
    'The system has integrity.',
    'The system is dependable.',
    'The system is reliable.',
    'I can trust the system.',
    'I am familiar with the system.',
)
"""The 12 items of the checklist, in the published order (Jian, Bisantz & Drury 2000)."""
JIAN_REVERSED = frozenset(range(5))
"""Zero-based indices of the distrust items (items 1-5), reverse-scored."""
JIAN_SCALE = (1, 7)
"""The answer scale: 1 (not at all) to 7 (extremely)."""
ITEM_NAMES = tuple(f'jian_{i + 1:02d}' for i in range(len(JIAN_ITEMS)))
"""Names of the answers in the recorded questionnaire message."""
SCORE_NAME = 'trust_score'
"""Name of the score in the recorded questionnaire message."""


class RatingError(TrustAvError):
    """A rating or a questionnaire answer is out of range; the message names it."""


def questionnaire_score(answers: Sequence[int]) -> float:
    """The trust score of one questionnaire, in [0, 1].

    Args:
        answers: the 12 answers in item order, each an integer in [1, 7].

    Raises:
        RatingError: not 12 answers, or one not an integer in [1, 7] (named).
    """
    if len(answers) != len(JIAN_ITEMS):
        raise RatingError(f'the questionnaire has {len(JIAN_ITEMS)} items, got '
                          f'{len(answers)} answers')
    low, high = JIAN_SCALE
    scored = []
    for i, answer in enumerate(answers):
        if isinstance(answer, bool) or not isinstance(answer, int) or not low <= answer <= high:
            raise RatingError(f'{ITEM_NAMES[i]} must be an integer in [{low}, {high}], got '
                              f'{answer!r}')
        scored.append(low + high - answer if i in JIAN_REVERSED else answer)
    return (float(np.mean(scored)) - low) / (high - low)


@dataclass(frozen=True)
class DriveSeries:
    """What a drive recorded that trust models take: the AV's plans as the monitor saw them.

    Attributes:
        times_s: the plans' stamps, s since the drive started (increasing).
        plans: the AV's plan u_R at each time, m/s^2.
        expected: the plan the person was expected to expect, u_R^H, m/s^2.
        monitor_trust: the monitor's published trust at each time (NaN where none).
    """

    times_s: np.ndarray
    plans: list[list[float]]
    expected: list[list[float]]
    monitor_trust: np.ndarray


TrustModel = Callable[[DriveSeries], Sequence[UnitTrust]]
"""A trust model for the comparison: the drive's plans -> its trust at each plan time, on
the common scale (:class:`~trust_monitor.model_interface.UnitTrust`)."""


def trust_model_series(config: TrustConfig, values: Mapping[str, Any] | None = None
                       ) -> TrustModel:
    """The trust model ``config.trust_model`` names (with ``values`` for its own parameters,
    as the run's params files give them) over a drive's plans, each update scaled by the
    time to the next plan, run by the monitor's own :class:`TrustEstimator`; its trust on
    the common scale (:func:`~trust_monitor.model_interface.common_trust`)."""
    from trust_monitor.model_interface import make_trust_model

    def model(series: DriveSeries) -> list[UnitTrust]:
        estimator = TrustEstimator(config, make_trust_model(config, values))
        out = []
        gaps = np.diff(series.times_s, append=series.times_s[-1:])
        for i, (plan, expected) in enumerate(zip(series.plans, series.expected, strict=True)):
            estimator.step(plan, expected, float(gaps[i]))
            out.append(common_trust(estimator.model, estimator.state))
        return out
    return model


@dataclass(frozen=True)
class Agreement:
    """How one model's trust agrees with the person's ratings.

    Attributes:
        model: the model's name.
        ratings: number of ratings compared.
        rmse: RMSE at lag 0, on the common scale [0, 1].
        correlation: Pearson correlation at lag 0 (NaN with < 3 ratings or no variance).
        best_lag_s: the lag with the smallest RMSE, s (model trust at t - lag vs rating at t).
        rmse_at_best_lag: that RMSE.
    """

    model: str
    ratings: int
    rmse: float
    correlation: float
    best_lag_s: float
    rmse_at_best_lag: float


def _at(times_s: np.ndarray, values: np.ndarray, when_s: np.ndarray) -> np.ndarray:
    """The series' last value at or before each time (its first before the first)."""
    index = np.searchsorted(times_s, when_s, side='right') - 1
    return values[np.clip(index, 0, len(values) - 1)]


def _correlation(a: np.ndarray, b: np.ndarray) -> float:
    if len(a) < 3 or np.ptp(a) < 1e-12 or np.ptp(b) < 1e-12:
        return math.nan
    return float(np.corrcoef(a, b)[0, 1])


def compare(rating_times_s: Sequence[float] | np.ndarray, ratings: Sequence[float] | np.ndarray,
            series: DriveSeries,
            models: Sequence[tuple[str, TrustModel]], *, max_lag_s: float = 10.0,
            lag_step_s: float = 0.5) -> list[Agreement]:
    """Compare the person's ratings with every model's trust on the drive's clock.

    Args:
        rating_times_s: when each rating was given, s since the drive started.
        ratings: the ratings on the common scale [0, 1] (a 0-100 rating / 100).
        series: the drive's plans (what each model is run on).
        models: (name, model) pairs, e.g. :func:`registered_models`.
        max_lag_s: largest lag tried, s (>= 0).
        lag_step_s: lag grid step, s (> 0).

    Returns:
        One :class:`Agreement` per model, in the given order.

    Raises:
        RatingError: no rating, no plan, ratings and times of different lengths, a rating
            outside [0, 1] (a 0-100 rating not divided by 100), or a model whose trust is not
            :class:`~trust_monitor.model_interface.UnitTrust` (a raw reading).
    """
    when = np.asarray(rating_times_s, dtype=float)
    person = np.asarray(ratings, dtype=float)
    if len(when) != len(person) or len(person) == 0:
        raise RatingError(f'need one time per rating and at least one rating, got '
                          f'{len(when)} times and {len(person)} ratings')
    if len(series.times_s) == 0:
        raise RatingError('the drive recorded no plan: no model trust to compare with')
    if not np.all((person >= 0.0) & (person <= 1.0)):
        raise RatingError(f'ratings must be on the common scale [0, 1], got '
                          f'{float(np.nanmin(person)):g} to {float(np.nanmax(person)):g} '
                          '(a 0-100 rating is divided by 100)')
    lags = np.arange(0.0, max_lag_s + lag_step_s / 2, lag_step_s)
    out = []
    for name, model in models:
        readings = model(series)
        if not all(isinstance(value, UnitTrust) for value in readings):
            raise RatingError(f'trust model {name!r}: its trust is not on the common scale '
                              '(UnitTrust, made by trust_monitor.model_interface.unit_trust); '
                              'a raw reading cannot be compared with ratings')
        trust = np.asarray(readings, dtype=float)
        errors = [float(np.sqrt(np.mean((_at(series.times_s, trust, when - lag) - person)
                                        ** 2))) for lag in lags]
        best = int(np.argmin(errors))
        at_zero = _at(series.times_s, trust, when)
        out.append(Agreement(name, len(person), errors[0], _correlation(at_zero, person),
                             float(lags[best]), errors[best]))
    return out


def agreement_lines(agreements: Sequence[Agreement]) -> list[str]:
    """The comparison as a text table (one line per model)."""
    lines = [f'{"model":<16} {"ratings":>7} {"rmse":>7} {"corr":>7} {"best lag s":>10} '
             f'{"rmse@lag":>8}']
    for a in agreements:
        lines.append(f'{a.model:<16} {a.ratings:>7d} {a.rmse:>7.3f} {a.correlation:>7.3f} '
                     f'{a.best_lag_s:>10.1f} {a.rmse_at_best_lag:>8.3f}')
    return lines


def registered_models(config: TrustConfig, values: Mapping[str, Any] | None = None
                      ) -> list[tuple[str, TrustModel]]:
    """Every registered trust model (group ``trust_av.trust_models``, plug-ins included) as a
    comparison model, each with the run's parameters (``values``: the params files' values
    of the models' own parameters, ``RunConfig.trust_model_params``)."""
    from trust_av_common.registry import names
    from trust_monitor.model_interface import TRUST_MODELS

    return [(name, trust_model_series(dataclasses.replace(config, trust_model=name), values))
            for name in names(TRUST_MODELS)]
