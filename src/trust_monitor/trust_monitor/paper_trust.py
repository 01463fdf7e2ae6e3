"""Explicability, performance and trust dynamics of the human follower (Ozkan & Ma, eqs. 8-11).

Everything here is pure: no ROS, no wall clock. :func:`explicability` is written with
plain arithmetic so that the same function builds the CasADi expression inside the AV's
NMPC and evaluates floats in the monitor: the equation exists once.

Reading of the paper (docs/concepts/reading-the-paper.md): E is the Tanimoto (extended Jaccard)
*distance* of the offset plans ``a = u_R + eps`` and ``b = u_R^H + eps``,
``E = 1 - sum(a*b) / sum(a*a + b*b - a*b)``, so that E = 0 for equal plans and E is in
[0, 1] whenever ``a, b > 0`` (accelerations above ``-eps``).

Time (docs/concepts/time-consistency.md): trust is defined per second. The
growth rate delta is in trust units per second and an update over an elapsed time dt is
``T += delta * dt * u_T``; one 1 s step is exactly eq. (10), so the paper's 1 Hz loop is
unchanged and the same drive gives the same trust at any control rate (docs/MODEL.md,
"Time consistency").
"""

from __future__ import annotations

import math
import re
import warnings
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

from trust_av_common.component_checks import PASSING, call, check_number, raised
from trust_av_common.moved import MovedPathWarning
from trust_av_common.params import ParamsError, check_fields, param
from trust_monitor.model_interface import TRUST_MODELS

__all__ = ['SAME_MODEL', 'MonitorConfig', 'TrustConfig', 'TrustEstimator', 'explicability',
           'paper_explicability_bound', 'performance', 'trust_input',
           'trust_step']

SAME_MODEL = 'the planner and the monitor must run the same trust model'


@dataclass(frozen=True)
class TrustConfig:
    """Parameters of the trust model (paper: Table I and Section III-C).

    Attributes:
        epsilon_mps2: acceleration offset eps of eq. (8), m/s^2 (paper: 6).
        trust_growth_rate: delta of eq. (10), trust units per second (paper: 0.1 per 1 s
            step).
        performance_threshold: P_thre of eq. (11), dimensionless in (0, 1) (paper: 0.8).
        trust_initial: T(0), trust units.
        trust_model: the registered trust model that turns E into trust
            (``trust_av.trust_models``; ``paper`` = eqs. 9-11 with the three values above).
    """

    epsilon_mps2: float = param('acceleration offset eps of eq. (8)', unit='m/s^2', low=0.0,
                                low_inclusive=False, high=1000.0, reason=SAME_MODEL)
    trust_growth_rate: float = param('trust growth rate delta of eq. (10), per second',
                                     unit='1/s', low=0.0, low_inclusive=False,
                                     high=1000.0, reason=SAME_MODEL)
    performance_threshold: float = param('performance threshold P_thre of eq. (11)', low=0.0,
                                         high=1.0, low_inclusive=False, high_inclusive=False,
                                         reason=SAME_MODEL)
    trust_initial: float = param('initial trust T(0)', low=-1e6, high=1e6,
                                 reason=SAME_MODEL)
    trust_model: str = param('registered trust model (trust_av.trust_models), e.g. paper',
                             reason=SAME_MODEL, default='paper')

    def __post_init__(self) -> None:
        check_fields(self)
        if not re.fullmatch(r'[a-z][a-z0-9_]*', self.trust_model):
            raise ParamsError(f'trust_model must be a registered name (a lower-case '
                              f'identifier), got {self.trust_model!r}')


def explicability(plan: Sequence[Any], expected: Sequence[Any], epsilon_mps2: float) -> Any:
    """Explicability score E of eq. (8), read as the Tanimoto distance
    (docs/concepts/reading-the-paper.md).

    Works on floats (returns a float) and on CasADi symbols (returns an expression).

    Args:
        plan: the AV's planned accelerations u_R^0..u_R^{N-1}, m/s^2.
        expected: the plan the human expects, u_R^H, m/s^2, same length.
        epsilon_mps2: offset eps, m/s^2.

    Returns:
        E, dimensionless; 0 for equal plans.
    """
    if len(plan) != len(expected) or len(plan) == 0:
        raise ValueError(f'plans must have the same non-zero length, got {len(plan)} and '
                         f'{len(expected)}')
    dot = 0.0
    union = 0.0
    for u, e in zip(plan, expected, strict=True):
        a = u + epsilon_mps2
        b = e + epsilon_mps2
        dot = dot + a * b
        union = union + a * a + b * b - a * b
    if isinstance(union, float):
        if union == 0.0:
            return 0.0  # both offset plans are zero: equal plans
        # Rounding can put dot/union a few ulp above 1 for equal plans: E is a distance.
        return min(max(1.0 - dot / union, 0.0), 1.0)
    return 1.0 - dot / union


def performance(score: float) -> float:
    """Performance level P = 1 - tanh(E), eq. (9)."""
    return 1.0 - math.tanh(score)


def trust_input(perf: float, threshold: float) -> float:
    """Trust input u_T of eq. (11): P when P >= P_thre, else -(1 - P)."""
    return perf if perf >= threshold else -(1.0 - perf)


def trust_step(trust: float, score: float, config: TrustConfig, dt_s: float = 1.0) -> float:
    """One trust update over ``dt_s`` seconds: T += delta * dt * u_T (eq. 10 for dt = 1 s).

    Args:
        trust: trust before the update.
        score: explicability E of the plan applied over the interval.
        config: trust model parameters (delta per second).
        dt_s: elapsed time the plan is applied for, s (>= 0).
    """
    return trust + config.trust_growth_rate * dt_s * trust_input(performance(score),
                                                                 config.performance_threshold)


def paper_explicability_bound(trust: float, trust_min: float, config: TrustConfig,
                              steps: int, dt_s: float = 1.0) -> float | None:
    """Largest E whose propagated trust stays >= trust_min over the horizon (eq. 12).

    The constraint ``T^k >= T_min`` for k = 1..N, with ``T^k = T + k * delta * dt * u_T(E)``
    (the per-second rule of :func:`trust_step` on the NMPC's grid of step ``dt_s``),
    depends on the plan only through E, and u_T(E) is non-increasing in E. So the set of
    admissible plans is exactly ``E <= E_max`` with E_max computed here. The NMPC uses this
    smooth inequality instead of the discontinuous if-else of eq. (11): the same feasible
    set, without a jump for the SQP solver. ``tests`` check the equivalence against the
    trust propagated step by step with :func:`trust_step`.

    Args:
        trust: current trust T(t).
        trust_min: T_min of eq. (12).
        config: trust model parameters.
        steps: horizon length N in steps.
        dt_s: the horizon's step, s (the NMPC's prediction grid).

    Returns:
        E_max (>= 1 means no restriction, since E < 1 always), or None when no plan can
        satisfy the constraint (trust cannot climb back to T_min in one step).
    """
    delta = config.trust_growth_rate * dt_s  # trust units per step of the grid
    p_thr = config.performance_threshold
    if trust >= trust_min:
        # u_T >= 0 keeps every T^k >= T >= T_min; u_T < 0 is worst at k = N.
        required = (trust_min - trust) / (steps * delta)
    else:
        # Below T_min now: T^1 must already be back above it, so u_T > 0 is needed.
        required = (trust_min - trust) / delta
    score_threshold = math.atanh(1.0 - p_thr)  # E at which P = P_thre
    if required > 1.0:
        return None
    if required > p_thr:
        return math.atanh(1.0 - required)  # need 1 - tanh(E) >= required
    if required > -(1.0 - p_thr):
        return score_threshold  # only the positive branch of eq. (11) reaches `required`
    if required <= -1.0:
        return math.inf
    return max(math.atanh(-required), score_threshold)  # -tanh(E) >= required


@dataclass(frozen=True)
class MonitorConfig:
    """The trust monitor's time step in lock-step (each update covers ``dt_s`` seconds).

    Attributes:
        dt_s: control step of the lock-step graph, s.
    """

    dt_s: float = param('control step: the time each scored plan is applied for in '
                        'lock-step', unit='s', low=0.0, low_inclusive=False, high=10.0,
                        reason='the step of a deterministic run')

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass(frozen=True)
class TrustEstimate:
    """One step of the monitor: E, P and the trust *after* the update (eq. 10 for
    ``paper``), with its variance when the model has one."""

    explicability: float
    performance: float
    trust: float
    variance: float | None = None


class TrustEstimator:
    """Trust state of the human follower, updated once per control step from observed plans
    (each update scaled by the time the plan is applied for) by a trust model
    (:mod:`trust_monitor.model_interface`).

    Attributes:
        model: the trust model.
        state: its state (for the NMPC's bound); ``trust`` is its trust reading.
    """

    def __init__(self, config: TrustConfig, model: Any = None) -> None:
        """Args:
            config: the shared trust parameters (eps, and ``trust_model``).
            model: the :class:`~trust_monitor.model_interface.TrustModel` to run; None
                builds ``config.trust_model`` with its parameters' defaults.
        """
        # Imported here: the registered models import this module.
        from trust_monitor.model_interface import make_trust_model
        self.config = config
        self.model = make_trust_model(config) if model is None else model
        self.steps_done = 0
        self.state = call(TRUST_MODELS, config.trust_model, 0, 'initial_state()',
                          self.model.initial_state)
        self._reading(self.state)   # the initial trust: a number too

    @property
    def trust(self) -> float:
        """The trust estimate now."""
        return float(self.model.trust(self.state))

    def step(self, plan: Iterable[float], expected: Iterable[float],
             dt_s: float = 1.0) -> TrustEstimate:
        """Score the AV's plan against the expected plan and update the trust.

        Args:
            plan: the AV's plan u_R(t), m/s^2.
            expected: the plan the human expects, u_R^H(t), m/s^2.
            dt_s: time the plan is applied for (the control period), s.

        Raises:
            ValueError: ``dt_s`` is negative or not finite.
            ComponentError: the trust model raised or gave a bad reading.
        """
        if not (math.isfinite(dt_s) and dt_s >= 0.0):
            raise ValueError(f'dt_s must be finite and >= 0, got {dt_s}')
        score = float(explicability(list(plan), list(expected), self.config.epsilon_mps2))
        perf = performance(score)
        try:
            self.state = self.model.step(self.state, score, dt_s)
        except PASSING:
            raise
        except BaseException as err:
            raise raised(TRUST_MODELS, self.config.trust_model, self.steps_done, 'step()',
                         err) from err
        trust, variance = self._reading(self.state)
        self.steps_done += 1
        return TrustEstimate(score, perf, trust, variance)

    def _reading(self, state: Any) -> tuple[float, float | None]:
        """The model's trust and variance of ``state``, checked where they enter the loop
        (:mod:`trust_av_common.component_checks`): trust a finite number, the variance
        None or a finite number >= 0.

        Raises:
            ComponentError: the model raised, or a reading is none of those.
        """
        name, k = self.config.trust_model, self.steps_done
        try:
            trust, variance = self.model.trust(state), self.model.variance(state)
        except PASSING:
            raise
        except BaseException as err:
            raise raised(TRUST_MODELS, name, k, 'its trust() or variance()', err) from err
        trust = check_number(trust, group=TRUST_MODELS, name=name, step=k, what='trust')
        if variance is not None:
            variance = check_number(variance, group=TRUST_MODELS, name=name, step=k,
                                    what='variance', low=0.0)
        return trust, variance


# import-rewrite: off (the old name, on purpose)
def __getattr__(name: str) -> Any:
    """``explicability_bound``, this module's name for :func:`paper_explicability_bound`
    until the cut (one name per concept: :func:`trust_monitor.model_interface.explicability_bound`
    is any model's), still answers for one release, with a warning."""
    if name == 'explicability_bound':
        warnings.warn('trust_monitor.trust_model.explicability_bound is now '
                      'trust_monitor.paper_trust.paper_explicability_bound; the old name goes '
                      'in the next release', MovedPathWarning, stacklevel=2)
        return paper_explicability_bound
    raise AttributeError(f'module {__name__!r} has no attribute {name!r}')
# import-rewrite: on
