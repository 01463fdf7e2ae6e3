"""Intelligent Driver Model (Treiber, Hennecke & Helbing 2000), the car-following baseline.

Two fixed parameter sets are named here: :data:`TEXTBOOK_MOTORWAY` and the physical
bounds of a fit, :data:`FIT_BOUNDS`. The fit itself is in :mod:`human_driver_sim.fitting`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class IdmParams:
    """IDM parameters (SI units); validated on construction."""

    desired_speed_mps: float = 33.0
    time_headway_s: float = 1.5
    min_gap_m: float = 2.0
    max_accel_mps2: float = 1.0
    comfort_decel_mps2: float = 1.5

    def __post_init__(self) -> None:
        for name in ('desired_speed_mps', 'time_headway_s', 'max_accel_mps2',
                     'comfort_decel_mps2'):
            if not getattr(self, name) > 0.0:
                raise ValueError(f'IdmParams.{name} must be positive')
        if self.min_gap_m < 0.0:
            raise ValueError('IdmParams.min_gap_m must be non-negative')


TEXTBOOK_MOTORWAY = IdmParams(desired_speed_mps=120.0 / 3.6, time_headway_s=1.0, min_gap_m=2.0,
                              max_accel_mps2=1.0, comfort_decel_mps2=1.5)
"""IDM for motorway traffic as given by Treiber & Kesting, *Traffic Flow Dynamics* (Springer
2013), Table 11.2: v0 = 120 km/h, T = 1.0 s, s0 = 2 m, a = 1.0 m/s^2, b = 1.5 m/s^2, delta 4."""

FIT_BOUNDS = {'desired_speed_mps': (10.0, 45.0), 'time_headway_s': (0.5, 3.0),
              'min_gap_m': (1.0, 8.0), 'max_accel_mps2': (0.3, 4.0),
              'comfort_decel_mps2': (0.5, 4.0)}
"""Physical bounds of a fitted IDM (b <= 4 m/s^2, s0 >= 1 m, T >= 0.5 s), SI."""
PARAM_NAMES = tuple(FIT_BOUNDS)


def idm_accel_array(params: IdmParams, gap_m: np.ndarray, speed_mps: np.ndarray,
                    leader_speed_mps: np.ndarray) -> np.ndarray:
    """IDM accelerations for many states at once, m/s^2 (the gap floored at 0.1 m)."""
    speed = np.asarray(speed_mps, dtype=float)
    star = params.min_gap_m + np.maximum(
        0.0, speed * params.time_headway_s + speed * (speed - leader_speed_mps)
        / (2.0 * np.sqrt(params.max_accel_mps2 * params.comfort_decel_mps2)))
    ratio = (speed / params.desired_speed_mps) ** 4
    return np.asarray(params.max_accel_mps2
                      * (1.0 - ratio - (star / np.maximum(gap_m, 0.1)) ** 2), dtype=float)


def idm_accel(params: IdmParams, gap_m: float, speed_mps: float, leader_speed_mps: float) -> float:
    """IDM acceleration, m/s^2."""
    star = params.min_gap_m + max(0.0, speed_mps * params.time_headway_s + speed_mps
                                  * (speed_mps - leader_speed_mps)
                                  / (2.0 * np.sqrt(params.max_accel_mps2
                                                   * params.comfort_decel_mps2)))
    ratio = (speed_mps / params.desired_speed_mps) ** 4
    return float(params.max_accel_mps2 * (1.0 - ratio - (star / max(gap_m, 0.1)) ** 2))
