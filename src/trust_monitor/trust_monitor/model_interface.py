"""The trust-model interface: one update rule that the monitor, the NMPC and the tables share.

A trust model turns the explicability score E of each applied plan (eq. 8, scored by
:func:`trust_monitor.paper_trust.explicability`) into a trust estimate. Everything here is
pure (no ROS, no wall clock, no randomness).

**Per-second rule.** :meth:`TrustModel.step` advances the state over ``dt_s`` seconds during
which a plan with score E is applied. It must be *time-consistent*: ten steps of 0.1 s with
the same E give the state of one 1 s step (within rounding), and one 1 s step is the model's
own discrete equation (the paper's eq. (10) for ``paper``).
``tests/core/test_trust_model_contract.py`` holds every registered model to it.

**What the NMPC needs.** The trust constraint of eq. (12), ``T^k >= T_min`` for k = 1..N on
the NMPC's grid, depends on the plan only through E (the plan is scored once and its E
is assumed kept over the horizon, as in the paper). :func:`numeric_bound` derives the
largest admissible E *from the update itself*: it propagates :meth:`TrustModel.step` over
the horizon and bisects over E in [0, 1]. A model may give a closed form
(:attr:`TrustModel.closed_form_bound`, not None); the NMPC then uses it and the contract test
holds it to the numeric one.

**Monotonicity (assumed, checked by the contract test).** Bisection needs the admissible set
to be an interval ``[0, E_max]``: trust after a step must not increase with E. Every
shipped model satisfies this (the performance P = 1 - tanh E falls with E and each update
is non-decreasing in P); the contract test checks it on a grid for every registered
model, including plug-ins.

**Registration.** A model is a :class:`trust_av_common.registry.Component` in the
entry-point group ``trust_av.trust_models``; its ``factory(trust, params)`` takes the shared
:class:`~trust_monitor.paper_trust.TrustConfig` (eps, the paper's delta, P_thre, T(0)) and
an instance of its own ``config_type`` (None when it has none) and returns a
:class:`TrustModel`. A model's own parameters are fields of its ``config_type`` whose names
start with the model's name (``asymmetric_loss_ratio``), declared as ROS parameters like
every other (``docs/concepts/trust-models.md``).

**A fast path over a whole drive (optional).** A model may also give ``trajectory(scores,
dts_s)``: its trust (own units) after each step of a drive started from
:meth:`TrustModel.initial_state`, computed at once (numpy) instead of step by step; the fit
(:mod:`trust_monitor.trust_fit`) runs models through :func:`trust_trajectory`, which uses it
when present and the step loop otherwise (a plug-in needs only ``step``).
``tests/core/test_trust_model_contract.py`` holds every registered model's fast path to its
step loop (1e-12 on random drives).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, Protocol, runtime_checkable

import numpy as np

from trust_av_common.component_checks import PASSING, call, check_number, raised
from trust_av_common.params import build_config
from trust_av_common.registry import Component, build, config_types, declare, get

__all__ = ['TRUST_MODELS', 'CheckedBound', 'ClosedForm', 'FitParameter', 'TrustModel',
           'UnitTrust', 'build_trust_model', 'common_trust', 'explicability_bound',
           'fit_parameters', 'make_trust_model', 'numeric_bound', 'paper_bound_holds',
           'step_trajectory', 'trust_ceiling', 'trust_model_component',
           'trust_model_config_types', 'trust_trajectory', 'unit_trust']

TRUST_MODELS = declare('trust_av.trust_models', factory_arguments=('trust', 'params'),
                       interface=('name', 'closed_form_bound', 'initial_state', 'step', 'trust',
                                  'variance'))
"""Entry-point group of the trust models (trust from the explicability score), declared here
beside their interface: ``factory(trust, params)`` returns a :class:`TrustModel`."""

BOUND_TOLERANCE = 1e-12
"""Bisection stops when the bracket of E_max is this narrow (E is dimensionless, < 1)."""

ClosedForm = Callable[[Any, float, int, float], 'float | None']


@runtime_checkable
class TrustModel(Protocol):
    """A trust model: a state, its per-second update and its readings.

    Attributes:
        name: the registered name.
        closed_form_bound: None, or a function ``(state, trust_min, steps, dt_s)`` giving
            what :func:`numeric_bound` computes, in closed form (None: no plan is
            admissible; ``>= 1``: no restriction).

    Optional: a class attribute ``paper_bound_holds = True`` declares that the model runs
    eqs. (9)-(11) with the shared parameters (:func:`paper_bound_holds`); an attribute
    ``ceiling = (T0, rate_per_s)`` declares that its trust never exceeds ``T0 + rate_per_s *
    t`` (t in s since the start: what a perfectly explicable AV earns), which plots draw
    (:func:`trust_ceiling`; a model without one gets no such line); ``fit_parameters``
    declares what ratings may fit (:func:`fit_parameters`); ``trust_range`` maps its trust
    units to the common scale (:func:`common_trust`).
    """

    name: str
    closed_form_bound: ClosedForm | None

    def initial_state(self) -> Any:
        """The state before the first update (immutable: a float or a frozen dataclass)."""

    def step(self, state: Any, score: float, dt_s: float) -> Any:
        """The state after a plan with explicability ``score`` is applied for ``dt_s`` s.

        Args:
            state: the state before (not modified).
            score: explicability E of the applied plan, dimensionless, in [0, 1].
            dt_s: elapsed time, s (>= 0).
        """

    def trust(self, state: Any) -> float:
        """The trust estimate of ``state``, in the model's own trust units."""

    def variance(self, state: Any) -> float | None:
        """The variance of the trust estimate (trust units squared), None if the model
        has no uncertainty."""


@dataclass(frozen=True)
class FitParameter:
    """A parameter of a trust model that ``trust-av fit-trust`` may fit to ratings.

    A model declares them in an optional class attribute ``fit_parameters`` (a tuple of
    these; absent: none, the fit then adjusts only the rating observation model). The
    name is a field of the shared :class:`~trust_monitor.paper_trust.TrustConfig` or of the
    model's own ``config_type``.

    Attributes:
        name: the parameter's name (as in a params file).
        low: smallest value tried.
        high: largest value tried.
        prior_mean: mean of the prior (a normal, on the log scale when ``log_scale``).
        prior_std: its standard deviation (same scale).
        log_scale: the parameter is positive and searched (and its prior is) in log.
        identifiable: False when ratings cannot determine it (the reason in ``note``); the
            fit still reports it, the recovery benchmark gives it no correlation.
        note: why it is not identifiable, or '' .
    """

    name: str
    low: float
    high: float
    prior_mean: float
    prior_std: float
    log_scale: bool = False
    identifiable: bool = True
    note: str = ''

    def __post_init__(self) -> None:
        if not (math.isfinite(self.low) and math.isfinite(self.high) and self.low < self.high
                and self.prior_std > 0.0) or (self.log_scale and self.low <= 0.0):
            raise ValueError(f'fit parameter {self.name!r}: need finite low < high, '
                             f'prior_std > 0 and low > 0 on a log scale')


def fit_parameters(model: TrustModel) -> tuple[FitParameter, ...]:
    """The parameters ``model`` declares fittable (attribute ``fit_parameters``; () when it
    declares none).

    Raises:
        TypeError: the attribute is not a tuple of :class:`FitParameter`.
    """
    declared = getattr(model, 'fit_parameters', ())
    if not isinstance(declared, tuple) or not all(isinstance(p, FitParameter)
                                                   for p in declared):
        raise TypeError(f'trust model {getattr(model, "name", model)!r}: fit_parameters must '
                        'be a tuple of FitParameter')
    return declared


COMMON_SCALE = (0.0, 1.0)
"""The scale on which every model's trust is compared with ratings (rating / 100)."""


class UnitTrust(float):
    """A trust on the common scale [0, 1] (:data:`COMMON_SCALE`), made by :func:`unit_trust`
    (the one conversion). What compares a model's trust with ratings or with another model
    (a table, a figure, a topic, a fit) takes this type, so a model's own reading, a plain
    float, is refused: by mypy, and by ``isinstance`` where a plug-in's value enters.
    Arithmetic on it gives a plain float (a difference is no trust)."""


def unit_trust(model: TrustModel, reading: float) -> UnitTrust:
    """``reading``, a trust of ``model`` in its own units, on the common scale [0, 1].

    A model declares how its units map to it with an optional attribute
    ``trust_range = (low, high)``: common = (T - low) / (high - low), clipped to [0, 1].
    Without it the model's trust is taken to be on [0, 1] already (and is clipped).
    """
    low, high = getattr(model, 'trust_range', COMMON_SCALE)
    value = (float(reading) - low) / (high - low)
    return UnitTrust(min(max(value, 0.0), 1.0))


def common_trust(model: TrustModel, state: Any) -> UnitTrust:
    """The trust of ``state`` on the common scale [0, 1] (:func:`unit_trust` of its
    reading)."""
    return unit_trust(model, model.trust(state))


def propagate(model: TrustModel, state: Any, score: float, steps: int,
              dt_s: float) -> list[float]:
    """Trust after each of ``steps`` steps of ``dt_s`` if a plan with score E were kept.

    Args:
        model: the trust model.
        state: the state now.
        score: E kept over the horizon.
        steps: horizon length N in steps.
        dt_s: step of the horizon, s.

    Returns:
        T^1..T^N.
    """
    out = []
    for _ in range(steps):
        state = model.step(state, score, dt_s)
        out.append(model.trust(state))
    return out


def step_trajectory(model: TrustModel, scores: np.ndarray, dts_s: np.ndarray) -> np.ndarray:
    """The model's trust (own units) after each step of a drive from its initial state, by
    :meth:`TrustModel.step` (the reference the fast path is held to).

    Args:
        model: the trust model.
        scores: E applied in each step, in [0, 1].
        dts_s: each step's length, s (>= 0), as many as ``scores``.
    """
    state, step, trust = model.initial_state(), model.step, model.trust
    out = np.empty(len(scores))
    for i, (score, dt) in enumerate(zip(np.asarray(scores, float).tolist(),
                                        np.asarray(dts_s, float).tolist(), strict=True)):
        state = step(state, score, dt)
        out[i] = trust(state)
    return out


def trust_trajectory(model: TrustModel, scores: np.ndarray, dts_s: np.ndarray) -> np.ndarray:
    """:func:`step_trajectory`, through the model's own ``trajectory`` when it gives one
    (the module docstring: the fast path; same arguments and result).

    Raises:
        ValueError: ``scores`` and ``dts_s`` are not 1-D arrays of the same length.
    """
    scores, dts_s = np.asarray(scores, float), np.asarray(dts_s, float)
    if scores.ndim != 1 or scores.shape != dts_s.shape:
        raise ValueError(f'need scores and step lengths of one drive, as many of each, got '
                         f'shapes {scores.shape} and {dts_s.shape}')
    fast = getattr(model, 'trajectory', None)
    if fast is None:
        return step_trajectory(model, scores, dts_s)
    return np.asarray(fast(scores, dts_s), float)


def admissible(model: TrustModel, state: Any, score: float, trust_min: float, steps: int,
               dt_s: float) -> bool:
    """Whether keeping E = ``score`` keeps every propagated T^k >= ``trust_min``."""
    return min(propagate(model, state, score, steps, dt_s)) >= trust_min


def numeric_bound(model: TrustModel, state: Any, trust_min: float, steps: int,
                  dt_s: float) -> float | None:
    """Largest E whose propagated trust stays >= ``trust_min`` over the horizon, by
    bisection on the model's own update (monotone in E: see the module docstring).

    Args:
        model: the trust model.
        state: its state now.
        trust_min: T_min of eq. (12), trust units.
        steps: horizon N in steps (>= 1).
        dt_s: the horizon's step, s (> 0).

    Returns:
        An admissible E_max (the lower end of the final bracket, so the propagated update
        at the returned value satisfies the constraint); ``math.inf`` when E = 1 is
        admissible (no restriction, E < 1 always); None when not even E = 0 is.

    Raises:
        ValueError: ``steps`` < 1 or ``dt_s`` <= 0.
    """
    if steps < 1 or not dt_s > 0.0:
        raise ValueError(f'need steps >= 1 and dt_s > 0, got {steps} and {dt_s}')
    if not admissible(model, state, 0.0, trust_min, steps, dt_s):
        return None
    if admissible(model, state, 1.0, trust_min, steps, dt_s):
        return math.inf
    low, high = 0.0, 1.0
    while high - low > BOUND_TOLERANCE:
        mid = 0.5 * (low + high)
        if admissible(model, state, mid, trust_min, steps, dt_s):
            low = mid
        else:
            high = mid
    return low


def explicability_bound(model: TrustModel, state: Any, trust_min: float, steps: int,
                        dt_s: float) -> float | None:
    """What the NMPC's trust constraint uses: the model's closed form when it gives one,
    else :func:`numeric_bound` (same arguments and meaning)."""
    if model.closed_form_bound is not None:
        return model.closed_form_bound(state, trust_min, steps, dt_s)
    return numeric_bound(model, state, trust_min, steps, dt_s)


class CheckedBound:
    """:func:`explicability_bound` as the NMPC takes it, checked where it enters
    (:mod:`trust_av_common.component_checks`): None, inf, or a number >= 0; anything
    the model raises on the way names it, and so does a propagated trust that is no finite
    number where the bound fails or admits no E (NaN compares false).

    Args:
        model: the trust model.
        name: its registered name (for the message, with the count of bounds taken).
    """

    def __init__(self, model: TrustModel, name: str) -> None:
        self.model = model
        self.name = name
        self.steps_done = 0

    def __call__(self, state: Any, trust_min: float, steps: int, dt_s: float) -> float | None:
        """:func:`explicability_bound` of the model (same arguments and result).

        Raises:
            ComponentError: the model raised, or the bound is none of those.
        """
        k = self.steps_done   # the trust of `state`: checked by the TrustEstimator that made it
        try:
            e_max = explicability_bound(self.model, state, trust_min, steps, dt_s)
        except PASSING:
            raise
        except BaseException as err:
            self._propagated(state, steps, dt_s)   # names the bad reading, if one
            raise raised(TRUST_MODELS, self.name, k, 'the explicability bound', err) from err
        if e_max is None:          # no E keeps T >= T_min: or a reading that is no number?
            self._propagated(state, steps, dt_s)
        elif e_max != math.inf:
            check_number(e_max, group=TRUST_MODELS, name=self.name, step=k, what='E_max',
                         low=0.0)
        self.steps_done += 1
        return e_max

    def _propagated(self, state: Any, steps: int, dt_s: float) -> None:
        """Check the trust the model propagates from ``state`` at E = 0 and E = 1 (where
        the bound failed or found no admissible E: what a bad reading inside it looks
        like).

        Raises:
            ComponentError: a propagated trust is not a finite number, or a step raised.
        """
        k = self.steps_done
        for score in (0.0, 1.0):
            after = state
            for _ in range(steps):
                after = call(TRUST_MODELS, self.name, k, 'step()', self.model.step, after,
                             score, dt_s)
                check_number(call(TRUST_MODELS, self.name, k, 'trust()', self.model.trust,
                                  after),
                             group=TRUST_MODELS, name=self.name, step=k,
                             what=f'propagated trust (E = {score:g})')


def paper_bound_holds(model: TrustModel) -> bool:
    """Whether ``model`` declares that it runs eqs. (9)-(11) with the shared
    :class:`~trust_monitor.paper_trust.TrustConfig` (class attribute
    ``paper_bound_holds = True``): the final-trust bound of :mod:`trust_monitor.final_trust_bound`
    and the tables' column built on it hold only then."""
    return getattr(model, 'paper_bound_holds', False) is True


def trust_ceiling(model: TrustModel) -> tuple[float, float] | None:
    """The ceiling ``(T0, rate_per_s)`` that ``model`` declares (its ``ceiling`` attribute:
    trust never exceeds ``T0 + rate_per_s * t``), or None when it declares none or not two
    finite numbers."""
    ceiling = getattr(model, 'ceiling', None)
    if not (isinstance(ceiling, tuple) and len(ceiling) == 2
            and all(isinstance(v, (int, float)) and not isinstance(v, bool)
                    and math.isfinite(v) for v in ceiling)):
        return None
    return float(ceiling[0]), float(ceiling[1])


def trust_model_component(name: str) -> Component:
    """The registered trust model ``name`` (the registry scans the entry points once per
    process).

    Raises:
        RegistryError: not registered (one line listing the registered names).
    """
    return get(TRUST_MODELS, name)


def trust_model_config_types() -> tuple[type, ...]:
    """The ``config_type`` of every registered trust model (their parameters are known
    names in params files whichever model runs)."""
    return config_types(TRUST_MODELS)


def make_trust_model(trust: Any, values: Mapping[str, Any] | None = None) -> TrustModel:
    """Build the model that ``trust.trust_model`` names.

    Args:
        trust: the shared :class:`~trust_monitor.paper_trust.TrustConfig`.
        values: parameter name to value for the model's own ``config_type`` (missing
            names take the dataclass defaults); ignored keys belong to other components.

    Raises:
        RegistryError: the model is not registered.
        ParamsError: a parameter of the model has a wrong type or is out of range.
    """
    component = trust_model_component(trust.trust_model)
    params: Any = None
    if component.config_type is not None:
        params = build_config(component.config_type, dict(values or {}))
    return build_trust_model(trust, params)


def build_trust_model(trust: Any, params: Any) -> TrustModel:
    """The model ``trust.trust_model`` names, from its parameters already built (a node
    declares them: :func:`trust_av_common.ros.parameters.declare_component_params`).

    Raises:
        RegistryError: the model is not registered, its factory failed or returned no
            :class:`TrustModel`.
    """
    component = trust_model_component(trust.trust_model)
    model: TrustModel = build(TRUST_MODELS, component, trust, params)
    return model
