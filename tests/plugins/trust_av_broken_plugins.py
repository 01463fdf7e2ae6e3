"""Deliberately broken plug-ins, one per way a component can break its interface: each
works for its first :data:`GOOD_STEPS` steps, then gives a bad output (NaN, inf, the wrong
shape, the wrong type, out of its bounds), raises, or exits; and factories that raise,
return the wrong type or have the wrong signature. Installed with real entry points by
``tests/support/broken_plugins.py``; never shipped."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from human_driver_sim.driver_mpc import DriverResult
from trust_av_common.registry import Component

GOOD_STEPS = 3
"""Steps each broken component gets right before it breaks (the recording keeps them)."""


def bad_plan(mode: str, steps: int, high: float) -> Any:
    """A plan of ``steps`` values broken the way ``mode`` says."""
    if mode == 'nan':
        return np.full(steps, math.nan)
    if mode == 'inf':
        return np.full(steps, -math.inf)
    if mode == 'nan_short':                     # the follower: NaN, wrong length
        return np.full(steps - 2, math.nan)
    if mode == 'long':                          # three values too many
        return np.zeros(steps + 3)
    if mode == 'text':
        return ['fast'] * steps
    if mode == 'none':
        return None
    if mode == 'big':
        return np.full(steps, high + 5.0)
    if mode == 'raise':
        raise RuntimeError('broken on purpose')
    if mode == 'exit':
        raise SystemExit(0)
    raise AssertionError(mode)


class Predictor:
    """A plan estimator that predicts zeros, then breaks."""

    def __init__(self, planner: Any, mode: str) -> None:
        self.steps, self.high, self.mode, self.calls = (planner.horizon_steps,
                                                        planner.accel_max_mps2, mode, 0)

    def reset(self) -> None:
        self.calls = 0

    def observe(self, observation: Any) -> None:
        pass

    def predict(self) -> Any:
        self.calls += 1
        if self.calls <= GOOD_STEPS:
            return np.zeros(self.steps)
        return bad_plan(self.mode, self.steps, self.high)


class Follower:
    """A follower that coasts, then breaks."""

    def __init__(self, driver: Any, mode: str) -> None:
        self.steps, self.high, self.mode, self.calls = (driver.horizon_steps,
                                                        driver.accel_max_mps2, mode, 0)

    def reset(self) -> None:
        self.calls = 0

    def step(self, gap_m: float, speed_mps: float, av_speed_mps: float,
             expected_mps2: Any) -> Any:
        self.calls += 1
        if self.calls <= GOOD_STEPS:
            return DriverResult(np.zeros(self.steps), 'coast', True, 0, 0.0)
        if self.mode == 'array':                 # the plan alone, not a DriverResult
            return np.zeros(self.steps)
        return DriverResult(bad_plan(self.mode, self.steps, self.high), 'broken', True, 0, 0.0)


class TrustModel:
    """Trust that stays at 0.9 (state: the steps taken), then reads badly."""

    closed_form_bound = None

    def __init__(self, name: str, mode: str) -> None:
        self.name, self.mode = name, mode

    def initial_state(self) -> int:
        return 0

    def step(self, state: int, score: float, dt_s: float) -> int:
        if state >= GOOD_STEPS and self.mode in ('raise', 'exit'):
            bad_plan(self.mode, 1, 0.0)
        return state + 1

    def trust(self, state: int) -> Any:
        if state <= GOOD_STEPS or self.mode in ('raise', 'exit', 'negative_variance'):
            return 0.9
        return {'nan': math.nan, 'inf': math.inf, 'text': 'high'}[self.mode]

    def variance(self, state: int) -> float | None:
        return -1.0 if self.mode == 'negative_variance' and state > GOOD_STEPS else None


def _component(name: str, factory: Any) -> Component:
    return Component(name=name, factory=factory, description='broken on purpose')


def _predictor(mode: str) -> Component:
    return _component(f'broken_{mode}', lambda planner, params: Predictor(planner, mode))


def _follower(mode: str) -> Component:
    return _component(f'broken_{mode}', lambda driver, params: Follower(driver, mode))


def _trust(mode: str) -> Component:
    return _component(f'broken_{mode}', lambda trust, params: TrustModel(f'broken_{mode}', mode))


def _raising_factory(planner: Any, params: Any) -> Any:
    raise ValueError('cannot build this one')


PREDICTOR_MODES = ('nan', 'inf', 'nan_short', 'long', 'text', 'none', 'big', 'raise', 'exit')
FOLLOWER_MODES = ('nan', 'nan_short', 'array', 'big', 'raise', 'exit')
TRUST_MODES = ('nan', 'inf', 'text', 'negative_variance', 'raise', 'exit')
PREDICTORS = {f'broken_{m}': _predictor(m) for m in PREDICTOR_MODES}
FOLLOWERS = {f'broken_{m}': _follower(m) for m in FOLLOWER_MODES}
TRUST_MODELS = {f'broken_{m}': _trust(m) for m in TRUST_MODES}
FACTORIES = {
    'broken_factory_raises': _component('broken_factory_raises', _raising_factory),
    'broken_factory_type': _component('broken_factory_type', lambda planner, params: 42),
    'broken_signature': _component('broken_signature', lambda planner: Predictor(planner, '')),
}
"""Plan estimators whose factory breaks (they register in trust_av.predictors)."""

ENTRY_POINTS = {'trust_av.predictors': {**PREDICTORS, **FACTORIES},
                'trust_av.drivers': FOLLOWERS, 'trust_av.trust_models': TRUST_MODELS}
"""Group -> name -> component: what tests/support/broken_plugins.py registers."""
for _group, _table in ENTRY_POINTS.items():
    for _name, _component_of in _table.items():   # an entry point names a module attribute
        globals()[f'{_group.rsplit(".", 1)[-1].upper()}_{_name}'] = _component_of
