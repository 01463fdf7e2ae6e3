"""Constant-velocity (CV) plan estimator: the human expects the AV to keep its current speed.

u_R^H = (0, ..., 0): zero acceleration over the whole horizon, whatever the AV did. It is
the naive baseline below constant acceleration (which holds the last executed acceleration):
a human who assumes no change of speed. It observes nothing and needs nothing; the zero
plan is always within the AV's bounds (u_R,min < 0 < u_R,max, Table I).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from trust_av_common.registry import Component
from trust_av_planner.predictors import Observation

if TYPE_CHECKING:
    from trust_av_planner.nmpc import PlannerConfig

__all__ = ['COMPONENT']


class ConstantVelocityPredictor:
    """u_R^H = 0 over the horizon: the AV is expected to keep its current speed.

    Args:
        horizon_steps: N.
    """

    def __init__(self, horizon_steps: int) -> None:
        self.horizon_steps = horizon_steps

    def reset(self) -> None:
        """Nothing to forget."""

    def predict(self) -> np.ndarray:
        """Zero acceleration over the horizon, m/s^2."""
        return np.zeros(self.horizon_steps)

    def observe(self, observation: Observation) -> None:
        """Ignored: the expectation does not depend on what the AV did."""


def build(planner: PlannerConfig, params: None) -> ConstantVelocityPredictor:
    """The CV estimator on the planner's horizon (no parameters)."""
    return ConstantVelocityPredictor(planner.horizon_steps)


COMPONENT = Component(
    name='cv', factory=build,
    description='constant velocity: the AV is expected to keep its speed (zero acceleration)')
"""Registered as ``cv`` in ``trust_av.predictors`` (trust_av_planner's setup.py)."""
