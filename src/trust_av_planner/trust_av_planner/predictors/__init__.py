"""Estimators of the plan the human driver expects from the AV, u_R^H (Section III-B).

Every predictor follows one interface: :meth:`Predictor.predict` gives the N expected
accelerations from what the human has seen up to the previous step, and
:meth:`Predictor.observe` adds the step just executed to the history.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np


@dataclass(frozen=True)
class Observation:
    """What the human sees of the AV at the end of a step, eq. (6).

    Attributes:
        gap_m: d_H, human's bumper-to-bumper gap to the AV, m.
        relative_speed_mps: rs_H = v_R - v_H, m/s.
        time_headway_s: tau_H = d_H / v_H (capped), s.
        av_accel_mps2: u_R, the acceleration the AV executed, m/s^2.
    """

    gap_m: float
    relative_speed_mps: float
    time_headway_s: float
    av_accel_mps2: float


class Predictor(Protocol):
    """Interface of a plan estimator."""

    def reset(self) -> None:
        """Forget the history."""

    def predict(self) -> np.ndarray:
        """Expected AV plan u_R^H over the horizon, m/s^2."""

    def observe(self, observation: Observation) -> None:
        """Record the step just executed."""
