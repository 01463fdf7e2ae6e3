"""Constant-acceleration (CA) plan estimator: the AV's last observed acceleration, held."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from trust_av_common.registry import Component
from trust_av_planner.predictors import Observation

if TYPE_CHECKING:
    from trust_av_planner.nmpc import PlannerConfig

__all__ = ['COMPONENT', 'ConstantAccelerationPredictor']


class ConstantAccelerationPredictor:
    """u_R^H = (u_R(t-1), ..., u_R(t-1)); zero before the first observation.

    Args:
        horizon_steps: N.
        accel_min_mps2: lower clip of the prediction (the AV's bound).
        accel_max_mps2: upper clip of the prediction.
    """

    def __init__(self, horizon_steps: int, accel_min_mps2: float, accel_max_mps2: float) -> None:
        self.horizon_steps = horizon_steps
        self.accel_min_mps2 = accel_min_mps2
        self.accel_max_mps2 = accel_max_mps2
        self._last = 0.0

    def reset(self) -> None:
        """Forget the last acceleration."""
        self._last = 0.0

    def predict(self) -> np.ndarray:
        """The last observed acceleration held over the horizon."""
        accel = min(max(self._last, self.accel_min_mps2), self.accel_max_mps2)
        return np.full(self.horizon_steps, accel)

    def observe(self, observation: Observation) -> None:
        """Keep the executed acceleration."""
        self._last = observation.av_accel_mps2


def build(planner: PlannerConfig, params: None) -> ConstantAccelerationPredictor:
    """The CA estimator on the planner's horizon and acceleration bounds (no parameters)."""
    return ConstantAccelerationPredictor(planner.horizon_steps, planner.accel_min_mps2,
                                         planner.accel_max_mps2)


COMPONENT = Component(
    name='ca', factory=build,
    description="constant acceleration: the AV's last executed acceleration, held (TAC-CA)")
"""Registered as ``ca`` in ``trust_av.predictors`` (trust_av_planner's setup.py)."""
