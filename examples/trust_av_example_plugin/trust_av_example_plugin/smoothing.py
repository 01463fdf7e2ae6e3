"""A smoothed, damped acceleration plan estimator (``predictor: ses``).

The human is assumed to track the AV's acceleration with exponential smoothing and to expect
it to fade over the horizon (a damped trend, as in Gardner's damped-trend smoothing)::

    a_hat(t) = a_hat(t-1) + lambda * (u_R(t-1) - a_hat(t-1))      (a_hat = 0 at the start)
    u_R^H,k  = phi^k * a_hat(t),  k = 1..N, clipped to [u_R,min, u_R,max]

``lambda = 1, phi = 1`` is the constant-acceleration estimator (TAC-CA); ``phi = 0`` the
constant-velocity one. It uses only the AV's executed acceleration, so it declares no
``follower_state`` need and works without the follower's odometry.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from trust_av_common.params import check_fields, param
from trust_av_common.registry import Component
from trust_av_planner.nmpc import PlannerConfig
from trust_av_planner.predictors import Observation


@dataclass(frozen=True)
class SmoothingConfig:
    """The estimator's parameters: declared as ROS parameters of the planner node and read
    from its params-file section (``/**/planner``), each with a default."""

    ses_smoothing: float = param('smoothing factor lambda of the acceleration estimate',
                                 low=0.0, high=1.0, low_inclusive=False, default=0.5)
    ses_damping: float = param('damping phi per model step of the expected acceleration',
                               low=0.0, high=1.0, default=0.8)

    def __post_init__(self) -> None:
        check_fields(self)  # ranges of param(); raises ParamsError naming the parameter


class SmoothedDampedPredictor:
    """The estimator's state and its three methods (the Predictor interface).

    Args:
        horizon_steps: N, predictions per call.
        accel_min_mps2: lower clip of the prediction, m/s^2.
        accel_max_mps2: upper clip of the prediction, m/s^2.
        config: lambda and phi.
    """

    def __init__(self, horizon_steps: int, accel_min_mps2: float, accel_max_mps2: float,
                 config: SmoothingConfig) -> None:
        self.decay = config.ses_damping ** np.arange(1, horizon_steps + 1)
        self.accel_min_mps2 = accel_min_mps2
        self.accel_max_mps2 = accel_max_mps2
        self.smoothing = config.ses_smoothing
        self.estimate_mps2 = 0.0

    def reset(self) -> None:
        """Forget the estimate."""
        self.estimate_mps2 = 0.0

    def observe(self, observation: Observation) -> None:
        """Smooth in the acceleration the AV just executed."""
        self.estimate_mps2 += self.smoothing * (observation.av_accel_mps2 - self.estimate_mps2)

    def predict(self) -> np.ndarray:
        """The damped estimate over the horizon, m/s^2."""
        plan: np.ndarray = np.clip(self.estimate_mps2 * self.decay, self.accel_min_mps2,
                                   self.accel_max_mps2)
        return plan


def build(planner: PlannerConfig, params: SmoothingConfig) -> SmoothedDampedPredictor:
    """The factory trust-av calls: the planner's parameters and this component's."""
    return SmoothedDampedPredictor(planner.horizon_steps, planner.accel_min_mps2,
                                   planner.accel_max_mps2, params)


COMPONENT = Component(
    name='ses', factory=build, config_type=SmoothingConfig,
    description='smoothed, damped acceleration (exponential smoothing, damped over the '
                'horizon)')
"""What the entry point ``ses`` in ``pyproject.toml`` names."""
